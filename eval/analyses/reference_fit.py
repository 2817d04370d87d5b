"""``python -m eval.analyses.reference_fit --slam <slam run> --runs <own-map localize runs>... [--out FILE.json]``

How far the reference of the own-map tables can be trusted, scan by scan (issue 33). A log localized in its own SLAM
map is scored against that SLAM run's poses (eval.analyses.own_slam_map), and its confidence's AUROC counts a scan as
wrong where the estimate is more than RIGHT_M / RIGHT_DEG from the SLAM pose. The SLAM pose is no ground truth: the
map is the best particle's at the end of the run, so where a later visit redrew a corridor, or the SLAM run
dead-reckoned between two processed scans (GMapping processes a scan after 0.5 rad of turning), the SLAM pose of a
scan may fit that scan to the map worse than the localizer's pose does.

For each scan the SLAM run has a pose of, this reads the scan's agreement with the SLAM map at the SLAM pose
(``ScanAgreement``, the confidence's own measure: the share of end points within 0.2 m of a wall) and at each run's
pose of it. It reports:

* the reference's fit: quantiles of its agreement over every scan;
* over every scan of the runs and over their wrong scans, the share where the localizer's pose fits the scan better than the SLAM pose (by more than
  ``MARGIN``), and the other way round;
* the AUROC the scan's agreement at the reported pose alone would have as the score (every scan's own, between
  updates too), beside the confidence's;
* the confidence's AUROC over the scans whose SLAM pose agrees at least ``t`` with its map, for several ``t``: no
  threshold is chosen, the curve shows how much of the AUROC's shortfall lies where the reference fits its own map
  badly;
* each lost event on a right estimate (a false alarm, as ``own_slam_map`` counts them) with the lowest agreement of
  the scans before it at the estimate and at the SLAM pose, and the share of the log's scans the SLAM pose fits worse:
  is the alarm where the map explains the scan at no pose the label calls right?
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from eval.analyses.own_slam_map import confidence_per_scan, lost_rule_of_run, on_reference
from irmcl_warp.config import own_map_lost_rule_settings
from irmcl_warp.io import read_tum
from irmcl_warp.mapping.mapio import load_map
from irmcl_warp.mcl.confidence import ScanAgreement, auroc, right
from irmcl_warp.services.cli import guard
from irmcl_warp.types import match_stamps
from irmcl_warp.services.data import load_stream
from irmcl_warp.services.outputs import write_json

# the seconds of scans before a lost event that its rule read (2 updates below the bar, and the scans between)
ALARM_WINDOW_S = 2.0
THRESHOLDS = (0.0, 0.6, 0.7, 0.8, 0.9)  # the reference's agreement with its map at or above which a scan is judged
MARGIN = 0.02  # one pose fits a scan better than another when its agreement is higher by more than this


def auroc_where_reference_fits(conf, hit, ref_fit, thresholds=THRESHOLDS) -> list[dict]:
    """For each threshold t: the scans whose reference agreement is >= t, their share of all, how many are wrong, and
    the confidence's AUROC over them (None where they are all right or all wrong)."""
    conf, hit, ref_fit = np.asarray(conf, float), np.asarray(hit, bool), np.asarray(ref_fit, float)
    out = []
    for t in thresholds:
        s = ref_fit >= t
        both = s.any() and hit[s].any() and (~hit[s]).any()
        out.append(
            {
                "reference_agreement_at_least": float(t),
                "share_of_scans": float(s.mean()) if len(s) else 0.0,
                "wrong": int((~hit[s]).sum()),
                "auroc": auroc(conf[s], hit[s]) if both else None,
            }
        )
    return out


def who_fits_better(at_estimate, at_reference, margin: float = MARGIN) -> dict:
    """Over scans judged wrong: the share where the localizer's pose fits the scan better than the SLAM pose, the share
    where the SLAM pose fits better, and both poses' median agreement."""
    a, r = np.asarray(at_estimate, float), np.asarray(at_reference, float)
    if not len(a):
        return {"scans": 0}
    return {
        "scans": int(len(a)),
        "estimate_fits_better": float(np.mean(a > r + margin)),
        "reference_fits_better": float(np.mean(r > a + margin)),
        "median_at_estimate": float(np.median(a)),
        "median_at_reference": float(np.median(r)),
    }


