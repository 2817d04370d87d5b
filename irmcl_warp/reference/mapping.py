"""Numpy twin of kernels/mapping.py: the same cell walk and updates, one Python loop per beam."""

from __future__ import annotations

import numpy as np

from irmcl_warp.reference.raycast import BIG, _boundary, f32


def integrate(logodds, origin, res, poses, ranges, angles, far_m, l_occ, l_free, l_min, l_max):
    """Add a batch of scans to ``logodds`` (modified in place) and clamp it to [l_min, l_max]."""
    H, W = logodds.shape
    res, origin = f32(res), np.asarray(origin, dtype=f32)

    def add(ix, iy, v):
        if 0 <= ix < W and 0 <= iy < H:
            logodds[iy, ix] += v

    for pose, scan in zip(np.asarray(poses, dtype=f32), np.asarray(ranges, dtype=f32)):
        for a, r in zip(np.asarray(angles, dtype=f32), scan):
            if np.isnan(r):
                continue
            d = np.array([np.cos(pose[2] + a), np.sin(pose[2] + a)], dtype=f32)
            g = (pose[:2] - origin) / res
            length = min(r, f32(far_m)) / res
            ix, iy = int(np.floor(g[0])), int(np.floor(g[1]))
            t_max = [_boundary(g[0], d[0], ix), _boundary(g[1], d[1], iy)]
            delta = [BIG if d[k] == 0 else f32(1) / abs(d[k]) for k in (0, 1)]
            for _ in range(int(2 * length) + 4):
                if min(t_max) >= length:
                    break
                add(ix, iy, l_free)
                if t_max[0] < t_max[1]:
                    t_max[0], ix = t_max[0] + delta[0], ix + (1 if d[0] > 0 else -1)
                else:
                    t_max[1], iy = t_max[1] + delta[1], iy + (1 if d[1] > 0 else -1)
            add(ix, iy, l_occ if r <= far_m else l_free)
    np.clip(logodds, l_min, l_max, out=logodds)
    return logodds
