"""``python -m eval.analyses.rescore RUN_DIR...``: score finished localize runs again with today's metrics.

The trajectories (start<k>.tum) are kept; the metrics are not fixed. When the scoring rule changes (for example,
success now also needs the heading), this recomputes each start's metrics and the run's summary from its
trajectories and its log's ground truth. It keeps the timings and the settings, amends metrics.json (the
run's manifest records it: runs.amend), and prints what changed. Kidnapped runs are refused: their clock is rebuilt across the jump.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from omegaconf import OmegaConf

from irmcl_warp.io import read_tum
from irmcl_warp.mcl.stage import summarise
from irmcl_warp.services.data import load_stream
from irmcl_warp.services.metrics import localization_metrics
from irmcl_warp.runs import amend
from irmcl_warp.types import match_stamps


def run_trajectories(run: Path):
    """(log, [(stamps, estimates [N, 3], ground truth [N, 3]) per start, in start order]) of a localize run
    folder: its start<k>.tum read back (io.read_tum) and matched scan by scan to its log (config.yaml names
    it; the stream cache serves it)."""
    log = load_stream(OmegaConf.load(run / "config.yaml"))
    if log.ground_truth is None:
        raise ValueError(f"{run}: its log ({log.source}) has no ground truth")
    tums = sorted(run.glob("start*.tum"), key=lambda p: int(p.stem.removeprefix("start")))
    if not tums:
        raise FileNotFoundError(f"{run}: no start*.tum trajectories")
    out = []
    for tum in tums:
        stamps, est = read_tum(tum)
        idx = match_stamps(log.stamps, stamps, 1e-5)
        if (idx < 0).any():
            raise ValueError(f"{tum}: {int((idx < 0).sum())} stamps match no scan of {log.source}")
        out.append((stamps, est, log.ground_truth[idx]))
    return log, out


def rescore(run: Path) -> dict:
    doc = json.loads((run / "metrics.json").read_text())
    if doc["settings"].get("kidnap_at_s", 0) > 0:
        raise ValueError(f"{run}: a kidnapped run's clock is rebuilt across the jump; run it again instead")
    _, starts = run_trajectories(run)
    if len(starts) != len(doc["runs"]):
        raise ValueError(f"{run}: {len(starts)} trajectories for the {len(doc['runs'])} starts its metrics.json lists")
    runs = []
    for old, (stamps, est, gt) in zip(doc["runs"], starts):
        new = localization_metrics(stamps, est, gt)
        runs.append(
            {
                **{key: old[key] for key in ("start_s", "ms_per_scan", "steps", "ms_per_step_median") if key in old},
                **new,
            }
        )
    summary = {**doc["summary"], **summarise(runs, doc["settings"], doc["summary"].get("device", "?"))}
    changed = {
        key: (doc["summary"].get(key), value) for key, value in summary.items() if doc["summary"].get(key) != value
    }
    amend(run, {**doc, "summary": summary, "runs": runs}, "eval.analyses.rescore: today's localization metrics")
    return changed


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.rescore", description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="localize run folders with start*.tum and metrics.json")
    for run in ap.parse_args(argv).runs:
        changed = rescore(run)
        print(f"{run}: " + (", ".join(f"{k} {a} -> {b}" for k, (a, b) in changed.items()) or "unchanged"))


if __name__ == "__main__":
    main()
