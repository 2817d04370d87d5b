"""``python -m eval.analyses.paired_worlds <worlds run A> <worlds run B> [--out F.json]``: two runs of the worlds
stage on the same floors and drives, compared drive by drive (issue 33: "a count compared with another count needs a
test").

Both runs localize the same drives (world, path seed), so their outcomes are paired: the test is McNemar's exact
one, a two-sided binomial test on the drives where exactly one of the two ended right (``right_at_end``) or
localized by the protocol (``success``); on kidnapped runs also, over the drives right before the kidnapping in
both, detected within 2 s and re-converged within 5 s (``KIDNAP_OUTCOMES``). Prints, per outcome, both counts, the discordant drives and the p-value, and
the particles an update ran with on average (``particles_per_update``, with ``mcl.kld_sampling``); writes the same
as JSON with ``--out``. Given the runs' folders, also each run's AUROC (the confidence at every update against right
or wrong) and a 95 % interval of the difference from resampling the drives (``BOOTSTRAP`` draws): the updates of one
drive are not independent, the drives are. False alarms (a right estimate declared lost) are counts over each run's
hours of right tracking: compared by the exact conditional test of two Poisson rates (``rates_exact``: given the
total, A's share is binomial with p = A's hours over both runs').
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

OUTCOMES = ("right_at_end", "success", "localized_at_end")
# kidnapped runs (worlds.kidnap_at_s): outcome, the drive's field, within (s): the 2 s and 5 s
KIDNAP_OUTCOMES = (
    ("detected_within_2s", "detected_after_s", 2.0),
    ("reconverged_within_5s", "reconverged_after_s", 5.0),
)
BOOTSTRAP = 2000  # drive resamples for the AUROC difference's interval (fixed seed 0)


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided p of McNemar's exact test: the discordant pairs as a binomial draw with p = 1/2."""
    from scipy.stats import binomtest

    n = only_a + only_b
    return 1.0 if n == 0 else float(binomtest(only_a, n, 0.5).pvalue)


def rates_exact(count_a: int, hours_a: float, count_b: int, hours_b: float) -> float:
    """Two-sided p that two Poisson counts over these exposures share one rate (conditional binomial test)."""
    from scipy.stats import binomtest

    n = count_a + count_b
    return 1.0 if n == 0 else float(binomtest(count_a, n, hours_a / (hours_a + hours_b)).pvalue)


def _within(seconds, limit: float) -> bool:
    return seconds is not None and seconds <= limit


def paired(ra: dict, rb: dict) -> dict:
    """One outcome over the same drives (drive -> bool in each run): both counts, the discordant drives by name and
    McNemar's exact p."""
    only_a = sorted(d for d in ra if ra[d] and not rb[d])
    only_b = sorted(d for d in ra if rb[d] and not ra[d])
    return {
        "a": sum(ra.values()),
        "b": sum(rb.values()),
        "only_a": [f"{w}-run{k}" for w, k in only_a],
        "only_b": [f"{w}-run{k}" for w, k in only_b],
        "p_mcnemar": mcnemar_exact(len(only_a), len(only_b)),
    }


def drives(metrics: dict) -> dict[tuple[str, int], dict]:
    """(world, run) -> that drive's row of a worlds run's metrics.json."""
    return {(r["world"], int(r["run"])): r for r in metrics["runs"]}


def compare(a: dict, b: dict) -> dict:
    """The paired comparison of two worlds runs' metrics: an error when they did not localize the same drives."""
    da, db = drives(a), drives(b)
    if set(da) != set(db):
        only = sorted(set(da) ^ set(db))[:5]
        raise SystemExit(f"paired_worlds: the two runs localized different drives (e.g. {only}): nothing to pair")
    out = {"drives": len(da), "outcomes": {}}
    for key in OUTCOMES:
        out["outcomes"][key] = paired(
            {d: bool(r.get(key)) for d, r in da.items()}, {d: bool(r.get(key)) for d, r in db.items()}
        )
    kidnapped = [d for d in da if da[d].get("right_before_kidnap") and db[d].get("right_before_kidnap")]
    if kidnapped:  # kidnapped runs: detection and re-convergence over the drives right before it in both
        out["kidnapped_drives"] = len(kidnapped)
        for key, field, within in KIDNAP_OUTCOMES:
            ra = {d: _within(da[d].get(field), within) for d in kidnapped}
            rb = {d: _within(db[d].get(field), within) for d in kidnapped}
            out["outcomes"][key] = {**paired(ra, rb), "of": len(kidnapped)}
    sa, sb = a["summary"], b["summary"]
    if all("false_alarms" in x and "tracking_right_h" in x for x in (sa, sb)):  # (runs that scored them)
        out["false_alarms"] = {
            "a": int(sa["false_alarms"]),
            "b": int(sb["false_alarms"]),
            "hours_a": float(sa["tracking_right_h"]),
            "hours_b": float(sb["tracking_right_h"]),
            "p_rates": rates_exact(
                sa["false_alarms"], sa["tracking_right_h"], sb["false_alarms"], sb["tracking_right_h"]
            ),
        }
    for side, m in (("a", a), ("b", b)):
        out[f"particles_per_update_{side}"] = m["summary"].get("particles_per_update")
        out[f"num_particles_{side}"] = m["summary"]["num_particles"]
    return out


