"""``python -m eval.analyses.kidnaps RUN_DIR [--out F.json]``: why the kidnapped drives of a worlds run missed the
issue's "detected within 2 s, re-converged within 5 s" (issue 33), read from the run's own traces.

The worlds stage counts a drive re-converged at the first scan after the detection from which its estimate is right
to the end of the drive (``score_run``): a later excursion out of the tolerance (``RIGHT_M``, ``RIGHT_DEG``) moves
it, even one between two updates, where the estimate is the last update's pose moved by the odometry. This analysis
tells the misses apart, per drive that was right before the kidnapping:

- ``not detected``: no lost event after the kidnapping;
- ``back, off between updates only``: right again within 5 s of the detection, and wrong later only between two
  updates (the odometry-propagated pose), never at an update; with the excursion's largest heading and position error;
- ``back, then wrong again at updates``: right again within 5 s, then wrong at an update later (a look-alike place
  taken over again);
- ``look-alike``: not right again within 5 s of the detection;

and, for every miss, the seconds after the kidnapping spent wrong with the confidence at or above
``worlds.confident_above`` (confidently wrong). Prints a table and writes it as JSON.

``--evidence`` asks of every look-alike and undetected miss whether its scans could have told the places apart at all
(``window_evidence``): the drive is made again from the run's config.yaml (the simulator is deterministic; its truth
must match the trace's), and over the window the issue allows (5 s from the detection; 7 s from the kidnapping when
none was detected) each scan's agreement with the map at the true pose is set against the agreement at the wrong place
the filter ended the window on, carried back over the window by the odometry; both poses re-aligned with each scan
(``ScanAgreement.refine``), so neither loses to the odometry's drift. Where the true pose fits no better on average than
``TIE`` (a share of the scan's beams), the window held no evidence against the wrong place: no localizer that reads
only these scans could have been sure of the right one in time. Otherwise the evidence was there and the filter missed
it (it never put particles there, or lost them)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from irmcl_warp.geometry import compose, relative
from irmcl_warp.mcl.confidence import right
from irmcl_warp.services.outputs import write_json

DETECT_S, RECONVERGE_S = 2.0, 5.0  # the windows
TIE = 0.02  # the true pose fits the window's scans better than the wrong place by less than this (mean share of the
# scan's beams; 0.02 is about 2 of the ~90 beams ScanAgreement reads): the scans cannot tell the two apart


def drive(trace, row: dict, confident_above: float) -> dict:
    """One kidnapped drive's reading: its class and the figures behind it (``trace``: the drive's npz)."""
    t = trace["stamps"] - trace["stamps"][0]
    est, truth, updated, conf = trace["estimate"], trace["truth"], trace["updated"], trace["confidence"]
    has = np.all(np.isfinite(est), 1)
    ok = right(np.where(has[:, None], est, 0.0), truth) & has
    err = np.where(has, np.hypot(*(est[:, :2] - truth[:, :2]).T), np.nan)
    yaw = np.where(has, np.degrees(np.abs(np.angle(np.exp(1j * (est[:, 2] - truth[:, 2]))))), np.nan)
    kid = t >= row["kidnap_at_s"]
    sure_wrong = kid & ~ok & (np.nan_to_num(conf, nan=0.0) >= confident_above)
    dt = np.diff(t, append=t[-1])
    out = {
        "drive": f"{row['world']}-run{row['run']}",
        "detected_after_s": row.get("detected_after_s"),
        "reconverged_after_s": row.get("reconverged_after_s"),
        "confidently_wrong_s": float(dt[sure_wrong].sum()),
    }
    detected, back = row.get("detected_after_s"), row.get("reconverged_after_s")
    if detected is not None and detected <= DETECT_S and back is not None and back <= RECONVERGE_S:
        out["class"] = "met"
        return out
    if detected is None:
        out["class"] = "not detected"
        return out
    t_lost = row["kidnap_at_s"] + detected
    after = np.flatnonzero((t >= t_lost) & ok)
    first = float(t[after[0]] - t_lost) if len(after) else None
    out["first_right_after_s"] = first
    if first is not None and first <= RECONVERGE_S:
        later = (t > t_lost + first) & ~ok
        if not later.any():
            out["class"] = "met"
            return out
        between = not updated[later].any()
        out["class"] = "back, off between updates only" if between else "back, then wrong again at updates"
        out["excursion_at_s"] = float(t[np.flatnonzero(later)[-1]])
        seen = later & np.isfinite(err)  # (a later re-seed leaves scans without an estimate: wrong, no error)
        out["excursion_max_heading_deg"] = float(np.max(yaw[seen])) if seen.any() else None
        out["excursion_max_position_m"] = float(np.max(err[seen])) if seen.any() else None
        out["excursion_between_updates_only"] = bool(between)
        return out
    out["class"] = "look-alike"
    return out


def kidnaps(run: Path, evidence: bool = False) -> dict:
    """Every kidnapped drive of a worlds run that was right before the kidnapping, read as ``drive`` reads it (with
    ``evidence``: each look-alike or undetected miss also as ``window_evidence`` reads it)."""
    doc = json.loads((run / "metrics.json").read_text())
    confident_above = float(doc["settings"]["worlds"]["confident_above"])
    rows = [r for r in doc["runs"] if "kidnap_at_s" in r and r.get("right_before_kidnap")]
    if not rows:
        raise SystemExit(f"kidnaps: {run} has no kidnapped drive right before its kidnapping (worlds.kidnap_at_s)")
    out, drives = [], Drives(run) if evidence else None
    for r in rows:
        npz = run / f"{r['world']}-run{r['run']}.npz"
        if not npz.is_file():
            raise SystemExit(f"kidnaps: {npz} not found: the analysis reads each drive's trace")
        trace = np.load(npz)
        d = drive(trace, r, confident_above)
        if drives is not None and d["class"] in ("look-alike", "not detected"):
            d.update(window_evidence(trace, r, *drives(r)))
        out.append(d)
    classes = {}
    for d in out:
        classes[d["class"]] = classes.get(d["class"], 0) + 1
    res = {"run": str(run), "kidnaps": len(out), "classes": classes, "drives": out}
    if drives is not None:
        told = [d["scans_tell"] for d in out if "scans_tell" in d]
        res["evidence"] = {"tie": TIE, "misses_read": len(told), "scans_could_tell": int(sum(told))}
    return res


class Drives:
    """A worlds run's drives made again from its config.yaml, with each world's map and scan agreement (built once)."""

    def __init__(self, run: Path):
        from omegaconf import OmegaConf

        self.cfg, self.maps = OmegaConf.load(run / "config.yaml"), {}

    def __call__(self, row: dict):
        """(the drive's log, the agreement with its world's map) for a row of the run's metrics."""
        from irmcl_warp.mcl.confidence import ScanAgreement
        from irmcl_warp.mcl.worlds import query_log, world_map
        from irmcl_warp.sim import floors

        name = row["world"]
        if name not in self.maps:
            world = floors.build(name)
            grid = world_map(world, self.cfg, "cpu")
            self.maps[name] = (world, ScanAgreement.of_grid(grid, self.cfg.mcl.field_occ_threshold))
        world, agreement = self.maps[name]
        log, _ = query_log(world, self.cfg, int(row["run"]), "cpu")
        return log, agreement


