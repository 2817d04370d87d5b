"""docs/REPRODUCTION.md: each claim of the three papers, the paper's figure, ours (computed here from the
runs' metrics.json, never typed), and the command that makes the runs. Written by ``python -m eval.tables
--write``; a claim whose runs are missing says so instead of a number."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from eval.collect import REPO, converged, median_span, released_errors, slam_errors, slam_variant
from irmcl_warp.config import GlobLocConfig


def _pick(runs: dict, exp: str, folder: str):
    return runs.get((exp, folder))


def _synthesis(runs, exp, preset, method="NOF"):
    """The metrics of the first method whose name starts with ``method`` ("NOF", "OGM 5 cm")."""
    syn = runs.get((exp, preset), (None, None))[0]
    return next((m for name, m in syn["methods"].items() if name.startswith(method)), None) if syn else None


def _minute_spans(runs, exp: str = "fr079") -> dict[str, str]:
    """The one-minute preset's kept runs on ``exp`` (train.name minute, minute_s1, ...): seeds, and medians
    [min-max] over them of test MAE, Chamfer (m) and training time (s); {} when none is kept."""
    found = []
    for (e, preset), (syn, train) in runs.items():
        if e == exp and (preset == "minute" or preset.startswith("minute_s")) and syn and train:
            m = next((v for k, v in syn["methods"].items() if k.startswith("NOF")), None)
            if m:
                found.append((m["mae_m"], m["chamfer_m"], train["train_time_s"]))
    if not found:
        return {}
    mae, cham, secs = zip(*found)
    return {"seeds": str(len(found)), "mae": median_span(mae, ".3f"), "chamfer": median_span(cham, ".3f"),
            "time": median_span(secs, ".1f")}


def _minute_note(runs, exp: str = "fr079") -> str:
    m = _minute_spans(runs, exp)
    return (f"; `train=minute`, {m['seeds']} seeds each trained alone on an H100: MAE {m['mae']} m, "
            f"Chamfer {m['chamfer']} m in {m['time']} s") if m else ""


def _loc(runs, exp, tag):
    m = _pick(runs, exp, tag)
    return None if m is None else m["summary"]


def _slam(runs, ds, proposal="paper", resample="selective", particles=30, variant=""):
    errs = slam_errors(runs, ds, proposal, resample, particles, variant)
    if not errs:
        return None
    k, n, conv, _ = converged(errs)
    return f"{k}/{n} seeds converge, {conv:.3f} m" if k else f"0/{n} converge"


def _released(runs, ds, variant=""):
    """The released GMapping's seeds on ``ds`` (eval.reference.gmapping) at the wrapper's defaults (or a variant)."""
    errs = released_errors(runs or {}, ds, variant=variant)
    if not errs:
        return None
    k, n, conv, mean = converged(errs)
    return (f"{k}/{n} seeds converge, {conv:.3f} m" if k else f"0/{n} converge") + f", all runs {mean:.3f} m"


NOT_RUN = "not run"


def _slam_verdict(errs, published_m: float | None = None, what: str = "seeds converge") -> str:
    """reproduced: >= 9/10 converge (at most 25 % above the published error when one is given); partly: at
    least half converge; else not reproduced."""
    if not errs:
        return NOT_RUN
    k, n, conv, _ = converged(errs)
    if k >= 0.9 * n and (published_m is None or conv <= 1.25 * published_m):
        return "reproduced"
    return f"{'partly' if k >= n / 2 else 'not reproduced'}: {k}/{n} {what}"


def _count(text: str | None) -> tuple[int, int] | None:
    """(k, n) of a "k/n" figure."""
    m = re.match(r"(\d+)/(\d+)", text or "")
    return (int(m.group(1)), int(m.group(2))) if m else None


def _against_released(ours, released) -> str:
    """Ours at the released code's settings against the released code's runs: at least its successes?"""
    if not ours or not released:
        return NOT_RUN
    (k, n, _, _), (kr, nr, _, _) = converged(ours), converged(released)
    if k * nr >= kr * n:  # rates: the two sides may have run different numbers of seeds
        return f"reproduced: ours {k}/{n} seeds converge, the released code {kr}/{nr}"
    from scipy.stats import fisher_exact

    p = fisher_exact([[k, n - k], [kr, nr - kr]]).pvalue
    if p >= 0.05:
        return f"partly: ours {k}/{n}, the released code {kr}/{nr} (Fisher's exact test p = {p:.2f}: no difference shown)"
    return f"not reproduced: ours {k}/{n}, the released code {kr}/{nr} (Fisher's exact test p = {p:.2g})"


def _fails_verdict(errs) -> str:
    if not errs:
        return NOT_RUN
    k, n, _, _ = converged(errs)
    return "reproduced" if k == 0 else f"partly: {k}/{n} seeds converge with the odometry proposal"


def _globloc(runs, exp, method, key="localized"):
    """``method``'s count over the runs of ``exp`` made with the default trigger (not its ablation)."""
    for (e, _), m in runs.items():
        confirm = m.get("settings", {}).get("trigger_confirm_frames", 1)
        if e == exp and method in m["methods"] and confirm == GlobLocConfig.trigger_confirm_frames:
            s = m["methods"][method]["summary"]
            return f"{s[key]}/{s['runs']}"
    return None


