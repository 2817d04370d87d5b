"""The registry of the three papers' claims, each with its verdict computed from the run records.

A ``Claim`` is the paper's statement, where it is made, the published figures it rests on (papers.yaml),
the tolerance or statistical test that decides it, the command that makes our runs, and ``judge``: a
function of the ``Evidence`` (the records) returning a ``Verdict``:

* reproduced / partly / not reproduced, each with its reason and, where counts or per-start figures are
  compared, the test and its p-value: Fisher's exact test for success counts (9/10 against 7/10 is
  p = 0.58: no difference shown), a Wilson 95 % interval for one count, the Mann-Whitney U test for
  per-start errors and times;
* not testable here (what is missing from the data), not run (the runs are missing: the command makes them).

Figures of one run are marked "(one seed)"; means over converged runs stand beside means over all runs.
docs/REPRODUCTION.md is generated from this registry (eval/report/reproduction.py).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from eval.results.papers import figure
from eval.results.queries import converged, localize_records, median_span, released_errors, slam_errors
from eval.results.records import RESULTS, off_defaults
from irmcl_warp.services.metrics import SLAM_CONVERGED_M

ALPHA = 0.05  # a difference is "shown" below this p-value
REPRODUCED, PARTLY, NOT_REPRODUCED = "reproduced", "partly", "not reproduced"
NOT_TESTABLE, NOT_RUN = "not testable here", "not run"


@dataclass
class Evidence:
    """What the judges read: the records of each stage and the released GMapping's runs and benchmarks."""

    nof: dict  # {(exp, preset): (synthesis record, training record)}
    loc: list
    slam: list
    globloc: list
    released: dict
    bench: dict = field(default_factory=dict)  # results/bench/<name>.json, by name


@dataclass
class Verdict:
    verdict: str
    ours: str
    reason: str
    test: str = ""


@dataclass(frozen=True)
class Claim:
    key: str
    system: str
    statement: str
    paper: str  # a key of papers.yaml
    where: str
    published: tuple  # names of figures in papers.yaml
    tolerance: str
    command: str
    judge: Callable[[Evidence], Verdict]


# --- statistics ----------------------------------------------------------------------------------------------


def fisher(k1: int, n1: int, k2: int, n2: int) -> float:
    from scipy.stats import fisher_exact

    return float(fisher_exact([[k1, n1 - k1], [k2, n2 - k2]]).pvalue)


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return float("nan"), float("nan")
    p, d = k / n, 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return float(max(0.0, c - h)), float(min(1.0, c + h))


def mann_whitney(a, b) -> float:
    from scipy.stats import mannwhitneyu

    a, b = [float(x) for x in a if x is not None], [float(x) for x in b if x is not None]
    if not a or not b:
        return float("nan")
    return float(mannwhitneyu(a, b, alternative="two-sided").pvalue)


def more_successes(what_a: str, ka: int, na: int, what_b: str, kb: int, nb: int) -> tuple[str, str, str]:
    """(verdict, reason, test) of the claim "a succeeds more often than b", from success counts."""
    p = fisher(ka, na, kb, nb)
    test = f"Fisher's exact test on {ka}/{na} against {kb}/{nb}: p = {p:.2g}"
    if ka * nb > kb * na and p < ALPHA:
        return REPRODUCED, f"{what_a} succeeds more often than {what_b}", test
    if ka * nb > kb * na:
        return PARTLY, f"{what_a} succeeds more often than {what_b}, but not significantly (p >= {ALPHA})", test
    return NOT_REPRODUCED, f"{what_a} succeeds no more often than {what_b}", test


def lower(what_a: str, a: list, what_b: str, b: list, unit: str, quantity: str) -> tuple[str, str, str]:
    """(verdict, reason, test) of the claim "a's per-start ``quantity`` is lower than b's"."""
    a, b = [x for x in a if x is not None], [x for x in b if x is not None]
    if not a or not b:
        return NOT_RUN, f"no {quantity} to compare", ""
    p = mann_whitney(a, b)
    ma, mb = float(np.median(a)), float(np.median(b))
    test = f"Mann-Whitney U on {len(a)} against {len(b)} starts: p = {p:.2g}"
    if ma < mb and p < ALPHA:
        return REPRODUCED, f"{what_a}'s {quantity} is lower ({ma:.2f} against {mb:.2f} {unit}, medians)", test
    if ma < mb:
        return (
            PARTLY,
            f"{what_a}'s {quantity} is lower ({ma:.2f} against {mb:.2f} {unit}, medians) but not significantly",
            test,
        )
    if p < ALPHA:
        return NOT_REPRODUCED, f"{what_b}'s {quantity} is lower ({mb:.2f} against {ma:.2f} {unit}, medians)", test
    return NOT_REPRODUCED, f"no difference shown ({ma:.2f} against {mb:.2f} {unit}, medians)", test


