"""Metrics the stages compute (below every stage, so eval and the stages share them). Each takes arrays and
returns a flat dict of floats, ready for metrics.json."""

from __future__ import annotations

import numpy as np

from irmcl_warp.geometry import align_rigid, compose, interpolate_se2, relative, wrap_angle
from irmcl_warp.types import match_stamps


# --- the protocols' constants: each changes published numbers, so each is named here with its origin ------
FULL_COVERAGE = 0.9  # a relations score on a smaller share of the relations is shouted, never printed bare
SYNTHESIS_THRESHOLD_M = (
    0.5  # IR-MCL Table I (the authors' nof/criteria code): accuracy and F-score count errors below this
)
EVALUATE_AFTER_S = 20.0  # IR-MCL Sec. IV-C: localization errors are scored on the poses after 20 s
CONVERGED_M, CONVERGED_FOR_S = 0.5, 5.0  # ours: converged once the position error stays below 0.5 m for 5 s
SUCCESS_WITHIN_S = 60.0  # ours: a success converges within the 60 s of a start (IR-MCL's run length) ...
SUCCESS_RMSE_M = 0.30  # ... with a location RMSE below 0.30 m afterwards ...
SUCCESS_YAW_DEG = 30.0  # ... and a heading RMSE below 30 deg (the right corridor facing the wrong way is no success)
DIVERGED_M = 1.0  # ours: a converged filter whose error rises above 1 m has diverged
SLAM_CONVERGED_M = 0.15  # a SLAM run converged below this mean relations error (the threshold of issue 6's reference)


def coverage_warning(rel: dict, what: str) -> str | None:
    """A loud sentence when ``rel`` (a relations_error result) scored few of the relations: the figure is
    then not the log's error but that of the matched part."""
    used, unmatched = rel["relations_used"], rel["relations_unmatched"]
    share = used / max(used + unmatched, 1)
    if share >= FULL_COVERAGE:
        return None
    return (
        f"WARNING: {what}: only {used} of {used + unmatched} relations ({100 * share:.0f} %) match a pose by stamp; "
        f"the figure is the error of those, not of the whole log"
    )


def relations_error(stamps, poses, relations, tol_s: float = 1e-4, max_gap_s: float | None = None) -> dict:
    """The metric of Kümmerle et al. 2009 (Auton. Robots 27(4), eq. 2): for every relation (t1, t2, d*),
    compare the estimated motion d = x(t1)^-1 x(t2) with d*. Translational error = ||t(d* ^-1 d)||
    = ||t(d) - t(d*)||, rotational = |yaw(d) - yaw(d*)|. Reports mean and std of the absolute errors and
    of their squares; relations whose stamps have no pose are counted, not scored. ``max_gap_s``: the poses
    are a dense trajectory, SE(2)-interpolated at the relation stamps between poses at most this far apart
    (a stamp within ``tol_s`` of a pose takes it); None: poses are matched by stamp."""
    poses = np.asarray(poses, dtype=np.float64)
    if max_gap_s is None:
        i = match_stamps(stamps, relations.t1, tol_s)
        j = match_stamps(stamps, relations.t2, tol_s)
        ok = (i >= 0) & (j >= 0)
        p1, p2 = poses[i[ok]], poses[j[ok]]
    else:
        order = np.argsort(stamps, kind="stable")
        t, P = np.asarray(stamps, np.float64)[order], poses[order]
        a = interpolate_se2(t, P, relations.t1, max_gap_s, tol_s)
        b = interpolate_se2(t, P, relations.t2, max_gap_s, tol_s)
        ok = np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])
        p1, p2 = a[ok], b[ok]
    if not ok.any():
        raise ValueError("no relation could be matched to a pose by stamp")
    est = relative(p1, p2)
    gt = relations.motion[ok]
    e_t = np.hypot(est[:, 0] - gt[:, 0], est[:, 1] - gt[:, 1])
    e_r = np.degrees(np.abs(wrap_angle(est[:, 2] - gt[:, 2])))
    return {
        "relations_used": int(ok.sum()),
        "relations_unmatched": int((~ok).sum()),
        "relations_matched_share": float(ok.mean()),
        "trans_abs_mean_m": float(e_t.mean()),
        "trans_abs_std_m": float(e_t.std()),
        "trans_sq_mean_m2": float((e_t**2).mean()),
        "trans_sq_std_m2": float((e_t**2).std()),
        "rot_abs_mean_deg": float(e_r.mean()),
        "rot_abs_std_deg": float(e_r.std()),
        "rot_sq_mean_deg2": float((e_r**2).mean()),
        "rot_sq_std_deg2": float((e_r**2).std()),
    }