def window_evidence(trace, row: dict, log, agreement) -> dict:
    """Could the scans of a miss's window tell the true pose from the wrong place the filter ended the window on?
    (the module's docstring). Returns the window, the mean agreement at each pose and ``scans_tell``."""
    if not np.allclose(log.ground_truth, trace["truth"], atol=1e-6):
        raise SystemExit(
            f"kidnaps --evidence: {row['world']} run {row['run']}: the drive made again from config.yaml is not the "
            "one the run recorded (another simulator or code): its scans cannot be judged"
        )
    t = trace["stamps"] - trace["stamps"][0]
    detected = row.get("detected_after_s")
    start = row["kidnap_at_s"] + (detected if detected is not None else 0.0)
    end = start + RECONVERGE_S + (0.0 if detected is not None else DETECT_S)
    est, truth = trace["estimate"], trace["truth"]
    window = np.flatnonzero((t >= start) & (t <= end))
    held = window[np.all(np.isfinite(est[window]), 1) & ~right(np.nan_to_num(est[window]), truth[window])]
    if not len(held):  # (no estimate at all, a re-seed's: nothing to judge, so not counted either way)
        return {"window_s": [float(start), float(end)], "note": "no wrong estimate in the window"}
    last = held[-1]
    place = compose(est[last], relative(log.odom[last], log.odom[window]))  # the wrong place over the window
    angles, T = log.info.angles_rad, log.T_base_laser
    at_truth = np.array([agreement.refine(truth[i], log.ranges_m[i], angles, T)[1] for i in window])
    at_place = np.array([agreement.refine(p, log.ranges_m[i], angles, T)[1] for i, p in zip(window, place)])
    margin = float(np.mean(at_truth - at_place))
    return {
        "window_s": [float(start), float(end)],
        "wrong_place": [float(v) for v in est[last]],
        "agreement_at_truth": float(np.mean(at_truth)),
        "agreement_at_wrong_place": float(np.mean(at_place)),
        "margin": margin,
        "scans_tell": bool(margin >= TIE),
    }


def told(d: dict) -> str:
    """The evidence column of a miss (``window_evidence``), "-" where it was not read."""
    if "margin" not in d:
        return d.get("note", "-")
    verdict = "told apart" if d["scans_tell"] else "alike"
    return f"{d['agreement_at_truth']:.3f} / {d['agreement_at_wrong_place']:.3f} ({verdict})"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a worlds run's folder with worlds.kidnap_at_s")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--evidence", action="store_true", help="could the misses' scans tell the places apart?")
    a = ap.parse_args(argv)
    res = kidnaps(a.run, a.evidence)
    print(
        f"{a.run}: {res['kidnaps']} kidnappings right before it; "
        + ", ".join(f"{k} {v}" for k, v in res["classes"].items())
    )
    print(
        "| drive | class | detected after (s) | right again after (s) | re-converged (s) | excursion | confidently wrong (s) "
        "| agreement at truth / at the wrong place |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for d in res["drives"]:
        if d["class"] == "met":
            continue
        f = lambda v, spec=".1f": "-" if v is None else f"{v:{spec}}"  # noqa: E731
        exc = (
            f"{f(d['excursion_max_heading_deg'])} deg / {f(d['excursion_max_position_m'], '.2f')} m at "
            f"{d['excursion_at_s']:.1f} s" + (" (between updates)" if d["excursion_between_updates_only"] else "")
            if "excursion_at_s" in d
            else "-"
        )
        print(
            f"| {d['drive']} | {d['class']} | {f(d['detected_after_s'])} | {f(d.get('first_right_after_s'))} "
            f"| {f(d['reconverged_after_s'])} | {exc} | {d['confidently_wrong_s']:.1f} | {told(d)} |"
        )
    if "evidence" in res:
        e = res["evidence"]
        print(
            f"of {e['misses_read']} look-alike or undetected misses, the scans of the window told the true pose from "
            f"the wrong place (by >= {e['tie']} on average) in {e['scans_could_tell']}"
        )
    if a.out:
        write_json(a.out, res)
        print(f"-> {a.out}")
    return res


if __name__ == "__main__":
    main()
