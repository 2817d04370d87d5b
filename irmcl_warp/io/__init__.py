"""Readers: every source becomes one :class:`~irmcl_warp.types.LaserLog`.

``load_log(cfg)`` reads what ``cfg.data`` names (the simulator, a CARMEN log or a bag), attaches the
ground-truth poses by stamp, and the laser extrinsic from a bag when the log has none.
"""

from __future__ import annotations

import copy
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from irmcl_warp.geometry import compose, interpolate_se2, relative
from irmcl_warp.io.carmen import read_carmen, read_carmen_poses
from irmcl_warp.io.clock import estimate_clock_offset, scan_lag_note
from irmcl_warp.io.errors import LogDefectWarning, LogFormatError
from irmcl_warp.io.plausibility import check_beam_order
from irmcl_warp.io.groundtruth import read_g2o, read_matched_csv, read_relations, read_splits, read_tum, write_tum
from irmcl_warp.io.rosbag import read_bag, read_bag_extrinsic, write_bag
from irmcl_warp.types import LaserLog, match_stamps

__all__ = [
    "GEOMETRY_FIELDS",
    "GroundTruthMatch",
    "LogDefectWarning",
    "LogFormatError",
    "apply_ground_truth",
    "apply_laser_geometry",
    "attach_ground_truth",
    "check_ground_truth",
    "data_root",
    "load_log",
    "read_bag",
    "read_carmen",
    "read_log",
    "read_g2o",
    "read_ground_truth",
    "read_matched_csv",
    "read_tum",
    "read_relations",
    "read_splits",
    "resolve",
    "write_bag",
    "write_tum",
]


def data_root() -> Path:
    """``$IRMCL_DATA``, else ``../shared/data`` beside the repository."""
    env = os.environ.get("IRMCL_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[2].parent / "shared" / "data"


def resolve(path: str) -> Path:
    """A file a setting names: as given (absolute, or from the working directory) when it exists there, else
    under the data root (``IRMCL_DATA``), where the shared logs' paths are relative to."""
    p = Path(path).expanduser()
    if p.exists():
        return p
    if not p.is_absolute():
        p = data_root() / p
    if not p.exists():
        raise FileNotFoundError(
            f"{path} not found, neither from the working directory nor under IRMCL_DATA={data_root()}"
        )
    return p


def read_ground_truth(path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, T_map_base poses) from a matched CSV, a TUM trajectory (.tum) or a GMapping-corrected CARMEN log."""
    path = Path(path)
    if path.suffix == ".csv":
        return read_matched_csv(path)
    return read_tum(path) if path.suffix == ".tum" else read_carmen_poses(path)


GT_MIN_SHARE = 0.9  # ground truth matching fewer of its poses (or of the scans it spans) is refused


@dataclass(frozen=True)
class GroundTruthMatch:
    """How ground truth met a log. Keyframes: ``share`` = poses that matched a scan, of the poses inside the
    log's time span. Interpolated: ``share`` = scans that got a pose, of the scans inside the truth's span."""

    mode: str  # "keyframes" | "interpolated"
    scans_posed: int
    considered: int
    share: float


def attach_ground_truth(
    log: LaserLog,
    stamps,
    poses,
    *,
    offset_s: float = 0.0,
    max_gap_s: float | None = None,
    tol_s: float = 1e-4,
    fill: str = "none",
) -> GroundTruthMatch:
    """Set ``log.ground_truth`` (NaN where unknown) from poses whose stamps plus ``offset_s`` are the log's
    clock: matched by stamp within ``tol_s`` (keyframes), or SE(2)-interpolated at every scan between two
    poses at most ``max_gap_s`` apart (a dense trajectory). Keyframes with ``fill="odometry"``: every scan after
    the first keyframe is posed by the last keyframe before it plus the odometry's motion since (GMapping's
    path between its processed scans)."""
    t = np.asarray(stamps, np.float64) + float(offset_s)
    poses = np.asarray(poses, np.float64)
    if max_gap_s is None:
        scan = match_stamps(log.stamps, t, tol_s)  # each pose poses the one scan nearest to it, if near enough
        gt = np.full((len(log), 3), np.nan)
        gt[scan[scan >= 0]] = poses[scan >= 0]
        inside = (t >= log.stamps.min() - tol_s) & (t <= log.stamps.max() + tol_s)
        matched = int(np.sum(scan[inside] >= 0))
        considered = int(inside.sum())
        mode = "keyframes"
        if fill == "odometry":
            gt = fill_by_odometry(log.stamps, log.odom, gt)
            mode = "keyframes+odometry"
        elif fill != "none":
            raise ValueError(f"ground truth fill {fill!r}: choose none or odometry")
    else:
        gt = interpolate_se2(t, poses, log.stamps, max_gap_s, tol_s)
        considered = int(np.sum((log.stamps >= t[0]) & (log.stamps <= t[-1])))
        matched = int(np.isfinite(gt[:, 0]).sum())
        mode = "interpolated"
    log.ground_truth = gt
    return GroundTruthMatch(mode, int(np.isfinite(gt[:, 0]).sum()), considered, matched / max(considered, 1))


def fill_by_odometry(scan_stamps, odom, keyed: np.ndarray) -> np.ndarray:
    """Poses [N, 3] at every scan: where ``keyed`` holds a pose (a keyframe), that pose; at a scan after it (in
    stamp order) until the next keyframe, the keyframe's pose composed with the odometry's motion from the
    keyframe's scan to this one; NaN before the first keyframe."""
    order = np.argsort(np.asarray(scan_stamps, float), kind="stable")
    have = np.isfinite(keyed[order, 0])
    last = np.maximum.accumulate(np.where(have, np.arange(len(order)), -1))  # the last keyframe at or before
    out = np.full_like(keyed, np.nan)
    ok = last >= 0
    k, i = order[last[ok]], order[ok]
    out[i] = compose(keyed[k], relative(odom[k], odom[i]))
    return out


