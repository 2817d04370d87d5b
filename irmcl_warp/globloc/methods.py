"""The global-localization methods compared on identical streams, one class each (``METHODS``), and the loop
that drives any of them over a stream (``run_method``).

A method sees, per scan, the odometry step (``odometry``), at camera frames the hypotheses of the camera
pipeline (``camera``: [(pose, inliers, Scan2Map)] per cluster), and the laser scan (``scan``: its particle
filter steps, when it has one); ``pose`` is its estimate (None before it has one).
"""

from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from irmcl_warp.geometry import compose, relative
from irmcl_warp.globloc.scan2map import Scan2Map
from irmcl_warp.services.filters import WeightingMaps, build_filter, free_space_view
from irmcl_warp.kernels.motion import odometry_step


def laser_angles(cfg) -> np.ndarray:
    s = cfg.sim
    return -s.fov_rad / 2 + np.arange(s.num_beams) * s.fov_rad / max(s.num_beams - 1, 1)


def make_filter(cfg, grid, origin, device):
    """The MCL of the lidar methods: the likelihood field on the world's grid, AMCL's recovery (the filter
    every MCL user builds, services.filters.build_filter)."""
    g, res = cfg.globloc, cfg.globloc.map_resolution_m
    m = OmegaConf.merge(
        cfg.mcl,
        {
            "num_particles": g.num_particles,
            "num_beams": g.beams,
            "weighting": "likelihood_field",
            "estimate": "top_share",
            "reduce_to": 0,
            "recovery_alpha_slow": g.recovery_alpha_slow,
            "recovery_alpha_fast": g.recovery_alpha_fast,
            "seed": g.seed,
        },
    )
    maps = WeightingMaps(occupancy=grid, origin_xy=origin, resolution_m=res)
    return build_filter(
        m,
        free_space_view(grid, origin, res),
        (cfg.sim.laser_x_m, 0.0, 0.0),
        laser_angles(cfg),
        cfg.sim.range_max_m,  # the far bound: the simulated lidar's range (these stages read no log)
        device,
        maps,
    )


def pf_scan2map(cfg, pose, ranges, scorer: Scan2Map) -> float:
    """Scan2Map of the tracked pose: the best over a small grid around it (``trigger_search_m`` /
    ``trigger_search_rad``, 3 x 3 x 3 poses). The paper's score counts end points landing in occupied cells,
    so a tracked pose a few centimetres off scores far below a PnP pose on a look-alike bay; the search takes
    that tracking error out of the comparison."""
    g = cfg.globloc
    d = np.array([-1.0, 0.0, 1.0])
    offs = np.stack(
        np.meshgrid(d * g.trigger_search_m, d * g.trigger_search_m, d * g.trigger_search_rad, indexing="ij"), -1
    ).reshape(-1, 3)
    poses = np.asarray(pose, np.float64)[None] + offs
    return float(scorer(poses, (cfg.sim.laser_x_m, 0.0, 0.0), ranges, laser_angles(cfg)).max())


def seed_particles(pf, poses, share: float, std, rng) -> None:
    """Re-draw ``share`` of the particles around the camera's hypotheses (equal weights afterwards)."""
    P = pf.particles.numpy().astype(np.float64)
    n = int(share * len(P))
    pick = rng.choice(len(P), n, replace=False)
    centres = np.asarray(poses)[rng.integers(0, len(poses), n)]
    P[pick] = centres + rng.normal(0, 1, (n, 3)) * np.asarray(std)
    H, W = pf.free_space.shape
    cells = pf.free_space.node_of(P[:, :2])
    inside = np.all((cells >= 0) & (cells < np.array([W, H])), 1)
    pf.set_particles(P[inside].astype(np.float32))


class Method:
    """The hooks ``run_method`` calls; a method without a particle filter only overrides what it uses."""

    def __init__(self, cfg, grid, origin, device, rng):
        self.cfg, self.grid, self.origin, self.device, self.rng = cfg, grid, origin, device, rng
        self.pf, self.pose, self.relocs = None, None, []

    def new_filter(self):
        pf = make_filter(self.cfg, self.grid, self.origin, self.device)
        pf.rng = np.random.default_rng(int(self.rng.integers(1 << 30)))
        return pf

    def odometry(self, step) -> None:
        """The odometry moved by ``step`` since the last scan."""

    def camera(self, i: int, hyps: list, ranges, since_s: float | None) -> None:
        """Camera frame at scan ``i`` with its hypotheses; ``since_s``: time since the last frame."""

    def scan(self, u, ranges) -> None:
        if self.pf is not None:
            self.pose = np.asarray(self.pf.step(u, ranges)[0], np.float64)


