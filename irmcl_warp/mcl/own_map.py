"""The localize stage on your own log and map (``localize.map_path``): no ground truth needed.

    python -m irmcl_warp.localize data=bag data.path=run.bag localize.map_path=map.yaml mcl.weighting=likelihood_field
    python -m irmcl_warp.localize ... localize.initial_pose=[2.0,1.5,0.3]         # track from a pose, as RViz's
    python -m irmcl_warp.localize ... mcl.weighting=nog_raymarch localize.nof_path=nof.pt   # IR-MCL on your NOF

The map is a ROS map_server YAML (+ PGM or PNG) or a ``.npz`` grid (what the slam stage writes); the filter
starts uniform over its free cells, or around ``localize.initial_pose`` with ``localize.tracking_std``. One
run over ``localize.start_s`` .. ``+ run_s`` (None: to the end). Writes outputs/<exp>/localize/<weighting>-
<global|pose>-<particles>-in-<map>-<id>/ (the id follows the map's and the NOF's content, so two maps both
called map.yaml are two runs): trajectory.tum,
spread.csv (the particles' spread and N_eff over time), run.png (the map, the trajectory, the final particles,
the spread over time), particles.gif (the particles on the map as the run goes on) and metrics.json (where
the log has ground truth, the trajectory error after a rigid alignment to it: your map need not share its frame).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.config import CONF_DIR, own_map_calibration, own_map_lost_rule_settings
from irmcl_warp.geometry import align_rigid, compose, inverse
from irmcl_warp.io import resolve, write_tum
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.mcap_run import write_run_mcap
from irmcl_warp.io.plausibility import check_odometry
from irmcl_warp.mapping.mapio import load_map, occupancy_data
from irmcl_warp.mcl.confidence import Confidence, FeatureTracker, Judge, ScanAgreement, search_grid
from irmcl_warp.mcl.online import filter_in_map
from irmcl_warp.mcl.track import follow, window
from irmcl_warp.mcl.worlds import LostRule, RelocalizePlaces
from irmcl_warp import runs
from irmcl_warp.services.data import far_bound_m, load_stream
from irmcl_warp.services.metrics import CONVERGED_FOR_S, CONVERGED_M, aligned_error, localization_metrics
from irmcl_warp.services.plots import animate_particles, plot_own_map
from irmcl_warp.kernels import pick_device

FRAMES = 60  # animation frames over the run


CONFIDENT_ABOVE = 0.8  # as worlds.confident_above: a run ends "localized" only at or above it


def calibrated_judge(cfg, grid, log) -> tuple[Judge | None, str]:
    """(the confidence judge for this run, what it is or why there is none). A calibration holds for the filter
    it was fitted on: the worlds stage's (``mcl=amcl``, conf/mcl/amcl.yaml) at the calibration's particle count."""
    m = cfg.mcl
    path = own_map_calibration(m.weighting, m.num_particles)
    preset = OmegaConf.load(CONF_DIR / "mcl" / "amcl.yaml")
    differ = sorted(k for k in preset if k != "num_particles" and m.get(k) != preset[k])
    if path is None or differ:
        why = (
            f"no calibration for {m.weighting} with {m.num_particles} particles"
            if path is None
            else f"the filter differs from the calibrated one (mcl=amcl) in {', '.join(differ)}"
        )
        return None, f"no confidence: {why}"
    agreement = ScanAgreement.of_grid(grid, m.field_occ_threshold)
    conf = Confidence.load(path)
    tracker = FeatureTracker(  # tracking rivals as the runs it was fitted on did
        agreement,
        refine_rivals=conf.tracker["refine_rivals"],
        search_poses=search_grid(grid) if conf.tracker["search_every"] > 0 else None,
        search_every=conf.tracker["search_every"],
        mode_pose=conf.tracker["mode_pose"],
    )
    judge = Judge(tracker, conf, log.info.angles_rad, log.T_base_laser)
    return judge, f"confidence calibrated by {path.name}"


def converged_index(stamps, est, gt) -> int | None:
    """The first scan from which the estimate stays within the benchmark protocol's CONVERGED_M of the truth
    for CONVERGED_FOR_S (services.metrics.localization_metrics), the two frames tied by a rigid alignment of the
    run's second half (where a run that localizes has converged); None when it never does."""
    half = len(stamps) // 2
    if np.sum(np.all(np.isfinite(est[half:]), 1) & np.all(np.isfinite(gt[half:]), 1)) < 3:
        return None
    moved = compose(align_rigid(est[half:], gt[half:]), est)
    has = np.all(np.isfinite(moved), 1) & np.all(np.isfinite(gt), 1)
    if has.sum() < 2:
        return None
    t_conv = localization_metrics(stamps, moved, gt)["time_to_converge_s"]
    if t_conv is None:
        return None
    return int(np.flatnonzero(has)[np.searchsorted(stamps[has] - stamps[has][0], t_conv - 1e-9)])