def check_ground_truth(path, log: LaserLog, stamps, poses, match: GroundTruthMatch, offset_set: bool) -> None:
    """Refuse ground truth that meets too little of the log, saying why and what to set: when no offset was
    set, the clock offset found from the robot's turns (io.clock) is named with the setting that applies it."""
    if match.share >= GT_MIN_SHARE and match.scans_posed > 0:
        return
    t = np.asarray(stamps, np.float64)
    if match.considered == 0:
        what = (
            f"none of its {len(t)} poses lies in the log's time span ({log.stamps.min():.3f} to "
            f"{log.stamps.max():.3f} s; its own stamps run from {t.min():.3f} to {t.max():.3f} s)"
        )
    elif match.mode == "keyframes":
        what = f"{match.scans_posed} of the {match.considered} poses in the log's time span match a scan by stamp"
    else:
        what = f"{match.scans_posed} of the {match.considered} scans in its time span get a pose"
    msg = (
        f"ground truth for {log.source or 'the log'} is refused: {what} ({100 * match.share:.0f} %, at least "
        f"{100 * GT_MIN_SHARE:.0f} % needed)"
    )
    if not offset_set and len(stamps) > 2 and len(log) > 2:
        c = estimate_clock_offset(log.stamps, log.odom, stamps, poses)
        if c.convincing:
            msg += (
                f". Its clock appears offset from the log's by {c.offset_s:+.3f} s (its turns then agree with "
                f"the odometry's to {c.yaw_increment_error_deg:.2f} deg per step, {c.contrast:.2f} of the "
                f"disagreement a few seconds off): " + _checked_hint(log, stamps, poses, c.offset_s)
            )
        else:
            msg += ". No clock offset lines its turns up with the odometry's either"
    hint = (
        "; for a dense trajectory set data.ground_truth_max_gap_s (interpolate between poses), for keyframes "
        "whose stamps jitter data.ground_truth_tolerance_s"
    )
    raise LogFormatError(path, None, msg + hint)


def _checked_hint(log: LaserLog, stamps, poses, offset_s: float) -> str:
    """The settings that make the ground truth meet the log at ``offset_s``, tried before they are suggested:
    the offset alone (keyframes stamped as the scans), else with the trajectory read as dense (interpolated
    between poses up to three of its median steps apart), each with the share it reaches."""
    trial = copy.copy(log)
    step = float(np.median(np.diff(np.sort(np.asarray(stamps, float)))))
    tries = [({}, "as keyframes"), ({"max_gap_s": round(3 * step, 3)}, "interpolated")]
    for extra, how in tries:
        m = attach_ground_truth(trial, stamps, poses, offset_s=offset_s, **extra)
        if m.share >= GT_MIN_SHARE and m.scans_posed > 0:
            setting = f"data.ground_truth_time_offset_s={offset_s:.3f}" + (
                f" data.ground_truth_max_gap_s={extra['max_gap_s']:g}" if extra else ""
            )
            return f"set {setting} (tried: {100 * m.share:.0f} % of the log then gets a pose, {how})"
    return (
        f"but even at that offset it meets too little of the log ({100 * m.share:.0f} % interpolated); "
        f"set data.ground_truth_time_offset_s={offset_s:.3f} and look at its stamps"
    )


