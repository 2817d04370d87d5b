"""Whether a change keeps every output bit for bit: a fixed set of short seeded runs of each stage, made with the
code of one tree, hashed; two such records compared.

    python -m eval.same_bits run --tree /path/to/old/checkout --out old.json [--device cpu]
    python -m eval.same_bits run --tree . --out new.json
    python -m eval.same_bits compare old.json new.json

Each run is the stage's own command (``python -m irmcl_warp.<stage> ...``) in a fresh folder, with the tree put
first on ``PYTHONPATH``, its own table cache and ``TQDM_DISABLE=1``; fr079's localize runs read the tiny field
its first run trains (40 steps: a field to localize with, not a good one). What is hashed: every trajectory (``.tum``),
map (``.pgm``, ``.png``), array file (``.npz``) and checkpoint (``.pt``; not the trainer's resume state ``last.pt``, which holds wall times) the run writes, and its metrics.json with every timing
removed (``is_timing``). Settings that
changed their name between the trees are not used: the runs override only settings both trees have.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHORT = ["localize.num_starts=2", "localize.run_s=8", "mcl.num_particles=2000"]
TINY_NOF = ["train=cpu", "train.epochs=1", "train.steps_per_epoch=40", "train.val_scans=4"]  # a field in seconds
# folder: [(name, module, overrides)], run in order in one folder (fr079's localize runs read its training run)
GROUPS = {
    "fr079": [
        ("fr079-train", "irmcl_warp.train", ["+exp=fr079", *TINY_NOF]),
        (
            "fr079-nog_raymarch-tracking",
            "irmcl_warp.localize",
            ["+exp=fr079", *TINY_NOF, "localize.mode=tracking", *SHORT],
        ),
        (
            "fr079-nog_table-tracking",
            "irmcl_warp.localize",
            [
                "+exp=fr079",
                *TINY_NOF,
                "mcl.weighting=nog_table",
                "mcl.table_angles=90",
                "localize.mode=tracking",
                *SHORT,
            ],
        ),
        (
            "fr079-likelihood_field-global",
            "irmcl_warp.localize",
            ["+exp=fr079", "mcl.weighting=likelihood_field", "localize.mode=global", *SHORT],
        ),
        (
            "fr079-beam_model-tracking",
            "irmcl_warp.localize",
            ["+exp=fr079", "mcl.weighting=beam_model", "localize.mode=tracking", *SHORT],
        ),
    ],
    "sim": [
        (
            "sim-amcl-recovery-global",
            "irmcl_warp.localize",
            ["+exp=sim_office", "mcl=amcl", "sim.duration_s=40", "localize.mode=global", *SHORT],
        ),
        ("sim-gmapping", "irmcl_warp.slam", ["+exp=gmapping_sim", "sim.duration_s=60", "slam.num_particles=8"]),
    ],
    "worlds": [
        (
            "worlds-test",
            "irmcl_warp.worlds",
            ["+exp=worlds", "worlds.split=office-1001", "worlds.runs=2", "worlds.run_s=10", "mcl.num_particles=3000"],
        ),
    ],
}
HASHED = (".tum", ".pgm", ".png", ".npz", ".pt")
NOT_HASHED = ("last.pt",)  # the trainer's resume state: it holds the wall time of its epochs
TIMING_WORDS = {"ms", "time", "wall", "hz", "elapsed", "seconds", "manifest", "git", "host", "date", "epoch"}


def is_timing(key: str) -> bool:
    """Whether a metrics key holds a timing or provenance: one of its words (split at ``_``) is a timing word
    (``ms_per_step``, ``train_time_s``, ``epoch_s``), or it is a rate (``rays_per_s``). ``rmse_cm`` is not."""
    words = key.lower().split("_")
    return bool(TIMING_WORDS & set(words)) or key.lower().endswith("per_s")


def _untimed(value):
    """``value`` (a metrics.json document) without its timings and provenance."""
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if not is_timing(k)}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def digest_outputs(folder: Path) -> dict:
    """{relative path: sha256} of what a run wrote under ``folder``/outputs (timings removed from metrics)."""
    out = {}
    for path in sorted((folder / "outputs").rglob("*")):
        rel = str(path.relative_to(folder))
        if "/stream/" in rel or not path.is_file() or path.name in NOT_HASHED:
            continue  # the log's cache is an input
        if path.suffix in HASHED:
            out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
        elif path.name == "metrics.json":
            doc = _untimed(json.loads(path.read_text()))
            out[rel] = hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()
    return out


def run_all(tree: Path, out: Path, device: str, only: list[str]) -> dict:
    work = Path(tempfile.mkdtemp(prefix="same_bits-"))
    path = os.pathsep.join([str(tree.resolve()), *filter(None, [os.environ.get("PYTHONPATH")])])  # the tree first
    env = {**os.environ, "PYTHONPATH": path, "TQDM_DISABLE": "1", "IRMCL_CACHE_DIR": str(work / "cache")}
    record = {"tree": str(tree.resolve()), "device": device, "runs": {}}
    for group, runs in GROUPS.items():
        if only and group not in only:
            continue
        folder = work / group
        folder.mkdir()
        for name, module, overrides in runs:
            before = digest_outputs(folder)
            t0 = time.perf_counter()
            done = subprocess.run(
                [sys.executable, "-m", module, *overrides, f"device={device}"],
                cwd=folder,
                env=env,
                capture_output=True,
                text=True,
            )
            if done.returncode != 0:
                raise SystemExit(f"same_bits: {name} failed in {folder}:\n{done.stderr[-3000:]}")
            record["runs"][name] = {k: v for k, v in digest_outputs(folder).items() if before.get(k) != v}
            print(f"{name}: {len(record['runs'][name])} files hashed, {time.perf_counter() - t0:.0f} s", flush=True)
    out.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    shutil.rmtree(work, ignore_errors=True)
    return record


def compare(a: dict, b: dict) -> list[str]:
    """The differences between two records: runs or files one lacks, and files whose hashes differ. Paths are
    compared up to the run folder's id (the id digests the settings, whose names may differ between trees)."""

    def by_kind(files: dict) -> dict:
        out = {}
        for rel, h in files.items():
            if rel.rsplit("/", 1)[-1] in NOT_HASHED:
                continue
            parts = rel.split("/")
            parts[3:4] = [parts[3].rsplit("-", 1)[0]] if len(parts) > 4 else parts[3:4]  # drop the run id
            out.setdefault("/".join(parts), []).append(h)
        return {k: sorted(v) for k, v in out.items()}

    problems = []
    for name in sorted(set(a["runs"]) | set(b["runs"])):
        if name not in a["runs"] or name not in b["runs"]:
            problems.append(f"{name}: only in {'the first' if name in a['runs'] else 'the second'} record")
            continue
        fa, fb = by_kind(a["runs"][name]), by_kind(b["runs"][name])
        if not fa:
            problems.append(f"{name}: no output hashed")
        for rel in sorted(set(fa) | set(fb)):
            if fa.get(rel) != fb.get(rel):
                problems.append(f"{name}: {rel} differs" if rel in fa and rel in fb else f"{name}: {rel} in one only")
    return problems


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m eval.same_bits", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--tree", type=Path, default=REPO)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--device", default="cpu")
    r.add_argument("--only", nargs="*", default=[], help=f"groups of runs: {' '.join(GROUPS)}")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "run":
        run_all(args.tree, args.out, args.device, args.only)
        return 0
    a, b = (json.loads(p.read_text()) for p in (args.a, args.b))
    problems = compare(a, b)
    files = sum(len(v) for v in a["runs"].values())
    print(f"{len(a['runs'])} runs, {files} files: " + ("the same bits" if not problems else f"{len(problems)} differ"))
    for p in problems:
        print("  " + p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
