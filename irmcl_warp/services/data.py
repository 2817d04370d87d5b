"""The configured log, read once: ``load_stream(cfg)`` (one cache), ``prepare_beams(cfg)`` (the benchmark
splits cut from it) and the sensor's far bound, ``far_bound_m``.

The cache is ``outputs/<exp>/stream/stream-<key>.npz``: the log as its files say (``io.read_log``), the key a
digest of the settings the readers use and of the *content* of the files they read (a log replaced by
another of the same size and time is read again), one file per key (two bags of one experiment never evict
each other). The defects the readers warned about are kept in it and warned about again on every load, so
every run that uses a log says what is odd about it, not only the first.
"""

from __future__ import annotations

import io
import json
import math
import warnings

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.io import (
    GEOMETRY_FIELDS,
    LogDefectWarning,
    apply_laser_geometry,
    attach_ground_truth,
    check_ground_truth,
    read_ground_truth,
    read_log,
    read_splits,
    resolve,
)
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.nof.beams import SPLITS, BeamSet, beams_from_log, interleaved_splits, split_beams
from irmcl_warp.runs import cache_dir, content_digest, digest
from irmcl_warp.types import DefectReport, LaserInfo, LaserLog

# data fields the readers never look at: they do not change what the stream cache holds
NOT_READ = ("relations_path", "relation_stamps_path", "splits_path", "train_poses_path", "split", "far_m", "name")
READ_FILES = ("path", "ground_truth_path", "laser_frame_path")  # the files the readers open


def far_bound_m(cfg, range_max_m: float | None = None) -> float:
    """The sensor's far bound, one value for every stage (rendering, the filter's valid beams, SLAM's usable
    range): ``data.far_m``, else floor(range_max) as the IR-MCL code does."""
    if cfg.data.far_m is not None:
        return float(cfg.data.far_m)
    if range_max_m is None:
        raise ValueError(f"data={cfg.data.name}: set data.far_m (the sensor's far bound)")
    return float(math.floor(range_max_m))


def cache_key(cfg) -> str:
    """The digest of what the readers read: the data settings they use (the simulator's, for a simulated
    log) and the content of the files they open. The beam geometry is applied after reading, so it is not
    part of it."""
    d = OmegaConf.to_container(cfg.data, resolve=True)
    settings = {k: v for k, v in d.items() if k not in NOT_READ + GEOMETRY_FIELDS and k not in READ_FILES}
    files = {k: content_digest(resolve(d[k])) for k in READ_FILES if d.get(k)}
    sim = OmegaConf.to_container(cfg.sim, resolve=True) if d["format"] == "sim" else None
    return digest({"data": settings, "files": files, "sim": sim})[:20]


def _warn_again(notes: list[str]) -> None:
    for note in notes:
        warnings.warn(note, LogDefectWarning, stacklevel=3)


def load_stream(cfg) -> LaserLog:
    """The log that ``cfg.data`` names, with its beam geometry applied: from the cache when the settings and
    the files' content are unchanged, else read and cached. Its defects are warned about every time."""
    key = cache_key(cfg)
    path = cache_dir(cfg, "stream") / f"stream-{key}.npz"
    try:
        with np.load(path) as z:
            v = z["info"].tolist()
            info = LaserInfo(int(v[0]), *map(float, v[1:]))
            gt = z["ground_truth"] if z["ground_truth"].size else None
            defects = json.loads(str(z["defects"]))
            log = LaserLog(
                z["stamps"],
                z["ranges_m"],
                z["odom"],
                info,
                z["T_base_laser"],
                gt,
                source=str(z["source"]),
                defects=DefectReport(defects["counts"], defects["notes"]),
            )
        _warn_again(defects["warnings"])
        return apply_laser_geometry(log, cfg.data)
    except (OSError, KeyError, ValueError):
        pass  # no cache of this content yet (or an unreadable one): read the files
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LogDefectWarning)
        log = read_log(cfg)
    notes = [str(w.message) for w in caught if issubclass(w.category, LogDefectWarning)]
    for w in caught:  # the other warnings pass on as they came
        if not issubclass(w.category, LogDefectWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    i = log.info
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        key=np.array(key),
        stamps=log.stamps,
        ranges_m=log.ranges_m,
        odom=log.odom,
        T_base_laser=log.T_base_laser,
        source=np.array(str(log.source)),
        defects=np.array(json.dumps({"warnings": notes, "counts": log.defects.counts, "notes": log.defects.notes})),
        ground_truth=log.ground_truth if log.ground_truth is not None else np.zeros(0),
        info=np.array(
            [i.num_beams, i.angle_min_rad, i.angle_increment_rad, i.range_min_m, i.range_max_m, i.no_return_m],
            np.float64,
        ),
    )
    atomic_write_bytes(path, buf.getvalue())
    _warn_again(notes)
    return apply_laser_geometry(log, cfg.data)


def split_ids(cfg, stamps: np.ndarray) -> tuple[dict[str, np.ndarray], str]:
    """({split name: scan stamps}, where they came from): ``data.splits_path``, else the interleaved rule
    over ``stamps``."""
    if not cfg.data.splits_path:
        return interleaved_splits(stamps), f"{cfg.data.name} (interleaved rule)"
    path = resolve(cfg.data.splits_path)
    return read_splits(path), str(path)


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
