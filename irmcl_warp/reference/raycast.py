"""Numpy twins of kernels/raycast.py: one Python loop per ray, the same steps in float32."""

from __future__ import annotations

import numpy as np

f32 = np.float32
BIG = f32(1e30)


def _boundary(g, d, i):
    if d > 0:
        return (f32(i + 1) - g) / d
    if d < 0:
        return (g - f32(i)) / (-d)
    return BIG


def dda_range(occ, origin, res, start, d, far_m, occ_threshold):
    """Walk the cells a ray crosses (Amanatides & Woo); return the entry distance of the first occupied one."""
    H, W = occ.shape
    res, far_m = f32(res), f32(far_m)
    g = (start.astype(f32) - origin.astype(f32)) / res
    ix, iy = int(np.floor(g[0])), int(np.floor(g[1]))
    sx, sy = (1 if d[0] > 0 else -1), (1 if d[1] > 0 else -1)
    t_max = [_boundary(g[0], d[0], ix), _boundary(g[1], d[1], iy)]
    delta = [BIG if d[k] == 0 else f32(1) / abs(d[k]) for k in (0, 1)]
    t = f32(0)
    for _ in range(int(f32(2) * far_m / res) + 4):
        if not (0 <= ix < W and 0 <= iy < H) or t * res > far_m:
            return far_m
        if occ[iy, ix] >= occ_threshold:
            return t * res
        if t_max[0] < t_max[1]:
            t, t_max[0], ix = t_max[0], t_max[0] + delta[0], ix + sx
        else:
            t, t_max[1], iy = t_max[1], t_max[1] + delta[1], iy + sy
    return far_m


def field_range(dist, origin, res, start, d, far_m):
    """Sphere tracing on a distance field: step by (distance - margin), at least half a cell."""
    H, W = dist.shape
    res, far_m = f32(res), f32(far_m)
    t, min_step, margin = f32(0), f32(0.5) * res, f32(1.4142135) * res
    for _ in range(int(far_m / min_step) + 2):
        if t > far_m:
            return far_m
        p = start.astype(f32) + t * d
        ix, iy = int(np.floor((p[0] - origin[0]) / res)), int(np.floor((p[1] - origin[1]) / res))
        if not (0 <= ix < W and 0 <= iy < H):
            return far_m
        if dist[iy, ix] <= 0:
            return t
        t = t + max(dist[iy, ix] - margin, min_step)
    return far_m


def cast(method, grid, origin, res, poses, angles, far_m, occ_threshold=0.5):
    """ranges[P, B] for laser poses [P, 3]; ``grid`` is occupancy (dda) or distance field (distance_field)."""
    origin = np.asarray(origin, dtype=f32)
    out = np.empty((len(poses), len(angles)), dtype=f32)
    for p, pose in enumerate(np.asarray(poses, dtype=f32)):
        for b, a in enumerate(np.asarray(angles, dtype=f32)):
            d = np.array([np.cos(pose[2] + a), np.sin(pose[2] + a)], dtype=f32)
            out[p, b] = (
                dda_range(grid, origin, res, pose[:2], d, far_m, occ_threshold)
                if method == "dda"
                else field_range(grid, origin, res, pose[:2], d, far_m)
            )
    return out
