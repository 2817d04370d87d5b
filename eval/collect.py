"""Collecting the runs: the runs kept in the repository (``results/<group>/<exp>.json``, written by
``python -m eval.keep``) and your own (``outputs/<exp>/<stage>-*/`` with config.yaml and metrics.json; they
win where both hold the same experiment and run folder). Tables, claims and plots read runs only through
here, and every label they print comes from a run's config and metrics, never from its folder's name.

A run is its metrics dict (``Run``) with the config sections its stage read as ``run.config``."""

from __future__ import annotations

import json
import re
import statistics
from pathlib import Path

from omegaconf import OmegaConf

from eval.keep import migrate, read_run, stage_of
from irmcl_warp.mcl.folders import resolution_tag
from irmcl_warp.mcl.stage import cell_tag, run_tag as localize_run_tag
from irmcl_warp.nof.folders import run_name as nof_run_name
from irmcl_warp.slam.stage import variant_suffix as slam_variant_suffix

REPO = Path(__file__).resolve().parents[1]
RESULTS, OUTPUTS = REPO / "results", REPO / "outputs"
GLOBLOC_METHODS = {"lidar_mcl": "lidar-only MCL", "camera_only": "camera only", "paper": "paper's pipeline",
                   "mcl_seeded": "MCL seeded by the camera"}
CONVERGED_M = 0.15  # a SLAM run "converged" below this mean relations error (the threshold of issue 6's reference)
DATASET_ORDER = ("fr079", "intel", "mit_csail", "sim_office")


class Run(dict):
    """A run's metrics.json, with ``config``: the config sections its stage read, and ``source``: "results"
    (kept in the repository) or "outputs" (your own)."""

    def __init__(self, metrics: dict, config: dict, source: str = "outputs"):
        super().__init__(metrics)
        self.config, self.source = config, source


