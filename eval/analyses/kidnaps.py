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
``worlds.confident_above`` (confidently wrong). Prints a table and writes it as JSON."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from irmcl_warp.mcl.confidence import right
from irmcl_warp.services.outputs import write_json

DETECT_S, RECONVERGE_S = 2.0, 5.0  # the windows


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


def kidnaps(run: Path) -> dict:
    """Every kidnapped drive of a worlds run that was right before the kidnapping, read as ``drive`` reads it."""
    doc = json.loads((run / "metrics.json").read_text())
    confident_above = float(doc["settings"]["worlds"]["confident_above"])
    rows = [r for r in doc["runs"] if "kidnap_at_s" in r and r.get("right_before_kidnap")]
    if not rows:
        raise SystemExit(f"kidnaps: {run} has no kidnapped drive right before its kidnapping (worlds.kidnap_at_s)")
    out = []
    for r in rows:
        npz = run / f"{r['world']}-run{r['run']}.npz"
        if not npz.is_file():
            raise SystemExit(f"kidnaps: {npz} not found: the analysis reads each drive's trace")
        out.append(drive(np.load(npz), r, confident_above))
    classes = {}
    for d in out:
        classes[d["class"]] = classes.get(d["class"], 0) + 1
    return {"run": str(run), "kidnaps": len(out), "classes": classes, "drives": out}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a worlds run's folder with worlds.kidnap_at_s")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    res = kidnaps(a.run)
    print(
        f"{a.run}: {res['kidnaps']} kidnappings right before it; "
        + ", ".join(f"{k} {v}" for k, v in res["classes"].items())
    )
    print(
        "| drive | class | detected after (s) | right again after (s) | re-converged (s) | excursion | confidently wrong (s) |"
    )
    print("|---|---|---|---|---|---|---|")
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
            f"| {f(d['reconverged_after_s'])} | {exc} | {d['confidently_wrong_s']:.1f} |"
        )
    if a.out:
        write_json(a.out, res)
        print(f"-> {a.out}")
    return res


if __name__ == "__main__":
    main()