def run_in_map(cfg) -> Path:
    map_file = resolve(cfg.localize.map_path)
    load_map(map_file)  # a malformed map is an error naming it before anything else
    with runs.start(cfg, "localize") as run:
        return run.path if run.done else localize_in_map(run, map_file)


def localize_in_map(run: runs.Run, map_file: Path) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    m, loc = cfg.mcl, cfg.localize
    log = load_stream(cfg)
    far_m = far_bound_m(cfg, log.info.range_max_m)
    pf, grid = filter_in_map(
        map_file, m, log.T_base_laser, log.info.angles_rad, far_m, device, loc.nof_path, runs.cache_dir(cfg, "nog")
    )  # the online localizer's filter (mcl/online.py)
    if loc.initial_pose is not None:
        pose = np.asarray(list(loc.initial_pose), np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"localize.initial_pose={list(loc.initial_pose)}: expected [x, y, yaw] in the map")
        pf.init_gaussian(pose, list(loc.tracking_std))
    else:
        pf.init_uniform()
    t = log.stamps - log.stamps[0]
    idx = window(log, loc.start_s, loc.run_s, "localize")
    check_odometry(log.source, log.odom[idx])  # a corrupt jump would carry the estimate off the map
    every = max(1, len(idx) // FRAMES)
    spread, frames = np.zeros((len(idx), 2)), []
    keep = np.random.default_rng(0)

    cloud = {}  # scan position -> particles [<= 1500, 3]: the animation's frames and the MCAP's /particlecloud

    def watch(j, f):
        spread[j] = f.spread, f.num_particles
        if j % every == 0 or j == len(idx) - 1:
            p = f.particles.numpy()
            cloud[j] = p[keep.permutation(len(p))[:1500]]
            frames.append((float(t[idx[j]]), cloud[j][:, :2]))

    first = pf.particles.numpy()
    frames.append((float(t[idx[0]]), first[keep.permutation(len(first))[:1500], :2]))  # the start, before any scan
    t_run = time.perf_counter()
    covariances, confidences = [], []
    judge, judged = calibrated_judge(cfg, grid, log)
    lost_rule, places = None, None
    if judge is not None:  # the worlds stage's rule, and where a relocalization looks first
        w = own_map_lost_rule_settings()
        lost_rule = LostRule(w)
        search = judge.tracker.search_poses
        if search is None and w.relocalize_places > 0:
            search = search_grid(grid)
        places = RelocalizePlaces(w, judge.tracker.agreement, search, m.global_candidates)
    lost_at_s = []
    est = follow(
        pf,
        log,
        idx,
        m,
        loc.reduce_after_s if loc.initial_pose is None else None,
        watch,
        covariances=covariances,
        progress=f"localize {Path(str(log.source)).name}",
        judge=judge,
        confidences=confidences,
        report_pose=loc.report_pose,  # with the judge: the pose its confidence is about
        lost_rule=lost_rule,
        relocalize=loc.relocalize,
        lost_at_s=lost_at_s,
        places=places,
    )
    beside = places.describe() if places is not None else ""
    again = "; starting again from a uniform spread" + (f" with {beside}" if beside else "")
    for t_lost in lost_at_s:
        print(
            f"{log.source}: lost {t_lost:.1f} s into the run (the confidence stayed low, or the scan left the map)"
            + (again if loc.relocalize else "")
        )
    ms_per_scan = 1e3 * (time.perf_counter() - t_run) / len(idx)
    stamps = log.stamps[idx]
    write_tum(out / "trajectory.tum", stamps, est)
    atomic_write_bytes(
        out / "spread.csv",
        (
            "stamp,spread_m,particles,confidence\n"
            + "".join(f"{s:.6f},{a:.4f},{int(n)},{c:.4f}\n" for s, (a, n), c in zip(stamps, spread, confidences))
        ).encode(),
    )
    settled = np.flatnonzero(spread[:, 0] < 0.3)
    metrics = {
        "log": str(log.source),
        "map": str(map_file),
        "weighting": m.weighting,
        "device": device,
        "start": "initial pose" if loc.initial_pose is not None else "global",
        "scans": int(len(idx)),
        "duration_s": float(stamps[-1] - stamps[0]),
        "ms_per_scan": ms_per_scan,
        "final_spread_m": float(spread[-1, 0]),
        "spread_below_0.3m_after_s": float(stamps[settled[0]] - stamps[0]) if len(settled) else None,
        "confidence": judged,
        "confidence_at_end": None if np.isnan(confidences[-1]) else confidences[-1],
        "localized_at_end": None if np.isnan(confidences[-1]) else bool(confidences[-1] >= CONFIDENT_ABOVE),
        # when the worlds stage's rule declared the robot lost (s since the first scan); each a uniform start again
        # with localize.relocalize
        "lost_at_s": lost_at_s if judge is not None else None,
        "relocalized": len(lost_at_s) if (judge is not None and loc.relocalize) else 0,
    }
    gt, gt_in_map = log.ground_truth[idx] if log.ground_truth is not None else None, None
    if gt is not None and np.isfinite(gt).all(1).sum() >= 3:
        # a map of your own need not share the ground truth's frame (a SLAM map starts where its drive did):
        # the estimate is scored after a rigid alignment to the ground truth, as evo's --align, from the time
        # it converged on; the run as a whole, the global start's transient included, is reported beside it.
        # ground_truth.tum holds the truth at the same stamps (for evo).
        write_tum(out / "ground_truth.tum", stamps, gt)
        metrics["aligned_whole_run"] = aligned_error(est, gt)
        s = converged_index(stamps, est, gt)
        if s is not None:
            metrics["aligned_to_ground_truth"] = {
                **aligned_error(est[s:], gt[s:]),
                "from_s": float(stamps[s] - stamps[0]),
            }
            gt_in_map = compose(inverse(align_rigid(est[s:], gt[s:])), gt)  # drawn in the map
        else:
            metrics["aligned_to_ground_truth"] = None
            print(
                f"{log.source}: the estimate never converged on the ground truth (error below "
                f"{CONVERGED_M} m for {CONVERGED_FOR_S:g} s after a rigid alignment): no score after convergence"
            )
    image = np.where(grid.known, grid.probability, 0.5).astype(np.float32)
    extent = (
        grid.origin_xy[0],
        grid.origin_xy[0] + grid.shape[1] * grid.resolution_m,
        grid.origin_xy[1],
        grid.origin_xy[1] + grid.shape[0] * grid.resolution_m,
    )
    plot_own_map(out / "run.png", image, extent, stamps, est, pf.particles.numpy(), spread[:, 0], gt_in_map)
    animate_particles(out / "particles.gif", image, extent, frames, stamps, est)
    # the run for Foxglove / RViz: replay/replay.mcap (a ROS 2 bag folder; io/mcap_run.py lists the topics)
    write_run_mcap(
        out / "replay",
        log=log,
        idx=idx,
        est=est,
        grid=grid,
        map_data=occupancy_data(grid),
        covariances=np.array(covariances),
        particle_frames=cloud.items(),
        ground_truth_in_map=gt_in_map,
    )
    out = run.finish(metrics, device)
    c = metrics["confidence_at_end"]
    verdict = (
        f"{judged}"
        if c is None
        else f"localized, confidence {c:.2f}"
        if metrics["localized_at_end"]
        else f"NOT localized: confidence {c:.2f} at the end, below {CONFIDENT_ABOVE}"
    )
    print(
        f"{log.source}: {len(idx)} scans in {map_file} ({metrics['start']} start); particle spread "
        f"{metrics['final_spread_m']:.2f} m at the end; {verdict} -> {out}"
    )
    return out