def alarm_fits(lost_at_s, t, ok, fit_est, fit_ref, below: float, window_s: float = ALARM_WINDOW_S) -> list[dict]:
    """The lost events on a right estimate (``own_slam_map.false_alarms``' reading: the last scan before the event was
    right), each with the lowest agreement of the scans in the ``window_s`` before it at the estimate and at the SLAM
    pose. ``t``: the scans' seconds since the first; ``fit_est`` / ``fit_ref``: each scan's agreement (NaN where
    unread); ``below``: the rule's bar. Where the SLAM pose too fits below the bar, the map explains those scans at no
    pose the label calls right: the alarm says the map is not the world there, not that the robot is lost."""
    out = []
    for at in lost_at_s or ():
        before = np.flatnonzero(t < at - 1e-6)
        if not len(before) or not ok[before[-1]]:
            continue
        w = before[t[before] >= at - window_s]
        lo_est, lo_ref = np.nanmin(fit_est[w], initial=np.inf), np.nanmin(fit_ref[w], initial=np.inf)
        out.append(
            {
                "at_s": float(at),
                "scans": int(len(w)),
                "lowest_at_estimate": float(lo_est),
                "lowest_at_reference": float(lo_ref),
                "reference_below_bar": bool(lo_ref < below),
            }
        )
    return out


