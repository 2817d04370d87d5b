"""GMapping's per-particle maps (``ParticleMaps``: one [P, H, W] array of vec4 cells) and
``SLAM["integrate"]``, which adds a scan to every particle's map in one launch.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import SLAM, pick_device
from irmcl_warp.kernels.weighting.common import laser_pose


UNKNOWN = -1.0


@wp.func
def occupancy(c: wp.vec4) -> float:
    if c[0] <= 0.0:
        return UNKNOWN
    return c[1] / c[0]


@wp.func
def cell_at(cells: wp.array3d(dtype=wp.vec4), p: int, ix: int, iy: int) -> wp.vec4:
    """The cell, or an unvisited one outside the map."""
    if ix < 0 or iy < 0 or ix >= cells.shape[2] or iy >= cells.shape[1]:
        return wp.vec4(0.0)
    return cells[p, iy, ix]


@wp.func
def cell_of(x: float, y: float, origin: wp.vec2, res: float) -> wp.vec2i:
    return wp.vec2i(int(wp.floor((x - origin[0]) / res)), int(wp.floor((y - origin[1]) / res)))


@wp.func
def beam_segment(pose: wp.vec3, T_base_laser: wp.vec3, r: float, angle: float) -> wp.vec4:
    """(laser x, laser y, end x, end y) of a beam of range r at ``angle`` in the laser frame."""
    lp = laser_pose(pose, T_base_laser)
    a = lp[2] + angle
    return wp.vec4(lp[0], lp[1], lp[0] + r * wp.cos(a), lp[1] + r * wp.sin(a))


@wp.func
def visit(cells: wp.array3d(dtype=wp.vec4), p: int, x: int, y: int):
    if x >= 0 and y >= 0 and x < cells.shape[2] and y < cells.shape[1]:
        wp.atomic_add(cells, p, y, x, wp.vec4(1.0, 0.0, 0.0, 0.0))


@wp.func
def clear_dda(
    cells: wp.array3d(dtype=wp.vec4), p: int, seg: wp.vec4, c0: wp.vec2i, c1: wp.vec2i, origin: wp.vec2, res: float
):
    """Visit every cell the beam crosses from the laser's cell to the end cell, the end cell excluded
    (Amanatides & Woo)."""
    dx = seg[2] - seg[0]
    dy = seg[3] - seg[1]
    ix = c0[0]
    iy = c0[1]
    step_x = 1
    if dx < 0.0:
        step_x = -1
    step_y = 1
    if dy < 0.0:
        step_y = -1
    inv_dx = 1.0e30
    if wp.abs(dx) > 1.0e-9:
        inv_dx = 1.0 / wp.abs(dx)
    inv_dy = 1.0e30
    if wp.abs(dy) > 1.0e-9:
        inv_dy = 1.0 / wp.abs(dy)
    t_x = wp.abs(origin[0] + float(ix + wp.max(step_x, 0)) * res - seg[0]) * inv_dx
    t_y = wp.abs(origin[1] + float(iy + wp.max(step_y, 0)) * res - seg[1]) * inv_dy
    for _ in range(wp.abs(c1[0] - c0[0]) + wp.abs(c1[1] - c0[1])):
        visit(cells, p, ix, iy)
        if t_x < t_y:
            ix += step_x
            t_x += res * inv_dx
        else:
            iy += step_y
            t_y += res * inv_dy


@wp.func
def clear_bresenham(cells: wp.array3d(dtype=wp.vec4), p: int, c0: wp.vec2i, c1: wp.vec2i):
    """Visit the cells of the 8-connected integer line from the laser's cell to the end cell, the end cell
    excluded (one cell per step along the major axis, as the released code's gridLine)."""
    x = c0[0]
    y = c0[1]
    dx = wp.abs(c1[0] - x)
    dy = -wp.abs(c1[1] - y)
    sx = 1
    if c1[0] < x:
        sx = -1
    sy = 1
    if c1[1] < y:
        sy = -1
    err = dx + dy
    for _ in range(wp.max(dx, -dy)):
        visit(cells, p, x, y)
        e2 = 2 * err
        if e2 >= dy:
            err += dy
            x += sx
        if e2 <= dx:
            err += dx
            y += sy


def make_integrate_kernel(line: str):
    """Two kernels: ``free`` (one thread per particle x beam) adds a visit to every cell a beam passes,
    ``hits`` (one thread per particle, beams in order) adds the end points. Visits are whole numbers, so
    their atomic sums do not depend on the order the threads run in; the end points' coordinate sums do,
    and are added in beam order so that a run replays exactly on a GPU too."""

    @wp.kernel(module="unique")
    def free(
        poses: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        angles: wp.array(dtype=wp.float32),
        far_m: float,
        origin: wp.vec2,
        res: float,
        cells: wp.array3d(dtype=wp.vec4),
    ):
        p, b = wp.tid()
        r = ranges[b]
        if not (r == r) or r <= 0.0:
            return
        seg = beam_segment(poses[p], T_base_laser, wp.min(r, far_m), angles[b])
        c0 = cell_of(seg[0], seg[1], origin, res)
        c1 = cell_of(seg[2], seg[3], origin, res)
        if wp.static(line == "bresenham"):
            clear_bresenham(cells, p, c0, c1)
        else:
            clear_dda(cells, p, seg, c0, c1, origin, res)

    @wp.kernel(module="unique")
    def hits(
        poses: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        angles: wp.array(dtype=wp.float32),
        far_m: float,
        origin: wp.vec2,
        res: float,
        cells: wp.array3d(dtype=wp.vec4),
    ):
        p = wp.tid()
        for b in range(ranges.shape[0]):
            r = ranges[b]
            if r == r and r > 0.0 and r <= far_m:
                seg = beam_segment(poses[p], T_base_laser, r, angles[b])
                c1 = cell_of(seg[2], seg[3], origin, res)
                if c1[0] >= 0 and c1[1] >= 0 and c1[0] < cells.shape[2] and c1[1] < cells.shape[1]:
                    # the end point's offset from its cell's corner (see the module's docstring)
                    ox = (seg[2] - origin[0]) - float(c1[0]) * res
                    oy = (seg[3] - origin[1]) - float(c1[1]) * res
                    cells[p, c1[1], c1[0]] = cells[p, c1[1], c1[0]] + wp.vec4(1.0, 1.0, ox, oy)

    return free, hits


def keep_slots(parents: np.ndarray) -> np.ndarray:
    """The same multiset of parents, ordered so that every chosen parent j sits at slot j; the extra
    copies fill the slots of the parents nobody chose. No slot is then both overwritten and copied from."""
    parents = np.asarray(parents, int)
    P = len(parents)
    counts = np.bincount(parents, minlength=P)
    order = np.full(P, -1)
    chosen = counts > 0
    order[chosen] = np.flatnonzero(chosen)
    extra = np.repeat(np.arange(P), np.maximum(counts - 1, 0))
    order[~chosen] = extra
    return order


@wp.kernel
def shift_cells_kernel(src: wp.array3d(dtype=wp.vec4), dst: wp.array3d(dtype=wp.vec4), dx: int, dy: int):
    """dst[p, y + dy, x + dx] = src[p, y, x]: the maps copied into a larger frame (ParticleMaps.cover)."""
    p, y, x = wp.tid()
    dst[p, y + dy, x + dx] = src[p, y, x]


class ParticleMaps:
    """P maps of H x W point accumulators on one device, with their frame (origin = corner of cell (0, 0));
    ``cells`` [P, H, W] vec4 = (visits, hits, sx, sy). The frame grows by whole cells (``cover``) when a scan
    reaches beyond it, as the released code's maps do: no end point is dropped at the map's border, however
    far the corrected path strays from where the odometry went (MIT Killian: hundreds of metres)."""

    MAX_CELLS = 200_000_000  # per map: 3.2 GB each; a frame that would grow beyond it is an error

    FIELDS = ("visits", "hits", "sx", "sy")

    def __init__(self, num_particles: int, shape_hw, origin_xy, resolution_m: float, device: str = "auto"):
        H, W = map(int, shape_hw)
        if num_particles < 1 or H < 1 or W < 1 or not resolution_m > 0:
            raise ValueError(f"ParticleMaps: {num_particles} particles of {H} x {W} cells at {resolution_m} m")
        self.device = pick_device(device)
        self.origin_xy = (float(origin_xy[0]), float(origin_xy[1]))  # in double: growing adds whole cells to it
        self.origin, self.res = wp.vec2(*self.origin_xy), float(resolution_m)
        self.cells = wp.zeros((num_particles, H, W), dtype=wp.vec4, device=self.device)
        self.grown = 0  # times cover() enlarged the frame

    def cover(self, lo_xy, hi_xy, slack_m: float) -> bool:
        """Grow the frame, by whole cells so that every cell keeps its place, until it holds the box
        lo_xy..hi_xy; a side that grows gets ``slack_m`` or a quarter of the frame's extent beyond the box,
        whichever is more (geometric growth: the copies cost a few times the final maps, not one per scan).
        Returns whether it grew. Twin: the numpy slice assignment in tests/test_slam.py."""
        P, H, W = self.shape
        (ox, oy), res = self.origin_xy, self.res

        def need(gap: float, extent: float) -> int:  # cells to add on a side the box passes by ``gap`` (>= 0: out)
            return int(np.ceil((max(gap, 0.0) + max(slack_m, 0.25 * extent)) / res)) if gap >= 0 else 0

        g_left, g_right, g_down, g_up = self._gaps(lo_xy, hi_xy)
        left, right = need(g_left, W * res), need(g_right, W * res)
        down, up = need(g_down, H * res), need(g_up, H * res)
        if not (left or right or down or up):
            return False
        H2, W2 = H + down + up, W + left + right
        if H2 * W2 > self.MAX_CELLS:
            raise ValueError(
                f"slam: the maps would grow to {W2} x {H2} cells at {res} m to hold the scans from "
                f"{lo_xy} to {hi_xy}; raise slam.resolution_m"
            )
        cells = wp.zeros((P, H2, W2), dtype=wp.vec4, device=self.device)
        wp.launch(shift_cells_kernel, (P, H, W), [self.cells, cells, left, down], device=self.device)
        self.cells = cells
        self.origin_xy = (ox - left * res, oy - down * res)
        self.origin = wp.vec2(*self.origin_xy)
        self.grown += 1
        return True

    def _gaps(self, lo_xy, hi_xy) -> tuple[float, float, float, float]:
        """How far the box lo_xy..hi_xy passes the frame's left, right, lower and upper sides (>= 0: out)."""
        _, H, W = self.shape
        (ox, oy), res = self.origin_xy, self.res
        return ox - lo_xy[0] - 1e-9, hi_xy[0] - (ox + W * res), oy - lo_xy[1] - 1e-9, hi_xy[1] - (oy + H * res)

    def holds(self, lo_xy, hi_xy) -> bool:
        """Whether the frame holds the box lo_xy..hi_xy (cover would not grow for it, nor for any box inside)."""
        return all(g < 0 for g in self._gaps(lo_xy, hi_xy))

    @property
    def shape(self):
        return self.cells.shape

    def fields(self, p: int) -> dict:
        """Map p as numpy arrays [H, W] by field name (visits, hits, sx, sy)."""
        c = self.cells.numpy()[p]
        return {f: c[..., i] for i, f in enumerate(self.FIELDS)}

    def resample(self, parents: np.ndarray) -> np.ndarray:
        """Resample the maps: the new set holds map parents[k] once per k. Particles are exchangeable, so
        each surviving map keeps its slot and only the slots of dropped maps receive copies (in place, one
        contiguous block per map and field); returns the parent of each slot in the new order."""
        order = keep_slots(parents)
        P, H, W = self.shape
        n = H * W
        a = self.cells.flatten()
        for dst in np.flatnonzero(order != np.arange(P)):
            wp.copy(a, a, dest_offset=int(dst) * n, src_offset=int(order[dst]) * n, count=n)
        return order

    def occupancy(self, p: int) -> np.ndarray:
        """[H, W] hits / visits of map p, -1 where never visited."""
        c = self.cells.numpy()[p]
        v, h = c[..., 0], c[..., 1]
        return np.where(v > 0, h / np.maximum(v, 1), UNKNOWN).astype(np.float32)


class Integrator:
    """Adds a scan to every particle's map; ``free_space=False`` adds the end points only (the released
    code with generateMap off, the way its ROS wrapper runs the particles: their maps never learn free
    space, so a cell once hit stays occupied)."""

    LINES = ("bresenham", "dda")

    def __init__(self, far_m: float, line: str = "bresenham", free_space: bool = True, device: str = "auto"):
        if line not in self.LINES:
            raise ValueError(f"slam.line={line!r}: choose one of {list(self.LINES)}")
        self.far_m, self.device, self.free_space = float(far_m), pick_device(device), bool(free_space)
        self.free, self.hits = make_integrate_kernel(line)

    def __call__(self, maps: ParticleMaps, poses: wp.array, T_base_laser, ranges: wp.array, angles: wp.array) -> None:
        args = [
            poses,
            wp.vec3(*map(float, T_base_laser)),
            ranges,
            angles,
            self.far_m,
            maps.origin,
            maps.res,
            maps.cells,
        ]
        if self.free_space:
            wp.launch(self.free, (poses.shape[0], ranges.shape[0]), args, device=self.device)
        wp.launch(self.hits, poses.shape[0], args, device=self.device)


SLAM.register("integrate")(lambda **kw: Integrator(**kw))
