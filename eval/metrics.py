"""Trajectory metrics. Each takes arrays and returns a flat dict of floats, ready for metrics.json."""

from __future__ import annotations

import numpy as np

from irmcl_warp.geometry import relative, wrap_angle
from irmcl_warp.types import match_stamps


def relations_error(stamps, poses, relations, tol_s: float = 1e-4) -> dict:
    """The metric of Kümmerle et al. 2009 (Auton. Robots 27(4), eq. 2): for every relation (t1, t2, d*),
    compare the estimated motion d = x(t1)^-1 x(t2) with d*. Translational error = ||t(d* ^-1 d)||
    = ||t(d) - t(d*)||, rotational = |yaw(d) - yaw(d*)|. Reports mean and std of the absolute errors and
    of their squares; relations whose stamps have no pose are counted, not scored."""
    i = match_stamps(stamps, relations.t1, tol_s)
    j = match_stamps(stamps, relations.t2, tol_s)
    ok = (i >= 0) & (j >= 0)
    if not ok.any():
        raise ValueError("no relation could be matched to a pose by stamp")
    poses = np.asarray(poses, dtype=np.float64)
    est = relative(poses[i[ok]], poses[j[ok]])
    gt = relations.motion[ok]
    e_t = np.hypot(est[:, 0] - gt[:, 0], est[:, 1] - gt[:, 1])
    e_r = np.degrees(np.abs(wrap_angle(est[:, 2] - gt[:, 2])))
    return {
        "relations_used": int(ok.sum()), "relations_unmatched": int((~ok).sum()),
        "trans_abs_mean_m": float(e_t.mean()), "trans_abs_std_m": float(e_t.std()),
        "trans_sq_mean_m2": float((e_t ** 2).mean()), "trans_sq_std_m2": float((e_t ** 2).std()),
        "rot_abs_mean_deg": float(e_r.mean()), "rot_abs_std_deg": float(e_r.std()),
        "rot_sq_mean_deg2": float((e_r ** 2).mean()), "rot_sq_std_deg2": float((e_r ** 2).std()),
    }