def reference_fit(slam: Path, runs: list[Path]) -> dict:
    cfg = OmegaConf.load(runs[0] / "config.yaml")  # the log the runs read (and the SLAM run made its map of)
    log = load_stream(cfg)
    grid = load_map(slam / "map.yaml")
    agreement = ScanAgreement.of_grid(grid)
    ref_stamps, ref = read_tum(slam / "trajectory.tum")
    k = match_stamps(log.stamps, ref_stamps)  # (the log's scans in their own order: intel's stamps go back)
    has_scan = k >= 0
    if has_scan.mean() < 0.9:
        raise ValueError(f"{slam}: fewer than 90 % of its poses have a scan of {cfg.data.name}'s log: another log?")
    scan = (log.info.angles_rad, log.T_base_laser)
    ref_fit = np.full(len(ref), np.nan)
    for i in np.flatnonzero(has_scan):
        ref_fit[i] = agreement(ref[i], log.ranges_m[k[i]], *scan)
    conf_all, hit_all, fit_all, at_est, alarms = [], [], [], [], {}
    for run in runs:
        stamps, est = read_tum(run / "trajectory.tum")
        on_ref = on_reference(stamps, est, ref_stamps, ref)
        j = np.clip(np.searchsorted(ref_stamps, stamps - 1e-6), 0, len(ref_stamps) - 1)
        conf = confidence_per_scan(run, stamps)
        use = np.isfinite(conf) & np.isfinite(on_ref).all(1) & np.isfinite(ref_fit[j])
        hit = right(est, on_ref)
        lost_at_s = json.loads((run / "metrics.json").read_text()).get("lost_at_s")
        t, near = stamps - stamps[0], np.zeros(len(stamps), bool)
        for at in lost_at_s or ():  # the scans an alarm's rule read
            near |= (t >= at - ALARM_WINDOW_S - 1e-6) & (t < at)
        # the agreement at the estimate, once a scan: at the scored scans and at those before an alarm
        fit_est = np.full(len(stamps), np.nan)
        for i in np.flatnonzero(use | (near & np.isfinite(est).all(1) & (k[j] >= 0))):
            fit_est[i] = agreement(est[i], log.ranges_m[k[j[i]]], *scan)
        conf_all.append(conf[use])
        hit_all.append(hit[use])
        fit_all.append(ref_fit[j][use])
        at_est.append(fit_est[use])
        if lost_at_s:
            below = (lost_rule_of_run(json.loads((run / "manifest.json").read_text())) or {}).get(
                "lost_agreement_below"
            )
            if below is None:
                below = own_map_lost_rule_settings().lost_agreement_below
                warnings.warn(f"{run}: its lost rule is not recorded; the bar read is today's ({below})", stacklevel=1)
            alarms[str(run)] = alarm_fits(lost_at_s, t, hit, fit_est, ref_fit[j], below)
    conf_all, hit_all, at_ref, at_est = (np.concatenate(x) for x in (conf_all, hit_all, fit_all, at_est))
    fit = ref_fit[np.isfinite(ref_fit)]
    wrong = ~hit_all  # at_est: each used scan's agreement at the estimate, in the order of the runs
    for events in alarms.values():  # how rare a fit that poor is for the reference: its share of the log's scans
        for e in events:
            e["reference_share_below"] = float(np.mean(fit < e["lowest_at_reference"]))
    return {
        "log": cfg.data.name,
        "slam_run": str(slam),
        "runs": [str(r) for r in runs],
        "reference_agreement": {
            "scans": int(len(fit)),
            "quantiles": {q: float(np.quantile(fit, float(q) / 100)) for q in ("5", "10", "25", "50")},
            "below_0.8": float(np.mean(fit < 0.8)),
        },
        "every_scan": who_fits_better(at_est, at_ref),
        "wrong_scans": who_fits_better(at_est[wrong], at_ref[wrong]),
        # (None where the runs kept no confidence per scan: spread.csv)
        "auroc_where_reference_fits": auroc_where_reference_fits(conf_all, hit_all, at_ref) if len(hit_all) else None,
        # the scan's agreement at the reported pose, every scan's own (between updates too), taken as the score
        "auroc_of_agreement_alone": auroc(at_est, ~wrong) if wrong.any() and (~wrong).any() else None,
        "false_alarms": alarms,
        "alarm_window_s": ALARM_WINDOW_S,
        "false_alarms_where_reference_below_bar": sum(a["reference_below_bar"] for r in alarms.values() for a in r),
        "false_alarms_total": sum(len(r) for r in alarms.values()),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.reference_fit", description=__doc__.split("\n\n")[1])
    ap.add_argument("--slam", required=True, type=Path, help="the SLAM run whose map.yaml the runs localized in")
    ap.add_argument("--runs", required=True, nargs="+", type=Path, help="own-map localization runs of that log")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    rec = reference_fit(a.slam, sorted(a.runs))
    q = rec["reference_agreement"]["quantiles"]
    print(
        f"{rec['log']}: the SLAM poses' scan agreement with their own map over {rec['reference_agreement']['scans']:,} "
        f"scans: 5 % {q['5']:.3f}, 10 % {q['10']:.3f}, 25 % {q['25']:.3f}, median {q['50']:.3f}; below 0.8 at "
        f"{rec['reference_agreement']['below_0.8']:.1%}"
    )
    for what, w in (("every scan", rec["every_scan"]), ("wrong scans", rec["wrong_scans"])):
        if not w["scans"]:
            continue
        print(
            f"{what} ({w['scans']:,} over {len(rec['runs'])} runs): the localizer's pose fits the scan better at "
            f"{w['estimate_fits_better']:.0%}, the SLAM pose at {w['reference_fits_better']:.0%} (median agreement "
            f"{w['median_at_estimate']:.3f} against {w['median_at_reference']:.3f})"
        )
    if rec["auroc_of_agreement_alone"] is not None:
        print(
            f"the scan's agreement at the reported pose alone as the score: AUROC {rec['auroc_of_agreement_alone']:.3f}"
        )
    if rec["auroc_where_reference_fits"] is None:
        print(
            "these runs kept no confidence per scan (spread.csv): no scan is scored, only the reference and the alarms"
        )
    else:
        print_auroc_rows(rec["auroc_where_reference_fits"])
    print_alarms(rec)
    if a.out:
        write_json(a.out, rec)
        print(f"-> {a.out}")
    return rec


def print_auroc_rows(rows) -> None:
    print("| SLAM pose's agreement at least | share of scans | wrong scans | AUROC |")
    print("|---|---|---|---|")
    for r in rows:
        auc = "-" if r["auroc"] is None else f"{r['auroc']:.3f}"
        print(f"| {r['reference_agreement_at_least']:.1f} | {r['share_of_scans']:.3f} | {r['wrong']:,} | {auc} |")


def print_alarms(rec: dict) -> None:
    if rec["false_alarms_total"]:
        print(
            f"lost events on a right estimate: {rec['false_alarms_total']}, of them "
            f"{rec['false_alarms_where_reference_below_bar']} where the SLAM pose too fits a scan of the {ALARM_WINDOW_S:.0f} s before below the rule's bar"
        )
        print("| run | at (s) | lowest agreement at the estimate | at the SLAM pose | scans the SLAM pose fits worse |")
        print("|---|---|---|---|---|")
        for run, events in rec["false_alarms"].items():
            for e in events:
                print(
                    f"| {Path(run).name} | {e['at_s']:.1f} | {e['lowest_at_estimate']:.2f} | "
                    f"{e['lowest_at_reference']:.2f} | {e['reference_share_below']:.1%} |"
                )


if __name__ == "__main__":
    guard(main)
