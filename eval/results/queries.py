"""What the tables, claims and plots ask of the run records, each question answered from settings.

* ``synthesis_pairs``: each scan-synthesis record with the training record of its field;
* ``slam_variant`` / ``slam_errors``: GMapping runs by proposal, resampling, particles and the settings
  they changed (``{"slam.srt": 0.4, "slam.stt": 0.4}``), their relations errors; ``converged``;
* ``released`` / ``released_errors``: the released GMapping's runs (eval.reference.gmapping);
* ``localize_cell``: a localization record's table cell and the settings beyond it;
* ``median_span``: how every figure of several runs is quoted.
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import numpy as np

from eval.results.records import OUTPUTS, RESULTS, load, off_defaults
from irmcl_warp import runs
from irmcl_warp.runs import Record
from irmcl_warp.services.metrics import SLAM_CONVERGED_M as CONVERGED_M

GLOBLOC_METHODS = {
    "lidar_mcl": "lidar-only MCL",
    "camera_only": "camera only",
    "paper": "paper's pipeline",
    "mcl_seeded": "MCL seeded by the camera",
}
DATASET_ORDER = ("fr079", "intel", "mit_csail", "sim_office")
GEOMETRY = ("data.fov_rad", "data.angle_min_rad", "data.laser_offset")  # where the beams point: a SLAM variant


def median_span(values, fmt: str = ".2f") -> str:
    """``median [min-max]`` of several runs' figures, each written with ``fmt``: how every figure of several
    runs is quoted (a median with its spread, never the best run)."""
    v = [float(x) for x in values]
    return f"{statistics.median(v):{fmt}} [{min(v):{fmt}}-{max(v):{fmt}}]"


def converged(errs) -> tuple[int, int, float | None, float]:
    """(converged runs, runs, mean error of the converged ones or None, mean error of all) of relations errors."""
    e = np.asarray(errs, float)
    ok = e < CONVERGED_M
    return int(ok.sum()), len(e), (float(e[ok].mean()) if ok.any() else None), float(e.mean())


# --- scan synthesis ----------------------------------------------------------------------------------------


def preset(rec: Record) -> str:
    """A NOF run's preset, plus the renderer when it is not Warp (``fast-torch_ref``), from its settings."""
    render = rec.setting("render.name", "warp")
    return rec.setting("train.name") + ("" if render == "warp" else f"-{render}")


def synthesis_pairs(recs: list[Record]) -> dict:
    """{(exp, preset): (synthesis record, the training record of the field it scored, or None)}: the training
    run the synthesis run consumed (its manifest), or the kept training record of the same settings."""
    trained = {(r.exp, r.id): r for r in recs if r.stage == "train"}
    by_settings = {(r.exp, r.settings_id, r.source): r for r in recs if r.stage == "train"}
    out = {}
    for r in recs:
        if r.stage != "synthesis":
            continue
        up = (getattr(r, "upstream", None) or {}).get("train")
        train = (
            trained.get((r.exp, up)) if up else by_settings.get((r.exp, runs.settings_id(r.config, "train"), r.source))
        )
        out[(r.exp, preset(r))] = (r, train)
    return out


# --- SLAM --------------------------------------------------------------------------------------------------

SLAM_CELL = ("slam.proposal", "slam.resample", "slam.num_particles", "slam.seed")


def slam_variant(rec: Record) -> dict:
    """The settings of a SLAM run beyond its table cell (proposal, resampling, particles, seed) that differ
    from the defaults, beam geometry overrides included; {} for a run at the defaults."""
    out = off_defaults(rec, ("slam",), ignore=SLAM_CELL)
    out.update({k: rec.setting(k) for k in GEOMETRY if rec.setting(k) is not None})
    return out


def slam_errors(
    recs,
    ds: str,
    proposal: str = "paper",
    resample: str = "selective",
    particles: int = 30,
    variant: dict | None = None,
) -> list[float]:
    """Mean relations errors (m) of the SLAM records on ``ds`` with these settings and exactly the settings
    ``variant`` changed."""
    return [
        r["relations"]["trans_abs_mean_m"]
        for r in recs
        if r.stage == "slam"
        and r.get("dataset") == ds
        and r.setting("slam.proposal") == proposal
        and r.setting("slam.resample") == resample
        and r.setting("slam.num_particles") == particles
        and isinstance(r.get("relations"), dict)
        and slam_variant(r) == (variant or {})
    ]