# --- IR-MCL ----------------------------------------------------------------------------------------------


def _methods(syn) -> tuple[dict | None, dict | None]:
    nof = next((m for name, m in syn["methods"].items() if m.get("kind") == "nof"), None)
    return nof, syn["methods"].get("OGM 5 cm")


def _minute_seeds(ev: Evidence, ds: str) -> list:
    """The one-minute preset's kept seeds on ``ds`` (train.name minute, minute_s1, ...): (MAE, Chamfer, s)."""
    out = []
    for (exp, preset), (syn, train) in ev.nof.items():
        if exp == ds and (preset == "minute" or preset.startswith("minute_s")) and train:
            nof, _ = _methods(syn)
            out.append((nof["mae_m"], nof["chamfer_m"], train["train_time_s"]))
    return out


def judge_synthesis(ds: str, recipe: str, published: bool) -> Callable[[Evidence], Verdict]:
    def judge(ev: Evidence) -> Verdict:
        pair = ev.nof.get((ds, recipe))
        if pair is None:
            return Verdict(NOT_RUN, "-", f"no synthesis run of the `{recipe}` field on {ds}")
        nof, grid = _methods(pair[0])
        ours = (
            f"`{recipe}` (one seed): MAE {nof['mae_m']:.3f} m, accuracy {nof['accuracy_pct']:.1f} %, Chamfer "
            f"{nof['chamfer_m']:.3f} m, F-score {nof['fscore_pct']:.1f} %; 5 cm grid MAE {grid['mae_m']:.3f} m"
        )
        better = nof["mae_m"] < grid["mae_m"]
        close = True
        reason = f"the NOF's MAE is {'below' if better else 'above'} the 5 cm grid's"
        if published:
            mae = figure(f"irmcl_{ds}_mae_m").number
            fs = figure(f"irmcl_{ds}_fscore_pct").number
            close = nof["mae_m"] <= 1.10 * mae and nof["fscore_pct"] >= fs - 1.0
            reason += f"; MAE {100 * (nof['mae_m'] / mae - 1):+.0f} % against the paper's, F-score {nof['fscore_pct'] - fs:+.1f} points"
        seeds = _minute_seeds(ev, ds)
        tuned = "chosen on this log's test split" if ds == "fr079" else "chosen on fr079, held out here"
        if len(seeds) > 1:
            mae_s, cham, secs = zip(*seeds)
            ours += (
                f"; `train=minute` ({tuned}), {len(seeds)} seeds: MAE {median_span(mae_s, '.3f')} m, Chamfer "
                f"{median_span(cham, '.3f')} m in {median_span(secs, '.1f')} s (H100)"
            )
        elif len(seeds) == 1:
            ours += f"; `train=minute` ({tuned}, one seed): MAE {seeds[0][0]:.3f} m"
        minute_better = bool(seeds) and float(np.median([s[0] for s in seeds])) < grid["mae_m"]
        if better and close:
            verdict = REPRODUCED
        elif minute_better:
            verdict = PARTLY
            reason += f"; `train=minute` ({tuned}) is below the grid"
        else:
            verdict = NOT_REPRODUCED
        return Verdict(verdict, ours, reason)

    return judge


def _cell(ev: Evidence, ds: str, weighting: str, mode: str, particles: int):
    found = localize_records(ev.loc, ds, weighting, mode, particles)
    return found[0] if found else None


def _starts(rec, key: str, ok_only: bool = True) -> list:
    return [s[key] for s in rec["runs"] if (s["success"] or not ok_only) and s.get(key) is not None]


def _loc_text(rec, what: str) -> str:
    s = rec["summary"]
    return (
        (
            f"{what} {s['successes']}/{s['starts']} starts, {s['location_rmse_cm_mean']:.1f} cm / "
            f"{s['yaw_rmse_deg_mean']:.2f} deg (means over the successful starts)"
        )
        if s["successes"]
        else f"{what} 0/{s['starts']} starts"
    )