def _real_vs_bench(variant: str) -> str:
    """A real fr079 run's median ms per filter step beside the micro-benchmark of ``variant`` (the settings
    it ran with) on its own NOG."""
    b = _bench("mcl-real-fr079-h100.json")
    if not b:
        return ""
    micro = next((r["step_ms"] for r in b["bench"]["rows"] if r.get("variant") == variant and r.get("graph")), None)
    real = b["real"]["summary"].get("ms_per_step_median")
    if micro is None or real is None:
        return ""
    text = f"; a real fr079 run {real:.2f} ms per step against {micro:.2f} ms from the benchmark on its NOG ({real / micro:.2f}x)"
    around = next((r["step_ms"] for r in b.get("bench_around", {}).get("rows", []) if r.get("variant") == variant
                   and r.get("graph") and r["particles"] == 100000), None)
    if around is not None:  # particles started as a converged filter holds them (eval.bench mcl --around)
        text += f", {around:.2f} ms with the particles around the scan's pose ({real / around:.2f}x)"
    return text


# the authors' training script on our fr079 split, scored (eval.reference.irmcl --stage nof-score, kept)
THEIR_RECIPE = REPO / "results" / "checks" / "irmcl_reference" / "fr079" / "reference-irmcl-nof" / "metrics.json"


def _their_recipe_note() -> str:
    """The authors' training script and evaluation on our fr079 split (eval.reference.irmcl), when kept."""
    if not THEIR_RECIPE.is_file():
        return ""
    m = json.loads(THEIR_RECIPE.read_text())
    epochs = len(m.get("their_val_per_epoch") or [])
    return (f"; the authors' code on our split: MAE {m['their_eval']['mae_m']:.3f} m after {epochs} of their 32 epochs "
            "(docs/fidelity.md)")


def _irmcl_reference_runs(ds: str) -> tuple[Path, Path, Path]:
    """The kept pose-tracking runs on ``ds`` of the authors' code with our field (eval.reference.irmcl), of our
    NOG and of our likelihood field, both with their motion model (fr079's are the yaw study's)."""
    checks = REPO / "results" / "checks"
    ours = checks / "fr079_yaw" if ds == "fr079" else checks / "irmcl_reference" / ds
    return (checks / "irmcl_reference" / ds / "reference-irmcl-tracking-10k", ours / "localize-nog_raymarch-tracking-10k-5cm-irmcl",
            ours / "localize-likelihood_field-tracking-10k-5cm-irmcl")


def _theirs_note(ds: str) -> str:
    """What the authors' own code did on this log with our field (eval.reference.irmcl, pose tracking), set
    beside our NOG and likelihood field with their motion model, when those runs are kept."""
    paths = _irmcl_reference_runs(ds)
    if not all((p / "metrics.json").is_file() for p in paths):
        return ""
    theirs, nog, lf = (json.loads((p / "metrics.json").read_text())["summary"]["yaw_rmse_deg_mean"] for p in paths)
    text = (f"; the authors' code, run on this log with our field (pose tracking), errs {theirs:.2f} deg in heading, "
            f"our NOG {nog:.2f}, our likelihood field {lf:.2f}")
    glob = paths[0].parent / "reference-irmcl-global-100k" / "metrics.json"
    if glob.is_file():
        g = json.loads(glob.read_text())["summary"]
        text += f"; globally with 100k particles, {g['successes']}/{g['starts']} starts, {g['yaw_rmse_deg_mean']:.2f} deg"
    return text


