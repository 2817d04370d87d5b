"""The configured log, read once: ``load_stream(cfg)`` (one cache), ``prepare_beams(cfg)`` (the benchmark
splits cut from it) and the sensor's far bound, ``far_bound_m``.

The one cache is ``outputs/<exp>/stream/stream.npz``: the log as its files say (``io.read_log``), keyed by
the settings the readers use and the size and mtime of the files they read. Without the raw files (a GPU
machine sent only the caches) the key stops after the settings part and a cache is accepted by that
prefix. The split ids read from ``data.splits_path`` are kept beside it (``splits.json``) for the same reason.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.io import (GEOMETRY_FIELDS, apply_laser_geometry, attach_ground_truth, check_ground_truth, read_ground_truth, read_log,
                           read_splits, resolve)
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.nof.beams import SPLITS, BeamSet, beams_from_log, interleaved_splits, split_beams
from irmcl_warp.services.outputs import settings_key, stage_dir, write_json
from irmcl_warp.types import LaserInfo, LaserLog

# data fields added after caches existed, left out of the cache key at these defaults so those caches stay valid
LATER_FIELDS = {"repair_reversing": False, "path_seed": None, "ground_truth_tolerance_s": 1e-4}
# data fields the readers never look at: they do not change what the stream cache holds
NOT_READ = ("relations_path", "relation_stamps_path", "splits_path", "train_poses_path", "split", "far_m")


def input_files(cfg) -> list[Path]:
    """The files a data config reads (the simulator's: only the pipeline's training poses, when set)."""
    d = cfg.data
    return [resolve(p) for p in (d.path, d.ground_truth_path, d.laser_frame_path, d.splits_path,
                                 d.get("train_poses_path")) if p]


def recorded_inputs(cfg) -> list[Path]:
    """Input files to hash into a manifest: none where only the cache was sent."""
    try:
        return input_files(cfg)
    except FileNotFoundError:
        return []


def far_bound_m(cfg, range_max_m: float | None = None) -> float:
    """The sensor's far bound, one value for every stage (rendering, the filter's valid beams, SLAM's usable
    range): ``data.far_m``, else floor(range_max) as the IR-MCL code does."""
    if cfg.data.far_m is not None:
        return float(cfg.data.far_m)
    if range_max_m is None:
        raise ValueError(f"data={cfg.data.name}: set data.far_m (the sensor's far bound)")
    return float(math.floor(range_max_m))


def cache_key(cfg) -> tuple[str, FileNotFoundError | None]:
    """(key, missing-input error): the reader settings, then "-" and the read files' size and mtime. Without
    the raw files the key stops after the settings part and the error says which file is missing."""
    def stable(node, drop_none: bool, drop=()) -> dict:
        return {k: v for k, v in OmegaConf.to_container(node).items()
                if not (drop_none and v is None) and not (k in LATER_FIELDS and v == LATER_FIELDS[k]) and k not in drop}

    # the beam geometry is applied after reading: a cache holds the log as its files say (io.read_log)
    key = settings_key(stable(cfg.data, drop_none=True, drop=GEOMETRY_FIELDS + NOT_READ), stable(cfg.sim, drop_none=False))
    d = cfg.data
    try:
        files = [resolve(p) for p in (d.path, d.ground_truth_path, d.laser_frame_path) if p]
        return key + "-" + settings_key([(str(p), p.stat().st_size, p.stat().st_mtime) for p in files]), None
    except FileNotFoundError as e:
        return key, e


def load_stream(cfg) -> LaserLog:
    """The log that ``cfg.data`` names, with its beam geometry applied: from the cache when the settings and
    files are unchanged (or when the raw files are absent and the settings match), else read and cached."""
    key, no_raw = cache_key(cfg)
    path = stage_dir(cfg, "stream") / "stream.npz"
    try:
        with np.load(path) as z:
            stored = str(z["key"])
            if stored == key or (no_raw is not None and stored.split("-")[0] == key):
                v = z["info"].tolist()
                info = LaserInfo(int(v[0]), *map(float, v[1:]))
                gt = z["ground_truth"] if z["ground_truth"].size else None
                return apply_laser_geometry(LaserLog(z["stamps"], z["ranges_m"], z["odom"], info, z["T_base_laser"], gt,
                                                     source=f"{path} (cache of {cfg.data.path or cfg.data.name})"),
                                            cfg.data)
    except (OSError, KeyError, ValueError):
        pass
    if no_raw is not None:
        raise no_raw
    log = read_log(cfg)
    i = log.info
    buf = io.BytesIO()
    np.savez_compressed(buf, key=np.array(key), stamps=log.stamps, ranges_m=log.ranges_m, odom=log.odom,
                        T_base_laser=log.T_base_laser,
                        ground_truth=log.ground_truth if log.ground_truth is not None else np.zeros(0),
                        info=np.array([i.num_beams, i.angle_min_rad, i.angle_increment_rad, i.range_min_m,
                                       i.range_max_m, i.no_return_m], np.float64))
    atomic_write_bytes(path, buf.getvalue())
    return apply_laser_geometry(log, cfg.data)


def split_ids(cfg, stamps: np.ndarray) -> tuple[dict[str, np.ndarray], str]:
    """({split name: scan stamps}, where they came from): ``data.splits_path`` (kept beside the stream cache
    for a machine without it), else the interleaved rule over ``stamps``."""
    if not cfg.data.splits_path:
        return interleaved_splits(stamps), f"{cfg.data.name} (interleaved rule)"
    kept = stage_dir(cfg, "stream") / "splits.json"
    try:
        path = resolve(cfg.data.splits_path)
    except FileNotFoundError:
        if not kept.is_file():
            raise
        import json

        stored = json.loads(kept.read_text())
        print(f"{cfg.data.splits_path} not found; using the split ids kept in {kept}")
        return {k: np.asarray(v, np.float64) for k, v in stored["splits"].items()}, stored["source"]
    splits = read_splits(path)
    write_json(kept, {"source": str(path), "splits": {k: [float(t) for t in v] for k, v in splits.items()}})
    return splits, str(path)


def prepare_beams(cfg) -> dict[str, BeamSet]:
    """{"train", "val", "test": BeamSet} of the split scheme ``cfg.data.split``, cut from the stream (posed
    by ``data.train_poses_path`` when set: the pipeline's SLAM, else by the ground truth)."""
    if cfg.data.split not in SPLITS:
        raise ValueError(f"data.split={cfg.data.split!r}: expected one of {sorted(SPLITS)}")
    log = load_stream(cfg)
    if cfg.data.get("train_poses_path"):  # train on these poses (the pipeline's SLAM), not the ground truth
        path = resolve(cfg.data.train_poses_path)
        stamps, poses = read_ground_truth(path)
        match = attach_ground_truth(log, stamps, poses)
        check_ground_truth(path, log, stamps, poses, match, offset_set=True)
        print(f"{cfg.data.name}: {match.scans_posed} of {len(log)} scans posed by {cfg.data.train_poses_path}")
    beams = beams_from_log(log, cfg.render.near_m, far_bound_m(cfg, log.info.range_max_m), name=cfg.data.name)
    splits, source = split_ids(cfg, beams.stamps)
    names = SPLITS[cfg.data.split]
    missing = [n for n in names if n not in splits]
    if missing:
        raise ValueError(f"data={cfg.data.name}: split file has no {missing}")
    sets = split_beams(beams, splits, names, source)
    return {role: sets[n] for role, n in zip(("train", "val", "test"), names)}