class LidarMCL(Method):
    """Global MCL: uniform start over the free space, AMCL's recovery; the camera is ignored."""

    def __init__(self, *args):
        super().__init__(*args)
        self.pf = self.new_filter()
        self.pf.init_uniform()


class MCLSeeded(LidarMCL):
    """Global MCL whose particles are partly re-drawn around the camera's hypotheses at each frame."""

    def camera(self, i, hyps, ranges, since_s):
        if hyps:
            g = self.cfg.globloc
            seed_particles(self.pf, [p for p, _, _ in hyps], g.seed_share, g.tracking_std, self.rng)


class CameraOnly(Method):
    """The retrieved pose with the most PnP inliers at each frame, dead reckoning in between."""

    def odometry(self, step):
        if self.pose is not None:
            self.pose = compose(self.pose, step)

    def camera(self, i, hyps, ranges, since_s):
        if hyps:
            self.pose = max(hyps, key=lambda x: x[1])[0]


class PaperPipeline(Method):
    """The paper's: the first Scan2Map winner starts MCL tracking; a later winner out of the tracked pose's
    reach with a clearly better Scan2Map, confirmed by the winners of the next ``trigger_confirm_frames``
    frames (moved by the odometry in between), re-initialises it (the relocalization trigger)."""

    def __init__(self, *args):
        super().__init__(*args)
        g = self.cfg.globloc
        self.scorer = Scan2Map(self.grid, self.origin, g.map_resolution_m, g.scan2map)  # once: an EDT
        self.pending, self.agreed = None, 0  # a relocalization candidate and the frames that confirmed it

    def odometry(self, step):
        if self.pending is not None:
            self.pending = compose(self.pending, step)

    def camera(self, i, hyps, ranges, since_s):
        if not hyps:
            return
        win = max(hyps, key=lambda x: x[2])
        if self.pf is None:
            self.pf = self.new_filter()
            self.pf.init_gaussian(win[0], self.cfg.globloc.tracking_std)
            self.relocs.append(i)
        elif self.pose is not None:
            self.trigger(i, win, ranges, since_s)

    def trigger(self, i, win, ranges, since_s) -> None:
        g = self.cfg.globloc
        reach = g.max_speed_mps * since_s + g.trigger_slack_m
        here = pf_scan2map(self.cfg, self.pose, ranges, self.scorer)
        out_of_reach = np.hypot(*(win[0][:2] - self.pose[:2])) > reach
        if not (out_of_reach and win[2] > here + g.trigger_margin * max(here, 1e-6)):
            self.pending = None
            return
        if self.pending is not None and np.hypot(*(win[0][:2] - self.pending[:2])) < g.trigger_slack_m:
            self.agreed += 1
            self.pending = np.asarray(win[0], np.float64)
        else:
            self.pending, self.agreed = np.asarray(win[0], np.float64), 0
        if self.agreed >= g.trigger_confirm_frames:
            self.pf.init_gaussian(win[0], g.tracking_std)
            self.relocs.append(i)
            self.pending = None


METHODS = {"lidar_mcl": LidarMCL, "camera_only": CameraOnly, "paper": PaperPipeline, "mcl_seeded": MCLSeeded}


def run_method(method: str, cfg, st, hyps: list, grid, origin, device, rng) -> tuple[np.ndarray, list]:
    """Estimates [N, 3] (NaN before a method has any) and the scan indices where it relocalized."""
    if method not in METHODS:
        raise ValueError(f"globloc.methods: unknown method {method!r}; choose from {sorted(METHODS)}")
    m = METHODS[method](cfg, grid, origin, device, rng)
    est = np.full((len(st.truth), 3), np.nan)
    cam_at = {int(i): j for j, i in enumerate(st.cam_idx)}
    last_cam_t = None
    for i in range(len(st.truth)):
        u = odometry_step(st.odom[i - 1], st.odom[i]) if i > 0 else np.zeros(3)
        m.odometry(relative(st.odom[i - 1][None], st.odom[i][None])[0] if i > 0 else np.zeros(3))
        if i in cam_at:
            m.camera(i, hyps[cam_at[i]], st.ranges[i], None if last_cam_t is None else st.stamps[i] - last_cam_t)
            last_cam_t = st.stamps[i]
        m.scan(u, st.ranges[i])
        if m.pose is not None:
            est[i] = m.pose
    return est, m.relocs