def _bench(name):
    p = REPO / "results" / "bench" / name
    return json.loads(p.read_text()) if p.is_file() else None


def claims(nof: dict, loc: dict, slam: dict, gl: dict, pipe: dict, released: dict | None = None) -> list[tuple]:
    """(system, claim, paper's figure, ours, verdict, command) rows. The verdict (reproduced, partly, not
    reproduced, or "not run") is computed from the same figures as "ours", with the reason."""
    rows = []
    s = _synthesis(nof, "fr079", "paper")
    g5 = _synthesis(nof, "fr079", "paper", "OGM 5 cm")
    rows.append(("IR-MCL", "the NOF synthesises fr079's test scans better than occupancy grids (Table I)",
                 "MAE 0.250 m, F-score 97.4 % (authors' code and recipe)",
                 f"MAE {s['mae_m']:.3f} m, F-score {s['fscore_pct']:.1f} %" + (f"; 5 cm grid {g5['mae_m']:.3f} m" if g5 else "")
                 + _their_recipe_note() + _minute_note(nof) if s else "not run",
                 NOT_RUN if not s else "reproduced" if s["mae_m"] <= 1.10 * 0.250 and s["fscore_pct"] >= 97.4 - 1.0 else
                 f"partly: MAE {100 * (s['mae_m'] / 0.250 - 1):+.0f} % against the authors'",
                 "python -m irmcl_warp.train +exp=fr079 train=paper && python -m eval.synthesis +exp=fr079 train=paper"))
    for ds in ("fr079", "intel", "mit_csail"):
        n = _loc(loc, ds, "localize-nog_raymarch-global-100k-5cm")
        lf = _loc(loc, ds, "localize-likelihood_field-global-100k-5cm")
        rows.append(("IR-MCL", f"global localization on {ds} with 100k particles on the NOG, more accurate than AMCL's "
                     "likelihood field", "measured on the authors' IPBLab sequences (not in our data): 6.62 cm / 1.11 deg "
                     "against AMCL 11.11 cm / 4.15 deg; on fr079, intel and MIT CSAIL the paper reports the observation "
                     "model only (Table I)",
                     (f"{n['successes']}/{n['starts']} starts, {n['location_rmse_cm_mean']:.1f} cm / "
                      f"{n['yaw_rmse_deg_mean']:.2f} deg; likelihood field {lf['successes']}/{lf['starts']}, "
                      f"{lf['location_rmse_cm_mean']:.1f} cm / {lf['yaw_rmse_deg_mean']:.2f} deg") if n and lf else "not run",
                     NOT_RUN if not (n and lf) else "reproduced" if (
                         n["location_rmse_cm_mean"] <= lf["location_rmse_cm_mean"]
                         and n["yaw_rmse_deg_mean"] <= lf["yaw_rmse_deg_mean"]) else
                     "not reproduced on this log: the likelihood field is more accurate; the NOG's heading likelihood is "
                     f"wider{_theirs_note(ds)} (docs/fidelity.md)",
                     f"python -m irmcl_warp.localize +exp={ds} train=<preset> mcl.weighting=nog_raymarch,likelihood_field -m"))
    b = _bench("mcl-cuda-h100.json")
    from eval.bench_mcl import DEFAULT_VARIANT

    rows_100k = [r for r in (b["rows"] if b else []) if r.get("variant", r["method"]) == DEFAULT_VARIANT
                 and r["particles"] == 100000 and r["step_ms"] is not None]
    step = min(rows_100k, key=lambda r: not r.get("graph", False))["step_ms"] if rows_100k else None  # the graph's
    rows.append(("IR-MCL", "100k particles in real time on a GPU", "85 ms GPU rendering of 100k particles (authors' code)",
                 (f"{step:.2f} ms per full filter step (H100)" if step else "not run") + _real_vs_bench(DEFAULT_VARIANT),
                 NOT_RUN if not step else "reproduced" if step < 85.0 else "not reproduced",
                 "python -m eval.bench mcl; bash eval/gpu/mcl.sh real"))
    for ds, pub in (("intel", 0.070), ("fr079", 0.061), ("mit_csail", 0.049)):
        rows.append(("GMapping", f"relations error on {ds}, 30 particles", f"{pub:.3f} m (Kümmerle et al. 2009)",
                     _slam(slam, ds) or "not run", _slam_verdict(slam_errors(slam, ds, "paper"), pub),
                     f"python -m irmcl_warp.slam -m +exp=gmapping_{ds} slam.seed=0,1,2,3,4,5,6,7,8,9"))
    for ds in ("intel", "fr079"):
        ref = _released(released, ds)
        rows.append(("GMapping", f"relations error on {ds} against the released C++ (same log, 30 particles, 10 seeds)",
                     f"{ref} (released code, `python -m eval.reference.gmapping +exp=gmapping_{ds}`)" if ref else
                     "not run (`bash eval/reference/build_gmapping.sh`, then `python -m eval.reference.gmapping`)",
                     f"released code's proposal: {_slam(slam, ds, 'gmapping_code') or 'not run'}; with twice its "
                     f"rotational noise (slam=gmapping_rot2x): {_slam(slam, ds, 'gmapping_code', variant='srt0.4, stt0.4') or 'not run'}",
                     _against_released(slam_errors(slam, ds, "gmapping_code"), released_errors(released or {}, ds)),
                     f"python -m irmcl_warp.slam -m +exp=gmapping_{ds} slam.proposal=gmapping_code slam=gmapping,gmapping_rot2x "
                     f"slam.seed=0,1,2,3,4,5,6,7,8,9"))
    gfs = "srt0.1, stt0.1, temporal5, beamsgfs, offset0_0_0"  # slam=gmapping_gfs data.laser_offset=[0,0,0]
    ref = _released(released, "fr079", variant="gfs")
    if ref:
        rows.append(("GMapping", "relations error on fr079 against the released code's own CARMEN-log tool (gfs_nogui, "
                     "its defaults, 30 particles)", f"{ref} (`python -m eval.reference.gmapping +exp=gmapping_fr079 --gfs`)",
                     f"ours on the tool's inputs: `gmapping_code` {_slam(slam, 'fr079', 'gmapping_code', variant=gfs) or 'not run'}; "
                     f"`paper` {_slam(slam, 'fr079', 'paper', variant=gfs) or 'not run'}",
                     _against_released(slam_errors(slam, "fr079", "gmapping_code", variant=gfs),
                                       released_errors(released or {}, "fr079", variant="gfs")),
                     "python -m irmcl_warp.slam -m +exp=gmapping_fr079 slam=gmapping_gfs 'data.laser_offset=[0,0,0]' "
                     "slam.proposal=gmapping_code,paper slam.seed=0,1,2,3,4,5,6,7,8,9"))
    few = {n: _slam(slam, "intel", particles=n) for n in (5, 10, 15)}
    rows.append(("GMapping", "intel is mapped with few particles thanks to the scan-based proposal",
                 "15 particles (Grisetti et al. 2007)", "; ".join(f"{n}: {v}" for n, v in few.items() if v) or "not run",
                 _slam_verdict(slam_errors(slam, "intel", particles=15), what="seeds converge with 15 particles"),
                 "bash eval/gpu/slam_sweep.sh particles"))
    killian = {pr: _slam(slam, "mit_killian", pr, particles=60) for pr in ("paper", "gmapping_code")}
    ref = released_errors(released or {}, "mit_killian", particles=60, variant="delta=0.1, particles=60")
    rows.append(("GMapping", "MIT Killian Court (1.9 km, large loops) is mapped with 60 particles",
                 "60-80 particles (Grisetti et al. 2007)",
                 "; ".join(f"`{pr}`: {v}" for pr, v in killian.items() if v) + (
                     f"; the released code at 10 cm: {converged(ref)[0]}/{len(ref)} seeds converge" if ref else "")
                 if any(killian.values()) else "not run",
                 _slam_verdict(slam_errors(slam, "mit_killian", "paper", particles=60)),
                 "python -m irmcl_warp.slam -m +exp=gmapping_mit_killian slam.num_particles=60 "
                 "slam.proposal=paper,gmapping_code slam.seed=0,1,2,3,4,5,6,7,8,9"))
    rows.append(("GMapping", "the odometry proposal fails where the scan-based one succeeds",
                 "fails on intel (Grisetti et al. 2007)", _slam(slam, "intel", "odometry", particles=60) or "not run",
                 _fails_verdict(slam_errors(slam, "intel", "odometry", particles=60)),
                 "python -m irmcl_warp.slam +exp=gmapping_intel slam.proposal=odometry slam.num_particles=60"))
    for exp, what in (("globloc_corridor", "from random starts"), ("globloc_corridor_kidnap", "after a kidnapping"),
                      ("globloc_corridor_8m", "from random starts, 8 m lidar"),
                      ("globloc_corridor_8m_kidnap", "after a kidnapping, 8 m lidar")):
        key = "recovered" if "kidnap" in exp else "localized"
        pa, li = _globloc(gl, exp, "paper", key), _globloc(gl, exp, "lidar_mcl", key)
        rows.append(("Lidar + camera", f"camera-aided localization succeeds {what} where lidar-only MCL fails "
                     "(repetitive corridor)", "more successes than lidar-only", f"pipeline {pa}, lidar-only MCL {li}"
                     if pa and li else "not run",
                     NOT_RUN if not (pa and li) else "reproduced" if _count(pa)[0] > _count(li)[0] else
                     "not reproduced: no more successes than lidar-only", f"python -m irmcl_warp.globloc +exp={exp}"))
    b = _bench("globloc-globloc_corridor-cpu-2core.json")
    rows.append(("Lidar + camera", "a relocalization decision over 1000 keyframes within 100 ms (issue goal, 2-core CPU)",
                 "-", f"{b['rows'][0]['decision_ms']:.1f} ms" if b else "not run",
                 NOT_RUN if not b else "met" if b["rows"][0]["decision_ms"] <= 100 else "not met",
                 "python -m eval.bench globloc --device cpu"))
    by_exp = {}
    for (exp, _), m in sorted(pipe.items()):
        by_exp.setdefault(exp, []).append(m)
    commands = {"pipeline_sim_office": "python -m irmcl_warp.pipeline pipeline.sim_path_seed=1..10",
                "pipeline_sim_office_30k": "python -m irmcl_warp.pipeline pipeline.sim_path_seed=1..10 mcl.num_particles=30000",
                "pipeline_fr079": "python -m irmcl_warp.pipeline +exp=pipeline_fr079 train=fast slam.num_particles=30 ..."}
    for exp, ms in by_exp.items():
        los = [m.get("localization") for m in ms]
        if len(ms) == 1:
            lo = los[0]
            ours = (f"converged after {lo['time_to_converge_s']:.1f} s, {lo['location_rmse_cm']:.1f} cm RMSE"
                    if lo and lo["converged"] else "did not converge" if lo else "no ground truth")
        else:
            ok = [lo["location_rmse_cm"] for lo in los if lo and lo["success"]]
            ours = (f"{len(ok)}/{len(ms)} second drives localized"
                    + (f", RMSE median {np.median(ok):.1f} cm [{min(ok):.1f}-{max(ok):.1f}]" if ok else ""))
        rows.append(("Pipeline", f"raw log to a localized robot ({exp})", "-", f"{ours} ({ms[0]['device']})",
                     "- (no published figure)", commands.get(exp, "python -m irmcl_warp.pipeline")))
    return rows


