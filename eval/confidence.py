"""The localizer's confidence: fitted on the tuning worlds, judged on the test worlds (issue 33).

    python -m eval.confidence fit outputs/worlds/worlds/tuning-<...> [...] [--out irmcl_warp/mcl/calibration/<w>.json]
    python -m eval.confidence judge outputs/worlds/worlds/test-<...> [...] [--calibration FILE] [--against FILE]
        [--out results/worlds]

``fit`` reads the features recorded at every filter update of worlds runs (``<world>-run<k>.npz``), labels each
update right or wrong (the heaviest mode within 0.5 m / 10 deg of the truth) and fits the logistic model of
irmcl_warp/mcl/confidence.py. It refuses runs on test worlds: the calibration is made on tuning data only.

``judge`` applies a calibration to runs of the test worlds (it refuses tuning worlds): the AUROC of the confidence
(right against wrong updates), its reliability curve (predicted against observed, per tenth), the same for the
features alone (the top mode's weight, the spread: the signals the filter used to report), and writes a record
``confidence-<weighting>-<particles>.json`` with a plot (``.png``) beside it. With ``--against`` a second calibration
is judged on the same updates, and the record holds both AUROCs with a 95 % interval of their difference from
resampling the drives (``eval.analyses.paired_worlds``: a drive's updates are not independent, the drives are). One
calibration is for one observation model and one particle count (the features depend on both): without ``--out``
or ``--calibration`` the file is the one shipped for the runs' particle count (``<w>.json`` at 20k, ``<w>-<n>k.json``
otherwise; until the 2026-12-02 session both took ``<w>.json`` whatever the count).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from irmcl_warp.config import calibration_file
from irmcl_warp.mcl.confidence import FEATURES, Confidence, auroc, fit_logistic, reliability, right, tracker_of
from irmcl_warp.services.outputs import save_figure, write_json
from irmcl_warp.sim import floors


def samples(run_dirs: list[Path], side: str) -> tuple[np.ndarray, np.ndarray, dict, np.ndarray]:
    """(features [n, F], right [n], provenance, the drive of each update [n]) of every filter update of the runs,
    which must all be on worlds of ``side`` (tuning | test)."""
    X, y, drive = [], [], []
    prov = {"runs": [], "worlds": set(), "weighting": set(), "particles": set(), "tracker": set(), "maps": set()}
    prov["unmapped_per_m"] = set()
    for d in run_dirs:
        doc = json.loads((Path(d) / "metrics.json").read_text())
        w = doc.get("settings", {}).get("worlds", {})
        prov["tracker"].add(tuple(tracker_of(w).items()))
        prov["maps"].add((w.get("map_drive", "random"), w.get("map_logodds_limit", 4.0)))  # (runs before: as named)
        prov["unmapped_per_m"].add(float(w.get("unmapped_per_m", 0.0) or 0.0))
        for r in doc["runs"]:
            if floors.split_of(r["world"]) != side:
                raise ValueError(
                    f"{d}: world {r['world']} is a {floors.split_of(r['world'])} world; this step reads "
                    f"{side} worlds only"
                )
            z = np.load(Path(d) / f"{r['world']}-run{r['run']}.npz")
            upd = z["updated"] & np.all(np.isfinite(z["features"]), 1) & np.all(np.isfinite(z["estimate"]), 1)
            if z["features"].shape[1] != len(FEATURES):
                raise ValueError(
                    f"{d}: {r['world']} run {r['run']} recorded {z['features'].shape[1]} features, this code "
                    f"computes {len(FEATURES)} ({', '.join(FEATURES)}): run the stage again"
                )
            X.append(z["features"][upd])
            y.append(right(z["estimate"][upd], z["truth"][upd]))
            drive.append(np.full(int(upd.sum()), f"{Path(d).name}/{r['world']}-run{r['run']}"))
            prov["worlds"].add(r["world"])
        prov["runs"].append(Path(d).name)
        prov["weighting"].add(doc["summary"]["weighting"])
        prov["particles"].add(doc["summary"].get("num_particles"))
    if len(prov["weighting"]) != 1:
        raise ValueError(f"runs of several weightings ({sorted(prov['weighting'])}): one calibration is for one")
    if len(prov["particles"]) != 1:
        raise ValueError(
            f"runs of several particle counts ({sorted(map(str, prov['particles']))}): the features "
            "depend on the count (a larger cloud keeps a wider spread); one calibration is for one"
        )
    if len(prov["tracker"]) != 1:
        raise ValueError(
            f"runs that tracked rivals or read modes differently ({[dict(t) for t in sorted(prov['tracker'])]}): "
            "their features differ; one calibration is for one"
        )
    tracker = dict(prov["tracker"].pop())
    maps = [{"map_drive": d, "map_logodds_limit": limit} for d, limit in sorted(prov["maps"], key=str)]
    prov = {
        "maps": maps[0] if len(maps) == 1 else maps,
        "unmapped_per_m": sorted(prov["unmapped_per_m"]),
        "tracker": tracker,
        "runs": prov["runs"],
        "worlds": sorted(prov["worlds"]),
        "weighting": prov["weighting"].pop(),
        "particles": prov["particles"].pop(),
    }
    return np.concatenate(X), np.concatenate(y), prov, np.concatenate(drive)


def fit(args) -> Path:
    X, y, prov, _ = samples(args.runs, "tuning")
    model = fit_logistic(X, y)
    out = Path(args.out) if args.out else calibration_file(prov["weighting"], prov["particles"])
    model.meta = {
        "source": f"eval.confidence fit on {', '.join(prov['runs'])}",
        "tuning_worlds": prov["worlds"],
        "weighting": prov["weighting"],
        "num_particles": prov["particles"],
        "tracker": prov["tracker"],
        "maps": prov["maps"],
        "unmapped_per_m": prov["unmapped_per_m"],
        "updates": int(len(y)),
        "right_share": float(y.mean()),
        "tuning_auroc": auroc(model(X), y),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(out, model.to_json())
    print(
        f"fitted on {len(y)} updates of {len(prov['worlds'])} tuning worlds ({100 * y.mean():.0f} % right); "
        f"AUROC on them {model.meta['tuning_auroc']:.3f} -> {out}"
    )
    return out


def judge(args) -> dict:
    X, y, prov, drive = samples(args.runs, "test")
    cal = Path(args.calibration) if args.calibration else calibration_file(prov["weighting"], prov["particles"])
    model = judging(cal, prov)
    p = model(X)
    doc = {
        "weighting": prov["weighting"],
        "num_particles": prov["particles"],
        "test_worlds": prov["worlds"],
        "runs": prov["runs"],
        "calibration": str(cal),
        "tuning_worlds": model.meta.get("tuning_worlds"),
        "updates": int(len(y)),
        "right_share": float(y.mean()),
        "auroc": auroc(p, y),
        "reliability": reliability(p, y),
        "auroc_top_weight": auroc(X[:, FEATURES.index("top_weight")], y),
        "auroc_spread": auroc(-X[:, FEATURES.index("log_spread")], y),
    }
    doc["max_calibration_gap"] = largest_gap(doc["reliability"])
    if args.against:
        doc["against"] = against(Path(args.against), prov, X, y, drive, p)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = f"confidence-{prov['weighting']}-{prov['particles'] // 1000}k"
    write_json(out / f"{name}.json", doc)
    plot(out / f"{name}.png", doc)
    print(
        f"{prov['weighting']} on {len(prov['worlds'])} test worlds, {len(y)} updates ({100 * y.mean():.0f} % right): "
        f"AUROC {doc['auroc']:.3f} (top mode's weight alone {doc['auroc_top_weight']:.3f}, spread alone "
        f"{doc['auroc_spread']:.3f}); largest calibration gap {doc['max_calibration_gap']:.2f}"
    )
    if "against" in doc:
        o = doc["against"]
        print(
            f"against {o['calibration']}: AUROC {o['auroc']:.3f}, largest calibration gap "
            f"{o['max_calibration_gap']:.2f}; difference {o['difference']:+.3f} (95 % over {o['drives']} drive "
            f"resamples {o['ci95'][0]:+.3f} to {o['ci95'][1]:+.3f})"
        )
    return doc


def largest_gap(curve) -> float:
    """The reliability curve's largest |predicted - observed| over its bins of at least 20 updates."""
    return max(abs(b["predicted"] - b["observed"]) for b in curve if b["count"] >= 20)


