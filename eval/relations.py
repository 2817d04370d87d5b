"""``python -m eval.relations +exp=fr079``: score the ground-truth poses and the raw odometry of a log
against its Kümmerle et al. 2009 relations; prints a table, writes outputs/<exp>/relations/metrics.json."""

from __future__ import annotations

import sys
import time

import hydra
import numpy as np

from irmcl_warp.services.metrics import coverage_warning, relations_error
from irmcl_warp.config import register
from irmcl_warp.io import load_log, read_relations, resolve
from irmcl_warp.services.outputs import stage_dir, write_json, write_manifest
from irmcl_warp.services.cli import run_entry


def run_relations(cfg):
    started = time.time()
    if not cfg.data.relations_path:
        raise ValueError(f"data={cfg.data.name} has no relations file (data.relations_path)")
    log = load_log(cfg)
    rel = read_relations(resolve(cfg.data.relations_path))
    out = stage_dir(cfg, "relations")
    metrics = {"odometry": relations_error(log.stamps, log.odom, rel)}
    if log.num_ground_truth:
        known = np.isfinite(log.ground_truth[:, 0])
        metrics["ground_truth"] = relations_error(log.stamps[known], log.ground_truth[known], rel)
    write_json(out / "metrics.json", metrics)
    write_manifest(out, cfg, [resolve(cfg.data.path), resolve(cfg.data.relations_path)], "cpu", started)
    print(f"{cfg.data.name}: relations metric (Kümmerle et al. 2009)")
    for name, m in metrics.items():
        if shout := coverage_warning(m, f"{cfg.data.name} {name} ({cfg.data.relations_path})"):
            print(shout, file=sys.stderr)
    print(f"{'poses':<14}{'used':>6}{'trans m':>10}{'± std':>8}{'rot deg':>9}{'± std':>8}")
    for name, m in metrics.items():
        print(f"{name:<14}{m['relations_used']:>6}{m['trans_abs_mean_m']:>10.3f}{m['trans_abs_std_m']:>8.3f}"
              f"{m['rot_abs_mean_deg']:>9.2f}{m['rot_abs_std_deg']:>8.2f}")
    return out


register()


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg) -> None:
    run_entry(run_relations, cfg)


if __name__ == "__main__":
    main()