def facts(slam: dict, released: dict, nof: dict | None = None) -> dict[str, str]:
    """The figures the README's prose quotes, by name, from the kept runs: ``eval.tables --write`` puts each
    between ``<!-- fact:<name> -->`` and ``<!-- /fact -->``, and tests/test_tables.py fails when the prose and
    the results disagree."""
    out = {}

    def count(name, errs):
        if errs:
            k, n, _, _ = converged(errs)
            out[name] = f"{k}/{n}"

    def error(name, errs):
        conv = converged(errs)[2] if errs else None
        if conv is not None:
            out[name] = f"{conv:.3f} m"

    for ds in ("fr079", "intel", "mit_csail"):
        code, paper = slam_errors(slam, ds, "gmapping_code"), slam_errors(slam, ds, "paper")
        count(f"{ds}_code", code)
        count(f"{ds}_paper", paper)
        count(f"{ds}_code_rot2x", slam_errors(slam, ds, "gmapping_code", variant="srt0.4, stt0.4"))
        error(f"{ds}_code_error", code)
        error(f"{ds}_paper_error", paper)
        rel = released_errors(released, ds)
        count(f"{ds}_released", rel)
        error(f"{ds}_released_error", rel)
    count("fr079_code_60p", slam_errors(slam, "fr079", "gmapping_code", particles=60))
    count("fr079_code_laserframe", slam_errors(slam, "fr079", "gmapping_code", variant="laserframe"))
    count("fr079_paper_laserframe", slam_errors(slam, "fr079", "paper", variant="laserframe"))
    for proposal, short in (("gmapping_code", "code"), ("paper", "paper")):  # MIT Killian, the paper's 60 particles
        count(f"killian_{short}_60p", slam_errors(slam, "mit_killian", proposal, particles=60))
        error(f"killian_{short}_60p_error", slam_errors(slam, "mit_killian", proposal, particles=60))
    count("killian_paper_30p", slam_errors(slam, "mit_killian", "paper", particles=30))
    count("killian_released_60p", released_errors(released, "mit_killian", particles=60, variant="delta=0.1, particles=60"))
    error("killian_released_60p_error", released_errors(released, "mit_killian", particles=60, variant="delta=0.1, particles=60"))
    processed = sorted({m["processed_scans"] for m in released.values() if m.get("dataset") == "intel"})
    if processed:
        out["intel_released_processed"] = "/".join(str(p) for p in processed)
    ours = sorted({m["processed_scans"] for m in slam.values() if m.get("dataset") == "intel"
                   and m.get("proposal") == "gmapping_code" and m.get("particles") == 30 and slam_variant(m) == ""})
    if ours:
        out["intel_code_processed"] = "/".join(str(p) for p in ours)
    count("fr079_released_gfs_noise", released_errors(released, "fr079", variant="srt=0.1, stt=0.1"))
    # the released code's own CARMEN tool (gfs_nogui) at its defaults, and ours on the same inputs
    count("fr079_released_gfs", released_errors(released, "fr079", variant="gfs"))
    error("fr079_released_gfs_error", released_errors(released, "fr079", variant="gfs"))
    for p in ("gmapping_code", "paper"):
        count(f"fr079_{'code' if p == 'gmapping_code' else p}_gfs_inputs",
              slam_errors(slam, "fr079", p, variant="srt0.1, stt0.1, temporal5, beamsgfs, offset0_0_0"))
    for ds in ("fr079", "intel"):  # the authors' MCL with our field beside our likelihood field (pose tracking)
        theirs, _, lf = _irmcl_reference_runs(ds)
        for name, run in ((f"irmcl_theirs_yaw_{ds}", theirs), (f"irmcl_lf_yaw_{ds}", lf)):
            if (run / "metrics.json").is_file():
                out[name] = f"{json.loads((run / 'metrics.json').read_text())['summary']['yaw_rmse_deg_mean']:.2f} deg"
    if THEIR_RECIPE.is_file():  # the authors' training script on our split
        m = json.loads(THEIR_RECIPE.read_text())
        out["nof_theirs_mae"] = f"{m['their_eval']['mae_m']:.3f} m"
        out["nof_theirs_epochs"] = str(len(m.get("their_val_per_epoch") or []))
    for ds in ("fr079", "intel"):  # the one-minute preset's kept seeds
        for key, value in _minute_spans(nof or {}, ds).items():
            out[f"nof_minute_{ds}_{key}"] = value
    return out


