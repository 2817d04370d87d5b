"""Numpy twins of kernels/slam/ (per-particle point-accumulator maps, GMapping's matcher model and motion
model), one Python loop per beam: for small cases in tests."""

from __future__ import annotations

import numpy as np


def laser_pose(pose, T_base_laser):
    x, y, t = pose
    c, s = np.cos(t), np.sin(t)
    return np.array(
        [
            x + c * T_base_laser[0] - s * T_base_laser[1],
            y + s * T_base_laser[0] + c * T_base_laser[1],
            t + T_base_laser[2],
        ]
    )


def cell(x, y, origin, res):
    return int(np.floor((x - origin[0]) / res)), int(np.floor((y - origin[1]) / res))


def traversed_cells(x0, y0, x1, y1, origin, res):
    """Cells a segment passes through from its start cell to its end cell (both included), in order."""
    c0, c1 = cell(x0, y0, origin, res), cell(x1, y1, origin, res)
    ix, iy = c0
    dx, dy = x1 - x0, y1 - y0
    sx, sy = (1 if dx >= 0 else -1), (1 if dy >= 0 else -1)
    inv_dx = 1 / abs(dx) if abs(dx) > 1e-9 else 1e30
    inv_dy = 1 / abs(dy) if abs(dy) > 1e-9 else 1e30
    t_x = abs(origin[0] + (ix + max(sx, 0)) * res - x0) * inv_dx
    t_y = abs(origin[1] + (iy + max(sy, 0)) * res - y0) * inv_dy
    out = []
    for _ in range(abs(c1[0] - c0[0]) + abs(c1[1] - c0[1])):
        out.append((ix, iy))
        if t_x < t_y:
            ix, t_x = ix + sx, t_x + res * inv_dx
        else:
            iy, t_y = iy + sy, t_y + res * inv_dy
    return out + [c1]


def bresenham_cells(x0, y0, x1, y1, origin, res):
    """The 8-connected integer line from the start cell to the end cell (both included), in order."""
    (x, y), (X, Y) = cell(x0, y0, origin, res), cell(x1, y1, origin, res)
    dx, dy = abs(X - x), -abs(Y - y)
    sx, sy = (1 if X >= x else -1), (1 if Y >= y else -1)
    err, out = dx + dy, []
    for _ in range(max(dx, -dy)):
        out.append((x, y))
        e2 = 2 * err
        if e2 >= dy:
            err, x = err + dy, x + sx
        if e2 <= dx:
            err, y = err + dx, y + sy
    return out + [(X, Y)]


def integrate(maps, pose, T_base_laser, ranges, angles, far_m, origin, res, line="bresenham", free_space=True):
    """maps: dict of [H, W] arrays (visits, hits, sx, sy: the sums of the end points' offsets from their cell's corner) of one particle, updated in place; ``line``:
    bresenham (the released code) or dda (every crossed cell); ``free_space=False``: only the end cells
    (the released code with generateMap off, as its ROS wrapper runs it)."""
    walk = bresenham_cells if line == "bresenham" else traversed_cells
    H, W = maps["visits"].shape
    lp = laser_pose(pose, T_base_laser)
    for r, a in zip(ranges, angles):
        if not np.isfinite(r) or r <= 0:
            continue
        hit, r = r <= far_m, min(r, far_m)
        ex, ey = lp[0] + r * np.cos(lp[2] + a), lp[1] + r * np.sin(lp[2] + a)
        cells = walk(lp[0], lp[1], ex, ey, origin, res)
        if not hit:
            cells = cells[:-1]  # a beam without echo leaves the cell at the usable range untouched
        if not free_space:
            cells = cells[-1:] if hit else []
        for k, (ix, iy) in enumerate(cells):
            if 0 <= ix < W and 0 <= iy < H:
                maps["visits"][iy, ix] += 1
                if k == len(cells) - 1 and hit:
                    maps["hits"][iy, ix] += 1
                    maps["sx"][iy, ix] += ex - (origin[0] + ix * res)  # offsets from the cell's corner, as the kernel
                    maps["sy"][iy, ix] += ey - (origin[1] + iy * res)


