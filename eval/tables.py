"""``python -m eval.tables [--write]``: every results table, generated from the runs' metrics.json files.

Runs are read from ``results/`` (runs kept in the repository, e.g. GPU runs) and ``outputs/`` (your own
runs; they win where both hold the same experiment and preset). ``--write`` replaces the generated
blocks of README.md (between ``<!-- table:<name> -->`` and ``<!-- /table:<name> -->``).
"""

from __future__ import annotations

import argparse
import re

from omegaconf import OmegaConf

from eval.claims import claims, facts, reproduction_markdown, write_facts
from eval.collect import (CONVERGED_M, DATASET_ORDER, GLOBLOC_METHODS, REPO, collect_globloc, collect_localization,
                          collect_pipeline, collect_slam, collect_slam_reference, collect_synthesis, converged,
                          localize_cell, reference_variant, released_errors, slam_errors, slam_variant)
from irmcl_warp.config import GlobLocConfig, LocalizeConfig, MCLConfig
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.pipeline import run_folder as pipeline_run_folder
from irmcl_warp.services.metrics import FULL_COVERAGE
from irmcl_warp.services.cli import guard

# GMapping references. The released code's rows come from runs this project repeats (python -m
# eval.reference.gmapping, kept in results/slam/reference/); the published figures are cited facts (relations
# metric, mean translational error): Kümmerle et al. 2009 (Auton. Robots 27(4)) / the Cartographer paper (Hess
# et al. ICRA 2016).
SLAM_REFERENCES = {
    "intel": [("published GMapping (Kümmerle et al. 2009)", "", "0.070", ""),
              ("published Cartographer (Hess et al. 2016)", "", "0.0229", "")],
    "fr079": [("published GMapping (Kümmerle et al. 2009)", "", "0.061", ""),
              ("published Cartographer (Hess et al. 2016)", "", "0.0452", "")],
    "mit_csail": [("published GMapping (Kümmerle et al. 2009)", "", "0.049", ""),
                  ("published Cartographer (Hess et al. 2016)", "", "0.0319", "")],
}
METHODS = {"nog_raymarch": "IR-MCL (NOG)", "nof_direct": "IR-MCL (NOF, no grid)", "likelihood_field": "likelihood field",
           "beam_model": "beam model"}


def _order(key):
    syn = key[1]
    ds = syn["dataset"]
    return (DATASET_ORDER.index(ds) if ds in DATASET_ORDER else 99, ds, syn["split"])


def synthesis_table(runs: dict) -> str:
    """IR-MCL Table I style: one row per method and (dataset, test split); grids once per test split."""
    rows, seen_grids = [], set()
    for (exp, preset), (syn, train) in sorted(runs.items(), key=lambda kv: (_order((kv[0], kv[1][0])), kv[0][1])):
        for name, m in syn["methods"].items():
            if m["kind"] == "grid":
                if (syn["dataset"], syn["split"], name) in seen_grids:
                    continue
                seen_grids.add((syn["dataset"], syn["split"], name))
                how = "-"
            else:
                name = f"NOF ({preset})"  # the folder's name: preset, and the renderer when not Warp
                how = (f"{train['train_time_s']:.0f} s, {train['epochs_done']} ep, {train.get('gpu') or train['device']}"
                       if train else "?")
            rows.append((syn["dataset"], syn["split"], name, m, how))
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    rows.sort(key=lambda r: (ds_rank.get(r[0], 99), r[0], r[1], r[2].startswith("OGM"), r[2]))
    lines = ["| dataset | test split | method | MAE (m) | median (m) | accuracy (%) | Chamfer (m) | F-score (%) | training |",
             "|---|---|---|---|---|---|---|---|---|"]
    for ds, split, name, m, how in rows:
        lines.append(f"| {ds} | {split} | {name} | {m['mae_m']:.3f} | {m['median_error_m']:.3f} | {m['accuracy_pct']:.1f} | "
                     f"{m['chamfer_m']:.3f} | {m['fscore_pct']:.1f} | {how} |")
    return "\n".join(lines)


def _f(v, fmt="{:.1f}"):
    return "-" if v is None else fmt.format(v)


