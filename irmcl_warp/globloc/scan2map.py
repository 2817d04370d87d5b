"""Scan2Map: how well a lidar scan fits the map from a proposed pose. ``paper``: the sum of the occupancy
values of the cells hit by the scan's end points (the paper's score); ``likelihood_field``: the mean of
exp(-d^2 / 2 sigma^2) over the end points, d the distance to the nearest occupied cell."""

from __future__ import annotations

import numpy as np

from irmcl_warp.geometry import compose
from irmcl_warp.kernels.raycast import distance_to_occupied


class Scan2Map:
    def __init__(
        self,
        occupancy: np.ndarray,
        origin_xy,
        resolution_m: float,
        kind: str = "paper",
        sigma_m: float = 0.2,
        occ_threshold: float = 0.65,
    ):
        if kind not in ("paper", "likelihood_field"):
            raise ValueError(f"globloc.scan2map={kind!r}: choose paper or likelihood_field")
        self.occ = np.asarray(occupancy, np.float32)
        if self.occ.ndim != 2 or self.occ.size == 0:
            raise ValueError(f"Scan2Map: expected a 2D occupancy grid, got {self.occ.shape}")
        self.origin, self.res, self.kind, self.sigma = np.asarray(origin_xy, float), float(resolution_m), kind, sigma_m
        if kind == "likelihood_field":
            self.dist = distance_to_occupied(self.occ, self.res, occ_threshold)

    def __call__(self, poses, T_base_laser, ranges_m, angles_rad) -> np.ndarray:
        """Scores [P] of robot poses [P, 3] for one scan (NaN ranges = no return)."""
        poses = np.asarray(poses, np.float64).reshape(-1, 3)
        ok = np.isfinite(ranges_m)
        r, a = np.asarray(ranges_m)[ok], np.asarray(angles_rad)[ok]
        lp = compose(poses, np.asarray(T_base_laser, np.float64))
        ang = lp[:, 2:3] + a[None]
        ex = lp[:, :1] + r * np.cos(ang)
        ey = lp[:, 1:2] + r * np.sin(ang)
        ix = np.floor((ex - self.origin[0]) / self.res).astype(int)
        iy = np.floor((ey - self.origin[1]) / self.res).astype(int)
        H, W = self.occ.shape
        inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
        ixc, iyc = np.clip(ix, 0, W - 1), np.clip(iy, 0, H - 1)
        if self.kind == "paper":
            return np.where(inside, self.occ[iyc, ixc], 0.0).sum(1)
        d = np.where(inside, self.dist[iyc, ixc], 10 * self.sigma)
        return np.exp(-0.5 * (d / self.sigma) ** 2).mean(1) if r.size else np.zeros(len(poses))
