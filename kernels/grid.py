"""Helpers shared by kernels that walk an occupancy grid.

Grid convention (same as ROS map_server once flipped): cell (row iy, col ix) covers world
[origin.x + ix*res, origin.x + (ix+1)*res) x [origin.y + iy*res, origin.y + (iy+1)*res).
"""

import warp as wp

BIG = 1.0e30


@wp.func
def inside(ix: int, iy: int, width: int, height: int) -> bool:
    return ix >= 0 and iy >= 0 and ix < width and iy < height


@wp.func
def first_boundary(g: float, d: float, i: int) -> float:
    """Ray parameter (grid units) at which a ray starting at coordinate g, direction d, leaves cell i."""
    if d > 0.0:
        return (float(i + 1) - g) / d
    if d < 0.0:
        return (g - float(i)) / (-d)
    return BIG


@wp.func
def step_sign(d: float) -> int:
    if d > 0.0:
        return 1
    return -1


@wp.func
def inv_abs(d: float) -> float:
    if d == 0.0:
        return BIG
    return 1.0 / wp.abs(d)


@wp.func
def walk_start(g: wp.vec2, d: wp.vec2):
    """The state of an exact cell walk (Amanatides & Woo) of a ray from g (grid units) along d: the cell
    (ix, iy), the step per axis (sx, sy), the ray parameter of the next cell boundary per axis (t_max_x,
    t_max_y) and the parameter between boundaries per axis (dx, dy)."""
    ix = int(wp.floor(g[0]))
    iy = int(wp.floor(g[1]))
    return (
        ix,
        iy,
        step_sign(d[0]),
        step_sign(d[1]),
        first_boundary(g[0], d[0], ix),
        first_boundary(g[1], d[1], iy),
        inv_abs(d[0]),
        inv_abs(d[1]),
    )
