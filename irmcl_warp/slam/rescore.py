"""``python -m irmcl_warp.slam.rescore <run folder>...``: score finished SLAM runs against the relations
again, from their trajectory.tum and config.yaml (e.g. where the relations file was missing on the
machine that ran them, or to score older runs in the laser's frame); amends metrics.json (runs.amend: the
manifest records the new digest and why).
The laser's mounting comes from metrics.json, else from the config's data.laser_frame_path."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.services.metrics import relations_error
from irmcl_warp.geometry import compose
from irmcl_warp.io import read_relations, read_tum, resolve
from irmcl_warp.runs import amend
from irmcl_warp.io.rosbag import read_bag_extrinsic
from irmcl_warp.services.cli import guard


def mounting(cfg, metrics: dict) -> np.ndarray:
    """T_base_laser of the run: as recorded in metrics.json, else read from the data config's bag."""
    if "relations_frame" in metrics:
        return np.asarray(metrics["relations_frame"]["T_base_laser"], np.float64)
    if cfg.data.get("laser_frame_path"):
        return read_bag_extrinsic(resolve(cfg.data.laser_frame_path), base_frame=cfg.data.get("base_frame"))
    return np.zeros(3)


def rescore(run: Path) -> dict:
    cfg = OmegaConf.load(run / "config.yaml")
    if not cfg.data.relations_path:
        raise ValueError(f"{run}: data={cfg.data.name} has no relations file")
    if cfg.data.get("relation_stamps_path"):
        raise ValueError(
            f"{run}: data={cfg.data.name} matches its relations through {cfg.data.relation_stamps_path}, "
            f"not through the trajectory's stamps: rerun the slam stage to score it"
        )
    metrics = json.loads((run / "metrics.json").read_text())
    stamps, poses = read_tum(run / "trajectory.tum")
    T = mounting(cfg, metrics)
    metrics["relations_frame"] = {"frame": "laser", "T_base_laser": [float(v) for v in T]}
    metrics["relations"] = relations_error(stamps, compose(poses, T), read_relations(resolve(cfg.data.relations_path)))
    amend(run, metrics, "slam.rescore: the relations scored again on the laser's path")
    return metrics["relations"]


def main(argv=None) -> None:
    for run in map(Path, argv if argv is not None else sys.argv[1:]):
        r = rescore(run)
        print(
            f"{run}: {r['trans_abs_mean_m']:.3f} m / {r['rot_abs_mean_deg']:.2f} deg over {r['relations_used']} relations"
        )


if __name__ == "__main__":
    guard(main)
