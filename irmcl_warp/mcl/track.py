"""Driving a particle filter over a recorded log: ``follow(pf, log, idx, mcl)``, the loop every MCL user
shares (the localize stage, the pipeline)."""

from __future__ import annotations

import time

import numpy as np

from irmcl_warp.geometry import compose, relative
from irmcl_warp.types import LaserLog
from irmcl_warp.kernels.motion import odometry_step


def window(log: LaserLog, start_s: float, run_s: float | None, section: str) -> np.ndarray:
    """Indices of the scans from ``start_s`` for ``run_s`` seconds (None: to the end), times counted from the
    log's first scan; ``section`` names the settings in the error for an empty window."""
    t = log.stamps - log.stamps[0]
    end = np.inf if run_s is None else start_s + run_s
    idx = np.flatnonzero((t >= start_s) & (t <= end))
    if len(idx) < 2:
        raise ValueError(f"{section}.start_s={start_s}, run_s={run_s}: {len(idx)} scans of a {t[-1]:.0f} s log "
                         f"({log.source}) in the window")
    return idx


def moved(odom_step, min_trans: float, min_rot: float) -> bool:
    """Has the robot moved enough since the last update (AMCL's update_min_d / update_min_a)?"""
    rot1, trans, rot2 = odom_step
    return abs(trans) > min_trans or abs(rot1 + rot2) > min_rot


def between_updates(pose, odom_at_update, odom_now):
    """The pose at a scan the filter did not weigh: the last update's estimate moved by the odometry since
    (what AMCL's map -> odom transform gives a robot between updates). None yet: NaN (mcl.first_update=motion)."""
    if pose is None:
        return np.full(3, np.nan)
    delta = relative(np.asarray(odom_at_update, float)[None], np.asarray(odom_now, float)[None])[0]
    return pose if np.all(np.abs(delta) < 1e-12) else compose(np.asarray(pose, float)[None], delta[None])[0]


def follow(pf, log: LaserLog, idx: np.ndarray, m, reduce_after_s: float | None = None, watch=None,
           step_times: list | None = None) -> np.ndarray:
    """Estimates [len(idx), 3] of one run over the scans ``idx``; the filter is already initialised. As
    IR-MCL's code, the filter weighs and resamples only after the odometry moved (``m.update_min_*``), and
    keeps the ``m.reduce_to`` heaviest particles ``reduce_after_s`` into the run (None: never). With
    ``m.first_update=motion`` the first scan waits for the gates too; until then the estimate is NaN (no pose). A jump in
    ``idx`` (kidnapping) is invisible to the odometry: the step across it is zero. ``watch(j, pf)``, when given,
    sees the filter after every scan (plots, animations). ``step_times``, when given, gets the wall time (s)
    of every filter step (each reads its estimate back, so the step is done when it returns)."""
    est = np.empty((len(idx), 3))
    last_odom, t_start, pose = log.odom[idx[0]], log.stamps[idx[0]], None
    reduce_pending = reduce_after_s is not None and 0 < m.reduce_to < pf.num_particles
    for j, i in enumerate(idx):
        if j > 0 and idx[j - 1] != i - 1:  # teleported: continue from here as if nothing moved
            last_odom = log.odom[i]
        u = odometry_step(last_odom, log.odom[i])
        if (pose is None and m.first_update == "scan") or moved(u, m.update_min_trans_m, m.update_min_rot_rad):
            t0 = time.perf_counter()
            pose = pf.step(u, log.ranges_m[i])[0]
            if step_times is not None:
                step_times.append(time.perf_counter() - t0)
            last_odom = log.odom[i]
            if reduce_pending and log.stamps[i] - t_start >= reduce_after_s:
                pf.reduce(m.reduce_to)
                reduce_pending = False
        est[j] = between_updates(pose, last_odom, log.odom[i])
        if watch is not None:
            watch(j, pf)
    return est