def judging(cal: Path, prov: dict) -> Confidence:
    """The calibration ``cal``, refused where it was fitted on runs that tracked rivals otherwise than these."""
    model = Confidence.load(cal)
    if model.tracker != prov["tracker"]:
        raise ValueError(
            f"{cal} was fitted on runs that tracked rivals as {model.tracker}, these runs did as {prov['tracker']}"
        )
    return model


def against(cal: Path, prov: dict, X, y, drive, p) -> dict:
    """A second calibration on the same updates: its AUROC beside the first's (``p``), with the 95 % interval of
    (first - second) over drive resamples."""
    from eval.analyses.paired_worlds import auroc_difference

    model = judging(cal, prov)  # (the same checks as the first's)
    q, keys = model(X), np.unique(drive)
    first = {k: (p[drive == k], y[drive == k]) for k in keys}
    second = {k: (q[drive == k], y[drive == k]) for k in keys}
    diff, meta = auroc_difference(first, second), model.meta
    return {
        "calibration": str(cal),
        "tuning_worlds": meta.get("tuning_worlds"),
        "source": meta.get("source"),
        "auroc": diff["b"],
        "max_calibration_gap": largest_gap(reliability(q, y)),
        "difference": diff["difference"],
        "ci95": diff["ci95"],
        "drives": int(len(keys)),
    }


def plot(path: Path, doc: dict) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    rel = doc["reliability"]
    ax.plot([0, 1], [0, 1], "k:", lw=1, label="calibrated")
    ax.plot([b["predicted"] for b in rel], [b["observed"] for b in rel], "o-", label="confidence")
    for b in rel:
        ax.annotate(
            str(b["count"]), (b["predicted"], b["observed"]), fontsize=6, xytext=(3, -8), textcoords="offset points"
        )
    ax.set_xlabel("predicted probability of being right")
    ax.set_ylabel("share right (test worlds)")
    ax.set_title(f"{doc['weighting']}, {doc['num_particles'] // 1000}k: AUROC {doc['auroc']:.3f}")
    ax.legend(loc="upper left")
    save_figure(fig, path)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.confidence", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fit", help="fit the confidence on tuning-world runs")
    f.add_argument("runs", nargs="+", type=Path)
    f.add_argument("--out", help="calibration file (default: the one shipped for the weighting and particle count)")
    j = sub.add_parser("judge", help="AUROC and reliability on test-world runs")
    j.add_argument("runs", nargs="+", type=Path)
    j.add_argument("--calibration", help="default: the one shipped for the runs' weighting and particle count")
    j.add_argument("--against", help="a second calibration, judged on the same updates")
    j.add_argument("--out", default="outputs/worlds/judged")
    args = ap.parse_args(argv)
    try:
        fit(args) if args.command == "fit" else judge(args)
    except (ValueError, FileNotFoundError) as e:
        raise SystemExit(f"error: {e}") from None


if __name__ == "__main__":
    main()
