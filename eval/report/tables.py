"""The README's tables, each built from run records (eval/results): which records a table takes is decided
by their settings (``localize_cell``, ``slam_variant``, ``off_defaults``), never by a folder's name.
``python -m eval.tables`` prints them and writes them into README.md (eval/tables.py)."""

from __future__ import annotations

import re
from collections import Counter


import numpy as np

from eval.results.queries import (
    CONVERGED_M,
    DATASET_ORDER,
    GLOBLOC_METHODS,
    converged,
    localize_cell,
    median_span,
    reference_variant,
    released_errors,
    slam_errors,
    slam_variant,
)  # noqa: F401
from eval.results.records import describe, exp_defaults, off_defaults
from irmcl_warp.config import GlobLocConfig
from irmcl_warp.services.metrics import FULL_COVERAGE

# GMapping references. The released code's rows come from runs this project repeats (python -m
# eval.reference.gmapping, kept in results/slam/reference/); the published figures are cited facts (relations
# metric, mean translational error): Kümmerle et al. 2009 (Auton. Robots 27(4)) / the Cartographer paper (Hess
# et al. ICRA 2016).
SLAM_REFERENCES = {
    "intel": [
        ("published GMapping (Kümmerle et al. 2009)", "", "0.070", ""),
        ("published Cartographer (Hess et al. 2016)", "", "0.0229", ""),
    ],
    "fr079": [
        ("published GMapping (Kümmerle et al. 2009)", "", "0.061", ""),
        ("published Cartographer (Hess et al. 2016)", "", "0.0452", ""),
    ],
    "mit_csail": [
        ("published GMapping (Kümmerle et al. 2009)", "", "0.049", ""),
        ("published Cartographer (Hess et al. 2016)", "", "0.0319", ""),
    ],
}
METHODS = {
    "nog_raymarch": "IR-MCL (NOG)",
    "nog_table": "IR-MCL (NOG, range table)",
    "nof_direct": "IR-MCL (NOF, no grid)",
    "likelihood_field": "likelihood field",
    "beam_model": "beam model",
}


def _order(key):
    syn = key[1]
    ds = syn["dataset"]
    return (DATASET_ORDER.index(ds) if ds in DATASET_ORDER else 99, ds, syn["split"])


SEEDED = re.compile(r"^(?P<base>.+)_s\d+$")  # a kept NOF run's name with its seed: <recipe>_s<seed>
FIELDS = (
    ("mae_m", ".3f"),
    ("median_error_m", ".3f"),
    ("accuracy_pct", ".1f"),
    ("chamfer_m", ".3f"),
    ("fscore_pct", ".1f"),
)


def _recipes(presets: set) -> dict[str, str]:
    """The recipe each kept NOF run belongs to: its name without a trailing ``_s<seed>`` when that leaves a name
    another run carries or more than one run shares (``h_g_s1``, ``h_g_s42`` -> ``h_g``; ``sg64_e5_s1`` ->
    ``sg64_e5``, the seed-42 run's own name); otherwise the name itself."""
    bases = {p: m.group("base") for p in presets if (m := SEEDED.match(p))}
    shared = Counter(bases.values())
    return {p: bases[p] if p in bases and (bases[p] in presets or shared[bases[p]] > 1) else p for p in presets}


def _span(values, spec: str) -> str:
    """The value, or of several runs' values the median with [min-max] (``median_span``)."""
    return f"{values[0]:{spec}}" if len(values) == 1 else median_span(values, spec)