def judge_accuracy(ds: str, mode: str, particles: int) -> Callable[[Evidence], Verdict]:
    """IR-MCL (NOG) more accurate than AMCL's likelihood field, per start, in ``mode``."""

    def judge(ev: Evidence) -> Verdict:
        nog, lf = _cell(ev, ds, "nog_raymarch", mode, particles), _cell(ev, ds, "likelihood_field", mode, particles)
        if not (nog and lf):
            return Verdict(NOT_RUN, "-", f"no {mode} runs of both models on {ds}")
        ours = f"{_loc_text(nog, 'NOG')}; {_loc_text(lf, 'likelihood field')}"
        v_cm, r_cm, t_cm = lower(
            "the NOG",
            _starts(nog, "location_rmse_cm"),
            "the likelihood field",
            _starts(lf, "location_rmse_cm"),
            "cm",
            "location RMSE",
        )
        v_deg, r_deg, t_deg = lower(
            "the NOG",
            _starts(nog, "yaw_rmse_deg"),
            "the likelihood field",
            _starts(lf, "yaw_rmse_deg"),
            "deg",
            "heading RMSE",
        )
        verdict = v_cm if v_cm == v_deg else PARTLY if REPRODUCED in (v_cm, v_deg) else NOT_REPRODUCED
        return Verdict(verdict, ours, f"{r_cm}; {r_deg}", f"{t_cm} (location), {t_deg} (heading)")

    return judge


def judge_convergence(ds: str) -> Callable[[Evidence], Verdict]:
    def judge(ev: Evidence) -> Verdict:
        nog, lf = _cell(ev, ds, "nog_raymarch", "global", 100000), _cell(ev, ds, "likelihood_field", "global", 100000)
        if not (nog and lf):
            return Verdict(NOT_RUN, "-", f"no global runs of both models on {ds}")
        a, b = _starts(nog, "time_to_converge_s", False), _starts(lf, "time_to_converge_s", False)
        ours = (
            f"NOG converged in {len(a)}/{len(nog['runs'])} starts after {median_span(a, '.1f')} s; likelihood field "
            f"{len(b)}/{len(lf['runs'])} after {median_span(b, '.1f')} s"
            if a and b
            else "-"
        )
        verdict, reason, test = lower("the NOG", a, "the likelihood field", b, "s", "time to converge")
        if verdict == NOT_REPRODUCED and "no difference" in reason:
            verdict = PARTLY  # "at least as fast": no slower is what the claim needs
            reason += ": as fast, not faster"
        return Verdict(verdict, ours, reason, test)

    return judge


def judge_realtime(ev: Evidence) -> Verdict:
    b = ev.bench.get("mcl-h100")
    if not b:
        return Verdict(NOT_RUN, "-", "no kept GPU benchmark of the MCL step")
    from eval.bench.mcl import DEFAULT_VARIANT

    rows = [
        r
        for r in b["rows"]
        if r.get("variant", r["method"]) == DEFAULT_VARIANT and r["particles"] == 100000 and r["step_ms"] is not None
    ]
    if not rows:
        return Verdict(NOT_RUN, "-", "the kept benchmark has no 100k row of the default weighting")
    step = min(rows, key=lambda r: not r.get("graph", False))["step_ms"]
    paper = figure("irmcl_render_100k_ms").number
    return Verdict(
        REPRODUCED if step < paper else NOT_REPRODUCED,
        f"{step:.2f} ms per full filter step (H100)",
        f"{paper / step:.0f}x under the paper's rendering time",
    )


def judge_online(ev: Evidence) -> Verdict:
    b = ev.bench.get("mcl-real-fr079-h100")
    if not b:
        return Verdict(NOT_RUN, "-", "no kept real fr079 run with step times")
    real = b["real"]["summary"].get("ms_per_step_median")
    period_ms = 1e3 * 1061.0 / 4934  # fr079: 4934 scans over 1061 s (../shared/data/README.md)
    return Verdict(
        REPRODUCED if real < period_ms else NOT_REPRODUCED,
        f"a real fr079 global run (100k particles, H100): {real:.2f} ms per filter step",
        f"the log's scans come every {period_ms:.0f} ms",
    )


# --- GMapping ----------------------------------------------------------------------------------------------


