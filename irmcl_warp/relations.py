"""``python -m irmcl_warp.relations +exp=fr079``: score the ground-truth poses and the raw odometry of a log
against its Kümmerle et al. 2009 relations; prints a table, writes outputs/<exp>/relations/<log>-<id>/metrics.json."""

from __future__ import annotations

import json
import sys

import hydra
import numpy as np

from irmcl_warp.services.metrics import coverage_warning, relations_error
from irmcl_warp.config import register
from irmcl_warp import runs
from irmcl_warp.io import read_relations, resolve
from irmcl_warp.services.data import load_stream
from irmcl_warp.services.cli import hydra_main, run_entry


def run_relations(cfg):
    if not cfg.data.relations_path:
        raise ValueError(f"data={cfg.data.name} has no relations file (data.relations_path)")
    with runs.start(cfg, "relations") as run:
        if not run.done:
            cfg = run.cfg
            log = load_stream(cfg)
            rel = read_relations(resolve(cfg.data.relations_path))
            metrics = {"odometry": relations_error(log.stamps, log.odom, rel)}
            if log.num_ground_truth:
                known = np.isfinite(log.ground_truth[:, 0])
                metrics["ground_truth"] = relations_error(log.stamps[known], log.ground_truth[known], rel)
            run.finish(metrics, "cpu")
    out = run.path
    metrics = json.loads((out / "metrics.json").read_text())
    print(f"{cfg.data.name}: relations metric (Kümmerle et al. 2009)")
    for name, m in metrics.items():
        if shout := coverage_warning(m, f"{cfg.data.name} {name} ({cfg.data.relations_path})"):
            print(shout, file=sys.stderr)
    print(f"{'poses':<14}{'used':>6}{'trans m':>10}{'± std':>8}{'rot deg':>9}{'± std':>8}")
    for name, m in metrics.items():
        print(
            f"{name:<14}{m['relations_used']:>6}{m['trans_abs_mean_m']:>10.3f}{m['trans_abs_std_m']:>8.3f}"
            f"{m['rot_abs_mean_deg']:>9.2f}{m['rot_abs_std_deg']:>8.2f}"
        )
    return out


register()


@hydra.main(version_base="1.3", config_path="pkg://irmcl_warp.conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_relations, cfg)


if __name__ == "__main__":
    hydra_main(main)
