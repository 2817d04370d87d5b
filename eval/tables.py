"""``python -m eval.tables [--write]``: every table and generated document, from the run records.

Without ``--write``: the tables of the kept records (results/) and of your own finished runs (outputs/; one of
yours replaces a kept record of the same settings), printed. With ``--write``: from the kept records only (a
document never depends on what a machine happens to hold in outputs/), the generated blocks of README.md
(between ``<!-- table:<name> -->`` and ``<!-- /table:<name> -->``) and its quoted figures (``<!-- fact:... -->``),
docs/REPRODUCTION.md (the claims registry's verdicts) and docs/fidelity.md.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from eval.report.facts import facts, write_facts
from eval.report.reproduction import reproduction_markdown
from eval.report.tables import (
    ablation_table,
    globloc_table,
    kidnap_table,
    localization_table,
    pipeline_table,
    released_table,
    slam_table,
    synthesis_table,
    own_slam_map_table,
    worlds_table,
)
from eval.results.claims import Evidence, load_bench, verdicts
from eval.results.queries import CONVERGED_M, released, synthesis_pairs
from eval.results.records import OUTPUTS, REPO, load
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.services.cli import guard


def evidence(outputs=OUTPUTS) -> tuple[Evidence, list, list]:
    """(the records the tables and claims read, the pipeline records, the worlds records); ``outputs`` None: the
    kept ones only."""
    recs = load(outputs=outputs)
    by = {
        s: [r for r in recs if r.stage == s]
        for s in ("train", "synthesis", "localize", "slam", "globloc", "pipeline", "worlds")
    }
    # a log localized in its own map (localize.map_path) is not a run of the benchmark protocol: its table is made
    # from results/own_slam_map by eval.analyses.own_slam_map
    by["localize"] = [r for r in by["localize"] if not (r.config.get("localize") or {}).get("map_path")]
    return (
        Evidence(
            synthesis_pairs(by["train"] + by["synthesis"]),
            by["localize"],
            by["slam"],
            by["globloc"],
            released(outputs=outputs),
            load_bench(),
        ),
        by["pipeline"],
        by["worlds"],
    )


def tables(ev: Evidence, pipe: list, worlds: list = ()) -> dict[str, tuple[str, str]]:
    out = {}
    if ev.nof:
        out["nof"] = (
            "Scan synthesis (IR-MCL protocol; NOF rendered with 256 samples, grids by ray casting)",
            synthesis_table(ev.nof),
        )
    if ev.loc:
        out["mcl"] = (
            "Localization (10 seeded starts per cell, 60 s each; means over the successful starts)",
            localization_table(ev.loc),
        )
        out["ablation"] = (
            "Ablations of IR-MCL's global localization, one setting at a time (10 starts of 60 s; ms per "
            "scan: the whole filter step, median over the starts)",
            ablation_table(ev.loc),
        )
        out["kidnap"] = (
            "Kidnapped robot (pose tracking teleported mid-run, AMCL-style recovery on)",
            kidnap_table(ev.loc),
        )
    if ev.slam:
        out["slam"] = (
            f"GMapping, relations metric (Kümmerle et al. 2009); converged = mean error < {CONVERGED_M} m",
            slam_table(ev.slam, ev.released),
        )
        out["released"] = (
            "GMapping against the released C++, same logs, 30 particles, seeds 0-9",
            released_table(ev.slam, ev.released),
        )
    if pipe:
        out["pipeline"] = (
            "The pipeline, raw log to localized robot (global localization from a uniform start over the second log)",
            pipeline_table(pipe),
        )
    if ev.globloc:
        out["globloc"] = (
            "Lidar + camera global localization (simulated worlds, identical sensor streams per method; "
            "localized = within 0.5 m and 15 deg to the end of the run or of the part before the kidnapping)",
            globloc_table(ev.globloc),
        )
    own = own_slam_map_records()
    if own:
        out["own_slam_map"] = (
            "Real logs localized from their first scan over the whole log in their own SLAM map, scored against the "
            "SLAM poses (python -m eval.analyses.own_slam_map)",
            own_slam_map_table(own),
        )
    if worlds:
        out["worlds"] = (
            "Global localization from the first scan on held-out simulated floors (test split; settings and "
            "calibration chosen on the tuning split)",
            worlds_table(worlds),
        )
    return out


def own_slam_map_records(repo=REPO) -> list:
    """The kept records of eval.analyses.own_slam_map (results/own_slam_map/*.json)."""
    return [json.loads(p.read_text()) for p in sorted((Path(repo) / "results" / "own_slam_map").glob("*.json"))]


def replace_block(text: str, name: str, table: str) -> str:
    begin, end = f"<!-- table:{name} -->", f"<!-- /table:{name} -->"
    pattern = re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise SystemExit(f"README.md has no {begin} ... {end} block")
    return pattern.sub(lambda _: f"{begin}\n{table}\n{end}", text)


def documents(repo=REPO) -> dict:
    """{path: text} of every generated document, from the kept records."""
    from eval.report.fidelity import document

    ev, pipe, worlds = evidence(outputs=None)
    text = (repo / "README.md").read_text()
    for name, (_, table) in tables(ev, pipe, worlds).items():
        text = replace_block(text, name, table)
    judged = verdicts(ev)
    text = write_facts(text, facts(ev.slam, ev.released, ev.nof, pipe, judged))
    return {
        repo / "README.md": text,
        repo / "docs" / "REPRODUCTION.md": reproduction_markdown(judged),
        repo / "docs" / "fidelity.md": document(),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.tables", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--write",
        action="store_true",
        help="write README.md's tables and facts, REPRODUCTION.md and fidelity.md (from the kept records)",
    )
    a = ap.parse_args(argv)
    if a.write:
        for path, text in documents().items():
            atomic_write_bytes(path, text.encode())
            print(f"-> {path}")
        return
    ev, pipe, worlds = evidence()
    made = tables(ev, pipe, worlds)
    if not made:
        raise SystemExit("no records under results/ or outputs/ (run a stage, e.g. python -m irmcl_warp.slam)")
    for title, table in made.values():
        print(f"{title}\n\n{table}\n")


if __name__ == "__main__":
    guard(main)
