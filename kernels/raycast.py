"""2D ray casting on an occupancy grid: ``RAYCAST["dda"]`` and ``RAYCAST["distance_field"]``.

Both return, for each (pose, beam), the distance from the laser origin to the first cell whose
occupancy is >= ``occ_threshold`` or ``max_range_m`` if the ray leaves the grid or goes farther.
* dda: exact cell traversal (Amanatides & Woo 1987); the range is where the ray enters the hit cell.
* distance_field: sphere tracing on the distance transform of the occupied cells, stepping by the
  safe distance (at least half a cell); the range is the first sample that lands in an occupied cell,
  so it overshoots the cell boundary by less than half a cell. Fast in open space, used by MCL.
Poses are laser poses in the grid's world frame (x, y, yaw); beam b points at yaw + angles[b].
Numpy twins: irmcl_warp/reference/raycast.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import RAYCAST, pick_device
from irmcl_warp.kernels.grid import inside, walk_start


@wp.func
def dda_range(
    occ: wp.array2d(dtype=wp.float32),
    origin: wp.vec2,
    res: float,
    start: wp.vec2,
    d: wp.vec2,
    far_m: float,
    occ_threshold: float,
) -> float:
    g = (start - origin) / res
    ix, iy, sx, sy, t_max_x, t_max_y, dx, dy = walk_start(g, d)
    t = float(0.0)
    max_steps = int(2.0 * far_m / res) + 4
    for _ in range(max_steps):
        if not inside(ix, iy, occ.shape[1], occ.shape[0]):
            return far_m
        if t * res > far_m:
            return far_m
        if occ[iy, ix] >= occ_threshold:
            return t * res
        if t_max_x < t_max_y:
            t = t_max_x
            t_max_x = t_max_x + dx
            ix = ix + sx
        else:
            t = t_max_y
            t_max_y = t_max_y + dy
            iy = iy + sy
    return far_m


@wp.func
def field_range(
    dist: wp.array2d(dtype=wp.float32), origin: wp.vec2, res: float, start: wp.vec2, d: wp.vec2, far_m: float
) -> float:
    t = float(0.0)
    min_step = 0.5 * res
    margin = 1.4142135 * res  # point-to-cell-centre plus cell half-diagonal, both at most res/sqrt(2)
    max_steps = int(far_m / min_step) + 2
    for _ in range(max_steps):
        if t > far_m:
            return far_m
        p = start + t * d
        ix = int(wp.floor((p[0] - origin[0]) / res))
        iy = int(wp.floor((p[1] - origin[1]) / res))
        if not inside(ix, iy, dist.shape[1], dist.shape[0]):
            return far_m
        dd = dist[iy, ix]
        if dd <= 0.0:
            return t
        t = t + wp.max(dd - margin, min_step)
    return far_m


@wp.kernel
def dda_kernel(
    occ: wp.array2d(dtype=wp.float32),
    origin: wp.vec2,
    res: float,
    poses: wp.array(dtype=wp.vec3),
    angles: wp.array(dtype=wp.float32),
    far_m: float,
    occ_threshold: float,
    out: wp.array2d(dtype=wp.float32),
):
    p, b = wp.tid()
    pose = poses[p]
    a = pose[2] + angles[b]
    out[p, b] = dda_range(
        occ, origin, res, wp.vec2(pose[0], pose[1]), wp.vec2(wp.cos(a), wp.sin(a)), far_m, occ_threshold
    )


@wp.kernel
def field_kernel(
    dist: wp.array2d(dtype=wp.float32),
    origin: wp.vec2,
    res: float,
    poses: wp.array(dtype=wp.vec3),
    angles: wp.array(dtype=wp.float32),
    far_m: float,
    out: wp.array2d(dtype=wp.float32),
):
    p, b = wp.tid()
    pose = poses[p]
    a = pose[2] + angles[b]
    out[p, b] = field_range(dist, origin, res, wp.vec2(pose[0], pose[1]), wp.vec2(wp.cos(a), wp.sin(a)), far_m)


def distance_to_occupied(occ: np.ndarray, res: float, occ_threshold: float) -> np.ndarray:
    """Euclidean distance (m) from each cell centre to the nearest occupied cell centre (0 inside)."""
    from scipy.ndimage import distance_transform_edt

    occupied = occ >= occ_threshold
    if not occupied.any():
        return np.full(occ.shape, 1e6, dtype=np.float32)
    return (distance_transform_edt(~occupied) * res).astype(np.float32)


class GridRaycaster:
    """Casts rays on one grid; the grid (or its distance field) is uploaded once, ``cast`` only launches."""

    def __init__(
        self,
        method: str,
        occupancy: np.ndarray,
        origin_xy,
        resolution_m: float,
        far_m: float,
        occ_threshold: float = 0.5,
        device: str = "auto",
    ):
        occupancy = np.asarray(occupancy, dtype=np.float32)
        if occupancy.ndim != 2 or occupancy.size == 0:
            raise ValueError(f"occupancy grid must be a non-empty 2D array, got shape {occupancy.shape}")
        self.device = pick_device(device)
        self.method, self.res, self.far_m = method, float(resolution_m), float(far_m)
        self.origin = wp.vec2(float(origin_xy[0]), float(origin_xy[1]))
        self.occ_threshold = float(occ_threshold)
        grid = occupancy if method == "dda" else distance_to_occupied(occupancy, self.res, self.occ_threshold)
        self.grid = wp.array(grid, dtype=wp.float32, device=self.device)

    def cast(self, poses: wp.array, angles: wp.array, out: wp.array) -> None:
        dims = (poses.shape[0], angles.shape[0])
        if self.method == "dda":
            wp.launch(
                dda_kernel,
                dims,
                [self.grid, self.origin, self.res, poses, angles, self.far_m, self.occ_threshold, out],
                device=self.device,
            )
        else:
            wp.launch(
                field_kernel,
                dims,
                [self.grid, self.origin, self.res, poses, angles, self.far_m, out],
                device=self.device,
            )

    def cast_numpy(self, poses: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Convenience for tests and offline tools: allocates, launches, copies back."""
        poses_wp = wp.array(np.asarray(poses, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device=self.device)
        angles_wp = wp.array(np.asarray(angles, dtype=np.float32), dtype=wp.float32, device=self.device)
        out = wp.zeros((poses_wp.shape[0], angles_wp.shape[0]), dtype=wp.float32, device=self.device)
        self.cast(poses_wp, angles_wp, out)
        return out.numpy()


@RAYCAST.register("dda")
def make_dda(**grid) -> GridRaycaster:
    return GridRaycaster("dda", **grid)


@RAYCAST.register("distance_field")
def make_distance_field(**grid) -> GridRaycaster:
    return GridRaycaster("distance_field", **grid)
