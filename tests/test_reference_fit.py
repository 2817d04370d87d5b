"""eval.analyses.reference_fit: how much of a real log's AUROC shortfall lies where the SLAM reference fits its own
map badly, and on which side a wrong scan's better fit is."""

from __future__ import annotations

import numpy as np

from eval.analyses.reference_fit import alarm_fits, auroc_where_reference_fits, who_fits_better
from irmcl_warp.mcl.confidence import auroc


def test_the_auroc_is_read_again_over_the_scans_whose_reference_fits(rng):
    n = 4000
    ref_fit = rng.uniform(0.3, 1.0, n)
    doubtful = ref_fit < 0.7  # where the reference fits its map badly, the labels are noise the confidence cannot see
    hit = np.where(doubtful, rng.random(n) < 0.5, rng.random(n) < 0.9)
    conf = np.where(doubtful, rng.random(n), np.where(hit, rng.uniform(0.6, 1.0, n), rng.uniform(0.0, 0.5, n)))
    rows = auroc_where_reference_fits(conf, hit, ref_fit, thresholds=(0.0, 0.7, 1.01))
    assert [r["reference_agreement_at_least"] for r in rows] == [0.0, 0.7, 1.01]
    assert rows[0]["share_of_scans"] == 1.0 and rows[0]["wrong"] == int((~hit).sum())
    assert abs(rows[0]["auroc"] - auroc(conf, hit)) < 1e-12
    assert rows[1]["share_of_scans"] == np.mean(ref_fit >= 0.7) and rows[1]["wrong"] == int((~hit & ~doubtful).sum())
    assert rows[1]["auroc"] == 1.0 and rows[0]["auroc"] < 0.9  # the shortfall lay where the reference was in doubt
    assert rows[2] == {"reference_agreement_at_least": 1.01, "share_of_scans": 0.0, "wrong": 0, "auroc": None}


def test_a_threshold_that_leaves_only_right_scans_has_no_auroc(rng):
    hit = np.array([True, True, False, True])
    rows = auroc_where_reference_fits(rng.random(4), hit, np.array([0.9, 0.95, 0.5, 0.99]), thresholds=(0.8,))
    assert rows[0]["wrong"] == 0 and rows[0]["auroc"] is None and rows[0]["share_of_scans"] == 0.75


def test_which_pose_fits_a_wrong_scan_better_counts_only_beyond_the_margin():
    at_estimate = np.array([0.90, 0.50, 0.70, 0.71])
    at_reference = np.array([0.60, 0.80, 0.70, 0.70])  # the last two are a tie within the margin
    w = who_fits_better(at_estimate, at_reference, margin=0.02)
    assert w["scans"] == 4 and w["estimate_fits_better"] == 0.25 and w["reference_fits_better"] == 0.25
    assert w["median_at_estimate"] == np.median(at_estimate) and w["median_at_reference"] == 0.70
    assert who_fits_better([], []) == {"scans": 0}


def test_scans_are_found_by_stamp_in_a_log_whose_stamps_go_back(rng):
    """intel's log keeps its scans in recording order, 631 of them stamped before the one before: the SLAM poses
    (sorted by stamp) still find their scans through ``match_stamps``, which reference_fit uses."""
    from irmcl_warp.types import match_stamps

    stamps = 100.0 + 0.2 * np.arange(500)
    log_order = rng.permutation(500)  # the log's scans in another order than their stamps
    k = match_stamps(stamps[log_order], stamps[::3])
    assert (k >= 0).all() and np.array_equal(stamps[log_order][k], stamps[::3])
    k = match_stamps(stamps[log_order], stamps[::3] + 0.05)  # no scan stamped there
    assert not (k >= 0).any()


def test_an_alarm_on_a_right_estimate_is_read_with_the_fit_of_the_scans_its_rule_read(rng):
    """Only events whose last scan before was right are false alarms; each carries the lowest agreement of the scans
    in the window before it, at the estimate and at the SLAM pose, and whether the SLAM pose too fell below the bar."""
    t = np.arange(0.0, 30.0, 0.1)
    ok = np.ones(len(t), bool)
    ok[(t > 19.0) & (t < 21.0)] = False  # wrong before the event at 20 s: not a false alarm
    fit_est = rng.uniform(0.8, 1.0, len(t))
    fit_ref = rng.uniform(0.8, 1.0, len(t))
    fit_est[np.isclose(t, 9.0)], fit_ref[np.isclose(t, 9.0)] = 0.1, 0.2  # at 10 s the map fits nowhere
    fit_est[np.isclose(t, 28.0)] = 0.3  # at 28.5 s only the estimate fits badly
    fit_ref[(t > 5.0) & (t < 6.0)] = 0.0  # outside every window: not read
    events = alarm_fits([10.0, 20.0, 28.5], t, ok, fit_est, fit_ref, below=0.4, window_s=2.0)
    assert [e["at_s"] for e in events] == [10.0, 28.5]
    first, last = events
    assert first["lowest_at_estimate"] == 0.1 and first["lowest_at_reference"] == 0.2 and first["reference_below_bar"]
    assert last["lowest_at_estimate"] == 0.3 and last["lowest_at_reference"] >= 0.8 and not last["reference_below_bar"]
    assert first["scans"] == 20  # the 2 s before, at 10 Hz
    assert alarm_fits(None, t, ok, fit_est, fit_ref, below=0.4) == []
