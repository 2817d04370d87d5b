"""Collecting the runs: every metrics.json under ``results/`` (runs kept in the repository, e.g. GPU runs) and
``outputs/`` (your own runs; they win where both hold the same experiment and run folder). Tables, claims
and plots read runs only through here."""

from __future__ import annotations

import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOTS = (REPO / "results" / "nof", REPO / "outputs")
MCL_ROOTS = (REPO / "results" / "mcl", REPO / "outputs")
SLAM_ROOTS = (REPO / "results" / "slam", REPO / "outputs")
GLOBLOC_ROOTS = (REPO / "results" / "globloc", REPO / "outputs")
GLOBLOC_METHODS = {"lidar_mcl": "lidar-only MCL", "camera_only": "camera only", "paper": "paper's pipeline",
                   "mcl_seeded": "MCL seeded by the camera"}
CONVERGED_M = 0.15  # a SLAM run "converged" below this mean relations error (the threshold of issue 6's reference)
# localize-<weighting>-<mode>-<particles>-<res>cm[-kidnap<s>s][-recovery], see irmcl_warp.localize.run_tag
TAG = re.compile(r"localize-(?P<w>[a-z_]+)-(?P<mode>global|tracking)-(?P<n>\d+k?)-(?P<res>[\d.]+)cm(?P<rest>.*)$")
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


def collect_localization(roots=MCL_ROOTS) -> dict:
    """{(exp, run folder): metrics} of the localize stage; later roots override earlier ones. Folders that do
    not follow the run-tag naming (older layouts) are left out."""
    return _collect_runs(roots, "localize-*", TAG.match)


def _collect_runs(roots, folders: str, keep=lambda name: True) -> dict:
    """{(exp, run folder): metrics} of root/<exp>/<folders>/metrics.json; later roots override earlier ones."""
    runs = {}
    for root in roots:
        for f in sorted(Path(root).glob(f"*/{folders}/metrics.json")):
            if keep(f.parent.name):
                runs[(f.parent.parent.name, f.parent.name)] = _load(f)
    return runs


def slam_variant(tag: str) -> str:
    """The ablation settings a SLAM run folder names after its seed ("" for the defaults): ``freecheck, dda``."""
    import re

    m = re.match(r"slam-\w+?-\w+?-\d+p-seed\d+(.*)$", tag)
    return ", ".join(re.split(r"-(?=[a-z])", m.group(1))[1:]) if m and m.group(1) else ""


def collect_slam(roots=SLAM_ROOTS) -> dict:
    """{(exp, run folder): metrics} of the slam stage; later roots override earlier ones."""
    return _collect_runs(roots, "slam-*")


def collect_pipeline(roots=(REPO / "results" / "pipeline", REPO / "outputs")) -> dict:
    return _collect_runs(roots, "pipeline")


def collect_globloc(roots=GLOBLOC_ROOTS) -> dict:
    return _collect_runs(roots, "globloc-*")
