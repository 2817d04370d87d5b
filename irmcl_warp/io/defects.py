"""Detect the defects real logs have (../shared/data/README.md, "Known defects"), as counts.

Every check works on arrays in *recording order* and returns a number; readers put them in the log's
:class:`~irmcl_warp.types.DefectReport` and warn once.
"""

from __future__ import annotations

import numpy as np

from irmcl_warp.geometry import wrap_angle
from irmcl_warp.types import DefectReport
from irmcl_warp.geometry import compose, relative


def count_stamps_backwards(stamps_recording_order) -> int:
    """Messages stamped earlier than the message recorded just before them."""
    return int(np.sum(np.diff(np.asarray(stamps_recording_order, dtype=np.float64)) < 0))


def count_duplicate_stamps(stamps) -> int:
    s = np.asarray(stamps, dtype=np.float64)
    return int(len(s) - len(np.unique(s)))


def count_odometry_jumps(stamps, poses, max_speed_mps: float, max_step_m: float, min_dt_s: float = 0.02) -> int:
    """Steps whose translation exceeds ``max_step_m``, or implies a speed above ``max_speed_mps`` over at
    least ``min_dt_s`` (shorter intervals say more about the stamps than about the motion)."""
    step = np.hypot(*np.diff(np.asarray(poses)[:, :2], axis=0).T)
    dt = np.abs(np.diff(np.asarray(stamps, dtype=np.float64)))
    fast = (dt >= min_dt_s) & (step > max_speed_mps * np.maximum(dt, min_dt_s)) & (step > 0.05)
    return int(np.sum((step > max_step_m) | fast))


def count_velocity_contradictions(poses, forward_velocity_mps, min_speed_mps=0.02, min_step_m=1e-3) -> int:
    """Odometry steps whose displacement along the heading has the opposite sign of the reported
    forward velocity (fr079: the robot reverses, the odometry keeps advancing)."""
    p = np.asarray(poses, dtype=np.float64)
    v = np.asarray(forward_velocity_mps, dtype=np.float64)[1:]
    d = np.diff(p[:, :2], axis=0)
    heading = p[:-1, 2] + 0.5 * wrap_angle(np.diff(p[:, 2]))
    along = d[:, 0] * np.cos(heading) + d[:, 1] * np.sin(heading)
    return int(np.sum((np.abs(v) > min_speed_mps) & (np.abs(along) > min_step_m) & (np.sign(along) != np.sign(v))))


def repair_reversing(poses, forward_velocity_mps) -> tuple[np.ndarray, int, float]:
    """(poses, steps repaired, metres repaired): every odometry step whose two messages report a negative
    mean forward velocity but which advances along the heading is driven backwards instead (its
    translation, in the frame of the step's first pose, negated; its rotation kept), and the chain is
    re-integrated. fr079's bag needs it: its odometry never reverses (../shared/data/README.md)."""
    p = np.asarray(poses, dtype=np.float64)
    v = np.asarray(forward_velocity_mps, dtype=np.float64)
    steps = relative(p[:-1], p[1:])
    flip = (0.5 * (v[:-1] + v[1:]) < 0) & (steps[:, 0] > 0)
    steps[flip, :2] *= -1.0
    out = np.empty_like(p)
    out[0] = p[0]
    for i, step in enumerate(steps):
        out[i + 1] = compose(out[i], step)
    return out, int(flip.sum()), float(np.hypot(steps[flip, 0], steps[flip, 1]).sum())


def scan_defects(
    report: DefectReport, stamps_recording_order, odom_poses, *, max_speed_mps=3.0, max_step_m=2.0, what="scans"
) -> DefectReport:
    """The checks every reader runs on its scans and their odometry."""
    report.add(
        f"{what}_stamps_backwards",
        count_stamps_backwards(stamps_recording_order),
        f"{what} stamped earlier than the one recorded before them",
    )
    report.add(
        f"{what}_duplicate_stamps",
        count_duplicate_stamps(stamps_recording_order),
        f"{what} sharing a stamp with another",
    )
    report.add(
        "odometry_jumps",
        count_odometry_jumps(stamps_recording_order, odom_poses, max_speed_mps, max_step_m),
        f"odometry steps between scans over {max_step_m} m or {max_speed_mps} m/s",
    )
    return report