def apply_ground_truth(log: LaserLog, path, d) -> GroundTruthMatch:
    """Read the ground truth at ``path`` and attach it as ``d`` (a data config) says, or refuse it."""
    stamps, poses = read_ground_truth(path)
    offset = d.get("ground_truth_time_offset_s")
    match = attach_ground_truth(
        log,
        stamps,
        poses,
        offset_s=offset or 0.0,
        max_gap_s=d.get("ground_truth_max_gap_s"),
        tol_s=d.get("ground_truth_tolerance_s", 1e-4),
        fill=d.get("ground_truth_fill", "none"),
    )
    check_ground_truth(path, log, stamps, poses, match, offset is not None)
    if match.mode.startswith("keyframes") and not offset:  # poses stamped as the scans: does the odometry agree?
        note = scan_lag_note(log.stamps, log.odom, stamps, poses, float(d.get("scan_time_offset_s") or 0.0))
        if note:
            warnings.warn(f"{log.source or 'the log'} (ground truth {path}): {note}", LogDefectWarning, stacklevel=2)
    return match


def load_log(cfg) -> LaserLog:
    """Read the log that ``cfg.data`` names; ``cfg`` is the whole config (for ``sim`` and ``device``)."""
    return apply_laser_geometry(read_log(cfg), cfg.data)


# data fields that say where the beams point, applied after reading (caches of the read log stay valid)
GEOMETRY_FIELDS = ("fov_rad", "angle_min_rad", "laser_offset")


def apply_laser_geometry(log: LaserLog, d) -> LaserLog:
    """The log with data.fov_rad / data.angle_min_rad (beam angles: FLASER lines do not record them) and
    data.laser_offset (T_base_laser, in place of the one read) applied where they are set."""
    import dataclasses

    fov, start = d.get("fov_rad"), d.get("angle_min_rad")
    if fov is not None or start is not None:
        i = log.info
        fov = float(fov) if fov is not None else i.fov_rad
        start = float(start) if start is not None else -fov / 2
        log.info = dataclasses.replace(i, angle_min_rad=start, angle_increment_rad=fov / max(i.num_beams - 1, 1))
    if d.get("laser_offset") is not None:
        off = np.asarray(list(d.laser_offset), np.float64)
        if off.shape != (3,):
            raise ValueError(f"data.laser_offset={list(d.laser_offset)}: expected [x, y, yaw] of the laser on the base")
        log.T_base_laser = off
    return log


def read_log(cfg) -> LaserLog:
    """The log as its files say (no :data:`GEOMETRY_FIELDS` applied): what stream caches hold."""
    d = cfg.data
    if d.format == "sim":
        from irmcl_warp.sim import simulate  # lazy: only the simulator source needs its Warp kernels and world builder

        return simulate(cfg.sim, device=cfg.device)[0]
    if d.path is None:
        raise ValueError(f"data={d.name}: data.path is not set")
    path = resolve(d.path)
    if d.format == "carmen":
        log = read_carmen(
            path,
            no_return_m=d.no_return_m,
            beam_policy=d.beam_policy,
            max_speed_mps=d.max_speed_mps,
            max_step_m=d.max_step_m,
            scan_time_offset_s=d.scan_time_offset_s,
        )
    elif d.format == "bag":
        log = read_bag(
            path,
            scan_topic=d.scan_topic,
            odom_topic=d.odom_topic,
            base_frame=d.base_frame,
            odom_frame=d.odom_frame,
            beam_policy=d.beam_policy,
            max_speed_mps=d.max_speed_mps,
            max_step_m=d.max_step_m,
            repair_reversing=d.repair_reversing,
            scan_time_offset_s=d.scan_time_offset_s,
        )
    else:
        raise ValueError(f"data.format={d.format!r}: expected sim, carmen or bag")
    if d.laser_frame_path:
        log.T_base_laser = read_bag_extrinsic(resolve(d.laser_frame_path), base_frame=d.base_frame)
    if d.ground_truth_path:
        apply_ground_truth(log, resolve(d.ground_truth_path), d)
    check_beam_order(path, log.ranges_m, log.odom, log.info.angle_increment_rad)
    return log
