"""Occupancy-grid mapping with known poses: ``MAPPING["logodds"]``.

One thread per (scan, beam) walks the cells from the laser to the end point (the DDA of raycast.py):
cells the beam passes add ``l_free``, the end point's cell adds ``l_occ``; a beam longer than
``max_range_m`` only clears space up to it, a no-return (NaN) beam does nothing. Updates are atomic adds,
so the result does not depend on thread order; the caller clamps between batches.
Numpy twin: irmcl_warp/reference/mapping.py.
"""

from __future__ import annotations

import warp as wp

from kernels.registry import MAPPING
from kernels.grid import inside, walk_start


@wp.func
def add(grid: wp.array2d(dtype=wp.float32), ix: int, iy: int, value: float):
    if inside(ix, iy, grid.shape[1], grid.shape[0]):
        wp.atomic_add(grid, iy, ix, value)


@wp.kernel
def integrate_kernel(logodds: wp.array2d(dtype=wp.float32), origin: wp.vec2, res: float,
                     poses: wp.array(dtype=wp.vec3), ranges: wp.array2d(dtype=wp.float32),
                     angles: wp.array(dtype=wp.float32), max_range: float, l_occ: float, l_free: float):
    s, b = wp.tid()
    r = ranges[s, b]
    if not (r == r):  # NaN: no return
        return
    pose = poses[s]
    a = pose[2] + angles[b]
    d = wp.vec2(wp.cos(a), wp.sin(a))
    g = (wp.vec2(pose[0], pose[1]) - origin) / res
    length = wp.min(r, max_range) / res
    ix, iy, sx, sy, t_max_x, t_max_y, dx, dy = walk_start(g, d)
    for _ in range(int(2.0 * length) + 4):
        t_exit = wp.min(t_max_x, t_max_y)
        if t_exit >= length:
            break
        add(logodds, ix, iy, l_free)
        if t_max_x < t_max_y:
            t_max_x = t_max_x + dx
            ix = ix + sx
        else:
            t_max_y = t_max_y + dy
            iy = iy + sy
    if r <= max_range:
        add(logodds, ix, iy, l_occ)
    else:
        add(logodds, ix, iy, l_free)


@wp.kernel
def clamp_kernel(logodds: wp.array2d(dtype=wp.float32), lo: float, hi: float):
    i, j = wp.tid()
    logodds[i, j] = wp.clamp(logodds[i, j], lo, hi)


class LogOddsIntegrator:
    def __init__(self, l_occ: float, l_free: float, l_min: float, l_max: float, max_range_m: float):
        self.l_occ, self.l_free, self.l_min, self.l_max, self.max_range = l_occ, l_free, l_min, l_max, max_range_m

    def integrate(self, logodds, origin_xy, res, poses, ranges, angles) -> None:
        """Add one batch of scans (laser poses [S] vec3, ranges [S, B]) to ``logodds``, then clamp."""
        dev = logodds.device
        wp.launch(integrate_kernel, ranges.shape, [logodds, wp.vec2(*map(float, origin_xy)), float(res), poses, ranges,
                                                   angles, self.max_range, self.l_occ, self.l_free], device=dev)
        wp.launch(clamp_kernel, logodds.shape, [logodds, self.l_min, self.l_max], device=dev)


@MAPPING.register("logodds")
def make_logodds(**settings) -> LogOddsIntegrator:
    return LogOddsIntegrator(**settings)
