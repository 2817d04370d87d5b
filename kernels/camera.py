"""A 2.5D camera for the simulated world: ``SIM["camera"]`` renders RGB and depth images of extruded wall
segments, in two launches per batch of frames:

1. columns: one thread per (frame, image column) casts the column's horizontal ray against every segment
   and keeps the nearest hit of any segment and the nearest hit of a full-height segment (a wall behind a
   low box or a person stays visible above it): distance along the ray, segment index and the position
   along the segment (the texture's u);
2. pixels: one thread per (frame, row, column) lifts its ray to 3D (pinhole: fx, fy, cx, cy, camera at
   ``height_m`` looking along the robot's heading + the extrinsic yaw) and takes the first of: the near
   segment if the ray passes below its top, the wall, or the floor / ceiling plane. Colour: a segment's
   paint with a darker dado band below 0.9 m, a poster (a 6 x 8 grid of colours hashed from its id, so
   that ORB finds corners) where the segment has one, floor tiles of 0.5 m, a plain ceiling; shaded by the
   angle to a fixed light and by distance. Depth: the z-depth along the optical axis (metres).

Per-session nuisances come with each call: exposure and tint multiply the colour, and Gaussian pixel noise
is drawn from Warp's counter-based RNG (seeded per frame and pixel, so a batch is reproducible anywhere).
Numpy twin: irmcl_warp/reference/camera.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import SIM, pick_device
from irmcl_warp.kernels.sim import NO_HIT, ray_segment


@wp.func
def hash3(a: int, b: int, c: int) -> float:
    """A deterministic value in [0, 1) from three integers (integer mixing, no state)."""
    h = a * 73856093 + b * 19349663 + c * 83492791
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return float(h & 65535) / 65536.0


@wp.kernel
def columns_kernel(
    segments: wp.array(dtype=wp.vec4),
    heights: wp.array(dtype=wp.float32),
    cam_poses: wp.array(dtype=wp.vec3),
    fx: float,
    cx: float,
    wall_height: float,
    near_t: wp.array2d(dtype=wp.float32),
    near_k: wp.array2d(dtype=wp.int32),
    near_u: wp.array2d(dtype=wp.float32),
    wall_t: wp.array2d(dtype=wp.float32),
    wall_k: wp.array2d(dtype=wp.int32),
    wall_u: wp.array2d(dtype=wp.float32),
):
    f, col = wp.tid()
    pose = cam_poses[f]
    a = pose[2] + wp.atan((cx - (float(col) + 0.5)) / fx)  # image x grows to the right = clockwise
    o = wp.vec2(pose[0], pose[1])
    d = wp.vec2(wp.cos(a), wp.sin(a))
    bn = float(NO_HIT)
    bw = float(NO_HIT)
    kn = int(-1)
    kw = int(-1)
    for k in range(segments.shape[0]):
        s = segments[k]
        t = ray_segment(o, d, wp.vec2(s[0], s[1]), wp.vec2(s[2], s[3]))
        if t < bn:
            bn = t
            kn = k
        if heights[k] >= wall_height and t < bw:
            bw = t
            kw = k
    near_t[f, col] = bn
    near_k[f, col] = kn
    wall_t[f, col] = bw
    wall_k[f, col] = kw
    if kn >= 0:
        s = segments[kn]
        near_u[f, col] = wp.length(o + bn * d - wp.vec2(s[0], s[1]))
    if kw >= 0:
        s = segments[kw]
        wall_u[f, col] = wp.length(o + bw * d - wp.vec2(s[0], s[1]))


@wp.func
def paint(
    segments: wp.array(dtype=wp.vec4),
    colours: wp.array(dtype=wp.vec3),
    posters: wp.array(dtype=wp.vec2),
    poster: wp.vec3,
    cells: wp.vec2,
    k: int,
    u: float,
    z: float,
    light: wp.vec2,
) -> wp.vec3:
    """Colour of segment k at (u along it, z above the floor), shaded by the angle to the light; ``poster``:
    a poster's (width, height, height of its lower edge) in m, ``cells``: its pattern's cells across and up."""
    c = colours[k]
    if z < 0.9:
        c = 0.7 * c
    pst = posters[k]  # (poster id or -1, u of its centre)
    if pst[0] >= 0.0:
        du = u - pst[1] + 0.5 * poster[0]
        dz = z - poster[2]
        if du >= 0.0 and du < poster[0] and dz >= 0.0 and dz < poster[1]:
            i = int(du / poster[0] * cells[0])
            j = int(dz / poster[1] * cells[1])
            pid = int(pst[0])
            c = wp.vec3(hash3(pid, i, j), hash3(pid, j, i + 17), hash3(pid + 7, i, j + 31))
    s = segments[k]
    e = wp.normalize(wp.vec2(s[2] - s[0], s[3] - s[1]))
    shade = 0.65 + 0.35 * wp.abs(e[0] * light[1] - e[1] * light[0])
    return shade * c


@wp.kernel
def pixels_kernel(
    segments: wp.array(dtype=wp.vec4),
    heights: wp.array(dtype=wp.float32),
    colours: wp.array(dtype=wp.vec3),
    posters: wp.array(dtype=wp.vec2),
    poster: wp.vec3,
    cells: wp.vec2,
    cam_poses: wp.array(dtype=wp.vec3),
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    cam_height: float,
    wall_height: float,
    near_t: wp.array2d(dtype=wp.float32),
    near_k: wp.array2d(dtype=wp.int32),
    near_u: wp.array2d(dtype=wp.float32),
    wall_t: wp.array2d(dtype=wp.float32),
    wall_k: wp.array2d(dtype=wp.int32),
    wall_u: wp.array2d(dtype=wp.float32),
    exposure: wp.array(dtype=wp.float32),
    tint: wp.array(dtype=wp.vec3),
    noise_std: float,
    seed: int,
    rgb: wp.array4d(dtype=wp.float32),
    depth: wp.array3d(dtype=wp.float32),
):
    f, row, col = wp.tid()
    pose = cam_poses[f]
    xc = ((float(col) + 0.5) - cx) / fx
    yc = ((float(row) + 0.5) - cy) / fy  # down
    stretch = wp.sqrt(1.0 + xc * xc)  # horizontal ray length per metre of optical axis
    light = wp.vec2(0.6, 0.8)
    colour = wp.vec3(0.0)
    z_depth = float(0.0)
    done = int(0)
    # the nearest segment, if the ray passes below its top (and above the floor) there
    tn = near_t[f, col]
    if tn < NO_HIT:
        zd = tn / stretch
        h = cam_height - yc * zd
        if h >= 0.0 and h <= heights[near_k[f, col]]:
            colour = paint(segments, colours, posters, poster, cells, near_k[f, col], near_u[f, col], h, light)
            z_depth = zd
            done = 1
    if done == 0:
        tw = wall_t[f, col]
        if tw < NO_HIT:
            zd = tw / stretch
            h = cam_height - yc * zd
            if h >= 0.0 and h <= wall_height:
                colour = paint(segments, colours, posters, poster, cells, wall_k[f, col], wall_u[f, col], h, light)
                z_depth = zd
                done = 1
    if done == 0:
        if yc > 1.0e-6:  # floor
            zd = cam_height / yc
            a = pose[2] + wp.atan(-xc)
            hx = pose[0] + zd * stretch * wp.cos(a)
            hy = pose[1] + zd * stretch * wp.sin(a)
            tile = (int(wp.floor(hx / 0.5)) + int(wp.floor(hy / 0.5))) & 1
            g = 0.35 + 0.15 * float(tile)
            colour = wp.vec3(g, g * 0.95, g * 0.85)
            z_depth = zd
        elif yc < -1.0e-6:  # ceiling
            zd = (wall_height - cam_height) / (-yc)
            colour = wp.vec3(0.85, 0.85, 0.82)
            z_depth = zd
    fade = 1.0 / (1.0 + 0.04 * z_depth)
    colour = fade * exposure[f] * wp.cw_mul(colour, tint[f])
    state = wp.rand_init(seed, (f * rgb.shape[1] + row) * rgb.shape[2] + col)
    for c in range(3):
        v = colour[c] + noise_std * wp.randn(state)
        rgb[f, row, col, c] = wp.clamp(v, 0.0, 1.0) * 255.0
    depth[f, row, col] = z_depth


class SegmentCamera:
    """RGB [F, H, W, 3] (0..255, float32) and depth [F, H, W] (m) of camera poses [F, 3] (x, y, yaw of the
    camera) in a world of segments [K, 4] with heights [K] (m), colours [K, 3] (0..1) and posters [K, 2]
    (poster id or -1, u of its centre along the segment); every poster measures ``poster_m`` (width, height,
    height of its lower edge) and its pattern ``poster_cells`` (across, up): the world's (irmcl_warp/sim/camera.py)."""

    def __init__(
        self,
        segments,
        heights,
        colours,
        posters,
        poster_m,
        poster_cells,
        width: int = 320,
        height: int = 240,
        hfov_rad: float = np.radians(58.0),
        cam_height_m: float = 1.0,
        wall_height_m: float = 2.5,
        device: str = "auto",
    ):
        self.device = pick_device(device)
        d = self.device
        self.segments = wp.array(np.asarray(segments, np.float32), dtype=wp.vec4, device=d)
        self.heights = wp.array(np.asarray(heights, np.float32), dtype=wp.float32, device=d)
        self.colours = wp.array(np.asarray(colours, np.float32), dtype=wp.vec3, device=d)
        self.posters = wp.array(np.asarray(posters, np.float32), dtype=wp.vec2, device=d)
        self.poster, self.cells = wp.vec3(*map(float, poster_m)), wp.vec2(*map(float, poster_cells))
        self.W, self.H = int(width), int(height)
        self.fx = self.fy = 0.5 * self.W / np.tan(0.5 * hfov_rad)
        self.cx, self.cy = 0.5 * self.W, 0.5 * self.H
        self.cam_height, self.wall_height = float(cam_height_m), float(wall_height_m)

    @property
    def K(self) -> np.ndarray:
        """OpenCV intrinsics: OpenCV puts pixel i's centre at coordinate i, the kernel casts through i + 0.5."""
        return np.array([[self.fx, 0, self.cx - 0.5], [0, self.fy, self.cy - 0.5], [0, 0, 1.0]])

    def render(
        self,
        cam_poses,
        exposure=1.0,
        tint=(1.0, 1.0, 1.0),
        noise_std: float = 0.0,
        seed: int = 0,
        on_device: bool = False,
    ):
        """(rgb [F, H, W, 3], depth [F, H, W]); exposure [F] or scalar, tint [F, 3] or [3]; noise in 0..1 units.
        numpy arrays, or the Warp arrays on the device with ``on_device``."""
        d = self.device
        poses = np.asarray(cam_poses, np.float32).reshape(-1, 3)
        F = len(poses)
        exp_ = np.broadcast_to(np.asarray(exposure, np.float32), (F,)).copy()
        tint_ = np.broadcast_to(np.asarray(tint, np.float32), (F, 3)).copy()
        wp_poses = wp.array(poses, dtype=wp.vec3, device=d)
        cols = [wp.zeros((F, self.W), dtype=t, device=d) for t in (wp.float32, wp.int32, wp.float32) * 2]
        wp.launch(
            columns_kernel,
            (F, self.W),
            [self.segments, self.heights, wp_poses, float(self.fx), float(self.cx), self.wall_height, *cols],
            device=d,
        )
        rgb = wp.zeros((F, self.H, self.W, 3), dtype=wp.float32, device=d)
        depth = wp.zeros((F, self.H, self.W), dtype=wp.float32, device=d)
        wp.launch(
            pixels_kernel,
            (F, self.H, self.W),
            [
                self.segments,
                self.heights,
                self.colours,
                self.posters,
                self.poster,
                self.cells,
                wp_poses,
                float(self.fx),
                float(self.fy),
                float(self.cx),
                float(self.cy),
                self.cam_height,
                self.wall_height,
                *cols,
                wp.array(exp_, dtype=wp.float32, device=d),
                wp.array(tint_, dtype=wp.vec3, device=d),
                float(noise_std),
                int(seed),
                rgb,
                depth,
            ],
            device=d,
        )
        return (rgb, depth) if on_device else (rgb.numpy(), depth.numpy())


SIM.register("camera")(lambda **kw: SegmentCamera(**kw))