def scan_synthesis_metrics(pred_m, meas_m, valid, angles_rad, threshold_m: float = SYNTHESIS_THRESHOLD_M) -> dict:
    """IR-MCL's scan-synthesis metrics (Kuang et al. 2023, Table I; the authors' nof/criteria code),
    each computed per scan over its valid beams and then averaged over scans:

    * mae_m: mean |rendered - measured| range;  accuracy_pct: % of beams with error < threshold;
    * chamfer_m: mean nearest-neighbour distance from rendered to measured end points plus the one from
      measured to rendered (the authors' sum of the two one-way means);
    * fscore_pct: 2PR / (P + R), P = % rendered end points within threshold of a measured one, R the reverse.

    ``median_error_m`` is the median over all valid beams pooled (beyond the paper). Shapes: [S, B].
    """
    from scipy.spatial import cKDTree

    pred_m, meas_m, valid = np.asarray(pred_m, np.float64), np.asarray(meas_m, np.float64), np.asarray(valid, bool)
    if pred_m.shape != meas_m.shape or valid.shape != meas_m.shape:
        raise ValueError(f"shapes differ: rendered {pred_m.shape}, measured {meas_m.shape}, valid {valid.shape}")
    c, s = np.cos(angles_rad), np.sin(angles_rad)
    per_scan, errors = [], []
    for k in range(len(meas_m)):
        v = valid[k]
        if not v.any():
            continue
        p, m = pred_m[k, v], meas_m[k, v]
        if not np.all(np.isfinite(p)):
            raise ValueError(f"scan {k}: rendered range is not finite")
        err = np.abs(p - m)
        errors.append(err)
        P = np.stack([p * c[v], p * s[v]], -1)
        M = np.stack([m * c[v], m * s[v]], -1)
        d_pm = cKDTree(M).query(P)[0]
        d_mp = cKDTree(P).query(M)[0]
        prec, rec = (d_pm < threshold_m).mean(), (d_mp < threshold_m).mean()
        f = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
        per_scan.append((err.mean(), 100 * (err < threshold_m).mean(), d_pm.mean() + d_mp.mean(), 100 * f))
    if not per_scan:
        raise ValueError("no scan has a valid beam to score")
    a = np.array(per_scan)
    return {
        "mae_m": float(a[:, 0].mean()),
        "accuracy_pct": float(a[:, 1].mean()),
        "chamfer_m": float(a[:, 2].mean()),
        "fscore_pct": float(a[:, 3].mean()),
        "median_error_m": float(np.median(np.concatenate(errors))),
        "scans": len(per_scan),
        "beams": int(sum(len(e) for e in errors)),
    }


