"""``python -m eval.keep [--results results] [--maps] [--check STUDY] RUN_DIR...``: keep finished runs in the
repository as run records (results/<group>/<exp>.json: stage, id, settings read, metrics; see
eval/results/records.py), the records the tables, claims and plots read. ``--check STUDY`` merges them into a
check study instead (results/checks/<STUDY>.json: runs made for one comparison, e.g. ``nog_table``), each run's
log and stage read from its manifest."""

from __future__ import annotations

import argparse
from pathlib import Path

import json

from eval.results.records import RESULTS, _unkeepable, keep, keep_check
from irmcl_warp.services.cli import guard


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.keep", description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="finished run folders, e.g. outputs/fr079/localize/*")
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--maps", action="store_true", help="also keep the map.png of SLAM runs (docs/maps)")
    ap.add_argument("--check", metavar="STUDY", help="merge into results/checks/STUDY.json (a check study)")
    a = ap.parse_args(argv)
    if a.check:
        for p in keep_checks(a.check, a.runs, a.results):
            print(f"-> {p}")
        return
    for p in keep(a.runs, a.results, a.maps):
        print(f"-> {p}")


def keep_checks(study: str, folders, results: Path = RESULTS) -> list[Path]:
    """Finished run folders into the check study ``study``, grouped by the log their manifest names; a folder that
    cannot be kept (no manifest, or its settings or metrics not what the run wrote) stops the whole call, naming it."""
    by_exp: dict[str, list] = {}
    for folder in map(Path, folders):
        why = _unkeepable(folder)
        if why:
            raise SystemExit(f"eval.keep: {folder}: {why}")
        manifest = json.loads((folder / "manifest.json").read_text())
        by_exp.setdefault(manifest["exp"], []).append((folder, manifest["stage"], [], None))
    return [keep_check(study, exp, entries, results) for exp, entries in sorted(by_exp.items())]


if __name__ == "__main__":
    guard(main)