def localization_table(runs: dict) -> str:
    """Per dataset and map: global localization and pose tracking side by side (means over the starts that
    succeeded; the starts are seeded and spread over the sequence). Where a cell was run with several
    particle counts, the largest is shown (the paper's setting; smaller ones are quick checks)."""
    cells = {}
    for m in runs.values():
        t = localize_cell(m)
        if t["extra"]:
            continue  # kidnapping runs (kidnap_table) and ablations (ablation_table)
        key = (m["dataset"], t["weighting"], float(t["res"]), t["mode"])
        if key not in cells or m["summary"]["num_particles"] >= cells[key]["num_particles"]:
            cells[key] = m["summary"]
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    w_rank = {w: i for i, w in enumerate(METHODS)}
    keys = sorted({k[:3] for k in cells}, key=lambda k: (ds_rank.get(k[0], 99), k[0], w_rank.get(k[1], 99), k[2]))
    lines = ["| dataset | method | map | global: particles | success | converged after (s) | RMSE (cm / deg) | "
             "within 10 cm / 1 deg (%) | tracking: particles | success | RMSE (cm / deg) | diverged |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
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


# the ablations' base run: MCLConfig's defaults, which are IR-MCL's global localization
ABLATION_BASE = {**{k: getattr(MCLConfig, k) for k in ("weighting", "num_particles", "map_resolution_m", "num_beams",
                                                        "t_min", "empty_below", "resample", "num_samples",
                                                        "recovery_alpha_fast")},
                 **{k: getattr(LocalizeConfig, k) for k in ("mode", "kidnap_at_s")}}
ABLATION_NAMES = {"weighting": "likelihood", "map_resolution_m": "NOG / grid resolution (m)",
                  "num_beams": "beams", "t_min": "early termination (transmittance floor)",
                  "empty_below": "empty-space skipping (p_occ floor)", "resample": "resampling"}


def ablation_table(runs: dict) -> str:
    """IR-MCL's global localization (100k particles, NOG 5 cm, 32 beams, early termination, low-variance
    resampling) and every run that changes one of those settings, per dataset. Time: the median over the
    starts of the filter's wall time per scan (the first start of a process also compiles kernels)."""
    import numpy as np

    rows = []
    for (exp, tag), m in runs.items():
        st = m.get("settings", {})
        if any(k not in st for k in ABLATION_BASE) or "ms_per_scan" not in m["runs"][0]:
            continue  # runs from before the settings or the timing were recorded
        diff = [k for k, v in ABLATION_BASE.items() if st[k] != v]
        if len(diff) > 1 or (diff and diff[0] not in ABLATION_NAMES):
            continue
        s = m["summary"]
        what, value = (ABLATION_NAMES[diff[0]], st[diff[0]]) if diff else ("(IR-MCL's settings)", "")
        if diff == ["num_beams"] and value >= 360:
            value = "all"
        rows.append(((DATASET_ORDER.index(m["dataset"]) if m["dataset"] in DATASET_ORDER else 99, bool(diff), what,
                      str(value)), f"| {m['dataset']} | {what} | {METHODS.get(value, value)} | {s['successes']}/{s['starts']} | "
                     f"{_f(s['time_to_converge_s_mean'])} | {_f(s['location_rmse_cm_mean'])} / "
                     f"{_f(s['yaw_rmse_deg_mean'], '{:.2f}')} | {_f(float(np.median([r['ms_per_scan'] for r in m['runs']])), '{:.2f}')} | "
                     f"{'H100' if str(s['device']).startswith('cuda') else s['device']} |"))
    head = ["| dataset | ablation | setting | success | converged after (s) | RMSE (cm / deg) | ms per scan | device |",
            "|---|---|---|---|---|---|---|---|"]
    return "\n".join(head + [r for _, r in sorted(rows)])


def kidnap_table(runs: dict) -> str:
    lines = ["| dataset | method | map | particles | kidnapped at (s) | recovery rates (slow / fast) | recovered | "
             "recovery time (s) | divergences |", "|---|---|---|---|---|---|---|---|---|"]
    rows = []
    for m in runs.values():
        t, s_ = localize_cell(m), m["summary"]
        if "recovered" not in s_:
            continue
        st = m.get("settings", {})
        rates = f"{st.get('recovery_alpha_slow', '?')} / {st.get('recovery_alpha_fast', '?')}"
        rows.append((DATASET_ORDER.index(m["dataset"]) if m["dataset"] in DATASET_ORDER else 99,
                     f"| {m['dataset']} | {METHODS.get(t['weighting'], t['weighting'])} | {t['res']} cm | {s_['num_particles'] // 1000}k | "
                     f"{s_['kidnap_at_s']:g} | {rates} | {s_['recovered']}/{s_['starts']} | "
                     f"{_f(s_['recovery_time_s_mean'])} | {s_['divergences']} |"))
    return "\n".join(lines + [r for _, r in sorted(rows)])


def slam_rows(ds: str, label: str, particles, rows: list, device: str) -> str:
    """A table row over seeds: converged count, error of the converged runs, mean of all runs, wall time."""
    import numpy as np

    t = np.array([r["relations"]["trans_abs_mean_m"] for r in rows])
    t_std = np.array([r["relations"]["trans_abs_std_m"] for r in rows])
    rot = np.array([r["relations"]["rot_abs_mean_deg"] for r in rows])
    ok = t < CONVERGED_M
    wall = np.array([r["wall_time_s"] for r in rows])
    if not ok.any():
        return (f"| {ds} | {label} | {particles} | 0/{len(rows)} | - | - | {t.mean():.3f} | "
                f"{wall.min():.0f}-{wall.max():.0f} s | {device} |")
    return (f"| {ds} | {label} | {particles} | {ok.sum()}/{len(rows)} | {t[ok].mean():.3f} +- {t_std[ok].mean():.3f} | "
            f"{rot[ok].mean():.2f} | {t.mean():.3f} | {wall.min():.0f}-{wall.max():.0f} s | {device} |")


def slam_table(runs: dict, reference: dict | None = None) -> str:
    """Per dataset and filter variant, over seeds: how many converged (relations error < CONVERGED_M), the
    error of the converged runs (their mean and std over the relations, averaged over those runs: the
    reference's convention), the mean over all runs, and the wall time; the references below each dataset.
    Runs with ablation settings (their folder names them) follow the default ones, settings in brackets."""

    groups = {}
    for m in runs.values():
        if not isinstance(m.get("relations"), dict):
            continue
        variant = slam_variant(m)
        key = (m["dataset"], variant != "", m["proposal"], m["resample"], m["particles"], variant,
               m.get("device", "?"))
        groups.setdefault(key, []).append(m)
    ds_rank = {d: i for i, d in enumerate(DATASET_ORDER)}
    lines = ["| dataset | method | particles | converged seeds | error of converged runs (m, mean +- std over relations) | rot. (deg) | "
             "mean of all runs (m) | wall time per run | device |", "|---|---|---|---|---|---|---|---|---|"]
    for ds in sorted({k[0] for k in groups}, key=lambda d: (ds_rank.get(d, 99), d)):
        for key in sorted(k for k in groups if k[0] == ds):
            rows = groups[key]
            method = f"{key[2]} + {key[3]}" + (f" ({key[5]})" if key[5] else "")
            counts = min(((r["relations"]["relations_used"], r["relations"]["relations_used"] + r["relations"][
                "relations_unmatched"]) for r in rows), key=lambda c: c[0] / max(c[1], 1))
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
            lines.append(f"| {ds} | *{name}* | {30 if conv else ''} | {conv} | {err} | | | {wall} | 2-core CPU |"
                         if conv else f"| {ds} | *{name}* | | | | | {err} | | |")
    return "\n".join(lines)


def released_table(runs: dict, reference: dict) -> str:
    """Ours against the released C++ on the same logs, 30 particles, seeds 0-9: the released code's runs
    (eval.reference.gmapping, the ROS wrapper's settings) beside ours at the released settings (its proposal,
    ``gmapping_code``) and with twice its rotational odometry noise. Each cell: converged seeds, the mean error
    of the converged runs, and the mean of all runs."""

    def cell(errs):
        if not errs:
            return "not run"
        k, n, conv, mean = converged(errs)
        return f"{k}/{n}" + (f", {conv:.3f} m" if k else "") + f" (all runs {mean:.3f} m)"

    lines = ["| log | released C++ (ROS wrapper's settings) | ours, released settings (`gmapping_code`) | "
             "ours, `slam=gmapping_rot2x` |", "|---|---|---|---|"]
    for ds in ("intel", "fr079", "mit_csail"):
        ours = [cell(slam_errors(runs, ds, "gmapping_code", variant=v)) for v in ("", "srt0.4, stt0.4")]
        lines.append(f"| {ds} | {cell(released_errors(reference, ds))} | {ours[0]} | {ours[1]} |")
    return "\n".join(lines)


def pipeline_table(runs: dict) -> str:
    """One row per pipeline run (SLAM, NOF and global localization of the second log, time per stage), and
    for an experiment run over several second drives a row of their medians [min-max] (RMSE over the
    successful ones: converged and under IR-MCL's 0.3 m)."""
    import numpy as np

    lines = ["| run | device | SLAM: processed scans, ATE (odometry) | NOF: validation MAE | localized scans | "
             "converged after | RMSE (cm / deg) | time: slam / train / nog / localize (s) |",
             "|---|---|---|---|---|---|---|---|"]
    by_exp = {}
    for (exp, folder), m in sorted(runs.items(), key=lambda kv: (kv[0][0], kv[1].config.get("pipeline", {}).get(
            "sim_path_seed", 0))):
        by_exp.setdefault(exp, []).append(m)
        sl, nof, lo, t = m.get("slam", {}), m.get("nof", {}), m.get("localization"), m["timing"]
        took = " / ".join("skipped" if t.get(k, {}).get("skipped") else _f(t.get(k, {}).get("s"), "{:.0f}")
                          for k in ("slam", "train", "nog", "localize"))
        conv = (f"{lo['time_to_converge_s']:.1f} s" if lo["converged"] else "no") if lo else "no ground truth"
        rmse = f"{_f(lo['location_rmse_cm'])} / {_f(lo['yaw_rmse_deg'], '{:.2f}')}" if lo else "-"
        if lo and not lo["success"]:
            rmse += " (failed)"
        cfg = OmegaConf.create(m.config)  # one of several second drives: as the pipeline names its run folders
        seed = cfg.pipeline.sim_path_seed if pipeline_run_folder(cfg) != "pipeline" else None
        name = exp + (f" (path seed {seed})" if seed is not None else "")
        lines.append(f"| {name} | {_device(m['device'])} | {sl.get('processed_scans', '-')}, {_f(sl.get('ate_rmse_m'), '{:.3f}')} m "
                     f"({_f(sl.get('odometry_ate_rmse_m'), '{:.2f}')} m) | {_f(nof.get('val_mae_m'), '{:.3f}')} m | "
                     f"{m['localized_scans']} | {conv} | {rmse} | {took} |")
    for exp, ms in by_exp.items():
        scored = [m["localization"] for m in ms if m.get("localization")]
        if len(ms) < 2 or not scored:
            continue
        ok = [lo for lo in scored if lo["success"]]

        def spread(values, fmt):
            v = [x for x in values if x is not None]
            return f"{fmt.format(np.median(v))} [{fmt.format(min(v))}-{fmt.format(max(v))}]" if v else "-"

        total = [sum(t["s"] for t in m["timing"].values()) for m in ms]
        lines.append(f"| **{exp}: median of {len(ms)} second drives** | {_device(ms[0]['device'])} | | | | "
                     f"{len(ok)}/{len(scored)} succeeded; converged after "
                     f"{spread([lo['time_to_converge_s'] for lo in ok], '{:.1f}')} s | "
                     f"{spread([lo['location_rmse_cm'] for lo in ok], '{:.1f}')} cm | "
                     f"time of the stages each run ran (finished ones are reused): {spread(total, '{:.0f}')} s |")
    return "\n".join(lines)


def _device(d) -> str:
    return "H100" if str(d).startswith("cuda") else "2-core CPU" if d == "cpu" else str(d)


def globloc_table(runs: dict) -> str:
    """One row per (experiment, scenario, method): success with its Wilson 95 % interval, time and distance
    until localized, kidnap recovery, false relocalizations per hour, accuracy after convergence."""
    rows = ["| world | scenario | method | localized | 95 % CI | time / distance to localize | recovered after kidnap "
            "(time) | kidnap detected | false relocalizations per hour | RMSE after convergence (cm) |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for (exp, _), m in sorted(runs.items()):
        world = ("repetitive corridor" if m.get("repetitive") else "office") + f" ({exp})"
        confirm = m.get("settings", {}).get("trigger_confirm_frames", 1)  # runs before the setting existed: 1
        for method, v in m["methods"].items():
            sm = v["summary"]
            lo, hi = sm["success_ci95"]
            label = GLOBLOC_METHODS.get(method, method)
            if method == "paper" and confirm != GlobLocConfig.trigger_confirm_frames:
                label += f" ({confirm} confirming frame{'s' if confirm != 1 else ''})"
            ttl = (f"{_f(sm['mean_time_to_localize_s'])} s / {_f(sm['mean_distance_to_localize_m'])} m"
                   if sm["mean_time_to_localize_s"] is not None else "-")
            rec = (f"{sm['recovered']}/{sm['runs']} ({_f(sm['mean_recovery_time_s'])} s)" if "recovered" in sm else "")
            det = f"{sm['detected']}/{sm['runs']}" if "detected" in sm and method == "paper" else ""
            rmse = _f(None if sm["mean_rmse_after_m"] is None else 100 * sm["mean_rmse_after_m"])
            rows.append(f"| {world} | {m['scenario']} | {label} | {sm['localized']}/{sm['runs']} "
                        f"| {lo:.2f}-{hi:.2f} | {ttl} | {rec} | {det} | {sm['false_relocalizations_per_hour']:.1f} | {rmse} |")
    return "\n".join(rows)


def replace_block(text: str, name: str, table: str) -> str:
    begin, end = f"<!-- table:{name} -->", f"<!-- /table:{name} -->"
    pattern = re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise SystemExit(f"README.md has no {begin} ... {end} block")
    return pattern.sub(lambda _: f"{begin}\n{table}\n{end}", text)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.tables")
    ap.add_argument("--write", action="store_true", help="update the generated blocks of README.md")
    a = ap.parse_args(argv)
    tables = {}
    runs = collect_synthesis()
    if runs:
        tables["nof"] = ("Scan synthesis (IR-MCL protocol; NOF rendered with 256 samples, grids by ray casting)",
                         synthesis_table(runs))
    loc = collect_localization()
    if loc:
        tables["mcl"] = ("Localization (10 seeded starts per cell, 60 s each; means over the successful starts)",
                         localization_table(loc))
        tables["ablation"] = ("Ablations of IR-MCL's global localization, one setting at a time (10 starts of "
                              "60 s; ms per scan: the whole filter step, median over the starts)", ablation_table(loc))
        tables["kidnap"] = ("Kidnapped robot (pose tracking teleported mid-run, AMCL-style recovery on)",
                            kidnap_table(loc))
    slam, reference = collect_slam(), collect_slam_reference()
    if slam:
        tables["slam"] = (f"GMapping, relations metric (Kümmerle et al. 2009); converged = mean error < {CONVERGED_M} m",
                          slam_table(slam, reference))
        tables["released"] = ("GMapping against the released C++, same logs, 30 particles, seeds 0-9",
                              released_table(slam, reference))
    pipe = collect_pipeline()
    if pipe:
        tables["pipeline"] = ("The pipeline, raw log to localized robot (global localization from a uniform "
                              "start over the second log)", pipeline_table(pipe))
    gl = collect_globloc()
    if gl:
        tables["globloc"] = ("Lidar + camera global localization (simulated worlds, identical sensor streams per "
                             "method; localized = within 0.5 m and 15 deg to the end of the run or of the part "
                             "before the kidnapping)", globloc_table(gl))
    if not tables:
        raise SystemExit("no results found under results/ or outputs/ (run python -m eval.synthesis or "
                         "python -m irmcl_warp.localize)")
    for title, table in tables.values():
        print(f"{title}\n\n{table}\n")
    if a.write:
        doc = REPO / "docs" / "REPRODUCTION.md"
        atomic_write_bytes(doc, reproduction_markdown(claims(runs, loc, slam, gl, pipe, reference)).encode())
        print(f"-> {doc}")
        readme = REPO / "README.md"
        text = readme.read_text()
        for name, (_, table) in tables.items():
            text = replace_block(text, name, table)
        text = write_facts(text, facts(slam, reference, runs))
        atomic_write_bytes(readme, text.encode())
        print(f"-> {readme}")


if __name__ == "__main__":
    guard(main)
