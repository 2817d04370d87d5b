"""The slam stage: ``python -m irmcl_warp.slam +exp=gmapping_intel [slam.num_particles=30 slam.proposal=paper slam.seed=0]``

Runs GMapping's RBPF over the whole log (file order; scans + odometry of the data config) and writes
outputs/<exp>/slam/<proposal>-<resample>-<N>p-seed<k>-<id>/ (irmcl_warp.runs): the best particle's map (map.pgm/.yaml/.png), its
trajectory at every scan (trajectory.tum: the last processed scan's corrected pose + the raw odometry
since then), the N_eff trace (neff.csv) and metrics.json: the relations metric of Kümmerle et al. 2009
where the log has relations, and the trajectory error against the ground truth after a rigid alignment
(the simulator's exact poses, or the matched corrected poses), with the raw odometry scored the same way.

Odometry jumps (steps over data.max_step_m or data.max_speed_mps) are not repaired here: they are counted
in metrics.json (``odometry_jumps``) and passed to the motion model as they are. A scan whose beam count
differs from the first is an error (the readers' data.beam_policy can reject or resample such scans).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import warp as wp
from omegaconf import OmegaConf

from irmcl_warp.geometry import compose, inverse
from irmcl_warp.io import read_relations, resolve, write_tum
from irmcl_warp.io.carmen import gfs_flaser_angles
from irmcl_warp.io.clock import scan_lag as find_scan_lag, scan_lag_note
from irmcl_warp.io.errors import LogDefectWarning
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.defects import count_odometry_jumps
from irmcl_warp.io.groundtruth import g2o_scan_stamps, read_g2o
from irmcl_warp.mapping.grid import OccupancyGrid, laser_bounds
from irmcl_warp.mapping.mapio import save_map
from irmcl_warp import runs
from irmcl_warp.services.data import far_bound_m, load_stream
from irmcl_warp.services.metrics import aligned_error, coverage_warning, relations_error
from irmcl_warp.slam.rbpf import RBPF, per_scan_poses
from irmcl_warp.kernels import SLAM, pick_device
from irmcl_warp.kernels.slam import ParticleMaps


def initial_frame(pose, margin_m: float, res: float):
    """(shape [H, W], origin) of the first map: a square of side 2 margin around the first pose. The maps then
    grow to hold every scan (ParticleMaps.cover), wherever the corrected path goes: a frame drawn around the
    odometry misses it where the odometry drifts (MIT Killian's lies hundreds of metres from its corrected
    path, whose scans fell outside such a frame)."""
    n = max(int(np.ceil(2 * margin_m / res)), 1)
    return (n, n), (float(pose[0]) - margin_m, float(pose[1]) - margin_m)


def filter_frame(cfg, log) -> tuple[np.ndarray, np.ndarray]:
    """(odometry the particles follow, base -> particle-frame transform) for ``slam.frame``: the base's
    odometry and the extrinsic (base), or the laser's odometry and identity (laser, the released code's way)."""
    frame = cfg.slam.get("frame", "base")
    if frame == "base":
        return log.odom, np.asarray(log.T_base_laser, float)
    if frame == "laser":
        return compose(log.odom, log.T_base_laser), np.zeros(3)
    raise ValueError(f"slam.frame={frame!r}: choose base or laser")


def available_memory(device: str) -> int:
    """Bytes the maps may take: the GPU's free memory, or the host's MemAvailable (/proc/meminfo; the physical
    memory where that file is missing)."""
    if device.startswith("cuda"):
        return int(wp.get_device(device).free_memory)
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def maps_memory(log, odom, usable_m: float, resolution_m: float, particles: int) -> tuple[int, int, tuple[int, int]]:
    """(bytes of the particles' maps over the box the scans' end points span on the odometry, the bytes they may
    take at their peak, the cells [W, H] of that box). ParticleMaps holds one vec4 of float32 per cell and
    particle; its frame grows with up to a quarter of slack per side and holds the old and the grown frame at
    once while it grows (the peak). The odometry's box is no bound either way: a SLAM path spans about as much,
    less where the odometry drifted (MIT Killian's box is 2-3 times the building's)."""
    with np.errstate(invalid="ignore"):
        ended = np.where(log.ranges_m < usable_m, log.ranges_m, np.nan)  # beams that end on something
    x0, y0, x1, y1 = laser_bounds(compose(odom, log.T_base_laser), ended, log.info.angles_rad, usable_m, margin_m=1.0)
    W, H = int(np.ceil((x1 - x0) / resolution_m)), int(np.ceil((y1 - y0) / resolution_m))
    box = particles * W * H * 16
    return box, int(2 * 1.25**2 * box), (W, H)


def check_maps_fit(cfg, log, odom, usable_m: float, device: str) -> None:
    """Refuse a SLAM run whose maps cannot fit before it starts (a hospital-sized log filled 13 GB and died at 8 %
    of its scans), naming the estimate and a resolution that fits; warn where the peak may not fit."""
    s = cfg.slam
    box, peak, (W, H) = maps_memory(log, odom, usable_m, s.resolution_m, s.num_particles)
    have = available_memory(device)
    gib = 2.0**30
    if box > 0.9 * have:
        fits = s.resolution_m * np.sqrt(box / (0.3 * have))  # the area in cells goes as 1 / resolution^2
        raise ValueError(
            f"slam: {s.num_particles} particle maps over the {W} x {H} cells the log spans at "
            f"{s.resolution_m} m (on its odometry) need about {box / gib:.1f} GiB, {have / gib:.1f} GiB is "
            f"free on {device}: set slam.resolution_m={np.ceil(fits * 100) / 100:g} or fewer slam.num_particles"
        )
    if peak > 0.5 * have:
        print(
            f"warning: slam: the particle maps take about {box / gib:.1f} GiB over the log's extent and may reach "
            f"{peak / gib:.1f} GiB while they grow, of the {have / gib:.1f} GiB free on {device}",
            file=sys.stderr,
        )


def start_filter(cfg, log, device: str) -> tuple[RBPF, np.ndarray]:
    """The RBPF of ``cfg.slam`` for ``log``, started on its first scan (the maps grow as the scans need), and
    the odometry its steps take (``filter_frame``)."""
    s = cfg.slam
    far_m = far_bound_m(cfg, log.info.range_max_m)
    odom, T = filter_frame(cfg, log)
    check_maps_fit(cfg, log, log.odom, far_m, device)
    shape, origin = initial_frame(odom[0], s.map_margin_m, s.resolution_m)
    angles = gfs_flaser_angles(log.ranges_m.shape[1]) if s.get("beam_angles", "log") == "gfs" else log.info.angles_rad
    rbpf = RBPF(s, shape, origin, T, angles, far_m, device)
    rbpf.start(odom[0], log.ranges_m[0], float(log.stamps[0]))
    return rbpf, odom


def best_map(rbpf: RBPF, particle: int, log=None, occ_thresh: float = 0.25, margin_cells: int = 20) -> OccupancyGrid:
    """The particle's map as an occupancy grid cropped to its visited cells: hits / visits above GMapping's
    occ_thresh (0.25, slam_gmapping) occupied, below it free, unvisited unknown. Where the particles' maps
    hold end points only (slam.generate_map false), the map is cast again, free space included, from the
    particle's path and the processed scans of ``log`` (what the ROS wrapper publishes)."""
    occ = rbpf.maps.occupancy(particle)
    if not rbpf.integrator.free_space:
        if log is None:
            raise ValueError("best_map: the particles' maps hold end points only; pass the log to cast the map")
        _, H, W = rbpf.maps.shape
        full = ParticleMaps(
            1, (H, W), (float(rbpf.maps.origin[0]), float(rbpf.maps.origin[1])), rbpf.maps.res, device=rbpf.device
        )
        cast = SLAM.build("integrate", far_m=rbpf.integrator.far_m, line=rbpf.cfg.line, device=rbpf.device)
        scans, poses = rbpf.trajectory(particle)
        pose = wp.zeros(1, dtype=wp.vec3, device=rbpf.device)
        ranges = wp.zeros(log.ranges_m.shape[1], dtype=wp.float32, device=rbpf.device)
        for k, p in zip(scans, poses):
            pose.assign(wp.array(p[None].astype(np.float32), dtype=wp.vec3, device=rbpf.device))
            ranges.assign(log.ranges_m[k].astype(np.float32))
            cast(full, pose, rbpf.T_base_laser, ranges, rbpf.angles)
        occ = full.occupancy(0)
    logodds = np.where(occ < 0, 0.0, np.where(occ > occ_thresh, 2.0, -2.0)).astype(np.float32)
    iy, ix = np.nonzero(occ >= 0)
    if len(ix) == 0:
        iy, ix = np.array([0]), np.array([0])
    y0, x0 = max(iy.min() - margin_cells, 0), max(ix.min() - margin_cells, 0)
    y1, x1 = min(iy.max() + margin_cells + 1, occ.shape[0]), min(ix.max() + margin_cells + 1, occ.shape[1])
    origin = (float(rbpf.maps.origin[0]) + x0 * rbpf.maps.res, float(rbpf.maps.origin[1]) + y0 * rbpf.maps.res)
    return OccupancyGrid(logodds[y0:y1, x0:x1], origin, rbpf.maps.res)