def localization_metrics(
    stamps,
    estimate,
    ground_truth,
    converge_after_s: float = EVALUATE_AFTER_S,
    success_within_s: float = SUCCESS_WITHIN_S,
    success_rmse_m: float = SUCCESS_RMSE_M,
    converged_m: float = CONVERGED_M,
    diverged_m: float = DIVERGED_M,
    success_yaw_deg: float = SUCCESS_YAW_DEG,
    pos_thresholds_m=(0.05, 0.10, 0.20),
    yaw_thresholds_deg=(0.5, 1.0, 2.0),
) -> dict:
    """IR-MCL's protocol (Kuang et al. 2023, Sec. IV-C) plus success, time to converge and divergence.

    * converged: the first time from which the position error stays below ``converged_m`` for CONVERGED_FOR_S
      (``time_to_converge_s``, from the first stamp); success = converged within ``success_within_s``,
      location RMSE afterwards < ``success_rmse_m`` and heading RMSE < ``success_yaw_deg`` (a filter near the
      true place facing the other way, as in a symmetric corridor, has not localized the robot);
    * location/yaw RMSE and % of poses within the thresholds over poses after max(converged,
      ``converge_after_s``) — IR-MCL evaluates after 20 s;
    * divergences: how often a converged filter's error rose above ``diverged_m``.
    Poses without ground truth (NaN) are skipped. Arrays: stamps [N], poses [N, 3].
    """
    stamps, est, gt = np.asarray(stamps, float), np.asarray(estimate, float), np.asarray(ground_truth, float)
    ok = np.all(np.isfinite(gt), axis=1) & np.all(np.isfinite(est), axis=1)
    if ok.sum() < 2:
        raise ValueError("fewer than two estimated poses have ground truth")
    t, e_xy = stamps[ok] - stamps[ok][0], np.hypot(*(est[ok, :2] - gt[ok, :2]).T)
    e_yaw = np.degrees(np.abs(wrap_angle(est[ok, 2] - gt[ok, 2])))
    below = e_xy < converged_m
    t_conv = None
    for i in np.flatnonzero(below):  # first index from which the error stays low for 5 s
        window = (t >= t[i]) & (t <= t[i] + CONVERGED_FOR_S)
        if below[window].all() and t[-1] >= t[i] + CONVERGED_FOR_S or (below[i:].all()):
            t_conv = float(t[i])
            break
    out = {"poses": int(ok.sum()), "time_to_converge_s": t_conv, "converged": t_conv is not None}
    if t_conv is None:
        return {**out, "success": False, "location_rmse_cm": None, "yaw_rmse_deg": None, "divergences": 0}
    after = t >= max(t_conv, converge_after_s)
    if not after.any():
        after = t >= t_conv
    out["location_rmse_cm"] = float(100 * np.sqrt(np.mean(e_xy[after] ** 2)))
    out["yaw_rmse_deg"] = float(np.sqrt(np.mean(e_yaw[after] ** 2)))
    for th in pos_thresholds_m:
        out[f"within_{int(round(th * 100))}cm_pct"] = float(100 * (e_xy[after] < th).mean())
    for th in yaw_thresholds_deg:
        out[f"within_{th:g}deg_pct"] = float(100 * (e_yaw[after] < th).mean())
    rmse_since = float(np.sqrt(np.mean(e_xy[t >= t_conv] ** 2)))
    out["success"] = bool(
        t_conv <= success_within_s and rmse_since < success_rmse_m and out["yaw_rmse_deg"] < success_yaw_deg
    )
    tracking = t >= t_conv
    high = (e_xy > diverged_m) & tracking
    out["divergences"] = int(np.sum(high[1:] & ~high[:-1]) + (high[0] if len(high) else 0))
    return out


def error_at_end(est: np.ndarray, ref: np.ndarray) -> float | None:
    """The position error (m) at the last pose where the estimate and the reference [n, 3] both exist; None if none."""
    both = np.isfinite(est).all(1) & np.isfinite(ref).all(1)
    return float(np.hypot(*(est[both][-1, :2] - ref[both][-1, :2]))) if both.any() else None


def aligned_error(est: np.ndarray, gt: np.ndarray) -> dict:
    """RMSE of positions after the rigid 2D alignment (Horn / Umeyama without scale) of est onto gt, and the
    mean absolute yaw error after it; over poses where both are finite."""
    ok = np.all(np.isfinite(est), 1) & np.all(np.isfinite(gt), 1)
    moved = compose(align_rigid(est, gt), est[ok])
    e_yaw = np.degrees(np.abs(wrap_angle(moved[:, 2] - gt[ok, 2])))
    return {
        "poses": int(ok.sum()),
        "ate_rmse_m": float(np.sqrt(np.mean(np.sum((moved[:, :2] - gt[ok, :2]) ** 2, 1)))),
        "yaw_mae_deg": float(e_yaw.mean()),
    }
