"""The built-in simulated world: ``simulate(cfg) -> (LaserLog with exact ground truth, World)``.

Deterministic for a given ``seed``: the floor plan and path come from numpy's seeded generator, the
lidar noise from Warp's counter-based RNG.
"""

from __future__ import annotations

import numpy as np

from irmcl_warp.geometry import compose
from irmcl_warp.sim.trajectory import follow, noisy_odometry, waypoints
from irmcl_warp.sim.world import World, office
from irmcl_warp.types import LaserInfo, LaserLog
from irmcl_warp.kernels import SIM


def drive_log(
    world: World,
    cfg,
    waypoints_xy,
    path_seed: int,
    duration_s: float | None = None,
    device: str = "auto",
    source: str = "sim",
    rng=None,
) -> LaserLog:
    """The log of a drive through ``world`` along ``waypoints_xy`` with the sensor, speeds and odometry noise
    of the ``sim`` config ``cfg`` (its seed and layout settings aside): exact ground truth, noisy odometry.
    The lidar's noise comes from ``path_seed``, the odometry's from ``rng`` (None: a generator of ``path_seed``)."""
    rng = np.random.default_rng(path_seed) if rng is None else rng
    T_world_base = follow(np.asarray(waypoints_xy, float), cfg.speed_mps, cfg.turn_rate_rps, cfg.rate_hz, duration_s)
    info = LaserInfo(
        cfg.num_beams, -cfg.fov_rad / 2, cfg.fov_rad / max(cfg.num_beams - 1, 1), 0.0, cfg.range_max_m, cfg.range_max_m
    )
    T_base_laser = np.array([cfg.laser_x_m, 0.0, 0.0])
    lidar = SIM.build(
        "segment_lidar",
        segments=world.segments,
        angles_rad=info.angles_rad,
        range_max_m=cfg.range_max_m,
        noise_std_m=cfg.range_noise_std_m,
        dropout_prob=cfg.dropout_prob,
        device=device,
    )
    ranges = lidar.scan(compose(T_world_base, T_base_laser), seed=path_seed)
    odom = noisy_odometry(T_world_base, list(cfg.odom_alphas), rng)
    stamps = cfg.start_stamp_s + np.arange(len(T_world_base)) / cfg.rate_hz
    return LaserLog(stamps, ranges, odom, info, T_base_laser, T_world_base, source)


def simulate(cfg, device: str = "auto") -> tuple[LaserLog, World]:
    """``cfg``: the ``sim`` config node (see irmcl_warp/config.py, SimConfig)."""
    path_seed = cfg.seed if cfg.get("path_seed") is None else int(cfg.path_seed)  # the world stays that of seed
    rng = np.random.default_rng(path_seed)
    world = office(
        cfg.seed,
        cfg.width_m,
        cfg.height_m,
        cfg.corridor_width_m,
        cfg.room_min_width_m,
        cfg.room_max_width_m,
        cfg.door_width_m,
        cfg.furniture_per_room,
        cfg.repetitive,
    )
    log = drive_log(
        world,
        cfg,
        waypoints(world, rng, cfg.visit_prob),
        path_seed,
        cfg.duration_s,
        device,
        f"sim:office(seed={cfg.seed}, path {path_seed})",
        rng,
    )  # the odometry draws after the waypoints
    return log, world