def _slam_text(errs) -> str:
    k, n, conv, mean = converged(errs)
    lo, hi = wilson(k, n)
    return (
        f"{k}/{n} seeds converge (95 % interval {lo:.2f}-{hi:.2f})"
        + (f", {conv:.3f} m over the converged" if k else "")
        + f", {mean:.3f} m over all"
    )


def judge_relations(ds: str) -> Callable[[Evidence], Verdict]:
    def judge(ev: Evidence) -> Verdict:
        errs = slam_errors(ev.slam, ds)
        if not errs:
            return Verdict(NOT_RUN, "-", "no runs")
        k, n, conv, _ = converged(errs)
        pub = figure(f"kuemmerle_gmapping_{ds}_m").number
        ok_rate, ok_err = k >= 0.9 * n, conv is not None and conv <= 1.25 * pub
        verdict = REPRODUCED if ok_rate and ok_err else PARTLY if k >= n / 2 else NOT_REPRODUCED
        reason = f"{k}/{n} converge (< {SLAM_CONVERGED_M} m)" + (
            f"; their error {100 * (conv / pub - 1):+.0f} % against the published" if conv else ""
        )
        return Verdict(
            verdict, _slam_text(errs), reason, f"Wilson 95 % interval {wilson(k, n)[0]:.2f}-{wilson(k, n)[1]:.2f}"
        )

    return judge


def judge_released(
    ds: str, variant: dict | None = None, ref_variant: str = "", proposal: str = "gmapping_code"
) -> Callable[[Evidence], Verdict]:
    def judge(ev: Evidence) -> Verdict:
        ours = slam_errors(ev.slam, ds, proposal, variant=variant)
        theirs = released_errors(ev.released, ds, variant=ref_variant)
        if not (ours and theirs):
            return Verdict(NOT_RUN, f"ours {len(ours)} runs, the released code {len(theirs)}", "both sides are needed")
        (k, n, _, _), (kr, nr, _, _) = converged(ours), converged(theirs)
        p = fisher(k, n, kr, nr)
        text = f"ours: {_slam_text(ours)}; the released code: {_slam_text(theirs)}"
        test = f"Fisher's exact test on {k}/{n} against {kr}/{nr}: p = {p:.2g}"
        if k * nr >= kr * n:
            return Verdict(REPRODUCED, text, "ours converges at least as often as the released code", test)
        if p >= ALPHA:
            return Verdict(PARTLY, text, "ours converges less often, but no difference is shown", test)
        return Verdict(NOT_REPRODUCED, text, "ours converges less often than the released code", test)

    return judge


def judge_particles(ds: str, particles: int) -> Callable[[Evidence], Verdict]:
    def judge(ev: Evidence) -> Verdict:
        errs = slam_errors(ev.slam, ds, particles=particles)
        if not errs:
            return Verdict(NOT_RUN, "-", f"no runs with {particles} particles")
        k, n, _, _ = converged(errs)
        lo, _ = wilson(k, n)
        verdict = REPRODUCED if k >= 0.9 * n else PARTLY if k >= n / 2 else NOT_REPRODUCED
        return Verdict(
            verdict,
            _slam_text(errs),
            f"{k}/{n} seeds converge with {particles} particles",
            f"Wilson 95 % lower bound {lo:.2f}",
        )

    return judge


def judge_odometry_fails(ev: Evidence) -> Verdict:
    odo = slam_errors(ev.slam, "intel", "odometry", particles=60)
    scan = slam_errors(ev.slam, "intel", "paper", particles=60)
    if not (odo and scan):
        return Verdict(NOT_RUN, "-", "both proposals at 60 particles on intel are needed")
    (ko, no, _, _), (ks, ns, _, _) = converged(odo), converged(scan)
    verdict, reason, test = more_successes("the scan-based proposal", ks, ns, "the odometry proposal", ko, no)
    return Verdict(verdict, f"odometry proposal: {_slam_text(odo)}; scan-based: {_slam_text(scan)}", reason, test)


