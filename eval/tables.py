"""``python -m eval.tables [--write]``: every results table, generated from the runs' metrics.json files.

Runs are read from ``results/`` (runs kept in the repository, e.g. GPU runs) and ``outputs/`` (your own
runs; they win where both hold the same experiment and preset). ``--write`` replaces the generated
blocks of README.md (between ``<!-- table:<name> -->`` and ``<!-- /table:<name> -->``).
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOTS = (REPO / "results" / "nof", REPO / "outputs")
DATASET_ORDER = ("fr079", "intel", "mit_csail", "sim_office")


def _load(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise SystemExit(f"{path}: unreadable metrics file ({e}); rerun the stage that wrote it")


def collect_synthesis(roots=ROOTS) -> dict:
    """{(exp, preset): (synthesis metrics, train metrics or None)}; later roots override earlier ones."""
    runs = {}
    for root in roots:
        for f in sorted(Path(root).glob("*/synthesis-*/metrics.json")):
            exp, preset = f.parent.parent.name, f.parent.name.split("-", 1)[1]
            train = f.parent.parent / f"train-{preset}" / "metrics.json"
            runs[(exp, preset)] = (_load(f), _load(train) if train.is_file() else None)
    return runs


def _order(key):
    syn = key[1]
    ds = syn["dataset"]
    return (DATASET_ORDER.index(ds) if ds in DATASET_ORDER else 99, ds, syn["split"])


def synthesis_table(runs: dict) -> str:
    """IR-MCL Table I style: one row per method and (dataset, test split); grids once per test split."""
    rows, seen_grids = [], set()
    for (exp, preset), (syn, train) in sorted(runs.items(), key=lambda kv: (_order((kv[0], kv[1][0])), kv[0][1])):
        for name, m in syn["methods"].items():
            if m["kind"] == "grid":
                if (syn["dataset"], syn["split"], name) in seen_grids:
                    continue
                seen_grids.add((syn["dataset"], syn["split"], name))
                how = "-"
            else:
                how = (f"{train['train_time_s']:.0f} s, {train['epochs_done']} ep, {train.get('gpu') or train['device']}"
                       if train else "?")
            rows.append((syn["dataset"], syn["split"], name, m, how))
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    rows.sort(key=lambda r: (ds_rank.get(r[0], 99), r[0], r[1], r[2].startswith("OGM"), r[2]))
    lines = ["| dataset | test split | method | MAE (m) | median (m) | accuracy (%) | Chamfer (m) | F-score (%) | training |",
             "|---|---|---|---|---|---|---|---|---|"]
    for ds, split, name, m, how in rows:
        lines.append(f"| {ds} | {split} | {name} | {m['mae_m']:.3f} | {m['median_error_m']:.3f} | {m['accuracy_pct']:.1f} | "
                     f"{m['chamfer_m']:.3f} | {m['fscore_pct']:.1f} | {how} |")
    return "\n".join(lines)


def replace_block(text: str, name: str, table: str) -> str:
    begin, end = f"<!-- table:{name} -->", f"<!-- /table:{name} -->"
    pattern = re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise SystemExit(f"README.md has no {begin} ... {end} block")
    return pattern.sub(lambda _: f"{begin}\n{table}\n{end}", text)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.tables")
    ap.add_argument("--write", action="store_true", help="update the generated blocks of README.md")
    a = ap.parse_args(argv)
    runs = collect_synthesis()
    if not runs:
        raise SystemExit("no scan-synthesis results found under results/nof or outputs (run python -m eval.synthesis)")
    table = synthesis_table(runs)
    print("Scan synthesis (IR-MCL protocol; NOF rendered with 256 samples, grids by ray casting)\n")
    print(table)
    if a.write:
        readme = REPO / "README.md"
        readme.write_text(replace_block(readme.read_text(), "nof", table))
        print(f"-> {readme}")


if __name__ == "__main__":
    main()
