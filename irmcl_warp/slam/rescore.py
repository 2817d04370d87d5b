"""``python -m irmcl_warp.slam.rescore <run folder>...``: score finished SLAM runs against the relations
again, from their trajectory.tum and config.yaml (e.g. where the relations file was missing on the
machine that ran them); updates metrics.json in place."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from eval.metrics import relations_error
from irmcl_warp.io import read_relations, resolve
from irmcl_warp.outputs import write_json


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps [N], poses [N, 3]) of a planar TUM file (yaw from the z-axis quaternion)."""
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns (stamp x y z qx qy qz qw), got {rows.shape[1]}")
    return rows[:, 0], np.column_stack([rows[:, 1], rows[:, 2], 2 * np.arctan2(rows[:, 6], rows[:, 7])])


def rescore(run: Path) -> dict:
    cfg = OmegaConf.load(run / "config.yaml")
    if not cfg.data.relations_path:
        raise ValueError(f"{run}: data={cfg.data.name} has no relations file")
    if cfg.data.get("relation_stamps_path"):
        raise ValueError(f"{run}: data={cfg.data.name} matches its relations through {cfg.data.relation_stamps_path}, "
                         f"not through the trajectory's stamps: rerun the slam stage to score it")
    metrics = json.loads((run / "metrics.json").read_text())
    stamps, poses = read_tum(run / "trajectory.tum")
    metrics["relations"] = relations_error(stamps, poses, read_relations(resolve(cfg.data.relations_path)))
    write_json(run / "metrics.json", metrics)
    return metrics["relations"]


def main(argv=None) -> None:
    for run in map(Path, argv if argv is not None else sys.argv[1:]):
        r = rescore(run)
        print(f"{run}: {r['trans_abs_mean_m']:.3f} m / {r['rot_abs_mean_deg']:.2f} deg over {r['relations_used']} relations")


if __name__ == "__main__":
    main()