FACT = re.compile(r"<!-- fact:([a-z0-9_]+) -->(.*?)<!-- /fact -->", re.S)


def readme_facts(text: str) -> dict[str, str]:
    return {name: value for name, value in FACT.findall(text)}


def write_facts(text: str, values: dict[str, str]) -> str:
    """``text`` with every fact it quotes set to its value; a quoted fact the results cannot give is an error."""
    missing = sorted(set(readme_facts(text)) - set(values))
    if missing:
        raise SystemExit(f"README.md quotes facts the results do not give: {missing}")
    return FACT.sub(lambda m: f"<!-- fact:{m.group(1)} -->{values[m.group(1)]}<!-- /fact -->", text)


def reproduction_markdown(rows: list[tuple]) -> str:
    lines = ["# Reproduction: each claim, the paper's figure, ours, the command", "",
             "Generated by `python -m eval.tables --write` from the runs' metrics.json (results/ and outputs/); ",
             "`python -m eval.reproduce` runs what is missing first. Devices and timings: docs/benchmarks.md.", "",
             "| system | claim | paper | ours | verdict | command |", "|---|---|---|---|---|---|"]
    lines += [f"| {a} | {b} | {c} | {d} | {v} | `{e}` |" for a, b, c, d, v, e in rows]
    return "\n".join(lines) + "\n"