def per_drive_judged(run: Path) -> dict[tuple[str, int], tuple] | None:
    """(world, run) -> (confidence, right) at that drive's updates, from a worlds run's folder (None when a drive's
    ``<world>-run<k>.npz`` is not there: a kept metrics.json alone)."""
    import numpy as np

    from irmcl_warp.mcl.confidence import right

    doc = json.loads((run / "metrics.json").read_text())
    if not all((run / f"{r['world']}-run{r['run']}.npz").is_file() for r in doc["runs"]):
        return None
    out = {}
    for r in doc["runs"]:
        z = np.load(run / f"{r['world']}-run{r['run']}.npz")
        ok = z["updated"] & np.isfinite(z["confidence"]) & np.all(np.isfinite(z["estimate"]), 1)
        out[(r["world"], int(r["run"]))] = (z["confidence"][ok], right(z["estimate"][ok], z["truth"][ok]))
    return out


def auroc_difference(a: dict, b: dict, draws: int = BOOTSTRAP) -> dict:
    """Both runs' AUROC over the same drives and the 2.5/97.5 percentiles of (A - B) over drive resamples."""
    import numpy as np

    from irmcl_warp.mcl.confidence import auroc

    keys = sorted(a)

    def both(sample):
        out = []
        for side in (a, b):
            p = np.concatenate([side[k][0] for k in sample])
            y = np.concatenate([side[k][1] for k in sample])
            out.append(auroc(p, y))
        return out

    whole = both(keys)
    rng = np.random.default_rng(0)
    diffs = []
    for _ in range(draws):
        pick = [keys[i] for i in rng.integers(0, len(keys), len(keys))]
        da, db = both(pick)
        if np.isfinite(da) and np.isfinite(db):
            diffs.append(da - db)
    lo, hi = np.percentile(diffs, [2.5, 97.5])
    return {"a": whole[0], "b": whole[1], "difference": whole[0] - whole[1], "ci95": [float(lo), float(hi)]}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path, help="a worlds run's folder (or its metrics.json)")
    ap.add_argument("b", type=Path)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    metrics = []
    for p in (args.a, args.b):
        f = p / "metrics.json" if p.is_dir() else p
        if not f.is_file():
            raise SystemExit(f"paired_worlds: {f} not found (a worlds run's folder or its metrics.json)")
        metrics.append(json.loads(f.read_text()))
    out = {"a": str(args.a), "b": str(args.b), **compare(*metrics)}
    print(f"A = {args.a}\nB = {args.b}\n{out['drives']} drives, paired")
    print("| outcome | A | B | only A | only B | McNemar exact p |\n|---|---|---|---|---|---|")
    for key, o in out["outcomes"].items():
        n = o.get("of", out["drives"])
        print(
            f"| {key} | {o['a']}/{n} | {o['b']}/{n} | {len(o['only_a'])} | {len(o['only_b'])} | {o['p_mcnemar']:.3g} |"
        )
    if "false_alarms" in out:
        fa = out["false_alarms"]
        print(
            f"false alarms: A {fa['a']} in {fa['hours_a']:.2f} h, B {fa['b']} in {fa['hours_b']:.2f} h of right "
            f"tracking (exact test of two Poisson rates p = {fa['p_rates']:.3g})"
        )
    judged = [per_drive_judged(p) if p.is_dir() else None for p in (args.a, args.b)]
    if all(j is not None for j in judged):
        out["auroc"] = auroc_difference(*judged)
        au = out["auroc"]
        print(
            f"AUROC: A {au['a']:.3f}, B {au['b']:.3f}; A - B {au['difference']:+.3f} "
            f"(95 % over drive resamples {au['ci95'][0]:+.3f} to {au['ci95'][1]:+.3f})"
        )
    for side in ("a", "b"):
        ppu = out[f"particles_per_update_{side}"]
        print(
            f"{side.upper()}: {out[f'num_particles_{side}']:,} particles at most, {ppu or float('nan'):,.0f} per update"
        )
    if args.out:
        args.out.write_text(json.dumps(out, indent=1) + "\n")
        print(f"-> {args.out}")
    return out


if __name__ == "__main__":
    main()
