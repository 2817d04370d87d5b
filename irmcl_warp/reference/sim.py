"""Numpy twins of kernels/sim.py (the deterministic parts: exact ranges and rasterisation)."""

from __future__ import annotations

import numpy as np


def lidar_ranges(segments, laser_poses, angles, range_max_m):
    """Exact ranges [S, B] (NaN beyond max_range), vectorised over segments."""
    seg = np.asarray(segments, dtype=np.float64)
    a, e = seg[:, :2], seg[:, 2:] - seg[:, :2]
    out = np.empty((len(laser_poses), len(angles)))
    for s, (x, y, yaw) in enumerate(np.asarray(laser_poses, dtype=np.float64)):
        for b, ang in enumerate(angles):
            d = np.array([np.cos(yaw + ang), np.sin(yaw + ang)])
            denom = d[0] * e[:, 1] - d[1] * e[:, 0]
            ao = a - np.array([x, y])
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (ao[:, 0] * e[:, 1] - ao[:, 1] * e[:, 0]) / denom
                u = (ao[:, 0] * d[1] - ao[:, 1] * d[0]) / denom
            ok = (np.abs(denom) >= 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
            best = t[ok].min() if ok.any() else np.inf
            out[s, b] = best if best <= range_max_m else np.nan
    return out


def rasterize(segments, origin_xy, resolution_m, shape_hw):
    H, W = shape_hw
    ys, xs = np.mgrid[0:H, 0:W]
    p = np.stack([origin_xy[0] + (xs + 0.5) * resolution_m, origin_xy[1] + (ys + 0.5) * resolution_m], -1)
    occ = np.zeros((H, W), dtype=np.float32)
    for x0, y0, x1, y1 in np.asarray(segments, dtype=np.float64):
        a, e = np.array([x0, y0]), np.array([x1 - x0, y1 - y0])
        u = np.clip(((p - a) @ e) / max(e @ e, 1e-12), 0, 1)
        dist = np.linalg.norm(p - (a + u[..., None] * e), axis=-1)
        occ[dist <= 0.5 * resolution_m * (1.0 + 1e-3)] = 1.0  # kernels/sim.py RASTER_SLACK
    return occ
