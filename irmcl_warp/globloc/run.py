"""``python -m irmcl_warp.globloc +exp=globloc_corridor``: seeded lidar + camera global localization runs on
a simulated world, every method on identical sensor streams.

An offline mapping run (visiting every room) records the occupancy grid of the world and keyframes (RGB-D +
pose every ``keyframe_every_m`` / ``keyframe_every_deg``, Gist described). Each query run starts at a random
place, with another session's lighting, the furniture moved, and optionally a kidnapping half-way (the
robot is carried to another start; the odometry does not see it). Methods:

* ``lidar_mcl``: global MCL (uniform start, AMCL's recovery), likelihood field on the grid;
* ``camera_only``: at each camera frame the retrieved pose with the most PnP inliers, odometry in between;
* ``paper``: Gist top-N -> k-means clusters -> ORB + PnP per cluster -> re-ranked by Scan2Map; the first
  winner starts MCL tracking, and a winner outside the reach of the tracked pose (``max_speed_mps`` since
  the last frame) with a better Scan2Map, confirmed by the next frame's winner (moved by the odometry in
  between), re-initialises it (the relocalization trigger);
* ``mcl_seeded``: global MCL whose particles are partly re-drawn around the camera's hypotheses at each
  camera frame.

Writes outputs/<exp>/globloc-<scenario>/: metrics.json (per method: success rate with a Wilson 95 %
interval, time and distance until localized, kidnap recovery, false relocalizations per hour, accuracy
after convergence), per run and method the trajectory (TUM), and a figure of the first kidnapped run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.geometry import compose, relative, wrap_angle
from irmcl_warp.globloc.database import build_database, cluster_candidates, describe, keyframe_indices
from irmcl_warp.globloc.gist import Gist
from irmcl_warp.globloc.methods import laser_angles, run_method
from irmcl_warp.globloc.pnp import OrbPnP
from irmcl_warp.globloc.scan2map import Scan2Map
from irmcl_warp.io import write_tum
from irmcl_warp import runs
from irmcl_warp.sim.camera import Camera, Session, appearance
from irmcl_warp.sim.trajectory import follow, noisy_odometry, waypoints
from irmcl_warp.sim.world import office
from irmcl_warp.kernels import SIM, pick_device

METHODS = ("lidar_mcl", "camera_only", "paper", "mcl_seeded")


@dataclass
class Stream:
    """One query run: true poses, odometry, scans and camera frames (every ``cam_every`` scans)."""

    stamps: np.ndarray
    truth: np.ndarray
    odom: np.ndarray
    ranges: np.ndarray
    cam_idx: np.ndarray
    rgb: np.ndarray
    kidnap_idx: int  # first scan after the kidnapping (-1: none)


def world_of(cfg):
    s = cfg.sim
    return office(
        s.seed,
        s.width_m,
        s.height_m,
        s.corridor_width_m,
        s.room_min_width_m,
        s.room_max_width_m,
        s.door_width_m,
        s.furniture_per_room,
        s.repetitive,
    )


def moved_furniture(world, rng, shift_m: float):
    """The world with every furniture box shifted by up to ``shift_m`` (same colours, new places)."""
    import copy

    w = copy.deepcopy(world)
    n = w.n_walls
    for b in range(n, len(w.segments), 4):  # boxes are 4 consecutive segments
        w.segments[b : b + 4] += np.tile(rng.uniform(-shift_m, shift_m, 2), 2)
    return w


def grid_of(world, res: float, margin: float = 1.0):
    shape = (int(np.ceil((world.height_m + 2 * margin) / res)), int(np.ceil((world.width_m + 2 * margin) / res)))
    origin = (-margin, -margin)
    return SIM.build("rasterize")(world.segments, origin, res, shape), origin


def make_stream(cfg, world, look, rng, k: int, device: str) -> Stream:
    g, s = cfg.globloc, cfg.sim
    dt = 1.0 / s.rate_hz

    def piece(seed, duration):
        r = np.random.default_rng(seed)
        pts = waypoints(world, r, 1.0)
        start = int(r.integers(0, len(pts) - 2))
        return follow(np.concatenate([pts[start:], pts[:start]]), s.speed_mps, s.turn_rate_rps, s.rate_hz, duration)

    kidnap = g.kidnap_at_s > 0
    first = piece(cfg.globloc.seed * 1000 + k, g.kidnap_at_s if kidnap else g.run_s)
    parts = [first] + ([piece(cfg.globloc.seed * 1000 + k + 500, g.run_s - g.kidnap_at_s)] if kidnap else [])
    truth = np.concatenate(parts)
    odom = noisy_odometry(parts[0], list(s.odom_alphas), rng)
    if kidnap:  # the odometry continues as if the robot had stood still across the jump
        more = noisy_odometry(parts[1], list(s.odom_alphas), rng)
        odom = np.concatenate([odom, compose(odom[-1], relative(more[:1], more))])
    query_world = moved_furniture(world, rng, g.moved_furniture_m)
    lidar = SIM.build(
        "segment_lidar",
        segments=query_world.segments,
        angles_rad=laser_angles(cfg),
        range_max_m=s.range_max_m,
        noise_std_m=s.range_noise_std_m,
        dropout_prob=s.dropout_prob,
        device=device,
    )
    ranges = lidar.scan(compose(truth, np.array([s.laser_x_m, 0.0, 0.0])), seed=int(rng.integers(1 << 30)))
    cam_every = max(1, int(round(g.camera_every_s * s.rate_hz)))
    cam_idx = np.arange(0, len(truth), cam_every)
    camera = Camera(query_world.segments, look, device=device)
    rgb, _ = camera.render(truth[cam_idx], Session.draw(rng, g.lighting))
    return Stream(np.arange(len(truth)) * dt, truth, odom, ranges, cam_idx, rgb, len(first) if kidnap else -1)


class Hypotheses:
    """Camera hypotheses of one query frame: per cluster the best PnP pose, its inliers and Scan2Map."""

    def __init__(self, cfg, db, camera: Camera, scan2map: Scan2Map):
        g = cfg.globloc
        self.cfg, self.db, self.scan2map = cfg, db, scan2map
        self.gist = Gist(tuple(g.gist_size), g.gist_blocks, tuple(g.gist_orientations))
        self.pnp = OrbPnP(camera.K, 1.0, camera.T_base_cam, g.orb_features, g.ratio, g.min_inliers)
        self.kf_features = {}
        self.timing = {"gist": 0.0, "retrieval": 0.0, "pnp": 0.0, "scan2map": 0.0, "frames": 0}

    def __call__(self, rgb, ranges) -> list[tuple[np.ndarray, int, float]]:
        g, t = self.cfg.globloc, time.perf_counter()
        q = describe(rgb, self.gist)[0]
        t1 = time.perf_counter()
        clusters = cluster_candidates(self.db, self.db.retrieve(q, g.top_n), g.clusters, g.cluster_space)
        t2 = time.perf_counter()
        feats, out = self.pnp.features(rgb), []
        for members in clusters:
            best = None
            for i in members[: g.pnp_per_cluster]:
                if i not in self.kf_features:
                    self.kf_features[i] = self.pnp.features(self.db.rgb[i])
                r = self.pnp.solve(feats, None, self.db.depth[i], self.db.poses[i], self.kf_features[i])
                if r.pose is not None and (best is None or r.inliers > best[1]):
                    best = (r.pose, r.inliers)
            if best is not None:
                out.append(best)
        t3 = time.perf_counter()
        scored = []
        if out:
            s = self.scan2map(
                np.array([p for p, _ in out]), (self.cfg.sim.laser_x_m, 0.0, 0.0), ranges, laser_angles(self.cfg)
            )
            scored = [(p, n, float(v)) for (p, n), v in zip(out, s)]
        t4 = time.perf_counter()
        for key, a, b in (("gist", t, t1), ("retrieval", t1, t2), ("pnp", t2, t3), ("scan2map", t3, t4)):
            self.timing[key] += b - a
        self.timing["frames"] += 1
        return scored


def localized_mask(est, truth, trans_m: float, rot_deg: float) -> np.ndarray:
    e = np.hypot(est[:, 0] - truth[:, 0], est[:, 1] - truth[:, 1])
    r = np.degrees(np.abs(wrap_angle(est[:, 2] - truth[:, 2])))
    return np.isfinite(e) & (e < trans_m) & (r < rot_deg)


def settle_index(ok: np.ndarray) -> int:
    """First index from which ``ok`` holds to the end (-1: never, or not at the end)."""
    if len(ok) == 0 or not ok[-1]:
        return -1
    bad = np.flatnonzero(~ok)
    return int(bad[-1] + 1) if len(bad) else 0


def score_run(est, st: Stream, relocs, g) -> dict:
    ok = localized_mask(est, st.truth, g.success_trans_m, g.success_rot_deg)
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(st.truth[:, :2], axis=0).T))])
    end1 = st.kidnap_idx if st.kidnap_idx > 0 else len(est)
    j = settle_index(ok[:end1])
    out = {
        "localized": j >= 0,
        "time_to_localize_s": float(st.stamps[j] - st.stamps[0]) if j >= 0 else None,
        "distance_to_localize_m": float(path[j]) if j >= 0 else None,
    }
    if j >= 0:
        e = np.hypot(*(est[j:end1, :2] - st.truth[j:end1, :2]).T)
        out["rmse_after_m"] = float(np.sqrt(np.mean(e**2)))
    if st.kidnap_idx > 0:
        k = settle_index(ok[st.kidnap_idx :])
        out["recovered"] = k >= 0
        out["recovery_time_s"] = float(st.stamps[st.kidnap_idx + k] - st.stamps[st.kidnap_idx]) if k >= 0 else None
        out["detected"] = any(r >= st.kidnap_idx for r in relocs)
    # a relocalization while the estimate was right (and no kidnapping just before) is a false one
    false = [r for r in relocs if r > 0 and ok[r - 1] and not (0 < st.kidnap_idx <= r < st.kidnap_idx + 50)]
    out["false_relocalizations"] = len(false)
    out["relocalizations"] = len(relocs)
    return out


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return (float("nan"), float("nan"))
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (float(max(0.0, c - h)), float(min(1.0, c + h)))


def summarise(rows: list, hours: float) -> dict:
    n = len(rows)
    k = sum(r["localized"] for r in rows)
    out = {
        "runs": n,
        "localized": k,
        "success_rate": k / n if n else float("nan"),
        "success_ci95": wilson(k, n),
        "false_relocalizations_per_hour": sum(r["false_relocalizations"] for r in rows) / max(hours, 1e-9),
    }
    for key in ("time_to_localize_s", "distance_to_localize_m", "rmse_after_m", "recovery_time_s"):
        v = [r[key] for r in rows if r.get(key) is not None]
        out[f"mean_{key}"] = float(np.mean(v)) if v else None
    if rows and "recovered" in rows[0]:
        out["recovered"] = sum(r["recovered"] for r in rows)
        out["recovery_ci95"] = wilson(out["recovered"], n)
        out["detected"] = sum(r["detected"] for r in rows)
    return out


def run_globloc(cfg) -> Path:
    bad = [m for m in cfg.globloc.methods if m not in METHODS]
    if bad:
        raise ValueError(f"globloc.methods: unknown {bad}; choose from {list(METHODS)}")
    with runs.start(cfg, "globloc") as run:
        return run.path if run.done else localize_runs(run)


def localize_runs(run: runs.Run) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    g, s = cfg.globloc, cfg.sim
    rng = np.random.default_rng(g.seed)
    world = world_of(cfg)
    look = appearance(world, s.seed, g.lookalike_share)
    grid, origin = grid_of(world, g.map_resolution_m)
    # the offline mapping run: every room, the mapping session's light, the furniture where it was
    mapping = follow(waypoints(world, np.random.default_rng(s.seed), 1.0), s.speed_mps, s.turn_rate_rps, s.rate_hz)
    kf = keyframe_indices(mapping, g.keyframe_every_m, np.radians(g.keyframe_every_deg))
    camera = Camera(world.segments, look, device=device)
    t0 = time.perf_counter()
    rgb, depth = camera.render(mapping[kf], Session(seed=s.seed))
    t_render = time.perf_counter() - t0
    gist = Gist(tuple(g.gist_size), g.gist_blocks, tuple(g.gist_orientations))
    db = build_database(mapping[kf], rgb, depth, gist)
    print(
        f"globloc: {len(db)} keyframes over {len(mapping) / s.rate_hz:.0f} s of mapping run "
        f"(rendered in {t_render:.1f} s on {device})"
    )
    scan2map = Scan2Map(grid, origin, g.map_resolution_m, g.scan2map)
    hyp = Hypotheses(cfg, db, camera, scan2map)
    rows = {m: [] for m in g.methods}
    first_run = {}  # run 0's position error over time per method, for eval.plots
    try:
        from tqdm import tqdm

        loop = tqdm(range(g.runs), desc=f"globloc {g.scenario}", unit="run")
    except ImportError:  # pragma: no cover
        loop = range(g.runs)
    for k in loop:
        st = make_stream(cfg, world, look, rng, k, device)
        hyps = [hyp(st.rgb[j], st.ranges[i]) for j, i in enumerate(st.cam_idx)]
        for m in g.methods:
            est, relocs = run_method(m, cfg, st, hyps, grid, origin, device, np.random.default_rng(g.seed * 7 + k))
            write_tum(out / f"run{k}-{m}.tum", st.stamps, est)  # no estimate yet: no line
            rows[m].append(score_run(est, st, relocs, g))
            if k == 0:
                err = np.hypot(*(est[:, :2] - st.truth[:, :2]).T)
                first_run[m] = {
                    "error_m": [None if not np.isfinite(e) else round(float(e), 4) for e in err],
                    "relocalized_at": [int(r) for r in relocs],
                }
                first_run["stamps_s"] = [round(float(t), 3) for t in st.stamps]
                first_run["kidnap_index"] = int(st.kidnap_idx)
    hours = g.runs * g.run_s / 3600.0
    frames = max(hyp.timing["frames"], 1)
    metrics = {
        "scenario": g.scenario,
        "device": device,
        "keyframes": len(db),
        "runs": g.runs,
        "run_s": g.run_s,
        "kidnap_at_s": g.kidnap_at_s,
        "lighting": g.lighting,
        "moved_furniture_m": g.moved_furniture_m,
        "repetitive": bool(s.repetitive),
        "methods": {m: {"summary": summarise(rows[m], hours), "runs": rows[m]} for m in g.methods},
        "ms_per_camera_frame": {k: 1e3 * v / frames for k, v in hyp.timing.items() if k != "frames"},
        "first_run": first_run,
        "settings": OmegaConf.to_container(g),
    }
    out = run.finish(metrics, device)
    for m in g.methods:
        sm = metrics["methods"][m]["summary"]
        print(
            f"  {m:12s} localized {sm['localized']}/{sm['runs']}"
            + (f", recovered {sm['recovered']}/{sm['runs']}" if "recovered" in sm else "")
            + f", false relocalizations/h {sm['false_relocalizations_per_hour']:.1f}"
        )
    return out