def judge_fewer_particles(ev: Evidence) -> Verdict:
    """The scan-based proposal with the fewest particles kept against the odometry proposal with the most."""
    scan = {n: slam_errors(ev.slam, "intel", "paper", particles=n) for n in (5, 10, 15, 30, 60)}
    odo = {n: slam_errors(ev.slam, "intel", "odometry", particles=n) for n in (5, 10, 15, 30, 60)}
    scan, odo = {n: e for n, e in scan.items() if e}, {n: e for n, e in odo.items() if e}
    if not (scan and odo):
        return Verdict(NOT_RUN, "-", "both proposals over particle counts on intel are needed")
    few, many = min(scan), max(odo)
    (ks, ns, _, _), (ko, no, _, _) = converged(scan[few]), converged(odo[many])
    verdict, reason, test = more_successes(
        f"the scan-based proposal with {few}", ks, ns, f"the odometry proposal with {many}", ko, no
    )
    ours = "; ".join(
        [f"scan-based {n}: {converged(e)[0]}/{len(e)}" for n, e in sorted(scan.items())]
        + [f"odometry {n}: {converged(e)[0]}/{len(e)}" for n, e in sorted(odo.items())]
    )
    if verdict == REPRODUCED and many < 10 * few:
        verdict, reason = PARTLY, reason + f"; {many} particles are not yet ten times {few}"
    return Verdict(verdict, ours, reason, test)


def judge_selective(ev: Evidence) -> Verdict:
    """Selective resampling (N_eff) against resampling at every step on intel, the paper proposal."""
    rows, worse, fewer = [], [], True
    for n in (5, 10, 15, 30, 60):
        sel = [
            r
            for r in ev.slam
            if r.exp == "gmapping_intel"
            and r.setting("slam.proposal") == "paper"
            and r.setting("slam.num_particles") == n
            and not off_defaults(r, ("slam",), ("slam.num_particles", "slam.seed", "slam.resample"))
        ]
        a = [r for r in sel if r.setting("slam.resample") == "selective"]
        b = [r for r in sel if r.setting("slam.resample") == "always"]
        if not (a and b):
            continue
        ka = converged([r["relations"]["trans_abs_mean_m"] for r in a])[0]
        kb = converged([r["relations"]["trans_abs_mean_m"] for r in b])[0]
        ra, rb = np.median([r["resamplings"] for r in a]), np.median([r["resamplings"] for r in b])
        fewer &= ra < rb
        p = fisher(ka, len(a), kb, len(b))
        if ka < kb and p < ALPHA:
            worse.append(n)
        rows.append(
            f"{n} particles: {ra:.0f} against {rb:.0f} resamplings, {ka}/{len(a)} against {kb}/{len(b)} "
            f"converge (p = {p:.2g})"
        )
    if not rows:
        return Verdict(NOT_RUN, "-", "selective and every-step resampling on intel are needed")
    verdict = REPRODUCED if fewer and not worse else PARTLY if fewer else NOT_REPRODUCED
    return Verdict(
        verdict,
        "; ".join(rows),
        "selective resampling resamples less often"
        + (", with no loss of convergence shown" if not worse else f", but converges less often with {worse}"),
        "median resamplings per run; Fisher's exact test on the converged counts per particle count",
    )


def not_testable(why: str) -> Callable[[Evidence], Verdict]:
    return lambda ev: Verdict(NOT_TESTABLE, "-", why)


def not_run(why: str) -> Callable[[Evidence], Verdict]:
    return lambda ev: Verdict(NOT_RUN, "-", why)


# --- lidar + camera --------------------------------------------------------------------------------------------


def _globloc(ev: Evidence, exp: str):
    """The record of ``exp`` at its experiment's settings (the default trigger, not its ablation)."""
    found = [r for r in ev.globloc if r.exp == exp and not off_defaults(r, ("globloc",))]
    return found[0] if found else None


def judge_camera(exp: str, key: str) -> Callable[[Evidence], Verdict]:
    def judge(ev: Evidence) -> Verdict:
        rec = _globloc(ev, exp)
        if rec is None:
            return Verdict(NOT_RUN, "-", f"no run of {exp}")
        pa, li = rec["methods"]["paper"]["summary"], rec["methods"]["lidar_mcl"]["summary"]
        verdict, reason, test = more_successes(
            "the camera-aided pipeline", pa[key], pa["runs"], "lidar-only MCL", li[key], li["runs"]
        )
        return Verdict(verdict, f"pipeline {pa[key]}/{pa['runs']}, lidar-only MCL {li[key]}/{li['runs']}", reason, test)

    return judge


