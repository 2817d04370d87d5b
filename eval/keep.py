"""``python -m eval.keep [--results results] [--maps] RUN_DIR...``: keep finished runs in the repository as run
records (results/<group>/<exp>.json: stage, id, settings read, metrics; see eval/results/records.py), the
records the tables, claims and plots read."""

from __future__ import annotations

import argparse
from pathlib import Path

from eval.results.records import RESULTS, keep
from irmcl_warp.services.cli import guard


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.keep", description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="finished run folders, e.g. outputs/fr079/localize/*")
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--maps", action="store_true", help="also keep the map.png of SLAM runs (docs/maps)")
    a = ap.parse_args(argv)
    for p in keep(a.runs, a.results, a.maps):
        print(f"-> {p}")


if __name__ == "__main__":
    guard(main)