def relation_stamps(cfg, log) -> np.ndarray:
    """The stamps the relations refer to: the log's own, or (data.relation_stamps_path, MIT Killian) the
    true stamps of the g2o keyframes with the same ranges, NaN for the other scans."""
    if not cfg.data.get("relation_stamps_path"):
        return log.stamps
    stamps = g2o_scan_stamps(read_g2o(resolve(cfg.data.relation_stamps_path)), log.ranges_m)
    print(f"{cfg.data.name}: {np.isfinite(stamps).sum()} scans carry a true stamp from {cfg.data.relation_stamps_path}")
    return stamps


def run_slam(cfg) -> Path:
    with runs.start(cfg, "slam") as run:
        return run.path if run.done else map_log(run)


def scan_lag(cfg, log, scans: np.ndarray, poses: np.ndarray) -> dict:
    """Do the processed scans' matched poses turn as the odometry does at their stamps? (io/clock.py: a lag says
    the scans' stamps and the odometry's clock disagree; the same check as on ground truth, here for a log that has
    none.) Warns naming the log and ``data.scan_time_offset_s``; returns what metrics.json keeps."""
    applied = float(cfg.data.get("scan_time_offset_s") or 0.0)
    stamps = np.asarray(log.stamps, float)[np.asarray(scans, int)]
    lag = find_scan_lag(log.stamps, log.odom, stamps, poses)
    if lag is None:
        return {"steps": 0, "applied_s": applied, "warned": False}
    note = scan_lag_note(log.stamps, log.odom, stamps, poses, applied, lag)
    if note:
        try:
            where = resolve(cfg.data.path) if cfg.data.path else cfg.data.name
        except FileNotFoundError:  # (a log given as arrays: its path as configured)
            where = cfg.data.path
        warnings.warn(
            f"{where}: GMapping's matched poses of its processed scans: {note}", LogDefectWarning, stacklevel=2
        )
    return {**dataclasses.asdict(lag), "applied_s": applied, "warned": bool(note)}