def judge_trigger(ev: Evidence) -> Verdict:
    found = [
        (r.exp, r["methods"]["paper"]["summary"])
        for r in ev.globloc
        if r.setting("globloc.kidnap_at_s", 0) > 0 and "paper" in r["methods"] and not off_defaults(r, ("globloc",))
    ]
    if not found:
        return Verdict(NOT_RUN, "-", "no kidnapping runs")
    k, n = sum(s["detected"] for _, s in found), sum(s["runs"] for _, s in found)
    lo, hi = wilson(k, n)
    verdict = REPRODUCED if lo >= 0.9 else PARTLY if k >= n / 2 else NOT_REPRODUCED
    return Verdict(
        verdict,
        "; ".join(f"{e}: {s['detected']}/{s['runs']} detected" for e, s in found),
        f"{k}/{n} kidnappings detected by the trigger (the others recovered through the particles)",
        f"Wilson 95 % interval {lo:.2f}-{hi:.2f}",
    )


# --- the registry --------------------------------------------------------------------------------------------


def _synthesis_claims() -> list[Claim]:
    out = []
    for ds, recipe, pub in (("fr079", "paper", True), ("intel", "paper", False), ("mit_csail", "fast", False)):
        out.append(
            Claim(
                f"irmcl.synthesis.{ds}",
                "IR-MCL",
                f"the NOF synthesises {ds}'s test scans better than occupancy grids",
                "irmcl",
                "Table I",
                tuple(f"irmcl_fr079_{m}" for m in ("mae_m", "accuracy_pct", "chamfer_m", "fscore_pct")) if pub else (),
                "below the 5 cm grid's MAE"
                + (
                    "; MAE within 10 % and F-score within 1 point of the paper's"
                    if pub
                    else " (the paper's figure for this log is not transcribed)"
                ),
                f"python -m irmcl_warp.train +exp={ds} train={recipe} && python -m irmcl_warp.synthesis +exp={ds} train={recipe}",
                judge_synthesis(ds, recipe, pub),
            )
        )
    return out


