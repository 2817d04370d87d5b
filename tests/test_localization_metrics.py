"""Localization metrics on trajectories with known errors."""

import numpy as np
import pytest

from irmcl_warp.services.metrics import localization_metrics


def _traj(n=400, rate=5.0):
    t = np.arange(n) / rate
    gt = np.column_stack([np.cos(t / 10), np.sin(t / 10), t / 10])
    return t, gt


def test_converging_filter_is_scored_after_convergence():
    t, gt = _traj()
    est = gt.copy()
    est[t < 12, 0] += 5.0  # lost for 12 s
    est[t >= 12, 0] += 0.08  # then 8 cm off
    est[t >= 12, 2] += np.radians(0.7)
    m = localization_metrics(t, est, gt)
    assert m["converged"] and m["time_to_converge_s"] == pytest.approx(12.0)
    assert m["location_rmse_cm"] == pytest.approx(8.0, abs=1e-6) and m["yaw_rmse_deg"] == pytest.approx(0.7, abs=1e-6)
    assert m["within_5cm_pct"] == 0 and m["within_10cm_pct"] == 100 and m["within_1deg_pct"] == 100
    assert m["within_0.5deg_pct"] == 0 and m["success"] and m["divergences"] == 0


def test_never_converging_and_diverging_filters():
    t, gt = _traj()
    lost = gt + [3.0, 0.0, 0.0]
    assert localization_metrics(t, lost, gt)["success"] is False
    est = gt.copy()
    est[(t > 30) & (t < 35), 1] += 2.0  # a 5 s excursion after converging at once
    m = localization_metrics(t, est, gt)
    assert m["converged"] and m["divergences"] == 1 and m["time_to_converge_s"] == 0.0
    late = gt.copy()
    late[t < 70, 0] += 4.0  # converges only after 70 s: no success
    assert localization_metrics(t, late, gt)["success"] is False
    flipped = gt + [0.05, 0.0, np.pi]  # at the right place facing the other way (seen on intel): no success
    m = localization_metrics(t, flipped, gt)
    assert m["converged"] and m["location_rmse_cm"] < 10 and m["yaw_rmse_deg"] > 170 and m["success"] is False
    with pytest.raises(ValueError, match="fewer than two"):
        localization_metrics(t[:1], gt[:1], gt[:1])


def test_a_relations_score_on_few_matched_relations_is_shouted():
    """Scored on a part of the relations (keyframe ground truth, an offset clock), the figure is not the log's
    error: the share is recorded and a loud warning names it."""
    from irmcl_warp.io.groundtruth import Relations
    from irmcl_warp.services.metrics import coverage_warning, relations_error

    stamps = np.arange(10.0)
    poses = np.column_stack([stamps, np.zeros(10), np.zeros(10)])
    t1 = np.arange(0.0, 20.0, 2.0)  # half the relations start at stamps no pose has
    rel = Relations(t1, t1 + 1.0, np.tile([1.0, 0.0, 0.0], (10, 1)))
    r = relations_error(stamps, poses, rel)
    assert (r["relations_used"], r["relations_unmatched"]) == (5, 5) and r["relations_matched_share"] == 0.5
    assert "only 5 of 10 relations (50 %)" in coverage_warning(r, "x")
    full = relations_error(stamps, poses, Relations(stamps[:9], stamps[1:], np.tile([1.0, 0.0, 0.0], (9, 1))))
    assert full["relations_matched_share"] == 1.0 and coverage_warning(full, "x") is None
