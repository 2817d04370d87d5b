"""The localize stage: ``python -m irmcl_warp.localize +exp=<name> [mcl.weighting=nog_table|nog_raymarch|likelihood_field|beam_model]``

Runs MCL over the recorded stream (scans + odometry) from ``localize.num_starts`` start times spread over
the sequence, each for ``localize.run_s`` seconds, globally (uniform over the free space) or tracking from a
noisy pose (``localize.mode``). The map comes from the training split only: the NOF of ``train=<preset>`` baked into a NOG
(nog_table, the default: the NOG's march read from a range table; nog_raymarch: marched per particle), or a log-odds grid of the training scans (grid baselines); particles start on the
grid's known free cells for every method. As IR-MCL's code, the filter weighs and resamples only after
the odometry moved (``mcl.update_min_*``), and a global run keeps the ``mcl.reduce_to`` heaviest
particles ``localize.reduce_after_s`` into the run.

``localize.kidnap_at_s`` > 0 teleports the robot: that far into each run the stream jumps to the next start
time (another place; the odometry does not see the jump), and metrics.json scores the recovery.

Writes outputs/<exp>/localize/<weighting>-<mode>-<particles>-<resolution>m-<id>/ (irmcl_warp.runs):
trajectories (TUM: stamp x y z qx qy qz qw), metrics.json (per start and summary), start0.png. A NOF
weighting reads the field of the finished training run of the same settings (never an unfinished one).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.io import write_tum
from irmcl_warp.io.plausibility import check_odometry
from irmcl_warp.mapping import integrate_scans
from irmcl_warp.mapping.grid import laser_bounds
from irmcl_warp.mcl.own_map import run_in_map
from irmcl_warp.mcl.track import follow
from irmcl_warp.nof.checkpoint import load_nof_for
from irmcl_warp.nog import NOG
from irmcl_warp.services.nog import bake_nog
from irmcl_warp import runs
from irmcl_warp.services.data import far_bound_m, load_stream, prepare_beams
from irmcl_warp.services.filters import NOF_WEIGHTINGS, WeightingMaps, build_filter, free_space_view, grid_maps
from irmcl_warp.services.metrics import localization_metrics
from irmcl_warp.services.plots import plot_run
from irmcl_warp.kernels import pick_device


def build_maps(cfg, device, nof: Path | None) -> tuple[NOG, WeightingMaps, np.ndarray]:
    """(free-space view for initialisation as a NOG, what the weighting reads, occupancy image for plots:
    p_occ, 0.5 where unknown) from the training split; ``nof``: the trained field (nof.pt) a NOF weighting reads."""
    train = prepare_beams(cfg)["train"]
    m, res, far_m = cfg.mcl, cfg.mcl.map_resolution_m, far_bound_m(cfg, load_stream(cfg).info.range_max_m)
    grid = integrate_scans(
        train.T_map_laser, train.ranges_m, train.angles_rad, resolution_m=res, far_m=far_m, device=device
    )
    free_view = free_space_view(grid.probability, grid.origin_xy, res, grid.known)
    image = np.where(grid.known, grid.probability, 0.5).astype(np.float32)
    if m.weighting not in NOF_WEIGHTINGS:
        return free_view, grid_maps(grid, m.weighting), image
    if m.weighting == "nof_direct":
        return (
            free_view,
            WeightingMaps(model=load_nof_for(nof, far_m, "cuda" if device.startswith("cuda") else "cpu")[0]),
            image,
        )
    nog = bake_nog(
        nof,
        laser_bounds(train.T_map_laser, train.ranges_m, train.angles_rad, far_m),
        far_m,
        res,
        cache_dir=runs.cache_dir(cfg, "nog"),
        device="cuda" if device.startswith("cuda") else "cpu",
    )
    return free_view, WeightingMaps(nog=nog), image


def start_times(t: np.ndarray, loc) -> np.ndarray:
    """The protocol's ``loc.num_starts`` start times (s since the log's first scan, ``t`` the scans' times),
    spread evenly so that each run of ``loc.run_s`` fits in the log."""
    return np.linspace(0.0, max(t[-1] - loc.run_s, 0.0), loc.num_starts)


def start_indices(t: np.ndarray, starts: np.ndarray, k: int, loc) -> np.ndarray:
    """The scans of run ``k`` (times ``t`` since the log's start): ``loc.run_s`` from ``starts[k]`` on; when
    kidnapped, the rest of the run continues from the next start time (another place)."""
    t0 = starts[k]
    idx = np.flatnonzero((t >= t0) & (t <= t0 + loc.run_s))
    if loc.kidnap_at_s > 0:
        t1 = starts[(k + 1) % len(starts)]
        idx = np.concatenate(
            [idx[t[idx] < t0 + loc.kidnap_at_s], np.flatnonzero((t >= t1) & (t <= t1 + loc.run_s - loc.kidnap_at_s))]
        )
    return idx


def run_localize(cfg) -> Path:
    if cfg.localize.map_path:  # your own log in your own map (no ground truth needed)
        return run_in_map(cfg)
    if cfg.localize.run_s is None:
        raise ValueError(
            "localize.run_s=null (to the end of the log) needs localize.map_path; the benchmark "
            "protocol follows each start for localize.run_s seconds"
        )
    with runs.start(cfg, "localize") as run:
        return run.path if run.done else localize_starts(run)


def localize_starts(run: runs.Run) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    m, loc = cfg.mcl, cfg.localize
    log = load_stream(cfg)
    far_m = far_bound_m(cfg, log.info.range_max_m)
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: localization is scored against ground truth, and this log has none")
    check_odometry(log.source, log.odom)
    view, maps, image = build_maps(cfg, device, run.upstream["train"] / "nof.pt" if "train" in run.upstream else None)
    t = log.stamps - log.stamps[0]
    times = start_times(t, loc)
    starts, kidnapped, all_steps = [], loc.kidnap_at_s > 0, []
    if kidnapped and not (0 < loc.kidnap_at_s < loc.run_s and loc.num_starts >= 2):
        raise ValueError(
            f"localize.kidnap_at_s={loc.kidnap_at_s} must lie inside the run (localize.run_s={loc.run_s}) "
            f"and the robot needs another start time to be teleported to (localize.num_starts={loc.num_starts})"
        )
    for k, t0 in enumerate(times):
        pf = build_filter(m, view, log.T_base_laser, log.info.angles_rad, far_m, device, maps)
        pf.rng = np.random.default_rng(m.seed * 1000 + k)
        idx = start_indices(t, times, k, loc)
        if loc.mode == "global":
            pf.init_uniform()
        else:
            known = idx[np.all(np.isfinite(log.ground_truth[idx]), axis=1)]
            if not len(known):  # a tracking start needs a pose to start from
                covered = t[np.all(np.isfinite(log.ground_truth), axis=1)]
                raise ValueError(
                    f"{log.source}: tracking start {k} at {t0:.1f} s has no ground-truth pose to start from within "
                    f"its {loc.run_s:g} s (localize.run_s); this log's ground truth covers "
                    + (f"{covered[0]:.1f}-{covered[-1]:.1f} s" if len(covered) else "no scan")
                    + ": move localize.start_s or lengthen localize.run_s"
                )
            first = known[0]
            pf.init_gaussian(log.ground_truth[first], loc.tracking_std)
        t_run = time.perf_counter()
        # synchronous: every step reads its estimate back; IR-MCL reduces the particles in global runs only
        step_times = []
        est = follow(
            pf,
            log,
            idx,
            m,
            loc.reduce_after_s if loc.mode == "global" else None,
            step_times=step_times,
            progress=f"start {k + 1}/{len(times)}",
        )
        ms_per_scan = 1e3 * (time.perf_counter() - t_run) / len(idx)
        all_steps.extend(step_times)
        stamps = log.stamps[idx]
        cut = int(np.argmax(np.diff(idx) != 1) + 1) if kidnapped else len(idx)  # the first scan after a jump
        if kidnapped:  # a continuous clock over the jump: the second part follows the first
            dt = np.diff(stamps, prepend=stamps[0])
            dt[cut] = np.median(dt[1:cut])
            stamps = stamps[0] + np.cumsum(dt)
        write_tum(out / f"start{k}.tum", stamps, est)
        gt = log.ground_truth[idx]
        write_tum(out / f"ground_truth-start{k}.tum", stamps, gt)  # the truth at the same stamps (for evo)
        metrics = localization_metrics(stamps, est, gt)
        if kidnapped:
            before = localization_metrics(stamps[:cut], est[:cut], gt[:cut])
            recovery = localization_metrics(stamps[cut:], est[cut:], gt[cut:])
            metrics = {
                **metrics,
                "localized_before_kidnap": before["converged"],
                "recovered": bool(before["converged"] and recovery["success"]),
                "recovery_time_s": recovery["time_to_converge_s"],
            }
        starts.append(
            {
                "start_s": float(t0),
                "ms_per_scan": ms_per_scan,
                "steps": len(step_times),
                "ms_per_step_median": 1e3 * float(np.median(step_times)) if step_times else None,
                **metrics,
            }
        )
        print(
            f"start {k} at {t0:.0f} s: "
            + (
                f"converged after {metrics['time_to_converge_s']:.1f} s, RMSE {metrics['location_rmse_cm']:.1f} cm"
                if metrics["converged"]
                else "did not converge"
            )
            + (f"; recovered from the kidnapping: {metrics['recovered']}" if kidnapped else "")
        )
        if k == 0:
            plot_run(
                out / "start0.png",
                view,
                image,
                stamps,
                gt,
                est,
                pf.particles.numpy(),
                metrics["time_to_converge_s"],
                stamps[cut] - stamps[0] if kidnapped else None,
            )
    settings = {**OmegaConf.to_container(m), **OmegaConf.to_container(loc), "far_m": far_m}
    summary = summarise(starts, settings, device)
    # every filter step of every start: the figure to set beside the micro-benchmark (eval.bench mcl), free
    # of what a start costs once (building the filter, loading the kernels, capturing the step's graph)
    summary["ms_per_step_median"] = 1e3 * float(np.median(all_steps)) if all_steps else None
    if all_steps:
        print(
            f"{len(all_steps)} filter steps, median {summary['ms_per_step_median']:.3f} ms per step "
            f"({summary['ms_per_scan_median']:.3f} ms per scan, the starts' median, set up included)"
        )
    out = run.finish({"dataset": cfg.data.name, "summary": summary, "runs": starts, "settings": settings}, device)
    print(f"{cfg.data.name}, {m.weighting} ({loc.mode}): success {summary['successes']}/{len(starts)} -> {out}")
    return out


def summarise(starts: list[dict], s: dict, device: str) -> dict:
    """The summary of a localize run's starts (``s``: its settings, mcl and localize sections together)."""
    ok = [r for r in starts if r["success"]]

    def mean(key, rows):
        vals = [r[key] for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    summary = {
        "weighting": s["weighting"],
        "mode": s["mode"],
        "num_particles": s["num_particles"],
        "map_resolution_m": s["map_resolution_m"],
        "device": device,
        "starts": len(starts),
        "successes": len(ok),
        "success_rate": len(ok) / len(starts),
        "divergences": int(sum(r["divergences"] for r in starts)),
    }
    summary["ms_per_scan_median"] = float(
        np.median([r["ms_per_scan"] for r in starts])
    )  # the first start also compiles
    for key in (
        "location_rmse_cm",
        "yaw_rmse_deg",
        "time_to_converge_s",
        "within_5cm_pct",
        "within_10cm_pct",
        "within_20cm_pct",
        "within_0.5deg_pct",
        "within_1deg_pct",
        "within_2deg_pct",
    ):
        summary[f"{key}_mean"] = mean(key, ok)
    if s["kidnap_at_s"] > 0:
        summary["kidnap_at_s"] = s["kidnap_at_s"]
        summary["recovered"] = int(sum(r["recovered"] for r in starts))
        summary["recovery_time_s_mean"] = mean("recovery_time_s", [r for r in starts if r["recovered"]])
    return summary