def load_slam(**where) -> list[Record]:
    return load(("slam",), **where)


# --- the released GMapping ------------------------------------------------------------------------------

TOOL = "reference_gmapping"  # eval.reference.gmapping's runs: outputs/<exp>/reference_gmapping/<run>/ (runs.tool_dir)
DERIVED_SETTINGS = ("maxRange", "angleIncrement")  # taken from the log by eval.reference.gmapping, not chosen


def released(results: Path | None = RESULTS, outputs: Path | None = OUTPUTS) -> dict:
    """{(exp, run): metrics} of the released GMapping's runs: kept (results/slam/reference/<exp>.json), then
    your own (eval.reference.gmapping's folders; they replace a kept run of the same name)."""
    out = {}
    for path in sorted((Path(results) / "slam" / "reference").glob("*.json")) if results is not None else ():
        for name, m in json.loads(path.read_text()).items():
            out[(path.stem, name)] = m
    for folder in runs.tool_runs(TOOL, root=outputs) if outputs is not None else ():
        m = json.loads((folder / "metrics.json").read_text())
        out[(folder.parents[1].name, m["run"])] = m
    return out


def reference_variant(m: dict) -> str:
    """The driver settings of a released-code run that differ from the ROS wrapper's defaults, then the
    overrides of the log's data config it ran with (``--data``); ``gfs`` for a run of the released code's
    own CARMEN-log tool (``--gfs``: its defaults, not the wrapper's)."""
    return ", ".join(
        [
            *(["gfs"] if m.get("tool") == "gfs_nogui" else []),
            *(f"{k}={v:g}" for k, v in sorted(m.get("settings", {}).items()) if k not in DERIVED_SETTINGS),
            *m.get("data_overrides", []),
        ]
    )


def released_errors(ref: dict, ds: str, particles: int = 30, variant: str = "") -> list[float]:
    """Mean relations errors (m) of the released GMapping's runs on ``ds`` (``variant``: reference_variant)."""
    return [
        m["relations"]["trans_abs_mean_m"]
        for m in ref.values()
        if m.get("dataset") == ds
        and m.get("particles") == particles
        and isinstance(m.get("relations"), dict)
        and reference_variant(m) == variant
    ]


# --- localization -----------------------------------------------------------------------------------------

LOCALIZE_CELL = ("mcl.weighting", "localize.mode", "mcl.num_particles", "mcl.map_resolution_m")


def resolution_cm(res_m: float) -> str:
    """A map resolution in cm as tables name it: ``5``, ``2.5``."""
    cm = res_m * 100
    return str(round(cm)) if abs(cm - round(cm)) < 1e-6 else f"{cm:g}"


def localize_cell(rec: Record) -> dict:
    """A localization record's table cell, from its settings: weighting, mode, map resolution in cm ("5",
    "2.5"), and ``extra``: the settings beyond the cell that differ from the defaults ({} for a run of the
    paper's cells; kidnapping, recovery and ablations otherwise)."""
    extra = off_defaults(rec, ("mcl", "localize"), ignore=LOCALIZE_CELL)
    return {
        "weighting": rec.setting("mcl.weighting"),
        "mode": rec.setting("localize.mode"),
        "res": resolution_cm(rec.setting("mcl.map_resolution_m")),
        "extra": extra,
    }


def localize_records(
    recs, exp: str, weighting: str, mode: str, particles: int, res_m: float = 0.05, extra: dict | None = None
) -> list[Record]:
    """The localization records of a cell of ``exp`` whose other settings are exactly ``extra`` off the
    defaults."""
    return [
        r
        for r in runs.find(
            "localize",
            exp,
            among=recs,
            mcl__weighting=weighting,
            localize__mode=mode,
            mcl__num_particles=particles,
            mcl__map_resolution_m=res_m,
        )
        if localize_cell(r)["extra"] == (extra or {})
    ]