CLAIMS: list[Claim] = [
    *_synthesis_claims(),
    *[
        Claim(
            f"irmcl.global.{ds}",
            "IR-MCL",
            f"global localization on {ds} with 100k particles is more accurate with "
            "the NOG than with AMCL's likelihood field",
            "irmcl",
            "the global-localization experiments",
            ("irmcl_ipblab_global_cm", "irmcl_ipblab_global_deg", "irmcl_ipblab_amcl_cm", "irmcl_ipblab_amcl_deg"),
            "per-start location and heading RMSE lower (the paper's figures are on its own sequences, not in our data)",
            f"python -m irmcl_warp.localize -m +exp={ds} train=<preset> mcl.weighting=nog_raymarch,likelihood_field",
            judge_accuracy(ds, "global", 100000),
        )
        for ds in ("fr079", "intel", "mit_csail")
    ],
    *[
        Claim(
            f"irmcl.convergence.{ds}",
            "IR-MCL",
            f"global localization on {ds} converges at least as fast with the NOG as with AMCL's likelihood field",
            "irmcl",
            "the global-localization experiments (convergence over time)",
            (),
            "per-start time to converge not longer",
            f"python -m irmcl_warp.localize -m +exp={ds} train=<preset> mcl.weighting=nog_raymarch,likelihood_field",
            judge_convergence(ds),
        )
        for ds in ("fr079", "intel", "mit_csail")
    ],
    *[
        Claim(
            f"irmcl.tracking.{ds}",
            "IR-MCL",
            f"pose tracking on {ds} (10k particles) is more accurate with the NOG than with AMCL's likelihood field",
            "irmcl",
            "the pose-tracking experiments",
            (),
            "per-start location and heading RMSE lower",
            f"python -m irmcl_warp.localize -m +exp={ds} train=<preset> localize.mode=tracking mcl.num_particles=10000 "
            "mcl.weighting=nog_raymarch,likelihood_field",
            judge_accuracy(ds, "tracking", 10000),
        )
        for ds in ("fr079", "intel", "mit_csail")
    ],
    Claim(
        "irmcl.realtime",
        "IR-MCL",
        "100k particles are weighed in real time on a GPU",
        "irmcl",
        "the runtime analysis",
        ("irmcl_render_100k_ms",),
        "a full filter step below the paper's rendering time",
        "python -m eval.bench mcl",
        judge_realtime,
    ),
    Claim(
        "irmcl.online",
        "IR-MCL",
        "the localization runs online on a real log",
        "irmcl",
        "the title and runtime analysis",
        (),
        "a filter step within the log's scan period",
        "bash eval/gpu/mcl.sh real",
        judge_online,
    ),
    *[
        Claim(
            f"gmapping.relations.{ds}",
            "GMapping",
            f"relations error on {ds} with 30 particles",
            "kuemmerle",
            figure(f"kuemmerle_gmapping_{ds}_m").where,
            (f"kuemmerle_gmapping_{ds}_m",),
            ">= 90 % of seeds converge; their error within 25 % of the published",
            f"python -m irmcl_warp.slam -m +exp=gmapping_{ds} slam.seed=0,1,2,3,4,5,6,7,8,9",
            judge_relations(ds),
        )
        for ds in ("intel", "fr079", "mit_csail")
    ],
    *[
        Claim(
            f"gmapping.released.{ds}",
            "GMapping",
            f"ours converges as the released C++ does on {ds} (same log, its settings, 30 particles, 10 seeds)",
            "gmapping",
            "the released code (openslam_gmapping), run here",
            (),
            "at least its convergence rate, else Fisher's exact test",
            f"python -m irmcl_warp.slam -m +exp=gmapping_{ds} slam.proposal=gmapping_code slam.seed=0,1,2,3,4,5,6,7,8,9; "
            f"python -m eval.reference.gmapping +exp=gmapping_{ds}",
            judge_released(ds),
        )
        for ds in ("intel", "fr079", "mit_csail")
    ],
    Claim(
        "gmapping.released.fr079_gfs",
        "GMapping",
        "ours converges as the released code's own CARMEN-log tool (gfs_nogui, its defaults) does on fr079",
        "gmapping",
        "the released code's gfs_nogui, run here",
        (),
        "at least its convergence rate, else Fisher's exact test",
        "python -m irmcl_warp.slam -m +exp=gmapping_fr079 slam=gmapping_gfs 'data.laser_offset=[0,0,0]' "
        "slam.proposal=gmapping_code slam.seed=0,...,9; python -m eval.reference.gmapping +exp=gmapping_fr079 --gfs",
        judge_released(
            "fr079",
            {
                "slam.srt": 0.1,
                "slam.stt": 0.1,
                "slam.temporal_update": 5.0,
                "slam.beam_angles": "gfs",
                "data.laser_offset": [0, 0, 0],
            },
            "gfs",
        ),
    ),
    Claim(
        "gmapping.particles.intel",
        "GMapping",
        "intel is mapped with 15 particles thanks to the scan-based proposal",
        "gmapping",
        figure("gmapping_intel_particles").where,
        ("gmapping_intel_particles",),
        ">= 90 % of seeds converge",
        "python -m irmcl_warp.slam -m +exp=gmapping_intel slam.num_particles=15 slam.seed=0,...,9",
        judge_particles("intel", 15),
    ),
    Claim(
        "gmapping.particles.campus",
        "GMapping",
        "the Freiburg campus is mapped with 30 particles",
        "gmapping",
        figure("gmapping_campus_particles").where,
        ("gmapping_campus_particles",),
        ">= 90 % of seeds converge",
        "-",
        not_testable("../shared/data holds only the GMapping-corrected campus log: no raw odometry to map it from"),
    ),
    Claim(
        "gmapping.particles.killian60",
        "GMapping",
        "MIT Killian Court (1.9 km, large loops) is mapped with 60 particles",
        "gmapping",
        figure("gmapping_killian_particles").where,
        ("gmapping_killian_particles",),
        ">= 90 % of seeds converge",
        "python -m irmcl_warp.slam -m +exp=gmapping_mit_killian slam.num_particles=60 slam.seed=0,...,9",
        judge_particles("mit_killian", 60),
    ),
    Claim(
        "gmapping.particles.killian80",
        "GMapping",
        "MIT Killian Court is mapped with 80 particles",
        "gmapping",
        figure("gmapping_killian_particles").where,
        ("gmapping_killian_particles",),
        ">= 90 % of seeds converge",
        "python -m irmcl_warp.slam -m +exp=gmapping_mit_killian slam.num_particles=80 slam.seed=0,...,9",
        judge_particles("mit_killian", 80),
    ),
    Claim(
        "gmapping.odometry_fails",
        "GMapping",
        "the odometry proposal fails on intel where the scan-based one succeeds",
        "gmapping",
        "the comparison of the proposals",
        (),
        "more successes for the scan-based proposal (Fisher)",
        "python -m irmcl_warp.slam -m +exp=gmapping_intel slam.num_particles=60 slam.proposal=odometry,paper slam.seed=0,...,9",
        judge_odometry_fails,
    ),
    Claim(
        "gmapping.fewer_particles",
        "GMapping",
        "the scan-based proposal needs an order of magnitude fewer particles than the odometry proposal",
        "gmapping",
        "the comparison of particle counts",
        (),
        "the scan-based proposal with n particles succeeds more often than the odometry proposal with 10 n (Fisher)",
        "bash eval/gpu/slam_sweep.sh particles",
        judge_fewer_particles,
    ),
    Claim(
        "gmapping.selective",
        "GMapping",
        "selective resampling (on N_eff) resamples less often without losing convergence",
        "gmapping",
        "selective resampling",
        (),
        "fewer resamplings at every particle count; no convergence count lower with p < 0.05",
        "bash eval/gpu/slam_sweep.sh particles",
        judge_selective,
    ),
    *[
        Claim(
            f"lidar_camera.{exp}",
            "Lidar + camera",
            f"camera-aided localization succeeds {what} more often than lidar-only MCL (repetitive corridor)",
            "lidar_camera",
            "its comparison with lidar-only MCL",
            (),
            "more successes than lidar-only MCL, Fisher's exact test",
            f"python -m irmcl_warp.globloc +exp={exp}",
            judge_camera(exp, "recovered" if "kidnap" in exp else "localized"),
        )
        for exp, what in (
            ("globloc_corridor", "from random starts"),
            ("globloc_corridor_kidnap", "after a kidnapping"),
            ("globloc_corridor_8m", "from random starts with an 8 m lidar"),
            ("globloc_corridor_8m_kidnap", "after a kidnapping with an 8 m lidar"),
        )
    ],
    Claim(
        "lidar_camera.trigger",
        "Lidar + camera",
        "the relocalization trigger detects a kidnapped robot",
        "lidar_camera",
        "its kidnapped-robot experiment",
        (),
        "Wilson lower bound of the detection rate >= 0.9",
        "python -m irmcl_warp.globloc +exp=globloc_corridor_kidnap; ... +exp=globloc_corridor_8m_kidnap",
        judge_trigger,
    ),
    Claim(
        "lidar_camera.lighting",
        "Lidar + camera",
        "retrieval and PnP are robust to lighting changes",
        "lidar_camera",
        "its robustness experiments",
        (),
        "success against globloc.lighting",
        "python -m irmcl_warp.globloc -m +exp=globloc_corridor globloc.lighting=0.0,0.2,0.5",
        not_run("only the default lighting change (globloc.lighting=0.2) is kept; the sweep is the command"),
    ),
    Claim(
        "lidar_camera.moved_objects",
        "Lidar + camera",
        "localization is robust to moved objects",
        "lidar_camera",
        "its robustness experiments",
        (),
        "success against globloc.moved_furniture_m",
        "python -m irmcl_warp.globloc -m +exp=globloc_corridor globloc.moved_furniture_m=0.0,0.3,1.0",
        not_run("only the default furniture shift (0.3 m) is kept; the sweep is the command"),
    ),
    Claim(
        "lidar_camera.pnp",
        "Lidar + camera",
        "ORB + PnP refines the retrieved keyframe's pose",
        "lidar_camera",
        "its pipeline (PnP after retrieval)",
        (),
        "pose error with and without PnP",
        "-",
        not_run("no run without the PnP step is kept (camera_only, the pipeline with PnP, is)"),
    ),
    Claim(
        "lidar_camera.clustering",
        "Lidar + camera",
        "clustering the candidates by keyframe index works as well as in pose space",
        "lidar_camera",
        "its keyframe clustering",
        (),
        "success by globloc.cluster_space",
        "python -m irmcl_warp.globloc -m +exp=globloc_corridor globloc.cluster_space=index,pose",
        not_run("the kept runs cluster in pose space only"),
    ),
]


def load_bench(results: Path = RESULTS) -> dict:
    """The kept benchmark records (results/bench/<name>.json) by name."""
    return {p.stem: json.loads(p.read_text()) for p in sorted((Path(results) / "bench").glob("*.json"))}


def verdicts(ev: Evidence) -> list[tuple[Claim, Verdict]]:
    return [(c, c.judge(ev)) for c in CLAIMS]
