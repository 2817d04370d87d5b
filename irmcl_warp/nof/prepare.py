"""``prepare_beams(cfg)``: read the log once, cut it into the benchmark splits, cache the result.

The cache ``outputs/<exp>/beams/beams.npz`` is keyed by the data settings and the size and mtime of the
input files, so a changed setting or file rebuilds it; it is also what a GPU machine without the raw
logs is sent (it carries no reader dependency).
"""

from __future__ import annotations

import math
from pathlib import Path

from omegaconf import OmegaConf

from irmcl_warp.io import GEOMETRY_FIELDS, load_log, read_splits, resolve
from irmcl_warp.nof.beams import (SPLITS, BeamSet, beams_from_log, interleaved_splits, load_beams, save_beams,
                                  settings_key, split_beams)
from irmcl_warp.outputs import stage_dir


# fields added after caches existed, left out of the cache key at these defaults so those caches stay valid
LATER_FIELDS = {"repair_reversing": False, "path_seed": None}


def input_files(cfg) -> list[Path]:
    """The files a data config reads (the simulator's: only the pipeline's training poses, when set)."""
    d = cfg.data
    return [resolve(p) for p in (d.path, d.ground_truth_path, d.laser_frame_path, d.splits_path,
                                 d.get("train_poses_path")) if p]


def far_m(cfg, range_max_m: float | None = None) -> float:
    """Far bound of rendering: render.far_m, else data.usable_range_m, else floor(range_max) (IR-MCL code)."""
    if cfg.render.far_m is not None:
        return float(cfg.render.far_m)
    if cfg.data.usable_range_m is not None:
        return float(cfg.data.usable_range_m)
    if range_max_m is None:
        raise ValueError(f"data={cfg.data.name}: set data.usable_range_m (the far bound of rendering)")
    return float(math.floor(range_max_m))


def cache_key(cfg, *settings) -> tuple[str, FileNotFoundError | None]:
    """(key, missing-input error): the data settings (+ ``settings``), then "-" and the inputs' size and
    mtime. Without the raw files (a GPU box sent only the caches) the key stops after the settings part
    and the error says which file is missing; a cache is then accepted by that prefix."""
    def stable(node, drop_none: bool, drop=()) -> dict:
        return {k: v for k, v in OmegaConf.to_container(node).items()
                if not (drop_none and v is None) and not (k in LATER_FIELDS and v == LATER_FIELDS[k]) and k not in drop}

    # the beam geometry is applied after reading: a cache holds the log as its files say (io.read_log)
    key = settings_key(stable(cfg.data, drop_none=True, drop=GEOMETRY_FIELDS), stable(cfg.sim, drop_none=False),
                       *settings)
    try:
        files = input_files(cfg)
        return key + "-" + settings_key([(str(p), p.stat().st_size, p.stat().st_mtime) for p in files]), None
    except FileNotFoundError as e:
        return key, e


def prepare_beams(cfg, cache: bool = True) -> dict[str, BeamSet]:
    """{split name: BeamSet} for the split scheme ``cfg.data.split`` (train, val, test names in that order)."""
    if cfg.data.split not in SPLITS:
        raise ValueError(f"data.split={cfg.data.split!r}: expected one of {sorted(SPLITS)}")
    # the beams are cut from the log with its geometry applied: the geometry is part of this cache's key
    data = OmegaConf.to_container(cfg.data)
    geometry = {k: data[k] for k in GEOMETRY_FIELDS if data.get(k) is not None}
    key, no_raw = cache_key(cfg, cfg.render.near_m, cfg.render.far_m, *([geometry] if geometry else []))
    path = stage_dir(cfg, "beams") / "beams.npz"
    sets = load_beams(path, key, prefix_only=no_raw is not None) if cache else None
    if no_raw is not None:
        if sets is None:
            raise no_raw
        print(f"{no_raw}; using the beams cached in {path}")
    if sets is None:
        log = load_log(cfg)
        if cfg.data.get("train_poses_path"):  # train on these poses (the pipeline's SLAM), not the ground truth
            from irmcl_warp.io import attach_ground_truth, read_ground_truth

            n = attach_ground_truth(log, *read_ground_truth(resolve(cfg.data.train_poses_path)))
            print(f"{cfg.data.name}: {n} of {len(log)} scans posed by {cfg.data.train_poses_path}")
        beams = beams_from_log(log, cfg.render.near_m, far_m(cfg, log.info.range_max_m), name=cfg.data.name)
        if cfg.data.splits_path:
            source = str(resolve(cfg.data.splits_path))
            splits = read_splits(resolve(cfg.data.splits_path))
        else:
            source, splits = f"{cfg.data.name} (interleaved rule)", interleaved_splits(beams.stamps)
        sets = split_beams(beams, splits, [n for names in SPLITS.values() for n in names if n in splits] or
                           list(SPLITS[cfg.data.split]), source)
        if cache:
            save_beams(path, sets, key)
    names = SPLITS[cfg.data.split]
    missing = [n for n in names if n not in sets]
    if missing:
        raise ValueError(f"data={cfg.data.name}: split file has no {missing}")
    return {role: sets[n] for role, n in zip(("train", "val", "test"), names)}


def recorded_inputs(cfg) -> list[Path]:
    """Input files to hash into a manifest: none where only the cache was sent."""
    try:
        return input_files(cfg)
    except FileNotFoundError:
        return []
