"""``python -m eval.analyses.own_slam_map --slam <slam run> --runs <localize runs>... [--out FILE.json]``

Global localization of a log in its own SLAM map (issue 33), scored against that SLAM run's poses of the same
scans: both live in the map's frame, so no alignment is fitted (a rigid fit to the truth would explain away a
filter that settled on a look-alike place and followed the robot there). Each localization run (an own-map run:
``localize.map_path=<slam run>/map.yaml``, its ``trajectory.tum``) is judged by the benchmark protocol
(services.metrics.localization_metrics: converged = within CONVERGED_M for CONVERGED_FOR_S, success = converged
within SUCCESS_WITHIN_S with the location and heading RMSE after it under the protocol's bounds), with the time
from the first scan. Prints a table and writes the JSON record.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.io import read_tum
from irmcl_warp.mcl.confidence import auroc, right
from irmcl_warp.config import WorldsConfig, own_map_calibration, own_map_lost_rule_file
from irmcl_warp.mcl.own_map import CONFIDENT_ABOVE
from irmcl_warp.runs import OWN_MAP_CALIBRATION, OWN_MAP_LOST_RULE, file_digest
from irmcl_warp.services.cli import guard
from irmcl_warp.services.metrics import error_at_end, localization_metrics
from irmcl_warp.services.outputs import write_json


def on_reference(stamps: np.ndarray, est: np.ndarray, ref_stamps: np.ndarray, ref: np.ndarray, tol_s: float = 1e-3):
    """The reference pose at each estimate's stamp (the same scans of the same log); NaN where none is within
    ``tol_s``."""
    k = np.clip(np.searchsorted(ref_stamps, stamps), 1, len(ref_stamps) - 1)
    k = np.where(np.abs(ref_stamps[k - 1] - stamps) <= np.abs(ref_stamps[k] - stamps), k - 1, k)
    out = ref[k].astype(float).copy()
    out[np.abs(ref_stamps[k] - stamps) > tol_s] = np.nan
    return out


def confidence_per_scan(run: Path, stamps: np.ndarray) -> np.ndarray:
    """The run's calibrated confidence at each of its scans (spread.csv; NaN before the filter's first update and
    where the run had none)."""
    if not (run / "spread.csv").is_file():
        return np.full(len(stamps), np.nan)
    rows = np.genfromtxt(run / "spread.csv", delimiter=",", names=True)
    if "confidence" not in rows.dtype.names:
        return np.full(len(stamps), np.nan)
    # in the trajectory's order: read_tum sorts by stamp (stable) and drops repeated stamps (intel's log has 628
    # scans stamped before the one before them), spread.csv keeps the scans' order
    at, conf = np.atleast_1d(rows["stamp"]).astype(float), np.atleast_1d(rows["confidence"]).astype(float)
    order = np.argsort(at, kind="stable")
    at, conf = at[order], conf[order]
    keep = np.concatenate([[True], np.diff(at) != 0])
    at, conf = at[keep], conf[keep]
    # each trajectory pose's row (the trajectory leaves out scans without an estimate; spread.csv has every scan)
    k = np.clip(np.searchsorted(at, stamps - 1e-6), 0, len(at) - 1)
    if np.abs(at[k] - stamps).max() > 1e-5:
        raise ValueError(f"{run / 'spread.csv'}: a trajectory stamp has no row (stamps differ by more than 10 us)")
    return conf[k]


def score_run(run: Path, ref_stamps: np.ndarray, ref: np.ndarray) -> dict:
    stamps, est = read_tum(run / "trajectory.tum")
    on_ref = on_reference(stamps, est, ref_stamps, ref)
    if np.isfinite(on_ref).all(1).sum() < 0.9 * len(stamps):
        raise ValueError(f"{run}: fewer than 90 % of its scans have a SLAM pose: was it localized in this log's map?")
    m = json.loads((run / "metrics.json").read_text())
    cfg = OmegaConf.load(run / "config.yaml")  # the settings the run read
    manifest = json.loads((run / "manifest.json").read_text())
    scored = localization_metrics(stamps, est, on_ref)
    return {
        "run": str(run),
        "seed": OmegaConf.select(cfg, "mcl.seed"),
        "particles": OmegaConf.select(cfg, "mcl.num_particles"),
        "weighting": OmegaConf.select(cfg, "mcl.weighting"),
        "global_candidates": OmegaConf.select(cfg, "mcl.global_candidates") or 1,  # (runs before the setting: 1)
        # the pose reported at each update: the judged mode's, or the filter's estimate (runs before the setting)
        "report_pose": OmegaConf.select(cfg, "localize.report_pose") or "filter",
        # each scan's odometry read this long after its stamp (data.scan_time_offset_s; runs before the setting: 0)
        "scan_time_offset_s": float(OmegaConf.select(cfg, "data.scan_time_offset_s") or 0.0),
        "device": manifest.get("device"),
        "wall_time_s": manifest.get("wall_time_s"),
        "scans": int(len(stamps)),
        "log_s": float(stamps[-1] - stamps[0]),
        **{
            k: scored[k]
            for k in ("converged", "time_to_converge_s", "success", "location_rmse_cm", "yaw_rmse_deg", "divergences")
        },
        "error_at_end_m": error_at_end(est, on_ref),
        "calibration": calibration_of_run(manifest, cfg),
        "confidence_at_end": m.get("confidence_at_end"),
        # the lost-robot rule's events (own-map runs since the thirtieth session; None before) and how many of them
        # came while the estimate was right (a false alarm: right by the SLAM pose at the scan before the event)
        "relocalize": bool(OmegaConf.select(cfg, "localize.relocalize")),
        "lost_at_s": m.get("lost_at_s"),
        "lost_rule": lost_rule_of_run(manifest),
        "false_alarms": false_alarms(m.get("lost_at_s"), stamps, est, on_ref),
        "localized_at_end": m.get("localized_at_end"),
        # per scan, where the confidence and the SLAM pose exist: the confidence, and whether the estimate was right
        # (within RIGHT_M and RIGHT_DEG of the SLAM pose); pooled over the runs by ``judge_confidence``
        **per_scan_judgement(confidence_per_scan(run, stamps), est, on_ref),
    }


def false_alarms(lost_at_s, stamps: np.ndarray, est: np.ndarray, on_ref: np.ndarray) -> int | None:
    """Of the lost events (s since the first scan), those whose last scan before held an estimate right by the SLAM
    pose (within RIGHT_M / RIGHT_DEG): the rule fired on a robot that was not lost. None without the record."""
    if lost_at_s is None:
        return None
    t = stamps - stamps[0]
    ok = right(est, on_ref)
    count = 0
    for at in lost_at_s:
        before = np.flatnonzero((t < at - 1e-6) & np.isfinite(est).all(1))
        count += bool(len(before) and ok[before[-1]])
    return count


def calibration_of_run(manifest: dict, cfg) -> str | None:
    """Which calibration judged an own-map run: the file and what it was fitted on (its ``source``), read from the file
    when its content is still the one the run's manifest digested (runs.OWN_MAP_CALIBRATION); else the digest's
    first 10 hex digits (a file since fitted again); None for a run with no calibration or made before the digest."""
    files = (manifest.get("inputs") or {}).get(OWN_MAP_CALIBRATION) or []  # [{"path", "sha256"}]
    if not files:
        return None
    digests = [f["sha256"] if isinstance(f, dict) else f for f in files]
    path = own_map_calibration(OmegaConf.select(cfg, "mcl.weighting"), OmegaConf.select(cfg, "mcl.num_particles"))
    if path is not None and path.is_file() and file_digest(path) == digests[0]:
        source = json.loads(path.read_text()).get("source")  # "eval.confidence fit on <tuning runs>"
        return f"{path.name} ({source})" if source else path.name
    return f"sha256 {digests[0][:10]}"


RULE_SETTINGS = ("lost_agreement_below", "lost_agreement_updates", "relocalize_places", "relocalize_keeps_particles")
# (what the own-map table names)


def lost_rule_of_run(manifest: dict) -> dict | None:
    """The lost-robot rule's settings an own-map run read (runs.OWN_MAP_LOST_RULE: conf/exp/worlds.yaml's digest in its
    manifest): from the file when its content is still the one digested, else from the version of the file in git
    history with that digest; None for a run made before the digest, {"sha256": ...} when no version matches."""
    import hashlib
    import subprocess

    files = (manifest.get("inputs") or {}).get(OWN_MAP_LOST_RULE) or []
    if not files:
        return None
    digest = files[0]["sha256"] if isinstance(files[0], dict) else files[0]
    path = own_map_lost_rule_file().resolve()
    texts = [path.read_bytes()] if file_digest(path) == digest else []
    if not texts:
        root = Path(__file__).resolve().parents[2]
        try:
            rel = path.relative_to(root).as_posix()
            shas = subprocess.run(
                ["git", "log", "--format=%H", "--", rel], cwd=root, capture_output=True, text=True, check=True
            ).stdout.split()
            for sha in shas:
                text = subprocess.run(["git", "show", f"{sha}:{rel}"], cwd=root, capture_output=True, check=True).stdout
                if hashlib.sha256(text).hexdigest() == digest:
                    texts = [text]
                    break
        except (ValueError, OSError, subprocess.CalledProcessError):
            pass
    if not texts:
        return {"sha256": digest[:10]}
    worlds = OmegaConf.merge(OmegaConf.structured(WorldsConfig), OmegaConf.create(texts[0].decode()).get("worlds", {}))
    return {k: worlds[k] for k in RULE_SETTINGS}


def per_scan_judgement(conf: np.ndarray, est: np.ndarray, on_ref: np.ndarray) -> dict:
    has = np.isfinite(conf) & np.isfinite(est).all(1) & np.isfinite(on_ref).all(1)
    return {"scan_confidence": conf[has].round(4).tolist(), "scan_right": right(est[has], on_ref[has]).tolist()}


def judge_confidence(rows: list[dict], threshold: float = CONFIDENT_ABOVE) -> dict:
    """How the confidence separates right from wrong over every scan of the runs: the AUROC (right against wrong
    scans), the confidence's median when right and when wrong, and the share of scans above the threshold when
    right (said localized) and when wrong (said localized although wrong)."""
    conf = np.concatenate([np.asarray(r["scan_confidence"], float) for r in rows]) if rows else np.zeros(0)
    ok = np.concatenate([np.asarray(r["scan_right"], bool) for r in rows]) if rows else np.zeros(0, bool)
    med = lambda v: float(np.median(v)) if len(v) else None  # noqa: E731
    share = lambda v: float(np.mean(v >= threshold)) if len(v) else None  # noqa: E731
    return {
        "scans": int(len(conf)),
        "scans_right": int(ok.sum()),
        "auroc": None if ok.all() or not ok.any() else auroc(conf, ok),
        "median_when_right": med(conf[ok]),
        "median_when_wrong": med(conf[~ok]),
        "above_threshold_when_right": share(conf[ok]),
        "above_threshold_when_wrong": share(conf[~ok]),
        "threshold": threshold,
    }


def false_alarm_rate(rows: list[dict]) -> dict | None:
    """The lost-robot rule's events over the runs that ran it, and its false alarms (fired while the estimate was
    right) per hour of right tracking, as issue 33 counts them: each run's hours times its share of scans judged
    right (the scans come at a steady rate). None when no run ran the rule."""
    lost = [r for r in rows if r["lost_at_s"] is not None]
    if not lost:
        return None
    right = sum(r["log_s"] * r["scans_judged_right"] / r["scans_judged"] for r in lost if r["scans_judged"]) / 3600
    false = sum(r["false_alarms"] or 0 for r in lost)
    return {
        "events": sum(len(r["lost_at_s"]) for r in lost),
        "false": false,
        "hours": sum(r["log_s"] for r in lost) / 3600,
        "hours_right": right,
        "per_hour_right": false / right if right else float("nan"),
        "relocalize": bool(lost[0]["relocalize"]),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.own_slam_map", description=__doc__.split("\n\n")[1])
    ap.add_argument("--slam", required=True, type=Path, help="the SLAM run whose map.yaml the runs localized in")
    ap.add_argument("--runs", required=True, nargs="+", type=Path, help="own-map localization runs")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    ref_stamps, ref = read_tum(a.slam / "trajectory.tum")
    rows = [score_run(r, ref_stamps, ref) for r in sorted(a.runs)]
    ok = sum(bool(r["success"]) for r in rows)
    print(f"{a.slam}: {len(rows)} runs localized in its map, scored against its poses")
    print("| seed | scans | converged after (s) | success | RMSE after (cm) | error at end (m) | confidence at end |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        conv = "-" if r["time_to_converge_s"] is None else f"{r['time_to_converge_s']:.1f}"
        rmse = "-" if r["location_rmse_cm"] is None else f"{r['location_rmse_cm']:.1f}"
        end = "-" if r["error_at_end_m"] is None else f"{r['error_at_end_m']:.2f}"
        conf = "-" if r["confidence_at_end"] is None else f"{r['confidence_at_end']:.2f}"
        print(f"| {r['seed']} | {r['scans']} | {conv} | {r['success']} | {rmse} | {end} | {conf} |")
    print(f"success {ok}/{len(rows)}")
    judged = judge_confidence(rows)
    for r in rows:  # the per-scan arrays are pooled above; the record keeps each run's share of right scans
        conf, hit = r.pop("scan_confidence"), r.pop("scan_right")
        r["scans_judged"], r["scans_judged_right"] = len(conf), int(sum(hit))
    alarms = false_alarm_rate(rows)
    if alarms:
        print(
            f"lost-robot rule: {alarms['events']} events in {alarms['hours']:.2f} h, {alarms['false']} of them while "
            f"the estimate was right, which it was for {alarms['hours_right']:.2f} h "
            f"({alarms['per_hour_right']:.1f} false alarms an hour of right tracking); "
            + ("each re-seeded" if alarms["relocalize"] else "reported")
        )
    if judged["scans"]:
        auc = "-" if judged["auroc"] is None else f"{judged['auroc']:.3f}"
        print(
            f"confidence over {judged['scans']:,} scans ({judged['scans_right']:,} right): AUROC {auc}; median "
            f"{judged['median_when_right']} when right, {judged['median_when_wrong']} when wrong"
        )
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        log = OmegaConf.select(OmegaConf.load(a.slam / "config.yaml"), "data.name")
        write_json(
            a.out,
            {
                "log": log,
                "slam_run": str(a.slam),
                "runs": rows,
                "successes": ok,
                "of": len(rows),
                "confidence": judged,
                "false_alarms": alarms,
            },
        )
        print(f"-> {a.out}")
    return rows


if __name__ == "__main__":
    guard(main)