def synthesis_table(runs: dict) -> str:
    """IR-MCL Table I style: one row per method and (dataset, test split); grids once per test split. The seeds of
    one NOF recipe (``<name>_s<seed>``, on one card, with as many epochs) make one row: the median of each figure
    with [min-max], and the number of seeds; times from two cards are never pooled."""
    rows, seen_grids, groups = [], set(), {}
    recipe = _recipes({preset for _, preset in runs})
    for (exp, preset), (syn, train) in sorted(runs.items(), key=lambda kv: (_order((kv[0], kv[1][0])), kv[0][1])):
        for name, m in syn["methods"].items():
            if m["kind"] == "grid":
                if (syn["dataset"], syn["split"], name) in seen_grids:
                    continue
                seen_grids.add((syn["dataset"], syn["split"], name))
                rows.append((syn["dataset"], syn["split"], name, [m], "-"))
                continue
            card = (train.get("gpu") or train["device"]) if train else None
            key = (syn["dataset"], syn["split"], recipe[preset], card, train["epochs_done"] if train else None)
            groups.setdefault(key, []).append((preset, m, train))
    for (ds, split, name, card, epochs), members in groups.items():
        presets, methods, trains = zip(*members)
        # one run: the folder's name (preset, and the renderer when not Warp); several: the recipe and its seeds
        name = f"NOF ({presets[0]})" if len(members) == 1 else f"NOF ({name}, {len(members)} seeds)"
        secs = [t["train_time_s"] for t in trains if t]
        how = f"{_span(secs, '.0f')} s, {epochs} ep, {card}" if secs else "?"
        rows.append((ds, split, name, methods, how))
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    rows.sort(key=lambda r: (ds_rank.get(r[0], 99), r[0], r[1], r[2].startswith("OGM"), r[2]))
    lines = [
        "| dataset | test split | method | MAE (m) | median (m) | accuracy (%) | Chamfer (m) | F-score (%) | training |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for ds, split, name, methods, how in rows:
        cells = " | ".join(_span([m[k] for m in methods], spec) for k, spec in FIELDS)
        lines.append(f"| {ds} | {split} | {name} | {cells} | {how} |")
    return "\n".join(lines)


def _f(v, fmt="{:.1f}"):
    return "-" if v is None else fmt.format(v)


def localization_table(runs: list) -> str:
    """Per dataset and map: global localization and pose tracking side by side (means over the starts that
    succeeded; the starts are seeded and spread over the sequence). Where a cell was run with several
    particle counts, the largest is shown (the paper's setting; smaller ones are quick checks)."""
    cells = {}
    for m in runs:
        t = localize_cell(m)
        if t["extra"]:
            continue  # kidnapping runs (kidnap_table) and ablations (ablation_table)
        key = (m["dataset"], t["weighting"], float(t["res"]), t["mode"])
        if key not in cells or m["summary"]["num_particles"] >= cells[key]["num_particles"]:
            cells[key] = m["summary"]
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    w_rank = {w: i for i, w in enumerate(METHODS)}
    keys = sorted({k[:3] for k in cells}, key=lambda k: (ds_rank.get(k[0], 99), k[0], w_rank.get(k[1], 99), k[2]))
    lines = [
        "| dataset | method | map | global: particles | success | converged after (s) | RMSE (cm / deg) | "
        "within 10 cm / 1 deg (%) | tracking: particles | success | RMSE (cm / deg) | diverged |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for ds, w, res in keys:
        g, tr = cells.get((ds, w, res, "global")), cells.get((ds, w, res, "tracking"))
        row = [ds, METHODS.get(w, w), f"{res:g} cm"]
        for s_, full in ((g, True), (tr, False)):
            if s_ is None:
                row += ["-"] * (5 if full else 4)
                continue
            row += [f"{s_['num_particles'] // 1000}k", f"{s_['successes']}/{s_['starts']}"]
            if full:
                row.append(_f(s_["time_to_converge_s_mean"]))
            row.append(f"{_f(s_['location_rmse_cm_mean'])} / {_f(s_['yaw_rmse_deg_mean'], '{:.2f}')}")
            if full:
                row.append(f"{_f(s_['within_10cm_pct_mean'], '{:.0f}')} / {_f(s_['within_1deg_pct_mean'], '{:.0f}')}")
            else:
                row.append(str(s_["divergences"]))
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


ABLATION_NAMES = {
    "mcl.weighting": "likelihood",
    "mcl.map_resolution_m": "NOG / grid resolution (m)",
    "mcl.num_beams": "beams",
    "mcl.t_min": "early termination (transmittance floor)",
    "mcl.empty_below": "empty-space skipping (p_occ floor)",
    "mcl.resample": "resampling",
}


ABLATION_BASE = "nog_raymarch"  # the ablations are of the paper's march; the package's default reads it from a table


def _off_the_march(m) -> dict:
    """The settings of ``m`` off the defaults, with the march (not the default range table) as the baseline's
    weighting: a run of the march at the defaults is the ablations' baseline, a run of the table an ablation."""
    diff = off_defaults(m, ("mcl", "localize"), ignore=("mcl.weighting",))
    weighting = m.setting("mcl.weighting")
    return diff if weighting == ABLATION_BASE else {"mcl.weighting": weighting, **diff}


def ablation_table(runs: list) -> str:
    """IR-MCL's global localization by the paper's march (the defaults otherwise: 100k particles, NOG 5 cm, 32
    beams, early termination, low-variance resampling) and every run that changes exactly one of the settings
    ABLATION_NAMES lists, per dataset. Time: the median over the starts of the filter's wall time per scan (the
    first start of a process also compiles kernels)."""
    rows = []
    for m in runs:
        if "ms_per_scan" not in m["runs"][0]:
            continue  # runs from before the timing was recorded
        diff = _off_the_march(m)
        if len(diff) > 1 or (diff and next(iter(diff)) not in ABLATION_NAMES):
            continue
        s = m["summary"]
        key = next(iter(diff), None)
        what, value = (ABLATION_NAMES[key], diff[key]) if key else ("(IR-MCL's settings)", "")
        if key == "mcl.num_beams" and value >= 360:
            value = "all"
        rows.append(
            (
                (
                    DATASET_ORDER.index(m["dataset"]) if m["dataset"] in DATASET_ORDER else 99,
                    bool(diff),
                    what,
                    str(value),
                ),
                f"| {m['dataset']} | {what} | {METHODS.get(value, value)} | {s['successes']}/{s['starts']} | "
                f"{_f(s['time_to_converge_s_mean'])} | {_f(s['location_rmse_cm_mean'])} / "
                f"{_f(s['yaw_rmse_deg_mean'], '{:.2f}')} | {_f(float(np.median([r['ms_per_scan'] for r in m['runs']])), '{:.2f}')} | "
                f"{'H100' if str(s['device']).startswith('cuda') else s['device']} |",
            )
        )
    head = [
        "| dataset | ablation | setting | success | converged after (s) | RMSE (cm / deg) | ms per scan | device |",
        "|---|---|---|---|---|---|---|---|",
    ]
    return "\n".join(head + [r for _, r in sorted(rows)])


def kidnap_table(runs: list) -> str:
    lines = [
        "| dataset | method | map | particles | kidnapped at (s) | recovery rates (slow / fast) | recovered | "
        "recovery time (s) | divergences |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for m in runs:
        t, s_ = localize_cell(m), m["summary"]
        if "recovered" not in s_:
            continue
        st = m.get("settings", {})
        rates = f"{st.get('recovery_alpha_slow', '?')} / {st.get('recovery_alpha_fast', '?')}"
        rows.append(
            (
                DATASET_ORDER.index(m["dataset"]) if m["dataset"] in DATASET_ORDER else 99,
                f"| {m['dataset']} | {METHODS.get(t['weighting'], t['weighting'])} | {t['res']} cm | {s_['num_particles'] // 1000}k | "
                f"{s_['kidnap_at_s']:g} | {rates} | {s_['recovered']}/{s_['starts']} | "
                f"{_f(s_['recovery_time_s_mean'])} | {s_['divergences']} |",
            )
        )
    return "\n".join(lines + [r for _, r in sorted(rows)])


def slam_rows(ds: str, label: str, particles, rows: list, device: str) -> str:
    """A table row over seeds: converged count, error of the converged runs, mean of all runs, wall time."""
    t = np.array([r["relations"]["trans_abs_mean_m"] for r in rows])
    t_std = np.array([r["relations"]["trans_abs_std_m"] for r in rows])
    rot = np.array([r["relations"]["rot_abs_mean_deg"] for r in rows])
    ok = t < CONVERGED_M
    wall = np.array([r["wall_time_s"] for r in rows])
    if not ok.any():
        return (
            f"| {ds} | {label} | {particles} | 0/{len(rows)} | - | - | {t.mean():.3f} | "
            f"{wall.min():.0f}-{wall.max():.0f} s | {device} |"
        )
    return (
        f"| {ds} | {label} | {particles} | {ok.sum()}/{len(rows)} | {t[ok].mean():.3f} +- {t_std[ok].mean():.3f} | "
        f"{rot[ok].mean():.2f} | {t.mean():.3f} | {wall.min():.0f}-{wall.max():.0f} s | {device} |"
    )


def slam_table(runs: list, reference: dict | None = None) -> str:
    """Per dataset and filter variant, over seeds: how many converged (relations error < CONVERGED_M), the
    error of the converged runs (their mean and std over the relations, averaged over those runs: the
    reference's convention), the mean over all runs, and the wall time; the references below each dataset.
    Runs with settings off the defaults (slam_variant) follow the default ones, those settings in brackets."""

    groups = {}
    for m in runs:
        if not isinstance(m.get("relations"), dict):
            continue
        variant = describe(slam_variant(m))
        key = (m["dataset"], variant != "", m["proposal"], m["resample"], m["particles"], variant, m.get("device", "?"))
        groups.setdefault(key, []).append(m)
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    lines = [
        "| dataset | method | particles | converged seeds | error of converged runs (m, mean +- std over relations) | rot. (deg) | "
        "mean of all runs (m) | wall time per run | device |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for ds in sorted({k[0] for k in groups}, key=lambda d: (ds_rank.get(d, 99), d)):
        for key in sorted(k for k in groups if k[0] == ds):
            rows = groups[key]
            method = f"{key[2]} + {key[3]}" + (f" ({key[5]})" if key[5] else "")
            counts = min(
                (
                    (
                        r["relations"]["relations_used"],
                        r["relations"]["relations_used"] + r["relations"]["relations_unmatched"],
                    )
                    for r in rows
                ),
                key=lambda c: c[0] / max(c[1], 1),
            )
            if counts[0] < FULL_COVERAGE * counts[1]:  # never print a score on a part of the relations as the log's
                method += f" [scored on {counts[0]} of {counts[1]} relations]"
            dev = "H100" if str(key[6]).startswith("cuda") else key[6]
            lines.append(slam_rows(ds, method, key[4], rows, dev))
        released = {}
        for m in (reference or {}).values():
            if m["dataset"] == ds and isinstance(m.get("relations"), dict):
                released.setdefault((m["particles"], reference_variant(m)), []).append(m)
        for (particles, variant), rows in sorted(released.items()):
            label = "*released C++ (python -m eval.reference.gmapping" + (f"; {variant}" if variant else "") + ")*"
            hosts = sorted({r.get("host", "2-core CPU") for r in rows})  # runs before the field: the 2-core CPU
            lines.append(slam_rows(ds, label, particles, rows, ", ".join(hosts)))
        for name, conv, err, wall in SLAM_REFERENCES.get(ds, []):
            lines.append(
                f"| {ds} | *{name}* | {30 if conv else ''} | {conv} | {err} | | | {wall} | 2-core CPU |"
                if conv
                else f"| {ds} | *{name}* | | | | | {err} | | |"
            )
    return "\n".join(lines)


ROT2X = {"slam.srt": 0.4, "slam.stt": 0.4}  # slam=gmapping_rot2x: twice the released code's rotational noise


def released_table(runs: list, reference: dict) -> str:
    """Ours against the released C++ on the same logs, 30 particles, seeds 0-9: the released code's runs
    (eval.reference.gmapping, the ROS wrapper's settings) beside ours at the released settings (its proposal,
    ``gmapping_code``) and with twice its rotational odometry noise. Each cell: converged seeds, the mean error
    of the converged runs, and the mean of all runs."""

    def cell(errs):
        if not errs:
            return "not run"
        k, n, conv, mean = converged(errs)
        return f"{k}/{n}" + (f", {conv:.3f} m" if k else "") + f" (all runs {mean:.3f} m)"

    lines = [
        "| log | released C++ (ROS wrapper's settings) | ours, released settings (`gmapping_code`) | "
        "ours, `slam=gmapping_rot2x` |",
        "|---|---|---|---|",
    ]
    for ds in ("intel", "fr079", "mit_csail"):
        ours = [cell(slam_errors(runs, ds, "gmapping_code", variant=v)) for v in ({}, ROT2X)]
        lines.append(f"| {ds} | {cell(released_errors(reference, ds))} | {ours[0]} | {ours[1]} |")
    return "\n".join(lines)


def pipeline_table(runs: list) -> str:
    """One row per pipeline run (SLAM, NOF and global localization of the second log, time per stage), and
    for an experiment run over several second drives a row of their medians [min-max] (RMSE over the
    successful ones: converged and under IR-MCL's 0.3 m)."""
    lines = [
        "| run | device | SLAM: processed scans, ATE (odometry) | NOF: validation MAE | localized scans | "
        "converged after | RMSE (cm / deg) | time: slam / train / nog / localize (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    by_exp = {}
    for m in sorted(runs, key=lambda r: (r.exp, r.setting("pipeline.sim_path_seed", 0))):
        exp = m.exp
        by_exp.setdefault(exp, []).append(m)
        sl, nof, lo, t = m.get("slam", {}), m.get("nof", {}), m.get("localization"), m["timing"]
        took = " / ".join(
            "skipped" if t.get(k, {}).get("skipped") else _f(t.get(k, {}).get("s"), "{:.0f}")
            for k in ("slam", "train", "nog", "localize")
        )
        conv = (f"{lo['time_to_converge_s']:.1f} s" if lo["converged"] else "no") if lo else "no ground truth"
        rmse = f"{_f(lo['location_rmse_cm'])} / {_f(lo['yaw_rmse_deg'], '{:.2f}')}" if lo else "-"
        if lo and not lo["success"]:
            rmse += " (failed)"
        second_drive = m.setting("data.format") == "sim" and m.setting("pipeline.path") is None
        seed = m.setting("pipeline.sim_path_seed") if second_drive else None  # one of several second drives
        name = exp + (f" (path seed {seed})" if seed is not None else "")
        lines.append(
            f"| {name} | {_device(m['device'])} | {sl.get('processed_scans', '-')}, {_f(sl.get('ate_rmse_m'), '{:.3f}')} m "
            f"({_f(sl.get('odometry_ate_rmse_m'), '{:.2f}')} m) | {_f(nof.get('val_mae_m'), '{:.3f}')} m | "
            f"{m['localized_scans']} | {conv} | {rmse} | {took} |"
        )
    for exp, ms in by_exp.items():
        scored = [m["localization"] for m in ms if m.get("localization")]
        if len(ms) < 2 or not scored:
            continue
        ok = [lo for lo in scored if lo["success"]]

        def spread(values, fmt):
            v = [x for x in values if x is not None]
            return f"{fmt.format(np.median(v))} [{fmt.format(min(v))}-{fmt.format(max(v))}]" if v else "-"

        total = [sum(t["s"] for t in m["timing"].values()) for m in ms]
        lines.append(
            f"| **{exp}: median of {len(ms)} second drives** | {_device(ms[0]['device'])} | | | | "
            f"{len(ok)}/{len(scored)} succeeded; converged after "
            f"{spread([lo['time_to_converge_s'] for lo in ok], '{:.1f}')} s | "
            f"{spread([lo['location_rmse_cm'] for lo in ok], '{:.1f}')} cm | "
            f"time of the stages each run ran (finished ones are reused): {spread(total, '{:.0f}')} s |"
        )
    return "\n".join(lines)


def _device(d) -> str:
    return "H100" if str(d).startswith("cuda") else "2-core CPU" if d == "cpu" else str(d)


def globloc_table(runs: list) -> str:
    """One row per (experiment, scenario, method): success with its Wilson 95 % interval, time and distance
    until localized, kidnap recovery, false relocalizations per hour, accuracy after convergence."""
    rows = [
        "| world | scenario | method | localized | 95 % CI | time / distance to localize | recovered after kidnap "
        "(time) | kidnap detected | false relocalizations per hour | RMSE after convergence (cm) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for m in sorted(runs, key=lambda r: (r.exp, r.setting("globloc.scenario"))):
        exp = m.exp
        world = ("repetitive corridor" if m.get("repetitive") else "office") + f" ({exp})"
        confirm = m.get("settings", {}).get("trigger_confirm_frames", 1)  # runs before the setting existed: 1
        for method, v in m["methods"].items():
            sm = v["summary"]
            lo, hi = sm["success_ci95"]
            label = GLOBLOC_METHODS.get(method, method)
            if method == "paper" and confirm != GlobLocConfig.trigger_confirm_frames:
                label += f" ({confirm} confirming frame{'s' if confirm != 1 else ''})"
            ttl = (
                f"{_f(sm['mean_time_to_localize_s'])} s / {_f(sm['mean_distance_to_localize_m'])} m"
                if sm["mean_time_to_localize_s"] is not None
                else "-"
            )
            rec = f"{sm['recovered']}/{sm['runs']} ({_f(sm['mean_recovery_time_s'])} s)" if "recovered" in sm else ""
            det = f"{sm['detected']}/{sm['runs']}" if "detected" in sm and method == "paper" else ""
            rmse = _f(None if sm["mean_rmse_after_m"] is None else 100 * sm["mean_rmse_after_m"])
            rows.append(
                f"| {world} | {m['scenario']} | {label} | {sm['localized']}/{sm['runs']} "
                f"| {lo:.2f}-{hi:.2f} | {ttl} | {rec} | {det} | {sm['false_relocalizations_per_hour']:.1f} | {rmse} |"
            )
    return "\n".join(rows)


def worlds_table(runs: list) -> str:
    """Global localization on the held-out simulated floors (stage worlds): one row per kept run of the test split
    (observation model, particles, kidnapped or not), its counts over all runs and, per floor, how many runs
    ended right. Runs on the maps of a random mapping drive (before the twenty-sixth session: some test drives
    entered rooms those maps lacked) say so in their label, as do runs on maps with bounded log-odds (before the
    twenty-seventh: the beams grazing a wall cleared it) and runs that seed a rival place; from the twenty-eighth, runs
    that read a mode's pose at its densest cluster and gate the confidence's timeout by the scan's agreement."""
    rows = [
        "| floors | weighting | particles | device | kidnap | localized (protocol) | right at the end | ended "
        "confident | confidently wrong | AUROC | false alarms per hour | kidnap detected <= 2 s | re-converged "
        "<= 5 s | right at the end, per floor |",
        "|" + "---|" * 14,
    ]
    test = [r for r in runs if r.setting("worlds.split") == "test"]
    for r in sorted(
        test,
        key=lambda r: (r.setting("mcl.weighting"), r.setting("mcl.num_particles"), r.setting("worlds.kidnap_at_s")),
    ):
        s, n = r["summary"], r["summary"]["runs"]
        kid, k = r.setting("worlds.kidnap_at_s"), s.get("kidnaps")
        per = " · ".join(f"{w} {v['right_at_end']}/{v['runs']}" for w, v in r["per_world"].items())
        fa = s["false_alarms"] / s["tracking_right_h"] if s["tracking_right_h"] > 0 else None
        detected = f"{s['detected_within_2s']}/{k}" if k else "-"
        back = f"{s['reconverged_within_5s']}/{k}" if k else "-"
        agree = r.setting("worlds.lost_agreement_below") or 0  # (runs before the agreement trigger: none)
        random_map = (r.setting("worlds.map_drive") or "random") == "random"  # (runs before the setting: random)
        limit = r.setting("worlds.map_logodds_limit")  # (runs before the setting: 4.0, records.BEFORE)
        seed = r.setting("worlds.rival_seed_below") or 0  # (runs before rival seeding: none)
        gate = r.setting("worlds.lost_timeout_agreement_below")  # (runs before it: none)
        upd = r.setting("worlds.lost_agreement_updates") or 1
        places = r.setting("worlds.relocalize_places") or 0  # (runs before it: none)
        fitted = s.get("calibration") or ""  # "eval.confidence fit on <run>, <run>, ...": calibrations before the
        fitted_on = len(fitted.split(" on ", 1)[1].split(", ")) if " on " in fitted else 1  # 37th were one run's
        how = (
            ([f"map of a random {r.setting('worlds.map_drive_m') or 400:g} m drive"] if random_map else [])
            + ([f"map's log-odds within +-{limit:g}"] if limit is not None and not random_map else [])
            + (["rivals re-aligned"] if r.setting("worlds.refine_rivals") else [])
            + (
                [f"searched every {r.setting('worlds.search_rivals_every')} updates"]
                if r.setting("worlds.search_rivals_every")
                else []
            )
            + ([f"a rival {seed:g} better seeded"] if seed > 0 else [])
            + (
                [f"lost also at agreement < {agree:g}" + (f" for {upd} updates" if upd > 1 else "")]
                if agree > 0
                else []
            )
            + ([f"a relocalization also from {places} searched places"] if places else [])
            + (["keeping its particles"] if r.setting("worlds.relocalize_keeps_particles") else [])
            + ([f"timeout only at agreement < {gate:g}"] if gate is not None else [])
            + (["modes' densest poses"] if r.setting("worlds.mode_pose") == "densest" else [])
            + (
                [f"a global start's first update from {r.setting('mcl.global_candidates')}x candidates"]
                if (r.setting("mcl.global_candidates") or 1) > 1
                else []
            )
            + (["not relocalizing"] if r.setting("worlds.relocalize") is False else [])
            + ([f"confidence fitted on {fitted_on} tuning runs"] if fitted_on > 1 else [])
            + (
                [f"drives among {r.setting('worlds.unmapped_per_m'):g} unmapped objects a metre"]
                if r.setting("worlds.unmapped_per_m")  # (runs before it: none)
                else []
            )
            + (
                [
                    f"KLD-sampling from {r.setting('mcl.kld_min_particles'):,}, "
                    f"{s['particles_per_update'] / 1000:.1f}k per update on average"
                ]
                if r.setting("mcl.kld_sampling")
                else []
            )
        )
        label = s["weighting"].replace("_", " ") + (f" ({', '.join(how)})" if how else "")
        rows.append(
            f"| test ({len(s['worlds'])}) | {label} | {s['num_particles'] // 1000}k "
            f"| {s['device']} | {f'{kid:g} s' if kid else '-'} | {s['successes']}/{n} | {s['right_at_end']}/{n} "
            f"| {s['localized_at_end']}/{n} | {s['confidently_wrong_at_end']} | {_f(s.get('auroc'), '{:.3f}')} "
            f"| {_f(fa)} | {detected} | {back} | {per} |"
        )
    return "\n".join(rows)


def _log_scan_offset(log: str) -> float:
    """``data.scan_time_offset_s`` as ``+exp=<log>`` composes it (the primary config's for a log without one)."""
    return float(exp_defaults(log, "localize")["data"].get("scan_time_offset_s") or 0.0)


def own_slam_map_table(records: list) -> str:
    """Real logs localized globally from their first scan, over the whole log, in their own SLAM map (issue 33): one
    row per record of eval.analyses.own_slam_map (results/own_slam_map/), its runs scored against the SLAM poses, with
    the calibration that judged them (the tuning runs its file was fitted on)."""
    rows = [
        "| log | weighting | particles | device | runs (seeds) | success (protocol) | converged after (s), median "
        "[min-max] | RMSE after (cm), median | ended confident (>= 0.8) | ended confident and wrong | AUROC, every "
        "scan | confidence when right / wrong, median | calibration |",
        "|" + "---|" * 13,
    ]
    for rec in sorted(
        records,
        key=lambda r: (
            r["log"],
            r["runs"][0]["particles"],
            r["runs"][0].get("global_candidates") or 1,
            r["runs"][0].get("report_pose") or "filter",
            bool(r["runs"][0].get("relocalize")),
            r["runs"][0].get("scan_time_offset_s") or 0.0,
        ),
    ):
        runs = rec["runs"]
        first = runs[0]
        k = first.get("global_candidates") or 1  # (records before the setting: 1)
        weighting = first["weighting"].replace("_", " ") + (f", start from {k}x candidates" if k > 1 else "")
        if first.get("report_pose") == "mode":  # (records before the setting reported the filter's estimate)
            weighting += ", the judged mode's pose"
        offset = first.get("scan_time_offset_s") or 0.0  # (records before the setting: read at the stamps)
        if offset != _log_scan_offset(rec["log"]):  # a row not made as the log's config reads it says how it was
            weighting += (
                f", each scan's odometry read {offset:+.3f} s from its stamp"
                if offset
                else ", each scan's odometry read at its stamp"
            )
        if first.get("relocalize"):
            weighting += ", re-seeded when lost"
            rule = first.get("lost_rule") or {}  # (records before it: the rule of the session before, unnamed)
            how = (
                (
                    [f"agreement < {rule['lost_agreement_below']:g} for {rule['lost_agreement_updates']} updates"]
                    if rule.get("lost_agreement_updates", 1) > 1
                    else []
                )
                + ([f"{rule['relocalize_places']} searched places"] if rule.get("relocalize_places") else [])
                + (["keeping its particles"] if rule.get("relocalize_keeps_particles") else [])
            )
            weighting += f" ({', '.join(how)})" if how else ""
        t = [r["time_to_converge_s"] for r in runs if r["time_to_converge_s"] is not None]
        e = [r["location_rmse_cm"] for r in runs if r["location_rmse_cm"] is not None]
        conf = sum(bool(r["localized_at_end"]) for r in runs)
        # said localized at the end although more than the protocol's 0.5 m off the SLAM pose
        wrong = sum(bool(r["localized_at_end"]) and (r["error_at_end_m"] or 0.0) > 0.5 for r in runs)
        judged = rec.get("confidence") or {}  # records before the per-scan judgement have none
        auc = _f(judged.get("auroc"), "{:.3f}")
        when_right, when_wrong = (_f(judged.get(k), "{:.2f}") for k in ("median_when_right", "median_when_wrong"))
        medians = f"{when_right} / {when_wrong}" if judged else "-"
        span = f"{np.median(t):.1f} [{min(t):.1f}-{max(t):.1f}]" if t else "-"
        seeds = ",".join(str(r["seed"]) for r in sorted(runs, key=lambda r: r["seed"]))
        # which calibration judged the runs (records before it was kept: "-"; runs judged by two: both)
        calibration = " / ".join(sorted({r.get("calibration") or "-" for r in runs}))
        rows.append(
            f"| {rec['log']} | {weighting} | {first['particles'] // 1000}k | {first['device']} "
            f"| {len(runs)} ({seeds}) | {rec['successes']}/{len(runs)} | {span} | {_f(np.median(e) if e else None)} "
            f"| {conf}/{len(runs)} | {wrong} | {auc} | {medians} | {calibration} |"
        )
    return "\n".join(rows)
