"""Simulator kernels: ``SIM["segment_lidar"]`` (a 2D lidar against wall segments, with range noise and
dropouts) and ``SIM["rasterize"]`` (segments -> occupancy grid).

Randomness uses Warp's counter-based RNG seeded per (seed, thread): a run is reproducible on any device.
Numpy twins (noise-free parts): irmcl_warp/reference/sim.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import SIM, pick_device

NO_HIT = 1.0e30


@wp.func
def cross2(a: wp.vec2, b: wp.vec2) -> float:
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def ray_segment(o: wp.vec2, d: wp.vec2, a: wp.vec2, b: wp.vec2) -> float:
    """Distance t along the ray o + t d (d unit) to segment [a, b]; NO_HIT if they do not meet."""
    e = b - a
    denom = cross2(d, e)
    if wp.abs(denom) < 1.0e-12:
        return NO_HIT
    ao = a - o
    t = cross2(ao, e) / denom
    u = cross2(ao, d) / denom
    if t > 0.0 and u >= 0.0 and u <= 1.0:
        return t
    return NO_HIT


@wp.func
def point_segment_distance(p: wp.vec2, a: wp.vec2, b: wp.vec2) -> float:
    e = b - a
    u = wp.clamp(wp.dot(p - a, e) / wp.max(wp.dot(e, e), 1.0e-12), 0.0, 1.0)
    return wp.length(p - (a + u * e))


@wp.kernel
def lidar_kernel(
    segments: wp.array(dtype=wp.vec4),
    poses: wp.array(dtype=wp.vec3),
    angles: wp.array(dtype=wp.float32),
    range_max_m: float,
    noise_std: float,
    dropout: float,
    seed: int,
    out: wp.array2d(dtype=wp.float32),
):
    s, b = wp.tid()
    pose = poses[s]
    a = pose[2] + angles[b]
    o = wp.vec2(pose[0], pose[1])
    d = wp.vec2(wp.cos(a), wp.sin(a))
    best = float(NO_HIT)
    for k in range(segments.shape[0]):
        seg = segments[k]
        best = wp.min(best, ray_segment(o, d, wp.vec2(seg[0], seg[1]), wp.vec2(seg[2], seg[3])))
    state = wp.rand_init(seed, s * angles.shape[0] + b)
    r = wp.max(best + noise_std * wp.randn(state), 0.0)
    if best > range_max_m or wp.randf(state) < dropout:
        r = wp.nan  # no return
    out[s, b] = r


@wp.kernel
def rasterize_kernel(
    segments: wp.array(dtype=wp.vec4),
    origin: wp.vec2,
    res: float,
    half_thickness: float,
    out: wp.array2d(dtype=wp.float32),
):
    iy, ix = wp.tid()
    p = origin + wp.vec2((float(ix) + 0.5) * res, (float(iy) + 0.5) * res)
    occ = float(0.0)
    for k in range(segments.shape[0]):
        seg = segments[k]
        if point_segment_distance(p, wp.vec2(seg[0], seg[1]), wp.vec2(seg[2], seg[3])) <= half_thickness:
            occ = 1.0
    out[iy, ix] = occ


class SegmentLidar:
    """Ranges of a planar lidar at laser poses [S, 3] against wall segments [K, 4] (x0, y0, x1, y1)."""

    def __init__(
        self,
        segments: np.ndarray,
        angles_rad: np.ndarray,
        range_max_m: float,
        noise_std_m: float = 0.0,
        dropout_prob: float = 0.0,
        device: str = "auto",
    ):
        self.device = pick_device(device)
        self.segments = wp.array(np.asarray(segments, dtype=np.float32), dtype=wp.vec4, device=self.device)
        self.angles = wp.array(np.asarray(angles_rad, dtype=np.float32), dtype=wp.float32, device=self.device)
        self.range_max_m, self.noise_std, self.dropout = float(range_max_m), float(noise_std_m), float(dropout_prob)

    def scan(self, laser_poses: np.ndarray, seed: int) -> np.ndarray:
        poses = wp.array(np.asarray(laser_poses, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device=self.device)
        out = wp.zeros((poses.shape[0], self.angles.shape[0]), dtype=wp.float32, device=self.device)
        wp.launch(
            lidar_kernel,
            out.shape,
            [self.segments, poses, self.angles, self.range_max_m, self.noise_std, self.dropout, int(seed), out],
            device=self.device,
        )
        return out.numpy()


RASTER_SLACK = 1e-3


def rasterize(segments: np.ndarray, origin_xy, resolution_m: float, shape_hw, device: str = "auto") -> np.ndarray:
    """Occupancy grid [H, W] (1 = wall) of the cells whose centre lies within half a cell of a segment, plus
    a hair (RASTER_SLACK): a wall exactly on a cell border marks both neighbours instead of, by float
    rounding, neither (the outer walls of the simulated office lie on the 5 and 10 cm lattices)."""
    dev = pick_device(device)
    segs = wp.array(np.asarray(segments, dtype=np.float32), dtype=wp.vec4, device=dev)
    out = wp.zeros(tuple(shape_hw), dtype=wp.float32, device=dev)
    wp.launch(
        rasterize_kernel,
        out.shape,
        [
            segs,
            wp.vec2(*map(float, origin_xy)),
            float(resolution_m),
            0.5 * float(resolution_m) * (1.0 + RASTER_SLACK),
            out,
        ],
        device=dev,
    )
    return out.numpy()


SIM.register("segment_lidar")(lambda **kw: SegmentLidar(**kw))
SIM.register("rasterize")(
    lambda **kw: (
        lambda segments, origin_xy, resolution_m, shape_hw: rasterize(segments, origin_xy, resolution_m, shape_hw, **kw)
    )
)
