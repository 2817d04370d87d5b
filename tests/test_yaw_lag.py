"""eval.yaw_lag: the fitted lag of a heading that trails the truth, on a synthetic turning trajectory."""

from __future__ import annotations

import numpy as np
import pytest

from eval.analyses.yaw_lag import heading_errors, summarise


def test_a_heading_that_trails_the_truth_gives_its_lag(rng):
    t = np.arange(0.0, 120.0, 0.1)
    rate = np.where((t % 20) < 8, 0.0, rng.uniform(0.4, 0.8))  # straight, then turning
    gt = np.cumsum(rate) * 0.1
    lag = rng.uniform(0.02, 0.2)
    est = np.interp(t - lag, t, gt) + rng.normal(0, 0.002, len(t))  # the estimate follows lag s late
    gap = gt.copy()
    gap[rng.choice(len(t), 40, replace=False)] = np.nan  # scans without ground truth are skipped, not spread
    e, w = heading_errors(t, est, gap, after_s=20.0)
    assert len(e) == int((np.isfinite(gap) & (t >= 20.0)).sum())
    s = summarise(e, w)
    assert s["lag_s"] == pytest.approx(lag, abs=0.01), f"seed {rng.seed}"
    assert s["turning_rms_deg"] > 3 * s["straight_rms_deg"], f"seed {rng.seed}: {s}"
    on_time = summarise(*heading_errors(t, gt + rng.normal(0, 0.002, len(t)), gt))
    assert abs(on_time["lag_s"]) < 0.005


def test_yaw_profile_of_the_likelihood_field_peaks_at_the_truth_and_narrows_with_beams(tmp_path, monkeypatch):
    """--profile on a simulator run: unbiased, and the likelihood field (a sum over beams) gets narrower in
    heading with more beams."""
    from eval.analyses.yaw_lag import yaw_profile
    from tests.test_mcl import sim_tracking_run

    monkeypatch.chdir(tmp_path)
    run = sim_tracking_run(duration_s=30, starts=1, run_s=10, particles=200)
    wide = yaw_profile(run, every=5, overrides=["mcl.num_beams=8"])
    narrow = yaw_profile(run, every=5, overrides=["mcl.num_beams=64"])
    assert abs(narrow["peak_deg_median"]) <= 0.5 and abs(wide["peak_deg_median"]) <= 0.75
    assert narrow["sigma_deg_per_scan"] < 0.6 * wide["sigma_deg_per_scan"], (
        narrow["sigma_deg_per_scan"],
        wide["sigma_deg_per_scan"],
    )
