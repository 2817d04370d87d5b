"""Numpy twin of kernels/camera.py without noise (one Python loop per column and pixel): for small images
in tests."""

from __future__ import annotations

import numpy as np

from irmcl_warp.sim.camera import POSTER_CELLS, POSTER_M

POSTER_W, POSTER_H, POSTER_Z0 = POSTER_M
POSTER_NX, POSTER_NY = POSTER_CELLS

NO_HIT = 1.0e30


def ray_segment(o, d, a, b) -> float:
    e = b - a
    denom = d[0] * e[1] - d[1] * e[0]
    if abs(denom) < 1e-12:
        return NO_HIT
    ao = a - o
    t = (ao[0] * e[1] - ao[1] * e[0]) / denom
    u = (ao[0] * d[1] - ao[1] * d[0]) / denom
    return t if t > 0 and 0 <= u <= 1 else NO_HIT


def hash3(a: int, b: int, c: int) -> float:
    def i32(v):
        return (v + 2**31) % 2**32 - 2**31

    h = i32(a * 73856093 + b * 19349663 + c * 83492791)
    h = i32((h ^ (h >> 13)) * 1274126177)
    h = h ^ (h >> 16)
    return float(h & 65535) / 65536.0


def paint(segments, colours, posters, k, u, z, light=np.array([0.6, 0.8])):
    c = colours[k] * (0.7 if z < 0.9 else 1.0)
    pid, pu = posters[k]
    if pid >= 0:
        du, dz = u - pu + 0.5 * POSTER_W, z - POSTER_Z0
        if 0 <= du < POSTER_W and 0 <= dz < POSTER_H:
            i, j, p = int(du / POSTER_W * POSTER_NX), int(dz / POSTER_H * POSTER_NY), int(pid)
            c = np.array([hash3(p, i, j), hash3(p, j, i + 17), hash3(p + 7, i, j + 31)])
    s = segments[k]
    e = (s[2:] - s[:2]) / np.linalg.norm(s[2:] - s[:2])
    return (0.65 + 0.35 * abs(e[0] * light[1] - e[1] * light[0])) * c


def render(
    segments,
    heights,
    colours,
    posters,
    cam_pose,
    W,
    H,
    fx,
    fy,
    cx,
    cy,
    cam_height,
    wall_height,
    exposure=1.0,
    tint=(1.0, 1.0, 1.0),
):
    """(rgb [H, W, 3] 0..255, depth [H, W]) of one camera pose, no pixel noise."""
    segments = np.asarray(segments, np.float64)
    rgb, depth = np.zeros((H, W, 3)), np.zeros((H, W))
    x, y, yaw = cam_pose
    o = np.array([x, y])
    for col in range(W):
        a = yaw + np.arctan((cx - (col + 0.5)) / fx)
        d = np.array([np.cos(a), np.sin(a)])
        hits = [ray_segment(o, d, s[:2], s[2:]) for s in segments]
        kn = int(np.argmin(hits))
        walls = [t if heights[k] >= wall_height else NO_HIT for k, t in enumerate(hits)]
        kw = int(np.argmin(walls))
        layers = [(hits[kn], kn, heights[kn]), (walls[kw], kw, wall_height)]
        for row in range(H):
            xc, yc = (col + 0.5 - cx) / fx, (row + 0.5 - cy) / fy
            stretch = np.sqrt(1 + xc * xc)
            colour, zd = None, 0.0
            for t, k, top in layers:
                if t < NO_HIT:
                    z = t / stretch
                    h = cam_height - yc * z
                    if 0 <= h <= top:
                        u = np.linalg.norm(o + t * d - segments[k, :2])
                        colour, zd = paint(segments, colours, posters, k, u, h), z
                        break
            if colour is None:
                if yc > 1e-6:
                    zd = cam_height / yc
                    hx, hy = o + zd * stretch * d
                    g = 0.35 + 0.15 * ((int(np.floor(hx / 0.5)) + int(np.floor(hy / 0.5))) & 1)
                    colour = np.array([g, g * 0.95, g * 0.85])
                elif yc < -1e-6:
                    zd = (wall_height - cam_height) / -yc
                    colour = np.array([0.85, 0.85, 0.82])
                else:
                    colour = np.zeros(3)
            rgb[row, col] = np.clip(colour / (1 + 0.04 * zd) * exposure * np.asarray(tint), 0, 1) * 255
            depth[row, col] = zd
    return rgb, depth
