"""Readers: every source becomes one :class:`~irmcl_warp.types.LaserLog`.

``load_log(cfg)`` reads what ``cfg.data`` names (the simulator, a CARMEN log or a bag), attaches the
ground-truth poses by stamp, and the laser extrinsic from a bag when the log has none.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from irmcl_warp.io.carmen import read_carmen, read_carmen_poses
from irmcl_warp.io.errors import LogDefectWarning, LogFormatError
from irmcl_warp.io.groundtruth import read_g2o, read_matched_csv, read_relations, read_splits, read_tum, write_tum
from irmcl_warp.io.rosbag import read_bag, read_bag_extrinsic, write_bag
from irmcl_warp.types import LaserLog, match_stamps

__all__ = ["GEOMETRY_FIELDS", "LogDefectWarning", "LogFormatError", "apply_laser_geometry", "data_root", "load_log",
           "read_bag", "read_carmen", "read_log",
           "read_g2o", "read_ground_truth", "read_matched_csv", "read_tum", "read_relations", "read_splits", "resolve",
           "write_bag", "write_tum"]


def data_root() -> Path:
    """``$IRMCL_DATA``, else ``../shared/data`` beside the repository."""
    env = os.environ.get("IRMCL_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[2].parent / "shared" / "data"


def resolve(path: str) -> Path:
    p = Path(path).expanduser()
    if not p.is_absolute():
        p = data_root() / p
    if not p.exists():
        raise FileNotFoundError(f"{p} not found (data paths are relative to IRMCL_DATA={data_root()})")
    return p


def read_ground_truth(path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, T_map_base poses) from a matched CSV, a TUM trajectory (.tum) or a GMapping-corrected CARMEN log."""
    path = Path(path)
    if path.suffix == ".csv":
        return read_matched_csv(path)
    return read_tum(path) if path.suffix == ".tum" else read_carmen_poses(path)


def attach_ground_truth(log: LaserLog, stamps, poses) -> int:
    """Set ``log.ground_truth`` from poses matched by stamp; returns how many scans got one."""
    idx = match_stamps(stamps, log.stamps)
    gt = np.full((len(log), 3), np.nan)
    gt[idx >= 0] = np.asarray(poses)[idx[idx >= 0]]
    log.ground_truth = gt
    return int((idx >= 0).sum())


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
        log = read_carmen(path, no_return_m=d.no_return_m, beam_policy=d.beam_policy,
                          max_speed_mps=d.max_speed_mps, max_step_m=d.max_step_m)
    elif d.format == "bag":
        log = read_bag(path, scan_topic=d.scan_topic, odom_topic=d.odom_topic, base_frame=d.base_frame,
                       odom_frame=d.odom_frame, beam_policy=d.beam_policy, max_speed_mps=d.max_speed_mps,
                       max_step_m=d.max_step_m, repair_reversing=d.repair_reversing)
    else:
        raise ValueError(f"data.format={d.format!r}: expected sim, carmen or bag")
    if d.laser_frame_path:
        log.T_base_laser = read_bag_extrinsic(resolve(d.laser_frame_path), base_frame=d.base_frame)
    if d.ground_truth_path:
        attach_ground_truth(log, *read_ground_truth(resolve(d.ground_truth_path)))
    return log