def map_log(run: runs.Run) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    s = cfg.slam
    log = load_stream(cfg)
    jumps = count_odometry_jumps(log.stamps, log.odom, cfg.data.max_speed_mps, cfg.data.max_step_m)
    if jumps:  # documented handling: kept as the motion model's input, counted in metrics.json
        print(
            f"{cfg.data.name}: {jumps} odometry steps jump (over {cfg.data.max_step_m} m or {cfg.data.max_speed_mps} "
            f"m/s); the motion model takes them as they are (its noise grows with the step), so expect a broken "
            f"map there; the derived logs of ../shared/data repair known jumps"
        )
    rbpf, odom = start_filter(cfg, log, device)
    neff_rows, t0 = [], time.perf_counter()
    try:
        from tqdm import tqdm

        bar = tqdm(range(1, len(log)), desc=f"{cfg.data.name} {s.proposal}", unit="scan", mininterval=1.0)
    except ImportError:  # pragma: no cover
        bar = range(1, len(log))
    for k in bar:
        st = rbpf.step(k, odom[k], log.ranges_m[k], float(log.stamps[k]))
        if st.processed:
            neff_rows.append((k, st.neff, int(st.resampled), st.match_rounds))
            if hasattr(bar, "set_postfix"):
                bar.set_postfix(processed=len(neff_rows), particles=rbpf.P, neff=f"{st.neff:.1f}", refresh=False)
    wall = time.perf_counter() - t0
    best = rbpf.best_particle()
    scans, poses = rbpf.trajectory(best)
    every = per_scan_poses(np.arange(len(log)), np.asarray(scans), poses, odom)
    if s.frame == "laser":  # the laser's poses carried: written as the base's, as in every run's files
        every = compose(every, inverse(np.asarray(log.T_base_laser, float)))
    write_tum(out / "trajectory.tum", log.stamps, every)
    atomic_write_bytes(
        out / "neff.csv",
        ("scan,neff,resampled,match_rounds\n" + "".join(f"{k},{n:.4f},{r},{m}\n" for k, n, r, m in neff_rows)).encode(),
    )
    save_map(best_map(rbpf, best, log), out / "map")
    lag = scan_lag(cfg, log, np.asarray(scans), poses)
    metrics = {
        "dataset": cfg.data.name,
        "particles": s.num_particles,
        "proposal": s.proposal,
        "resample": s.resample,
        "seed": s.seed,
        "device": device,
        "scans": len(log),
        "processed_scans": len(scans),
        "odometry_jumps": int(jumps),
        "resamplings": int(sum(r for _, _, r, _ in neff_rows)),
        "wall_time_s": wall,
        "map_cells": list(rbpf.maps.shape[1:]),
        "map_grown": rbpf.maps.grown,
        "time_s": dict(rbpf.timing),
        "ms_per_processed_scan": {k: 1e3 * v / max(len(scans) - 1, 1) for k, v in rbpf.timing.items()},
        "settings": OmegaConf.to_container(s),
        "scan_lag": lag,
    }
    if cfg.data.relations_path:
        try:
            rel = read_relations(resolve(cfg.data.relations_path))
            stamps = relation_stamps(cfg, log)
            # the relations are motions of the scans, i.e. of the laser: both paths are carried into its frame
            metrics["relations_frame"] = {"frame": "laser", "T_base_laser": [float(v) for v in log.T_base_laser]}
            metrics["relations"] = relations_error(stamps, compose(every, log.T_base_laser), rel)
            metrics["relations_odometry"] = relations_error(stamps, compose(log.odom, log.T_base_laser), rel)
            shout = coverage_warning(metrics["relations"], f"{cfg.data.name} ({cfg.data.relations_path})")
            if shout:
                print(shout, file=sys.stderr)
        except FileNotFoundError as e:
            metrics["relations"] = f"not scored: {e}"
    if log.ground_truth is not None:
        # the odometry frame differs from the ground truth's: both are aligned rigidly before scoring
        metrics["trajectory"] = aligned_error(every, log.ground_truth)
        metrics["trajectory_odometry"] = aligned_error(log.odom, log.ground_truth)
    out = run.finish(metrics, device)
    rel = metrics.get("relations")
    print(
        f"{cfg.data.name}: {len(scans)} of {len(log)} scans processed in {wall:.1f} s, "
        f"{metrics['resamplings']} resamplings"
        + (
            f"; relations {rel['trans_abs_mean_m']:.3f} m / {rel['rot_abs_mean_deg']:.2f} deg (odometry "
            f"{metrics['relations_odometry']['trans_abs_mean_m']:.3f} m)"
            if isinstance(rel, dict)
            else ""
        )
        + (
            f"; ATE {metrics['trajectory']['ate_rmse_m']:.3f} m (odometry "
            f"{metrics['trajectory_odometry']['ate_rmse_m']:.3f} m)"
            if "trajectory" in metrics
            else ""
        )
        + f" -> {out}"
    )
    return out


__all__ = ["run_slam"]
