"""``python -m eval.bench sweeps --reports <reproduce report JSONs> --out <folder>``: the wall time of
``python -m eval.reproduce`` for the same sweeps with one GPU and with several (the pool launcher), as a table
of medians and spreads over the repeats, and the speedup of each layout against one GPU with the same jobs per
GPU. The reports come from ``eval/gpu/reproduce.sh`` on a GPU host (each repeat in a fresh working folder, so
every job runs); this command only reads them, so the figure is the reports', not this machine's.

A layout is (GPUs, jobs per GPU): with more GPUs there are also more processes at once, so the table shows
one GPU with as many processes beside it where it was measured: what a second GPU adds over a busier first.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from irmcl_warp.io.atomic import atomic_write_json


def add_parser(sub) -> None:
    p = sub.add_parser("sweeps", help="wall time of eval.reproduce on one GPU against several (from its reports)")
    p.add_argument("--reports", nargs="+", required=True, help="report JSONs of eval.reproduce --report")
    p.add_argument("--out", default=".", help="folder for sweeps-<gpu>.json")


def layouts(reports: list[dict]) -> dict:
    """{(sweep selection, GPUs, jobs per GPU): [wall s of each repeat]} over reports with no failed command
    and every job run (a repeat that found runs done would time less than the sweep)."""
    out: dict = {}
    for r in reports:
        if r["failed_commands"] or any(s["done"] or s["kept"] for s in r["sweeps"]):
            continue
        what = " ".join(f"{s['module'].rsplit('.', 1)[1]} {' '.join(s['fixed'])}".strip() for s in r["sweeps"])
        jobs = sum(s["jobs_run"] for s in r["sweeps"])
        out.setdefault((what, jobs, r["gpus"], r["jobs_per_gpu"]), []).append(r["wall_s"])
    return out


def table(groups: dict) -> tuple[str, list[dict]]:
    rows = []
    for (what, jobs, gpus, per), walls in sorted(groups.items()):
        base = groups.get((what, jobs, 1, per))
        rows.append(
            {
                "sweeps": what,
                "jobs": jobs,
                "gpus": gpus,
                "jobs_per_gpu": per,
                "processes": gpus * per,
                "repeats": len(walls),
                "wall_s_median": float(np.median(walls)),
                "wall_s_all": walls,
                "speedup_vs_1gpu_same_jobs_per_gpu": float(np.median(base) / np.median(walls)) if base else None,
            }
        )
    lines = [
        "| sweeps | jobs | GPUs x jobs per GPU | repeats | wall (s), median [min-max] | against 1 GPU, same jobs per GPU |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        w = r["wall_s_all"]
        speed = r["speedup_vs_1gpu_same_jobs_per_gpu"]
        lines.append(
            f"| {r['sweeps']} | {r['jobs']} | {r['gpus']} x {r['jobs_per_gpu']} | {r['repeats']} | "
            f"{np.median(w):.0f} [{min(w):.0f}-{max(w):.0f}] | {'-' if speed is None or r['gpus'] == 1 else f'{speed:.2f}x'} |"
        )
    return "\n".join(lines), rows


def run_sweeps_bench(a) -> Path:
    reports = [json.loads(Path(p).read_text()) for p in a.reports]
    names = sorted({n for r in reports for n in r.get("gpu_names", [])}) or ["cpu"]
    text, rows = table(layouts(reports))
    print(text)
    kind = "h100" if any("H100" in n for n in names) else "h200" if any("H200" in n for n in names) else "gpu"
    path = Path(a.out) / f"sweeps-{kind}x{max(len(r.get('gpu_names', [])) for r in reports)}.json"
    atomic_write_json(
        path,
        {
            "what": "eval.reproduce wall time by GPU layout",
            "gpu_names": names,
            "host_cores": sorted({r["host_cores"] for r in reports}),
            "rows": rows,
            "reports": [str(p) for p in a.reports],
        },
    )
    print(f"-> {path}")
    return path
