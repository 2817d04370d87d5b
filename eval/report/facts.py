"""The figures README.md's prose quotes, by name, computed from the kept records: ``python -m eval.tables
--write`` puts each between ``<!-- fact:<name> -->`` and ``<!-- /fact -->``, and tests/test_tables.py fails
when the prose and the results disagree."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from eval.analyses.paired_worlds import rates_exact
from eval.results.queries import converged, median_span, released_errors, slam_errors, slam_variant
from eval.results.records import RESULTS, checks, find

ROT2X = {"slam.srt": 0.4, "slam.stt": 0.4}  # slam=gmapping_rot2x
LASER_FRAME = {"slam.frame": "laser"}
GFS_INPUTS = {
    "slam.srt": 0.1,
    "slam.stt": 0.1,
    "slam.temporal_update": 5.0,
    "slam.beam_angles": "gfs",
    "data.laser_offset": [0.0, 0.0, 0.0],
}  # slam=gmapping_gfs data.laser_offset=[0,0,0]


def _minute_spans(nof: dict, exp: str, fixed: bool = False) -> dict[str, str]:
    """The one-minute preset's kept runs on ``exp`` (train.name minute, minute_s1, ...), or with ``fixed`` its runs
    with a fixed sample count and a compiled MLP (``train=minute_compiled``: told by the count's record in their
    history, whatever their name): seeds, and medians [min-max] over them of test MAE, Chamfer (m) and training time
    (s); {} when none is kept."""
    found = []
    for (e, preset), (syn, train) in nof.items():
        if e != exp or not (syn and train):
            continue
        is_fixed = any("fixed_samples_cut_share" in h for h in train.get("history", []))
        if fixed:
            wanted = preset.startswith("minute") and is_fixed and train.get("epochs_done") == 10
        else:
            wanted = (preset == "minute" or preset.startswith("minute_s")) and not is_fixed
        m = next((v for k, v in syn["methods"].items() if k.startswith("NOF")), None) if wanted else None
        if m:
            found.append((m["mae_m"], m["chamfer_m"], train["train_time_s"]))
    return _seed_spans(found)


def _seed_spans(found: list) -> dict[str, str]:
    """Seeds, and medians [min-max] of test MAE, Chamfer (m) and training time (s), of (MAE, Chamfer, s, ...) rows;
    {} for none."""
    if not found:
        return {}
    mae, cham, secs = list(zip(*found))[:3]
    return {
        "seeds": str(len(found)),
        "mae": median_span(mae, ".3f"),
        "chamfer": median_span(cham, ".3f"),
        "time": median_span(secs, ".1f"),
    }


# the step-graph runs (train=graph, issue 36): the preset's own name and the sessions' names for the same settings
# (sg64_e5: the twenty-third session's, on an H200; h_g: the twenty-fourth's, on an H100)
GRAPH_RUNS = {"fr079": ("graph", "sg64_e5", "h_g"), "intel": ("graph_intel", "sg96_e10_intel")}


def gpu_slug(name: str) -> str:
    """A card's short name for a fact's key: "NVIDIA H100 80GB HBM3" -> "h100", "NVIDIA H200" -> "h200"."""
    m = re.search(r"\b([A-Z]\d{2,4}[A-Za-z]?)\b", name or "")
    return m.group(1).lower() if m else re.sub(r"[^a-z0-9]+", "_", (name or "unknown").lower()).strip("_")


def _graph_spans(nof: dict, exp: str) -> dict[str, dict[str, str]]:
    """The kept step-graph runs on ``exp`` (train.name in GRAPH_RUNS, or that name + _s<seed>), per card (times from
    two cards are never pooled): {gpu_slug: seeds, medians [min-max] of test MAE, Chamfer (m) and training time (s),
    and the card's name}; {} when none is kept."""
    per_gpu: dict[str, list] = {}
    for (e, preset), (syn, train) in nof.items():
        if e != exp or not (syn and train):
            continue
        if not any(preset == f or re.fullmatch(rf"{f}_s\d+", preset) for f in GRAPH_RUNS.get(exp, ())):
            continue
        m = next((v for k, v in syn["methods"].items() if k.startswith("NOF")), None)
        if m:
            gpu = train.get("gpu") or train.get("device")
            per_gpu.setdefault(gpu, []).append((m["mae_m"], m["chamfer_m"], train["train_time_s"]))
    return {gpu_slug(gpu): {**_seed_spans(found), "gpu": gpu} for gpu, found in per_gpu.items()}


PAIRED_WORLDS = (
    "kld100k_vs_20k",
    "kld20k_vs_20k",
    "kld100k_vs_100k_kidnap",
    "kld100k_vs_100k_gpu",
    "map_cover_vs_random_gpu",
    "map_cover_vs_random_cpu",
    "rivals_vs_before_cpu",
    "rivals_vs_before_gpu",
    "rivals_vs_before_kidnap",
    "unbounded_vs_bounded_cpu",
    "seed_vs_noseed_cpu",
    "unbounded_vs_bounded_gpu",
    "unbounded_vs_bounded_kidnap",
    "densest_gate_vs_before_gpu",
    "densest_gate_vs_before_kidnap",
    "densest_gate_vs_before_cpu",
    "densest_gate_vs_before_cpu_kidnap",
    "candidates_vs_before_gpu",
    "candidates_vs_before_kidnap",
    "candidates_vs_before_cpu",
    "candidates_vs_before_cpu_kidnap",
    "candidates_vs_off_tuning_kidnap",
    "calibration_mixed_vs_shipped_test_clean",  # the confidence fitted on clean and cluttered tuning floors, kidnapped
    "calibration_mixed_vs_shipped_test_unmapped03",  # and not, against the one fitted on the clean drives alone
    "calibration_mixed_vs_shipped_test_clean_kidnap",
    "calibration_mixed_vs_shipped_test_unmapped03_kidnap",
)  # results/checks/paired_worlds_<name>.json


def _paired_worlds(results=RESULTS) -> dict[str, dict[str, str]]:
    """The kept drive-by-drive comparisons of two worlds runs (eval.analyses.paired_worlds): per outcome "a/n against
    b/n (McNemar exact p = ...)", and each side's particles per update."""
    import json

    out = {}
    for name in PAIRED_WORLDS:
        path = results / "checks" / f"paired_worlds_{name}.json"
        if not path.is_file():
            continue
        d, facts = json.loads(path.read_text()), {}
        n = d["drives"]
        for key, o in d["outcomes"].items():
            of = o.get("of", n)  # (kidnapped runs' detection and re-convergence: the drives right before it in both)
            facts[key] = f"{o['a']}/{of} against {o['b']}/{of} (McNemar exact p = {o['p_mcnemar']:.2g})"
            for side in ("a", "b"):  # the drives only one side got right, by name
                facts[f"{key}_only_{side}"] = ", ".join(o[f"only_{side}"]) or "none"
        for side in ("a", "b"):
            facts[f"per_update_{side}"] = f"{d[f'particles_per_update_{side}'] / 1000:.1f}k"
        if "auroc" in d:  # comparisons made from the runs' folders: the AUROCs and their difference's interval
            au = d["auroc"]
            facts["auroc"] = (
                f"{au['a']:.3f} against {au['b']:.3f} (difference {au['difference']:+.3f}, 95 % over drive resamples "
                f"{au['ci95'][0]:+.3f} to {au['ci95'][1]:+.3f})"
            )
        if "false_alarms" in d:  # comparisons since the twenty-eighth session: the false alarms' rates
            fa = d["false_alarms"]
            facts["false_alarms"] = (
                f"{fa['a']} in {fa['hours_a']:.2f} h against {fa['b']} in {fa['hours_b']:.2f} h of right tracking "
                f"(exact test of two Poisson rates p = {fa['p_rates']:.2g})"
            )
        out[name] = facts
    return out


def _kidnap_evidence(results=RESULTS) -> dict[str, str]:
    """The kept ``eval.analyses.kidnaps --evidence`` readings (results/checks/kidnaps_evidence_<name>.json): the
    kidnappings that met the issue's windows, the misses whose window of scans fit the wrong place as well as the
    truth, and the share a localizer reading only the scans could be sure of (every kidnapping but those)."""
    out = {}
    for path in sorted((Path(results) / "checks").glob("kidnaps_evidence_*.json")):
        name, rec = path.stem[len("kidnaps_evidence_") :], json.loads(path.read_text())
        n, ev = rec["kidnaps"], rec["evidence"]
        alike = ev["misses_read"] - ev["scans_could_tell"]
        out[f"kidnaps_evidence_{name}_met"] = f"{rec['classes'].get('met', 0)}/{n}"
        out[f"kidnaps_evidence_{name}_alike"] = f"{alike} of the {ev['misses_read']}"
        names = [d["drive"] for d in rec["drives"] if "scans_tell" in d and not d["scans_tell"]]
        out[f"kidnaps_evidence_{name}_alike_drives"] = ", ".join(names) or "none"
        out[f"kidnaps_evidence_{name}_bound"] = f"{n - alike}/{n} ({100 * (n - alike) / n:.0f} %)"
    return out


def _alarms_reference_fit(results=RESULTS) -> dict[str, str]:
    """Where a real log's false alarms fall (eval.analyses.reference_fit's alarms): how many, and the largest share of
    the log's scans that the SLAM pose fits worse than it fits the scans before any of them."""
    out = {}
    for path in sorted((Path(results) / "checks").glob("alarms_reference_fit_*.json")):
        rec, name = json.loads(path.read_text()), path.stem[len("alarms_reference_fit_") :]
        events = [e for run in rec["false_alarms"].values() for e in run]
        if not events:
            continue
        out[f"alarms_{name}_count"] = str(len(events))
        out[f"alarms_{name}_reference_worst_share"] = f"{100 * max(e['reference_share_below'] for e in events):.1f} %"
        out[f"alarms_{name}_reference_fit"] = (
            f"{min(e['lowest_at_reference'] for e in events):.2f}-{max(e['lowest_at_reference'] for e in events):.2f}"
        )
        out[f"alarms_{name}_reference_median"] = f"{rec['reference_agreement']['quantiles']['50']:.3f}"
        out[f"alarms_{name}_window"] = f"{rec['alarm_window_s']:g} s"
    return out


def _yaw_of(log: str, weighting: str | None) -> float | None:
    """Heading RMSE of the authors' code (``weighting`` None) or of ours with their motion model on ``log``."""
    if weighting is None:
        found = [
            r
            for r in find("reference_irmcl", log, among=checks("irmcl_reference"), localize__mode="tracking")
            if r.draw == 0
        ]
    else:
        study = "fr079_yaw" if log == "fr079" else "irmcl_reference"
        found = [
            r
            for r in find(
                "localize", log, among=checks(study), mcl__weighting=weighting, mcl__motion="irmcl", mcl__sigma_m=0.5
            )
            if r.artifacts
        ]
    return found[0]["summary"]["yaw_rmse_deg_mean"] if found else None


def _nof_mae(nof: dict, exp: str, preset: str, method: str = "NOF") -> str | None:
    syn = nof.get((exp, preset), (None, None))[0]
    m = next((v for k, v in syn["methods"].items() if k.startswith(method)), None) if syn else None
    return f"{m['mae_m']:.3f} m" if m else None


def _localized(pipe: list, exp: str) -> str | None:
    """Of an experiment's pipeline runs (its second drives), how many localized: "k/n"."""
    scored = [r.get("localization") for r in pipe if r.exp == exp and r.get("localization")]
    return f"{sum(lo['success'] for lo in scored)}/{len(scored)}" if scored else None


def facts(slam: list, released: dict, nof: dict, pipe: list = (), verdicts: list = ()) -> dict[str, str]:
    out = {}
    for key, value in (
        ("nof_paper_intel_mae", _nof_mae(nof, "intel", "paper")),
        ("grid5_intel_mae", _nof_mae(nof, "intel", "paper", "OGM 5 cm")),
        ("pipeline_sim_office_localized", _localized(pipe, "pipeline_sim_office")),
        ("pipeline_sim_office_30k_localized", _localized(pipe, "pipeline_sim_office_30k")),
    ):
        if value is not None:
            out[key] = value
    counted = [v.verdict for _, v in verdicts]
    for name, verdict in (
        ("reproduced", "reproduced"),
        ("partly", "partly"),
        ("not_reproduced", "not reproduced"),
        ("not_testable", "not testable here"),
        ("not_run", "not run"),
    ):
        if counted:
            out[f"claims_{name}"] = str(counted.count(verdict))

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
        count(f"{ds}_code_rot2x", slam_errors(slam, ds, "gmapping_code", variant=ROT2X))
        error(f"{ds}_code_error", code)
        error(f"{ds}_paper_error", paper)
        rel = released_errors(released, ds)
        count(f"{ds}_released", rel)
        error(f"{ds}_released_error", rel)
    count("fr079_code_60p", slam_errors(slam, "fr079", "gmapping_code", particles=60))
    count("fr079_code_laserframe", slam_errors(slam, "fr079", "gmapping_code", variant=LASER_FRAME))
    count("fr079_paper_laserframe", slam_errors(slam, "fr079", "paper", variant=LASER_FRAME))
    for proposal, short in (("gmapping_code", "code"), ("paper", "paper")):  # MIT Killian, the paper's 60 particles
        count(f"killian_{short}_60p", slam_errors(slam, "mit_killian", proposal, particles=60))
        error(f"killian_{short}_60p_error", slam_errors(slam, "mit_killian", proposal, particles=60))
    count("killian_paper_30p", slam_errors(slam, "mit_killian", "paper", particles=30))
    count(
        "killian_released_60p",
        released_errors(released, "mit_killian", particles=60, variant="delta=0.1, particles=60"),
    )
    error(
        "killian_released_60p_error",
        released_errors(released, "mit_killian", particles=60, variant="delta=0.1, particles=60"),
    )
    processed = sorted({m["processed_scans"] for m in released.values() if m.get("dataset") == "intel"})
    if processed:
        out["intel_released_processed"] = "/".join(str(p) for p in processed)
    ours = sorted(
        {
            r["processed_scans"]
            for r in slam
            if r.get("dataset") == "intel"
            and r.get("proposal") == "gmapping_code"
            and r.get("particles") == 30
            and not slam_variant(r)
        }
    )
    if ours:
        out["intel_code_processed"] = "/".join(str(p) for p in ours)
    count("fr079_released_gfs_noise", released_errors(released, "fr079", variant="srt=0.1, stt=0.1"))
    # the released code's own CARMEN tool (gfs_nogui) at its defaults, and ours on the same inputs
    count("fr079_released_gfs", released_errors(released, "fr079", variant="gfs"))
    error("fr079_released_gfs_error", released_errors(released, "fr079", variant="gfs"))
    for p in ("gmapping_code", "paper"):
        count(
            f"fr079_{'code' if p == 'gmapping_code' else p}_gfs_inputs",
            slam_errors(slam, "fr079", p, variant=GFS_INPUTS),
        )
    for ds in ("fr079", "intel"):  # the authors' MCL with our field beside our likelihood field (pose tracking)
        for name, weighting in ((f"irmcl_theirs_yaw_{ds}", None), (f"irmcl_lf_yaw_{ds}", "likelihood_field")):
            value = _yaw_of(ds, weighting)
            if value is not None:
                out[name] = f"{value:.2f} deg"
    theirs = find("reference_irmcl_nof", "fr079", among=checks("irmcl_reference"))
    if theirs:  # the authors' training script on our split
        out["nof_theirs_mae"] = f"{theirs[0]['their_eval']['mae_m']:.3f} m"
        out["nof_theirs_epochs"] = str(len(theirs[0].get("their_val_per_epoch") or []))
    for ds in ("fr079", "intel"):  # the one-minute preset's kept seeds
        for key, value in _minute_spans(nof, ds).items():
            out[f"nof_minute_{ds}_{key}"] = value
        for key, value in _minute_spans(nof, ds, fixed=True).items():
            out[f"nof_compiled_{ds}_{key}"] = value
        for card, spans in _graph_spans(nof, ds).items():
            for key, value in spans.items():
                out[f"nof_graph_{ds}_{card}_{key}"] = value
    unmapped = RESULTS / "checks" / "worlds_unmapped_test.json"  # eval.analyses.unmapped: drives off their map
    if unmapped.is_file():
        import json

        u = json.loads(unmapped.read_text())
        n = len(u["shares"]["random"]) * u["runs"]
        for how, names in u["leaving"].items():
            out[f"worlds_unmapped_{how}_count"] = f"{len(names)} of the {n} test drives"
            out[f"worlds_unmapped_{how}_drives"] = ", ".join(names) or "none"
    import json

    for path in sorted((RESULTS / "checks").glob("worlds_twins_*.json")):  # eval.analyses.twins
        name = path.stem[len("worlds_twins_") :]
        rows = json.loads(path.read_text())["drives"]
        against = [f"{r['world']}-run{r['run']}" for r in rows if r["evidence"] <= 0]
        out[f"worlds_twins_{name}_against"] = f"{len(against)} of the {len(rows)} twin-floor drives" + (
            f" ({', '.join(against)})" if against else ""
        )
        wrong = [r for r in rows if not r["right_at_end"]]
        out[f"worlds_twins_{name}_wrong_against"] = f"{sum(r['evidence'] <= 0 for r in wrong)} of the {len(wrong)}"
    out.update(_kidnap_evidence())
    out.update(_alarms_reference_fit())
    # the calibration fitted among objects against the one fitted on clean drives, on real logs, poses unchanged:
    # calibration_mixed_real_logs.json at 20k, calibration_mixed_100k_real_logs.json at 100k
    for real in sorted((RESULTS / "checks").glob("calibration_mixed*_real_logs.json")):
        count = real.stem[len("calibration_mixed") : -len("_real_logs")]  # "" or "_100k"
        for log, sides in json.loads(real.read_text())["logs"].items():
            new, old = sides["mixed"]["confidence"]["auroc"], sides["shipped"]["confidence"]["auroc"]
            out[f"calibration_mixed{count}_{log}_auroc"] = f"{new:.3f} against {old:.3f}"
            a, b = sides["mixed"]["false_alarms"], sides["shipped"]["false_alarms"]
            p = rates_exact(a["false"], a["hours_right"], b["false"], b["hours_right"])
            out[f"calibration_mixed{count}_{log}_false_alarms"] = (
                f"{a['false']} against {b['false']} in {a['hours_right']:.2f} h of right tracking "
                f"({a['per_hour_right']:.1f} against {b['per_hour_right']:.1f} an hour; exact test of two Poisson "
                f"rates p = {p:.2g})"
            )
            out[f"calibration_mixed{count}_{log}_successes"] = f"{sides['mixed']['successes']}/{sides['mixed']['of']}"
            wrong = sides["shipped"]["confidence"]["above_threshold_when_wrong"]
            out[f"calibration_mixed{count}_{log}_confident_when_wrong"] = f"{100 * wrong:.0f} %"
    for name, paired in _paired_worlds().items():  # KLD-sampling against the fixed count, drive by drive
        for key, value in paired.items():
            out[f"worlds_{name}_{key}"] = value
    out["reference_fit_below"], out["reference_fit_at_least"] = "0.8", "0.9"  # the thresholds the prose quotes
    for path in sorted((RESULTS / "checks").glob("reference_fit_*.json")):  # eval.analyses.reference_fit
        name, rec = path.stem[len("reference_fit_") :], json.loads(path.read_text())
        out[f"reference_fit_{name}_below_08"] = f"{100 * rec['reference_agreement']['below_0.8']:.1f} %"
        wrong = rec["wrong_scans"]
        out[f"reference_fit_{name}_wrong"] = f"{wrong['scans']:,}"
        out[f"reference_fit_{name}_estimate_better"] = f"{100 * wrong['estimate_fits_better']:.0f} %"
        out[f"reference_fit_{name}_reference_better"] = f"{100 * wrong['reference_fits_better']:.0f} %"
        for row in rec["auroc_where_reference_fits"]:
            t = row["reference_agreement_at_least"]
            out[f"reference_fit_{name}_auroc_at_{round(10 * t):02d}"] = (
                "-" if row["auroc"] is None else f"{row['auroc']:.3f}"
            )
    out.update(_scan_lag("mit_csail"))
    out.update(_scan_lag("fr079"))
    out.update(_scan_lag("mit_killian"))
    for log in ("fr079", "mit_csail"):
        out.update(_scan_lag_tracking(log))
    out.update(_killian_maps())
    heading = {r.setting("slam.seed"): r for r in checks("gmapping_fr079_cpu_headings")}
    for seed, r in heading.items():  # the 2-core CPU's fr079 runs whose headings were compared
        out[f"fr079_cpu_seed{seed}_error"] = f"{r['relations']['trans_abs_mean_m']:.3f} m"
    return out


def _lag_study(study: str) -> tuple[list, float | None]:
    """(the records of the check study ``study``, the one ``data.scan_time_offset_s`` they were run at besides 0), or
    the lag None where the study is missing or holds another set of settings."""
    runs = checks(study)
    lags = sorted({r.setting("data.scan_time_offset_s", 0.0) for r in runs})
    if len(lags) != 2 or 0.0 not in lags:
        return runs, None
    return runs, [x for x in lags if x != 0.0][0]


def _scan_lag(log: str) -> dict[str, str]:
    """The check study ``scan_lag_<log>``: GMapping (30 seeds) and the localizer in its own SLAM map (10 seeds), each
    scan's odometry read at its stamp and at its stamp plus the lag the ground truth names (``data.scan_time_offset_s``).
    SLAM: the seeds that converged (relations error below CONVERGED_M; Fisher's exact test) and, over them, the
    relations error; the localizer: its heading and position against the ground truth's keyframes. Each a median
    [min-max], the lag's first, with the Mann-Whitney p of the two sets."""
    from eval.results.claims import fisher, mann_whitney
    from eval.results.queries import CONVERGED_M

    runs, lag = _lag_study(f"scan_lag_{log}")
    if lag is None:
        return {}
    out = {f"scan_lag_{log}_s": f"{-lag:.3f} s"}

    def of(stage, x):
        return [r for r in runs if r.stage == stage and r.setting("data.scan_time_offset_s", 0.0) == x]

    slam = [of("slam", x) for x in (lag, 0.0)]
    if all(slam):
        ok = [[r for r in s if r["relations"]["trans_abs_mean_m"] < CONVERGED_M] for s in slam]
        (ka, na), (kb, nb) = ((len(k), len(s)) for k, s in zip(ok, slam))
        out[f"scan_lag_{log}_slam_converged"] = (
            f"{ka}/{na} against {kb}/{nb} (Fisher's exact p = {fisher(ka, na, kb, nb):.2g})"
        )
        slam = ok
    measures = (
        ("slam", "rot", lambda r: r["relations"]["rot_abs_mean_deg"], "{:.2f}", "deg"),
        ("slam", "trans", lambda r: r["relations"]["trans_abs_mean_m"], "{:.3f}", "m"),
        ("localize", "yaw", lambda r: r["aligned_to_ground_truth"]["yaw_mae_deg"], "{:.2f}", "deg"),
        ("localize", "ate", lambda r: r["aligned_to_ground_truth"]["ate_rmse_m"], "{:.3f}", "m"),
    )
    for stage, name, value, fmt, unit in measures:
        sets = [[value(r) for r in s] for s in (slam if stage == "slam" else [of(stage, x) for x in (lag, 0.0)])]
        if not all(sets):
            continue
        spans = [f"{fmt.format(np.median(v))} [{fmt.format(min(v))}-{fmt.format(max(v))}] {unit}" for v in sets]
        out[f"scan_lag_{log}_{stage}_{name}"] = (
            f"{spans[0]} against {spans[1]} over {len(sets[0])} and {len(sets[1])} seeds "
            f"(Mann-Whitney p = {mann_whitney(*sets):.2g})"
        )
    return out


def _scan_lag_tracking(log: str) -> dict[str, str]:
    """The check study ``scan_lag_<log>_tracking``: the benchmark protocol's tracking runs (10 starts each) with each
    scan's odometry read at its stamp and at the lag: per run the median over its starts of the heading RMSE, then
    a median [min-max] over the runs of each setting, the lag's first, with the Mann-Whitney p."""
    from eval.results.claims import mann_whitney

    runs, lag = _lag_study(f"scan_lag_{log}_tracking")
    if lag is None:
        return {}
    sets = [
        [
            float(np.median([s["yaw_rmse_deg"] for s in r["runs"]]))
            for r in runs
            if r.setting("data.scan_time_offset_s", 0.0) == x
        ]
        for x in (lag, 0.0)
    ]
    spans = [f"{np.median(v):.2f} [{min(v):.2f}-{max(v):.2f}] deg" for v in sets]
    return {
        f"scan_lag_{log}_tracking_yaw": f"{spans[0]} against {spans[1]} over {len(sets[0])} and {len(sets[1])} seeds "
        f"(Mann-Whitney p = {mann_whitney(*sets):.2g})"
    }


def _killian_maps() -> dict[str, str]:
    """The check ``own_slam_map_mit_killian_20k_maps``: the same 20k own-map runs (5 seeds) in several GMapping maps of
    MIT Killian, each map's relations error read from the SLAM study ``scan_lag_mit_killian`` (the same seed and
    setting). Successes per map, the README's map (seed 6, no lag) apart."""
    path = RESULTS / "checks" / "own_slam_map_mit_killian_20k_maps.json"
    if not path.exists():
        return {}
    relations = {
        (r.setting("data.scan_time_offset_s", 0.0), r.setting("slam.seed")): r["relations"]["trans_abs_mean_m"]
        for r in checks("scan_lag_mit_killian")
    }
    from eval.analyses.own_slam_map import false_alarm_rate

    maps = []  # (offset, SLAM seed, record) from the keys "off<offset>-seed<seed>"
    for key, rec in json.loads(path.read_text())["maps"].items():
        m = re.fullmatch(r"off(?P<off>-?[0-9.]+)-seed(?P<seed>\d+)", key)
        maps.append((float(m["off"]), int(m["seed"]), rec))
    others, rows_map = [], None
    for off, seed, rec in maps:
        entry = (rec["successes"], rec["of"], relations[(off, seed)])
        if (off, seed) == (0.0, 6):
            rows_map = entry
        else:
            others.append(entry)
    others.sort()
    errs = [e[2] for e in others]
    failed = [r for _, _, rec in maps for r in rec["runs"] if not r["success"]]
    never = [r for r in failed if r["time_to_converge_s"] is None]
    off_share = [1 - r["scans_judged_right"] / r["scans_judged"] for r in failed if r["time_to_converge_s"] is not None]
    # the lag as a setting: every map of each setting, session 33's seed-6 map of the lag included
    runs_at = {}
    extra = json.loads((RESULTS / "checks" / "own_slam_map_mit_killian_20k_stamps_lag.json").read_text())
    for off, rec in [(off, rec) for off, _, rec in maps] + [(extra["runs"][0]["scan_time_offset_s"], extra)]:
        runs_at.setdefault(off, []).extend(rec["runs"])
    count = {off: (sum(r["success"] for r in runs), len(runs), false_alarm_rate(runs)) for off, runs in runs_at.items()}
    lag, at = count[min(count)], count[0.0]  # (the lag is negative: the scans read late)
    return {
        "killian_lag_successes": f"{lag[0]}/{lag[1]} against {at[0]}/{at[1]}",
        "killian_lag_false_alarms": f"{lag[2]['false']} times in {lag[2]['hours_right']:.1f} h of right tracking "
        f"against {at[2]['false']} in {at[2]['hours_right']:.1f} h",
        "killian_maps_failed": str(len(failed)),
        "killian_maps_never_right": str(len(never)),
        "killian_maps_off_a_stretch": str(len(off_share)),
        "killian_maps_off_share": f"{100 * min(off_share):.0f}-{100 * max(off_share):.0f} %" if off_share else "-",
        "killian_maps_count": str(len(others)),
        "killian_maps_relations": f"{min(errs):.3f}-{max(errs):.3f} m",
        "killian_maps_successes": ", ".join(f"{k}/{n}" for k, n, _ in others),
        "killian_maps_pooled": f"{sum(e[0] for e in others)}/{sum(e[1] for e in others)}",
        "killian_rows_map": f"{rows_map[0]}/{rows_map[1]}" if rows_map else "-",
        "killian_rows_map_relations": f"{rows_map[2]:.3f} m" if rows_map else "-",
    }


FACT = re.compile(r"<!-- fact:([a-z0-9_]+) -->(.*?)<!-- /fact -->", re.S)


def readme_facts(text: str) -> dict[str, str]:
    return {name: value for name, value in FACT.findall(text)}


def write_facts(text: str, values: dict[str, str]) -> str:
    """``text`` with every fact it quotes set to its value; a quoted fact the results cannot give is an error."""
    missing = sorted(set(readme_facts(text)) - set(values))
    if missing:
        raise SystemExit(f"README.md quotes facts the results do not give: {missing}")
    return FACT.sub(lambda m: f"<!-- fact:{m.group(1)} -->{values[m.group(1)]}<!-- /fact -->", text)