def _load_kept(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise SystemExit(f"{path}: unreadable results file ({e}); regenerate it with python -m eval.keep")


def collect(group: str, stages: tuple[str, ...], results: Path = RESULTS, outputs: Path | None = OUTPUTS) -> dict:
    """{(exp, run folder): Run} of the stages ``stages`` (results/<group>/<exp>.json, then outputs/)."""
    runs = {}
    for path in sorted((Path(results) / group).glob("*.json")):
        doc = _load_kept(path)
        for folder, r in doc["runs"].items():
            if stage_of(folder) in stages:  # in today's names, settings added since filled (as eval.keep does)
                config, metrics = migrate(r["config"], r["metrics"], stage_of(folder))
                runs[(doc["exp"], folder)] = Run(metrics, config, "results")
    for stage in stages if outputs is not None else ():
        for f in sorted(Path(outputs).glob(f"*/{stage}*/metrics.json")):
            if stage_of(f.parent.name) != stage:
                continue
            try:
                r = read_run(f.parent)
            except (OSError, ValueError) as e:
                raise SystemExit(f"{f.parent}: unreadable run ({e}); rerun the stage that wrote it")
            runs[(f.parent.parent.name, f.parent.name)] = Run(r["metrics"], r["config"])
    return runs


def run_name(run: Run) -> str:
    """A NOF run's preset, plus the renderer when it is not Warp, from its config (as the stage names it)."""
    return nof_run_name(OmegaConf.create(run.config))


def collect_synthesis(**where) -> dict:
    """{(exp, preset): (synthesis metrics, train metrics or None)}: each scan-synthesis run with the training
    run of the same preset and renderer from the same place (the field it scored)."""
    runs = collect("nof", ("synthesis", "train"), **where)
    trained = {(exp, run_name(r), r.source): r for (exp, folder), r in runs.items() if stage_of(folder) == "train"}
    return {(exp, run_name(r)): (r, trained.get((exp, run_name(r), r.source)))
            for (exp, folder), r in runs.items() if stage_of(folder) == "synthesis"}


def collect_localization(**where) -> dict:
    return collect("mcl", ("localize",), **where)


def collect_slam(**where) -> dict:
    return collect("slam", ("slam",), **where)


def collect_slam_reference(results: Path = RESULTS, outputs: Path | None = OUTPUTS) -> dict:
    """{(exp, run): metrics} of the released GMapping's runs (eval.reference.gmapping): kept ones
    (results/slam/reference/<exp>.json), then your own (outputs/<exp>/reference-gmapping-*/metrics.json)."""
    runs = {}
    for path in sorted((Path(results) / "slam" / "reference").glob("*.json")):
        for name, m in _load_kept(path).items():
            runs[(path.stem, name)] = m
    for f in sorted(Path(outputs).glob("*/reference-gmapping-*/metrics.json")) if outputs is not None else ():
        runs[(f.parent.parent.name, f.parent.name.removeprefix("reference-gmapping-"))] = json.loads(f.read_text())
    return runs


DERIVED_SETTINGS = ("maxRange", "angleIncrement")  # taken from the log by eval.reference.gmapping, not chosen


def reference_variant(m: dict) -> str:
    """The driver settings of a released-code run that differ from the ROS wrapper's defaults, then the
    overrides of the log's data config it ran with (``--data``); ``gfs`` for a run of the released code's
    own CARMEN-log tool (``--gfs``: its defaults, not the wrapper's)."""
    return ", ".join([*(["gfs"] if m.get("tool") == "gfs_nogui" else []),
                      *(f"{k}={v:g}" for k, v in sorted(m.get("settings", {}).items()) if k not in DERIVED_SETTINGS),
                      *m.get("data_overrides", [])])


def slam_errors(runs: dict, ds: str, proposal: str = "paper", resample: str = "selective", particles: int = 30,
                variant: str = "") -> list[float]:
    """Mean relations errors (m) of our SLAM runs on ``ds`` with these settings (``variant``: slam_variant)."""
    return [m["relations"]["trans_abs_mean_m"] for m in runs.values()
            if m.get("dataset") == ds and m.get("proposal") == proposal and m.get("resample") == resample
            and m.get("particles") == particles and isinstance(m.get("relations"), dict) and slam_variant(m) == variant]


def released_errors(runs: dict, ds: str, particles: int = 30, variant: str = "") -> list[float]:
    """Mean relations errors (m) of the released GMapping's runs on ``ds`` (``variant``: reference_variant)."""
    return [m["relations"]["trans_abs_mean_m"] for m in runs.values()
            if m.get("dataset") == ds and m.get("particles") == particles and isinstance(m.get("relations"), dict)
            and reference_variant(m) == variant]


def median_span(values, fmt: str = ".2f") -> str:
    """``median [min-max]`` of several runs' figures, each written with ``fmt``: how every figure of several
    runs is quoted (a median with its spread, never the best run)."""
    v = [float(x) for x in values]
    return f"{statistics.median(v):{fmt}} [{min(v):{fmt}}-{max(v):{fmt}}]"


def converged(errs) -> tuple[int, int, float | None, float]:
    """(converged runs, runs, mean error of the converged ones or None, mean error of all) of relations errors."""
    import numpy as np

    e = np.asarray(errs, float)
    ok = e < CONVERGED_M
    return int(ok.sum()), len(e), (float(e[ok].mean()) if ok.any() else None), float(e.mean())


def collect_pipeline(**where) -> dict:
    return collect("pipeline", ("pipeline",), **where)


def collect_globloc(**where) -> dict:
    return collect("globloc", ("globloc",), **where)


def slam_variant(run: Run) -> str:
    """The ablation settings of a SLAM run that differ from the defaults ("" for none): ``freecheck, dda``,
    from its settings and data config (as the slam stage names its folder)."""
    suffix = slam_variant_suffix(OmegaConf.create(run.config["slam"]), OmegaConf.create(run.config.get("data", {})))
    return ", ".join(re.split(r"-(?=[a-z])", suffix)[1:])


def localize_cell(run: Run) -> dict:
    """A localize run's table cell, from its settings (the mcl and localize sections it ran with): weighting,
    mode, map resolution as the stage names it ("5", "2.5" cm), and ``extra``: what its run tag adds beyond
    the cell (kidnapping, recovery, ablation settings; "" for a run of the paper's cells)."""
    st = OmegaConf.create(run["settings"])
    return {"weighting": st.weighting, "mode": st.mode, "res": resolution_tag(st.map_resolution_m),
            "extra": localize_run_tag(st, st)[len(cell_tag(st, st)):]}
