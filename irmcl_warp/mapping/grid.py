"""OccupancyGrid and mapping with known poses through the MAPPING kernel registry."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from irmcl_warp.geometry import compose, transform_points
from irmcl_warp.types import LaserLog
from irmcl_warp.kernels import MAPPING, pick_device


@dataclass
class OccupancyGrid:
    """``logodds[H, W]``; row iy, column ix covers [origin + (ix, iy) * res, origin + (ix+1, iy+1) * res)."""

    logodds: np.ndarray
    origin_xy: tuple[float, float]
    resolution_m: float

    @property
    def probability(self) -> np.ndarray:
        return 1.0 / (1.0 + np.exp(-np.clip(self.logodds, -80.0, 80.0)))  # unbounded log-odds: no overflow

    @property
    def known(self) -> np.ndarray:
        return self.logodds != 0.0

    @property
    def shape(self):
        return self.logodds.shape

    def cell_of(self, xy) -> np.ndarray:
        """(ix, iy) of world points [..., 2]."""
        return np.floor((np.asarray(xy) - np.asarray(self.origin_xy)) / self.resolution_m).astype(int)


def grid_bounds(log: LaserLog, T_map_base: np.ndarray, far_m: float, margin_m: float = 1.0):
    """Axis-aligned bounds (xmin, ymin, xmax, ymax) covering the beam end points used for mapping."""
    return laser_bounds(compose(T_map_base, log.T_base_laser), log.ranges_m, log.info.angles_rad, far_m, margin_m)


def laser_bounds(
    T_map_laser: np.ndarray, ranges_m: np.ndarray, angles_rad: np.ndarray, far_m: float, margin_m: float = 1.0
):
    r = np.minimum(np.nan_to_num(ranges_m, nan=0.0), far_m)
    pts = np.stack([r * np.cos(angles_rad), r * np.sin(angles_rad)], -1)
    ends = np.concatenate([transform_points(T_map_laser, pts).reshape(-1, 2), np.asarray(T_map_laser)[:, :2]])
    lo, hi = ends.min(0) - margin_m, ends.max(0) + margin_m
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def build_map(log: LaserLog, T_map_base: np.ndarray, **settings) -> OccupancyGrid:
    """Integrate every scan of ``log`` whose pose is known (finite) into one grid (see integrate_scans)."""
    known = np.all(np.isfinite(T_map_base), axis=1)
    if not known.any():
        raise ValueError(f"{log.source}: no scan has a known pose to build a map from")
    log, T_map_base = log.subset(known), T_map_base[known]
    return integrate_scans(compose(T_map_base, log.T_base_laser), log.ranges_m, log.info.angles_rad, **settings)


def integrate_scans(
    T_map_laser: np.ndarray,
    ranges_m: np.ndarray,
    angles_rad: np.ndarray,
    *,
    resolution_m: float = 0.05,
    far_m: float = 30.0,
    l_occ: float = 0.85,
    l_free: float = -0.4,
    l_min: float = -4.0,
    l_max: float = 4.0,
    batch_scans: int = 256,
    bounds=None,
    kernel: str = "logodds",
    device: str = "auto",
) -> OccupancyGrid:
    """Log-odds grid from laser poses [S, 3] and ranges [S, B] (NaN = no return). Returns it on the host."""
    xmin, ymin, xmax, ymax = bounds or laser_bounds(T_map_laser, ranges_m, angles_rad, far_m)
    W, H = int(np.ceil((xmax - xmin) / resolution_m)), int(np.ceil((ymax - ymin) / resolution_m))
    if W * H > 400_000_000:
        raise ValueError(f"map of {W}x{H} cells is too large: check poses and max_range_m")
    dev = pick_device(device)
    integrator = MAPPING.build(kernel, l_occ=l_occ, l_free=l_free, l_min=l_min, l_max=l_max, far_m=far_m)
    logodds = wp.zeros((H, W), dtype=wp.float32, device=dev)
    angles = wp.array(np.asarray(angles_rad, np.float32), dtype=wp.float32, device=dev)
    T_map_laser = np.asarray(T_map_laser, np.float32)
    for s in range(0, len(T_map_laser), batch_scans):
        poses = wp.array(T_map_laser[s : s + batch_scans], dtype=wp.vec3, device=dev)
        ranges = wp.array(np.asarray(ranges_m[s : s + batch_scans], np.float32), dtype=wp.float32, device=dev)
        integrator.integrate(logodds, (xmin, ymin), resolution_m, poses, ranges, angles)
    return OccupancyGrid(logodds.numpy(), (xmin, ymin), resolution_m)