def occupancy(maps, ix, iy):
    H, W = maps["visits"].shape
    if not (0 <= ix < W and 0 <= iy < H) or maps["visits"][iy, ix] <= 0:
        return -1.0
    return maps["hits"][iy, ix] / maps["visits"][iy, ix]


def score(
    maps,
    pose,
    T_base_laser,
    ranges,
    angles,
    far_m,
    origin,
    res,
    kernel_size=1,
    fullness=0.1,
    sigma=0.05,
    lsigma=0.075,
    null_likelihood=-0.5,
    free_delta=0.05 * np.sqrt(2),
    lskip=0,
    free_check=True,
):
    """(score, log-likelihood) of one pose against one map (GMapping's matcher model); ``free_check=False``
    accepts an occupied cell whatever the cell before it holds (what the released code does in effect)."""
    lp = laser_pose(pose, T_base_laser)
    s = loglik = 0.0
    for b, (r, a) in enumerate(zip(ranges, angles)):
        if b % (lskip + 1) or not np.isfinite(r) or r <= 0 or r > far_m:
            continue
        ca, sa = np.cos(lp[2] + a), np.sin(lp[2] + a)
        ex, ey = lp[0] + r * ca, lp[1] + r * sa
        hx, hy = cell(ex, ey, origin, res)
        fx, fy = cell(ex - free_delta * ca, ey - free_delta * sa, origin, res)
        best = None
        for ox in range(-kernel_size, kernel_size + 1):
            for oy in range(-kernel_size, kernel_size + 1):
                if occupancy(maps, hx + ox, hy + oy) > fullness and (
                    not free_check or occupancy(maps, fx + ox, fy + oy) < fullness
                ):
                    n = maps["hits"][hy + oy, hx + ox]
                    mx = origin[0] + (hx + ox) * res + maps["sx"][hy + oy, hx + ox] / n  # the cell's mean hit point
                    my = origin[1] + (hy + oy) * res + maps["sy"][hy + oy, hx + ox] / n
                    d2 = (ex - mx) ** 2 + (ey - my) ** 2
                    best = d2 if best is None else min(best, d2)
        if best is not None:
            s += np.exp(-best / sigma)
            loglik += -best / lsigma
        else:
            loglik += null_likelihood / lsigma
    return s, loglik


def motion_std(delta, srr=0.1, srt=0.2, str_=0.1, stt=0.2):
    """Standard deviations of GMapping's motion noise on (x, y, theta) of an odometry step in the old frame."""
    ax, ay, at = np.abs(delta)
    sxy = 0.3 * srr
    return np.array(
        [
            srr * ax + str_ * at + sxy * ay,
            srr * ay + str_ * at + sxy * ax,
            stt * at + srt * np.hypot(delta[0], delta[1]),
        ]
    )


MOVES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


def hill_climb(evaluate, start, lstep: float, astep: float, iterations: int, max_rounds: int = 200):
    """GMapping's matcher search for P poses at once: try the 6 moves (+-x, +-y, +-theta) of the current steps;
    take the best if it raises the score, else halve the steps; stop when a round at the steps halved
    ``iterations`` times fails as well. ``evaluate(cand [P, C, 3]) -> scores [P, C]``. Returns (poses,
    scores, rounds)."""
    pose = np.array(start, np.float64)
    P = len(pose)
    best = evaluate(pose[:, None])[:, 0]
    steps = np.tile([lstep, lstep, astep], (P, 1)).astype(np.float64)
    halvings = np.zeros(P, int)
    rounds = 0
    active = np.ones(P, bool)
    while active.any() and rounds < max_rounds:
        rounds += 1
        cand = pose[:, None, :] + MOVES[None] * steps[:, None, :]
        score = evaluate(cand)
        k = np.argmax(score, 1)
        top = score[np.arange(P), k]
        better = active & (top > best)
        pose[better] = cand[better, k[better]]
        best[better] = top[better]
        worse = active & ~better
        active[worse & (halvings >= iterations)] = False
        halve = worse & (halvings < iterations)
        steps[halve] *= 0.5
        halvings[halve] += 1
    return pose, best, rounds
