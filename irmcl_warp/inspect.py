"""``python -m irmcl_warp.inspect +exp=<name>``: read a log, print what it holds and what looks wrong,
and draw its map from the ground-truth poses (or the odometry, when there are none).

Writes ``outputs/<exp>/inspect/``: summary.json, map.{pgm,yaml,npz,png}, config.yaml, manifest.json,
and for the simulator the log as a ROS1 bag (sim.bag) that ``data=bag`` reads back.
"""

from __future__ import annotations

from pathlib import Path

import hydra
import numpy as np

from irmcl_warp.config import register
from irmcl_warp import runs
from irmcl_warp.io import write_bag
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.services.data import far_bound_m, load_stream
from irmcl_warp.services.outputs import write_json
from irmcl_warp.types import LaserLog
from irmcl_warp.kernels import pick_device
from irmcl_warp.services.cli import hydra_main, run_entry


def path_length_m(poses: np.ndarray) -> float:
    p = poses[np.all(np.isfinite(poses), axis=1)]
    return float(np.hypot(*np.diff(p[:, :2], axis=0).T).sum()) if len(p) > 1 else 0.0


def summarize(log: LaserLog) -> dict:
    i = log.info
    return {
        "source": log.source,
        "scans": len(log),
        "beams": i.num_beams,
        "fov_deg": float(np.degrees(i.fov_rad)),
        "angle_increment_deg": float(np.degrees(i.angle_increment_rad)),
        "range_max_m": i.range_max_m,
        "no_return_m": i.no_return_m,
        "valid_beam_share": float(log.valid.mean()),
        "duration_s": float(log.stamps.max() - log.stamps.min()),
        "odometry_path_m": path_length_m(log.odom),
        "ground_truth_poses": log.num_ground_truth,
        "ground_truth_path_m": path_length_m(log.ground_truth) if log.ground_truth is not None else 0.0,
        "T_base_laser": [float(v) for v in log.T_base_laser],
        "defects": dict(log.defects.counts),
    }


def run_inspect(cfg) -> Path:
    with runs.start(cfg, "inspect") as run:
        if run.done:
            return run.path
        return inspect_log(run)


def inspect_log(run: runs.Run) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    log = load_stream(cfg)
    summary = summarize(log)
    poses, label = (log.ground_truth, "ground truth") if log.num_ground_truth else (log.odom, "odometry")
    m = cfg.mapping
    grid = build_map(
        log,
        poses,
        resolution_m=m.resolution_m,
        far_m=far_bound_m(cfg, log.info.range_max_m),
        l_occ=m.l_occ,
        l_free=m.l_free,
        l_min=m.l_min,
        l_max=m.l_max,
        kernel=m.kernel,
        device=device,
    )
    save_map(grid, out / "map")
    summary["map"] = {
        "poses": label,
        "cells": list(grid.shape),
        "resolution_m": grid.resolution_m,
        "origin_xy": list(grid.origin_xy),
    }
    if cfg.data.format == "sim":
        write_bag(log, out / "sim.bag")
    write_json(out / "summary.json", summary)
    path = run.finish(None, device)
    print(
        f"{cfg.data.name}: {summary['scans']} scans of {summary['beams']} beams over {summary['fov_deg']:.1f} deg, "
        f"{summary['duration_s']:.0f} s, {summary['ground_truth_poses']} ground-truth poses"
    )
    print(
        f"  odometry path {summary['odometry_path_m']:.1f} m, ground-truth path {summary['ground_truth_path_m']:.1f} m, "
        f"valid beams {100 * summary['valid_beam_share']:.1f} %, no return at {summary['no_return_m']:.2f} m"
    )
    for line in log.defects.lines() or ["no defects found"]:
        print(f"  defect: {line}" if log.defects else f"  {line}")
    print(f"  map from {label}: {grid.shape[1]}x{grid.shape[0]} cells -> {path / 'map.png'}")
    return path


register()


@hydra.main(version_base="1.3", config_path="pkg://irmcl_warp.conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_inspect, cfg)


if __name__ == "__main__":
    hydra_main(main)
