"""``python -m eval.analyses.yaw_lag outputs/<exp>/localize-<run> [...]``: does a localization run's heading trail the
truth while the robot turns? (Issue 17: the NOG's yaw error grew with the turn rate.)

For every run folder, from its trajectories (start*.tum) and the ground truth of its log (config.yaml names
the log; the stream cache serves it; starts its metrics.json marks unsuccessful are left out): the signed heading error e = yaw_est - yaw_true at every scan after
``--after-s`` of each start, the true turn rate w (central differences of the ground truth), the RMS of e
while driving straight (|w| < ``--straight``) and while turning (|w| > ``--turning``), and a lag: the least
squares fit e = -lag * w (a heading that follows the truth ``lag`` seconds late). Prints a table and writes
``yaw_lag.json`` into each run folder.

``--profile``: the run's observation model itself, free of the filter. At every ``--every``-th scan with
ground truth, particles at the true pose with the heading turned by -5..5 deg are weighed as the filter
weighs them (its beams, its near/far masks). Per run: the median heading at which the log-likelihood
peaks (a bias of the map or the model), and the heading spread the model alone implies, from a quadratic
fit of the mean log-likelihood within +-2 deg (sigma = sqrt(-1 / 2a), per scan). Written to
``yaw_profile.json`` (``yaw_profile-<setting>=<value>.json`` with ``--set``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from eval.analyses.rescore import run_trajectories
from irmcl_warp.geometry import wrap_angle
from irmcl_warp.services.data import load_stream
from irmcl_warp.services.outputs import write_json


def heading_errors(stamps, est_yaw, gt_yaw, after_s=20.0) -> tuple[np.ndarray, np.ndarray]:
    """(signed heading error e = est - true, true turn rate w) at the scans ``after_s`` into one trajectory
    (arrays over the same scans; scans without ground truth dropped)."""
    t, est, gt = (np.asarray(a, float) for a in (stamps, est_yaw, gt_yaw))
    t_start = t[0]  # the trajectory's start, whether or not its first scan has ground truth
    known = np.isfinite(gt) & np.isfinite(est)
    if known.sum() < 3:
        return np.empty(0), np.empty(0)
    t, est, gt = t[known], est[known], gt[known]  # (np.unwrap would carry a NaN on to every later scan)
    w = np.gradient(np.unwrap(gt), t)
    keep = t - t_start >= after_s
    return wrap_angle(est - gt)[keep], w[keep]


def summarise(e: np.ndarray, w: np.ndarray, straight: float = 0.1, turning: float = 0.3) -> dict:
    """RMS heading error (deg) overall, straight and turning, and the lag (s) of the fit e = -lag * w."""
    rms = lambda m: float(np.degrees(np.sqrt(np.mean(e[m] ** 2)))) if m.any() else None  # noqa: E731
    return {
        "scans": int(len(e)),
        "rms_deg": rms(np.ones_like(e, bool)),
        "straight_rms_deg": rms(np.abs(w) < straight),
        "turning_rms_deg": rms(np.abs(w) > turning),
        "lag_s": float(-np.sum(e * w) / np.sum(w * w)) if np.sum(w * w) > 0 else None,
    }


def analyse(run: Path, after_s: float, straight: float, turning: float) -> dict:
    _, starts = run_trajectories(run)
    metrics = run / "metrics.json"  # a start that never converged has no heading to lag: left out, as from its RMSE
    ok = [r["success"] for r in json.loads(metrics.read_text())["runs"]] if metrics.is_file() else [True] * len(starts)
    pairs = [
        heading_errors(stamps, est[:, 2], gt[:, 2], after_s) for (stamps, est, gt), good in zip(starts, ok) if good
    ]
    if not pairs:
        raise ValueError(f"{run}: no start converged")
    e, w = (np.concatenate(a) for a in zip(*pairs))
    return {
        "run": run.name,
        "starts": len(pairs),
        **summarise(e, w, straight, turning),
        "after_s": after_s,
        "straight_rad_s": straight,
        "turning_rad_s": turning,
    }


def yaw_profile(run: Path, every: int = 10, max_deg: float = 5.0, steps: int = 41, overrides=()) -> dict:
    """The observation model's log-likelihood against a heading error at the true poses (see the docstring)."""
    import warp as wp

    from irmcl_warp.mcl.stage import build_maps
    from irmcl_warp.services.data import far_bound_m
    from irmcl_warp.services.filters import build_filter

    cfg = OmegaConf.merge(OmegaConf.load(run / "config.yaml"), OmegaConf.from_dotlist(list(overrides)))
    device = "cpu"
    log = load_stream(cfg)
    up = (
        json.loads((run / "manifest.json").read_text()).get("upstream", {}).get("train")
        if (run / "manifest.json").is_file()
        else None
    )  # the field the run read (a NOF weighting)
    view, maps, _ = build_maps(cfg, device, run.parents[2] / up["run"] / "nof.pt" if up else None)
    far_m = far_bound_m(cfg)
    m = OmegaConf.merge(cfg.mcl, {"num_particles": steps, "step_graph": "off"})
    pf = build_filter(m, view, log.T_base_laser, log.info.angles_rad, far_m, device, maps)
    offsets = np.radians(np.linspace(-max_deg, max_deg, steps))
    scans = np.flatnonzero(np.all(np.isfinite(log.ground_truth), axis=1))[::every]
    curves, peaks = [], []
    for k in scans:
        pose = log.ground_truth[k]
        poses = np.column_stack([np.full(steps, pose[0]), np.full(steps, pose[1]), wrap_angle(pose[2] + offsets)])
        pf.particles.assign(wp.array(poses.astype(np.float32), dtype=wp.vec3, device=device))
        pf.measured.assign(pf.chosen_ranges(log.ranges_m[k]))
        pf.weighting(pf.particles, pf.T_base_laser, pf.angles, pf.measured, pf.log_lik)
        ll = pf.log_lik.numpy().astype(np.float64)
        curves.append(ll - ll.max())
        peaks.append(np.degrees(offsets[np.argmax(ll)]))
    mean = np.mean(curves, axis=0)
    near = np.abs(np.degrees(offsets)) <= 2.0
    a = np.polyfit(offsets[near], mean[near], 2)[0]
    return {
        "run": run.name + "".join(f" {o}" for o in overrides),
        "weighting": cfg.mcl.weighting,
        "scans": int(len(scans)),
        "peak_deg_median": float(np.median(peaks)),
        "peak_deg_iqr": [float(np.percentile(peaks, 25)), float(np.percentile(peaks, 75))],
        "sigma_deg_per_scan": float(np.degrees(np.sqrt(-1.0 / (2 * a)))) if a < 0 else None,
        "offsets_deg": np.degrees(offsets).tolist(),
        "mean_log_likelihood": mean.tolist(),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.yaw_lag", description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="localize run folders (outputs/<exp>/localize-...)")
    ap.add_argument(
        "--after-s", type=float, default=20.0, help="skip this much of each start (IR-MCL scores after 20 s)"
    )
    ap.add_argument("--straight", type=float, default=0.1, help="|turn rate| below this (rad/s) counts as straight")
    ap.add_argument("--turning", type=float, default=0.3, help="|turn rate| above this (rad/s) counts as turning")
    ap.add_argument("--profile", action="store_true", help="the observation model's heading profile at the true poses")
    ap.add_argument("--every", type=int, default=10, help="--profile: every n-th scan with ground truth")
    ap.add_argument(
        "--set", action="append", default=[], help="--profile: a setting over the run's, e.g. mcl.sigma_m=0.25"
    )
    a = ap.parse_args(argv)
    if a.profile:
        print("| run | weighting | scans | peak heading (deg): median [IQR] | heading sigma per scan (deg) |")
        print("|---|---|---|---|---|")
        for run in a.runs:
            r = yaw_profile(run, a.every, overrides=a.set)
            write_json(run / ("yaw_profile" + "".join(f"-{o}" for o in a.set) + ".json"), r)
            sig = f"{r['sigma_deg_per_scan']:.2f}" if r["sigma_deg_per_scan"] else "flat"
            print(
                f"| {r['run']} | {r['weighting']} | {r['scans']} | {r['peak_deg_median']:+.2f} "
                f"[{r['peak_deg_iqr'][0]:+.2f}, {r['peak_deg_iqr'][1]:+.2f}] | {sig} |",
                flush=True,
            )
        return
    rows = []
    for run in a.runs:
        r = analyse(run, a.after_s, a.straight, a.turning)
        write_json(run / "yaw_lag.json", r)
        rows.append(r)
    print("| run | starts | scans | yaw RMS (deg) | straight | turning | fitted lag (s) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['run']} | {r['starts']} | {r['scans']} | {r['rms_deg']:.2f} | {r['straight_rms_deg']:.2f} | "
            f"{r['turning_rms_deg']:.2f} | {r['lag_s']:.3f} |"
        )


if __name__ == "__main__":
    main()
