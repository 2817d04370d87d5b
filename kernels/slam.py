"""Grid SLAM kernels for the Rao-Blackwellized particle filter (GMapping, Grisetti et al. T-RO 2007):
per-particle maps held as one [P, H, W] set of arrays, updated and read by one launch for all particles.

Cells are GMapping's point accumulators, one vec4 per cell (visits, hits, sx, sy): the times a beam passed
or ended in the cell, the times a beam ended in it, and the sum of those end points, so that a cell knows
where in it the walls were seen. The sums are of the end points' offsets from the cell's corner, not of
their world coordinates: in float32, a sum of a thousand hits 600 m from the origin (MIT Killian) keeps
only about 3 cm, and the matcher compares means to its 5 cm sigma (the released code sums in double). Occupancy = hits / visits, -1 where never visited. One vec4 rather than
four arrays: a lookup reads one 16-byte value (on the CPU, the matcher's cost is these cache misses).

* ``SLAM["integrate"]``: one thread per (particle, beam) walks the cells from the laser to the end point
  (``line="bresenham"``: the 8-connected integer line between the two cells, as the released code's
  gridLine; ``line="dda"``: every cell the ray crosses, Amanatides & Woo) adding a visit to each; then one
  thread per particle adds each end point (a visit, a hit and its point) in beam order. Beams longer than
  the usable range mark free space up to it and leave the cell there untouched (the released code's
  registerScan). ``free_space=False`` skips the walk: end points only, as the released code runs with
  generateMap off (its ROS wrapper's particles).
* ``SLAM["score"]``: the matcher's measurement model at candidate poses [P, C] (one thread per
  particle x candidate x beam on a GPU, x all beams on the CPU): for each beam end point, the cells of a
  (2k+1)^2 window around it that are occupied (> fullness) while the cell one free-delta before the end
  point, shifted alike, is not (``free_check=False``: occupied is enough, the released code in effect);
  mu = the end point minus the nearest such cell's mean hit point. Adds exp(-|mu|^2 / sigma) to the score
  and -|mu|^2 / lsigma (or null_likelihood / lsigma without a match) to the log-likelihood, as partial
  sums that ``reduce_partials_kernel`` adds up in beam order (the same sums on every run). Windows inside
  the map are read without a bounds check per cell.
* ``Scorer.climb``: GMapping's hill climbing, a particle's whole climb in one thread (the CPU's way: one
  launch per processed scan instead of several per round); the same poses, bit for bit, as the rounds
  that RBPF.match launches on a GPU.
* ``SLAM["motion"]``: GMapping's odometry model: the odometry step in the old pose's frame, each
  component perturbed by a Gaussian whose std grows with the motion (srr, srt, str, stt). It takes the
  steps of several scans at once and applies them in order (one launch per processed scan, not per scan).

Numpy twins: irmcl_warp/reference/slam.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import SLAM, pick_device
from irmcl_warp.kernels.weighting import laser_pose

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


@wp.func
def window_inside(c: wp.vec2i, k: int, x_hi: int, y_hi: int) -> bool:
    """Whether the (2k+1)^2 window around cell c lies in the map (x_hi, y_hi: the largest centre that fits)."""
    return c[0] >= k and c[1] >= k and c[0] <= x_hi and c[1] <= y_hi


@wp.func
def cell_inside(cells: wp.array3d(dtype=wp.vec4), p: int, ix: int, iy: int) -> wp.vec4:
    """The cell, read without a bounds check (the caller has checked the whole window)."""
    return cells[p, iy, ix]


@wp.func
def move(m: int) -> wp.vec3:
    """The 6 hill-climbing moves in units of the current steps: +-x, +-y, +-theta (map frame)."""
    if m == 0:
        return wp.vec3(1.0, 0.0, 0.0)
    if m == 1:
        return wp.vec3(-1.0, 0.0, 0.0)
    if m == 2:
        return wp.vec3(0.0, 1.0, 0.0)
    if m == 3:
        return wp.vec3(0.0, -1.0, 0.0)
    if m == 4:
        return wp.vec3(0.0, 0.0, 1.0)
    return wp.vec3(0.0, 0.0, -1.0)


def make_window_search(kernel_size: int, fullness: float, free_check: bool, read):
    """A wp.func: the smallest |end point - mean hit point|^2 over the matching cells of the (2k+1)^2 window
    around the end point's cell (1e30 where none matches), reading cells with ``read`` (``cell_at``, which
    answers an unvisited cell outside the map, or ``cell_inside``, which reads without checking). ``ex``,
    ``ey``: the end point's offset from the corner of its cell (the cells hold their hits' offsets alike)."""

    @wp.func
    def search(
        cells: wp.array3d(dtype=wp.vec4),
        p: int,
        hit_cell: wp.vec2i,
        free_cell: wp.vec2i,
        ex: float,
        ey: float,
        res: float,
    ) -> float:
        best = float(1.0e30)
        for oy in range(wp.static(-kernel_size), wp.static(kernel_size + 1)):  # row by row in memory
            for ox in range(wp.static(-kernel_size), wp.static(kernel_size + 1)):
                h = read(cells, p, hit_cell[0] + ox, hit_cell[1] + oy)
                # hits / visits > fullness, and the free cell's < fullness (or unvisited), without dividing
                if h[0] > 0.0 and h[1] > wp.static(fullness) * h[0]:
                    free = int(1)
                    if wp.static(free_check):
                        f = read(cells, p, free_cell[0] + ox, free_cell[1] + oy)
                        if f[0] > 0.0 and f[1] >= wp.static(fullness) * f[0]:
                            free = 0
                    if free == 1:
                        inv = 1.0 / h[1]
                        mx = ex - float(ox) * res - h[2] * inv
                        my = ey - float(oy) * res - h[3] * inv
                        d2 = mx * mx + my * my
                        if d2 < best:
                            best = d2
        return best

    return search


def make_score_kernel(
    kernel_size: int,
    fullness: float,
    sigma: float,
    lsigma: float,
    null_likelihood: float,
    free_delta: float,
    beam_stride: int,
    beams_per_thread: int,
    free_check: bool = True,
):
    """One thread per particle x candidate x ``beams_per_thread`` beams (1 on a GPU for parallelism; all
    beams on the CPU, where Warp runs the threads one after another and a thread per beam costs its own
    index arithmetic). Each thread writes its partial sums to [P, C, J]; ``reduce`` adds them up in beam
    order (atomic float sums would depend on the order the GPU runs the threads in, and the hill climbing
    compares scores, so a run would not replay). A beam's direction comes from the precomputed cos / sin
    of its angle rotated by the candidate's heading: two trigonometric calls per thread, not per beam.
    Windows that lie inside the map (almost all) are read without a bounds check per cell: the same cells
    and the same sums, 1.5x faster on the CPU (docs/benchmarks.md)."""
    k = int(kernel_size)
    search_checked = make_window_search(k, fullness, free_check, cell_at)
    search_inside = make_window_search(k, fullness, free_check, cell_inside)

    @wp.func
    def score_beams(
        cells: wp.array3d(dtype=wp.vec4),
        p: int,
        pose: wp.vec3,
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        beam_cs: wp.array(dtype=wp.vec2),
        far_m: float,
        origin: wp.vec2,
        res: float,
        b0: int,
        b1: int,
    ) -> wp.vec2:
        """(score, log-likelihood) of beams b0..b1-1 at ``pose`` on map p, summed in beam order."""
        lp = laser_pose(pose, T_base_laser)
        cl = wp.cos(lp[2])
        sl = wp.sin(lp[2])
        s = float(0.0)
        ll = float(0.0)
        x_hi = cells.shape[2] - 1 - wp.static(k)
        y_hi = cells.shape[1] - 1 - wp.static(k)
        for b in range(b0, b1):
            r = ranges[b]
            if (wp.static(beam_stride) == 1 or b % wp.static(beam_stride) == 0) and r == r and r > 0.0 and r <= far_m:
                cs = beam_cs[b]
                ca = cl * cs[0] - sl * cs[1]
                sa = sl * cs[0] + cl * cs[1]
                ex = lp[0] + r * ca
                ey = lp[1] + r * sa
                hit_cell = cell_of(ex, ey, origin, res)
                free_cell = cell_of(ex - wp.static(free_delta) * ca, ey - wp.static(free_delta) * sa, origin, res)
                inside = window_inside(hit_cell, wp.static(k), x_hi, y_hi)
                if wp.static(free_check):
                    inside = inside and window_inside(free_cell, wp.static(k), x_hi, y_hi)
                lx = (ex - origin[0]) - float(hit_cell[0]) * res  # the end point's offset from its cell's corner
                ly = (ey - origin[1]) - float(hit_cell[1]) * res
                best = float(1.0e30)
                if inside:
                    best = search_inside(cells, p, hit_cell, free_cell, lx, ly, res)
                else:
                    best = search_checked(cells, p, hit_cell, free_cell, lx, ly, res)
                if best < 1.0e30:
                    s += wp.exp(-best / wp.static(sigma))
                    ll += -best / wp.static(lsigma)
                else:
                    ll += wp.static(null_likelihood / lsigma)
        return wp.vec2(s, ll)

    @wp.kernel(module="unique")
    def score(
        poses: wp.array2d(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        beam_cs: wp.array(dtype=wp.vec2),
        far_m: float,
        origin: wp.vec2,
        res: float,
        cells: wp.array3d(dtype=wp.vec4),
        part_score: wp.array3d(dtype=wp.float32),
        part_loglik: wp.array3d(dtype=wp.float32),
        active: wp.array(dtype=wp.int32),
    ):
        p, c, j = wp.tid()
        if active[p] == 0:
            return
        b0 = j * wp.static(beams_per_thread)
        b1 = wp.min(b0 + wp.static(beams_per_thread), ranges.shape[0])
        sl = score_beams(cells, p, poses[p, c], T_base_laser, ranges, beam_cs, far_m, origin, res, b0, b1)
        part_score[p, c, j] = sl[0]
        part_loglik[p, c, j] = sl[1]

    @wp.kernel(module="unique")
    def climb(
        start: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        beam_cs: wp.array(dtype=wp.vec2),
        far_m: float,
        origin: wp.vec2,
        res: float,
        cells: wp.array3d(dtype=wp.vec4),
        first_steps: wp.vec3,
        iterations: int,
        max_rounds: int,
        pose_out: wp.array(dtype=wp.vec3),
        best_out: wp.array(dtype=wp.float32),
        rounds_out: wp.array(dtype=wp.int32),
    ):
        """The whole hill climb of one particle in one thread (the CPU's way: no launch per round, no
        particle waiting for the slowest). Each round is the one ``climb_candidates`` + ``score`` +
        ``climb_update`` make, with the same sums in the same order, so the poses are the same bit for bit."""
        p = wp.tid()
        B = ranges.shape[0]
        pose = start[p]
        best = score_beams(cells, p, pose, T_base_laser, ranges, beam_cs, far_m, origin, res, 0, B)[0]
        steps = first_steps
        halvings = int(0)
        rounds = int(0)
        # the pose the last move left and its score: the next round's opposite move lands on it again whenever
        # pose + step - step gives back the same floats (almost always), and is then not scored again (10 %
        # fewer beam evaluations on intel; it scored below the current best, so it cannot win the round anyway)
        left = pose
        left_score = float(0.0)
        back = int(-1)  # the move that goes back to ``left`` (-1: none)
        while rounds < max_rounds:
            rounds += 1
            top = float(0.0)
            top_pose = pose
            top_move = int(0)
            for m in range(6):
                cand = pose + wp.cw_mul(move(m), steps)
                sc = float(0.0)
                if m == back and cand[0] == left[0] and cand[1] == left[1] and cand[2] == left[2]:
                    sc = left_score
                else:
                    sc = score_beams(cells, p, cand, T_base_laser, ranges, beam_cs, far_m, origin, res, 0, B)[0]
                if m == 0 or sc > top:
                    top = sc
                    top_pose = cand
                    top_move = m
            if top > best:
                left = pose
                left_score = best
                back = top_move ^ 1  # moves come in pairs: +x -x, +y -y, +theta -theta
                pose = top_pose
                best = top
            elif halvings >= iterations:
                break
            else:
                steps = 0.5 * steps
                halvings += 1
        pose_out[p] = pose
        best_out[p] = best
        rounds_out[p] = rounds

    return score, climb, make_block_climb_kernel(score_beams)


vec6 = wp.types.vector(6, wp.float32)


def make_block_climb_kernel(score_beams):
    """GMapping's hill climbing for a GPU, one block of threads per particle and one thread per beam, the whole
    climb in one launch. Every thread holds the same climb state (pose, best, steps); per round each thread
    scores its beam at the 6 moves, the block shares the 6 contributions of every beam through a tile, and
    every thread adds them up in beam order, so all threads take the same decision and the sums are the
    partial sums ``score`` + ``reduce_partials_kernel`` make, in the same order: the same poses, bit for bit,
    as the launched rounds (tests/test_slam.py, on cuda:0 by eval/gpu/tests.sh), without a launch or a look
    from the host per round. Launch with ``wp.launch_tiled(..., dim=[P], block_dim=b)``, b >= the beams
    (``block_dim_for``; a scan of more than ``MAX_BLOCK_BEAMS`` beams climbs in launched rounds instead)."""

    @wp.func
    def beam_score(
        cells: wp.array3d(dtype=wp.vec4),
        p: int,
        pose: wp.vec3,
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        beam_cs: wp.array(dtype=wp.vec2),
        far_m: float,
        origin: wp.vec2,
        res: float,
        lane: int,
    ) -> float:
        """The beam ``lane``'s term of the score at ``pose`` (0 for a thread past the last beam)."""
        B = ranges.shape[0]
        return score_beams(
            cells, p, pose, T_base_laser, ranges, beam_cs, far_m, origin, res, wp.min(lane, B), wp.min(lane + 1, B)
        )[0]

    @wp.kernel(module="unique")
    def climb_block(
        start: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        ranges: wp.array(dtype=wp.float32),
        beam_cs: wp.array(dtype=wp.vec2),
        far_m: float,
        origin: wp.vec2,
        res: float,
        cells: wp.array3d(dtype=wp.vec4),
        first_steps: wp.vec3,
        iterations: int,
        max_rounds: int,
        pose_out: wp.array(dtype=wp.vec3),
        best_out: wp.array(dtype=wp.float32),
        rounds_out: wp.array(dtype=wp.int32),
    ):
        p, lane = wp.tid()
        B = ranges.shape[0]
        pose = start[p]
        t0 = wp.tile(beam_score(cells, p, pose, T_base_laser, ranges, beam_cs, far_m, origin, res, lane))
        best = float(0.0)
        for j in range(B):
            best += t0[j]
        steps = first_steps
        halvings = int(0)
        rounds = int(0)
        while rounds < max_rounds:
            rounds += 1
            mine = vec6()
            for m in range(6):
                mine[m] = beam_score(
                    cells, p, pose + wp.cw_mul(move(m), steps), T_base_laser, ranges, beam_cs, far_m, origin, res, lane
                )
            t = wp.tile(mine, preserve_type=True)
            sums = vec6()
            for j in range(B):  # in beam order, as reduce_partials_kernel
                sums += t[j]
            k = int(0)
            for m in range(1, 6):
                if sums[m] > sums[k]:
                    k = m
            if sums[k] > best:
                pose = pose + wp.cw_mul(move(k), steps)
                best = sums[k]
            elif halvings >= iterations:
                break
            else:
                steps = 0.5 * steps
                halvings += 1
        if lane == 0:
            pose_out[p] = pose
            best_out[p] = best
            rounds_out[p] = rounds

    return climb_block


MAX_BLOCK_BEAMS = 1024  # threads per block on NVIDIA GPUs


def block_dim_for(beams: int) -> int:
    """Threads per block of the block climb: the beams rounded up to whole warps of 32."""
    if not 1 <= beams <= MAX_BLOCK_BEAMS:
        raise ValueError(
            f"slam: the block climb runs a thread per beam, at most {MAX_BLOCK_BEAMS}; this scan has "
            f"{beams} (RBPF.match(how='rounds') climbs such scans)"
        )
    return 32 * ((beams + 31) // 32)


@wp.kernel
def reduce_partials_kernel(
    part_score: wp.array3d(dtype=wp.float32),
    part_loglik: wp.array3d(dtype=wp.float32),
    active: wp.array(dtype=wp.int32),
    out_score: wp.array2d(dtype=wp.float32),
    out_loglik: wp.array2d(dtype=wp.float32),
):
    """Sums of the partials in beam order (the same on every run); 0 for inactive particles."""
    p, c = wp.tid()
    if active[p] == 0:
        out_score[p, c] = 0.0
        out_loglik[p, c] = 0.0
        return
    s = float(0.0)
    ll = float(0.0)
    for j in range(part_score.shape[2]):
        s += part_score[p, c, j]
        ll += part_loglik[p, c, j]
    out_score[p, c] = s
    out_loglik[p, c] = ll


@wp.kernel
def motion_kernel(
    poses: wp.array(dtype=wp.vec3),
    deltas: wp.array(dtype=wp.vec3),
    srr: float,
    srt: float,
    str_: float,
    stt: float,
    seed: int,
):
    """GMapping's drawFromMotion, once per odometry step in order: delta = the step in the old pose's frame."""
    i = wp.tid()
    state = wp.rand_init(seed, i)
    sxy = 0.3 * srr
    p = poses[i]
    for k in range(deltas.shape[0]):
        delta = deltas[k]
        ax = wp.abs(delta[0])
        ay = wp.abs(delta[1])
        at = wp.abs(delta[2])
        nx = delta[0] + wp.randn(state) * (srr * ax + str_ * at + sxy * ay)
        ny = delta[1] + wp.randn(state) * (srr * ay + str_ * at + sxy * ax)
        nt = delta[2] + wp.randn(state) * (stt * at + srt * wp.sqrt(delta[0] * delta[0] + delta[1] * delta[1]))
        c = wp.cos(p[2])
        s = wp.sin(p[2])
        t = p[2] + nt
        p = wp.vec3(p[0] + c * nx - s * ny, p[1] + s * nx + c * ny, wp.atan2(wp.sin(t), wp.cos(t)))
    poses[i] = p


@wp.kernel
def climb_candidates_kernel(
    pose: wp.array(dtype=wp.vec3), steps: wp.array(dtype=wp.vec3), cand: wp.array2d(dtype=wp.vec3)
):
    p, m = wp.tid()
    cand[p, m] = pose[p] + wp.cw_mul(move(m), steps[p])


@wp.kernel
def climb_update_kernel(
    cand: wp.array2d(dtype=wp.vec3),
    score: wp.array2d(dtype=wp.float32),
    pose: wp.array(dtype=wp.vec3),
    best: wp.array(dtype=wp.float32),
    steps: wp.array(dtype=wp.vec3),
    halvings: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    iterations: int,
):
    """Take the best move if it raises the score, else halve the steps; a particle is done when a round at
    the steps halved ``iterations`` times fails too (GMapping's optimize: iterations + 1 step sizes)."""
    p = wp.tid()
    if active[p] == 0:
        return
    k = int(0)
    for m in range(1, 6):
        if score[p, m] > score[p, k]:
            k = m
    if score[p, k] > best[p]:
        pose[p] = cand[p, k]
        best[p] = score[p, k]
    elif halvings[p] >= iterations:
        active[p] = 0
    else:
        steps[p] = 0.5 * steps[p]
        halvings[p] = halvings[p] + 1


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


class Scorer:
    """Score and log-likelihood of candidate poses [P, C] against each particle's own map.

    On the CPU, Warp runs a launch's threads one after another on the calling thread; the scorer splits
    the launch into ``cpu_threads`` blocks (default: the machine's cores) and launches them from as many
    host threads (ctypes drops the GIL during a launch), so that the matcher uses every core."""

    def __init__(
        self,
        far_m: float,
        kernel_size: int = 1,
        fullness: float = 0.1,
        sigma: float = 0.05,
        lsigma: float = 0.075,
        null_likelihood: float = -0.5,
        free_delta_m: float = 0.05 * np.sqrt(2),
        lskip: int = 0,
        free_check: bool = True,
        cpu_threads: int | None = None,
        device: str = "auto",
    ):
        import os

        self.far_m, self.device = float(far_m), pick_device(device)
        cuda = wp.get_device(self.device).is_cuda
        self.per_thread = 1 if cuda else 1 << 16
        self.threads = 1 if cuda else max(1, int(cpu_threads or os.cpu_count() or 1))
        self._pool = None
        self._partials, self._beam_cs = {}, None
        self.kernel, self.climb_kernel, self.block_climb_kernel = make_score_kernel(
            int(kernel_size),
            float(fullness),
            float(sigma),
            float(lsigma),
            float(null_likelihood),
            float(free_delta_m),
            int(lskip) + 1,
            self.per_thread,
            bool(free_check),
        )

    def __call__(
        self,
        maps: ParticleMaps,
        candidates: wp.array,
        T_base_laser,
        ranges: wp.array,
        angles: wp.array,
        score: wp.array,
        loglik: wp.array,
        active: wp.array | None = None,
    ) -> None:
        """candidates [P, C] (vec3); fills score and loglik [P, C]; ``active`` [P] (int32): particles marked 0
        are skipped and get 0 (all scored when None)."""
        P, C = candidates.shape
        if active is None:
            if getattr(self, "_all", None) is None or self._all.shape[0] != P:
                self._all = wp.ones(P, dtype=wp.int32, device=self.device)
            active = self._all
        B, T = ranges.shape[0], wp.vec3(*map(float, T_base_laser))
        part_s, part_l = self.reserve(P, C, B)
        beam_cs = self._beam_directions(angles)

        def run(p0: int, p1: int) -> None:
            def part(a: wp.array) -> wp.array:  # one block of all particles: the arrays themselves, no views made
                return a if (p0, p1) == (0, P) else a[p0:p1]

            wp.launch(
                self.kernel,
                (p1 - p0, C, part_s.shape[2]),
                [
                    part(candidates),
                    T,
                    ranges,
                    beam_cs,
                    self.far_m,
                    maps.origin,
                    maps.res,
                    part(maps.cells),
                    part(part_s),
                    part(part_l),
                    part(active),
                ],
                device=self.device,
            )

        self._run_blocks(run, P)
        wp.launch(reduce_partials_kernel, (P, C), [part_s, part_l, active, score, loglik], device=self.device)

    def climb(
        self,
        maps: ParticleMaps,
        start: wp.array,
        T_base_laser,
        ranges: wp.array,
        angles: wp.array,
        first_steps,
        iterations: int,
        max_rounds: int,
        pose: wp.array,
        best: wp.array,
        rounds: wp.array,
    ) -> None:
        """GMapping's hill climbing from ``start`` [P] (vec3), one thread per particle for the whole climb
        (meant for the CPU; on a GPU the rounds are launched over particles x moves x beams instead, RBPF.match).
        Fills pose [P], best [P] (its score) and rounds [P] (the rounds each particle took)."""
        T, beam_cs = wp.vec3(*map(float, T_base_laser)), self._beam_directions(angles)
        steps = wp.vec3(*map(float, first_steps))

        def run(p0: int, p1: int) -> None:
            wp.launch(
                self.climb_kernel,
                p1 - p0,
                [
                    start[p0:p1],
                    T,
                    ranges,
                    beam_cs,
                    self.far_m,
                    maps.origin,
                    maps.res,
                    maps.cells[p0:p1],
                    steps,
                    int(iterations),
                    int(max_rounds),
                    pose[p0:p1],
                    best[p0:p1],
                    rounds[p0:p1],
                ],
                device=self.device,
            )

        self._run_blocks(run, start.shape[0])

    def climb_blocks(
        self,
        maps: ParticleMaps,
        start: wp.array,
        T_base_laser,
        ranges: wp.array,
        angles: wp.array,
        first_steps,
        iterations: int,
        max_rounds: int,
        pose: wp.array,
        best: wp.array,
        rounds: wp.array,
    ) -> None:
        """climb's GPU way: one block per particle, a thread per beam, the whole climb in one launch
        (``make_block_climb_kernel``); the same arguments and results as ``climb``. On the CPU only with
        ``wp.config.enable_cpu_blocks`` (Warp's CPU runs a block as one thread otherwise: the tests use it)."""
        if not wp.get_device(self.device).is_cuda and not wp.config.enable_cpu_blocks:
            raise ValueError(
                "Scorer.climb_blocks: a block per particle needs a GPU, or wp.config.enable_cpu_blocks "
                "on the CPU; use Scorer.climb there"
            )
        wp.launch_tiled(
            self.block_climb_kernel,
            dim=[start.shape[0]],
            inputs=[
                start,
                wp.vec3(*map(float, T_base_laser)),
                ranges,
                self._beam_directions(angles),
                self.far_m,
                maps.origin,
                maps.res,
                maps.cells,
                wp.vec3(*map(float, first_steps)),
                int(iterations),
                int(max_rounds),
                pose,
                best,
                rounds,
            ],
            block_dim=block_dim_for(ranges.shape[0]),
            device=self.device,
        )

    def reserve(self, P: int, C: int, B: int):
        """The partial-sum buffers for P x C candidates of B beams (allocate before a CUDA graph capture)."""
        key = (P, C, (B + self.per_thread - 1) // self.per_thread)
        if key not in self._partials:
            self._partials[key] = (
                wp.zeros(key, dtype=wp.float32, device=self.device),
                wp.zeros(key, dtype=wp.float32, device=self.device),
            )
        return self._partials[key]

    def _beam_directions(self, angles: wp.array) -> wp.array:
        """(cos, sin) of each beam's angle in the laser frame, computed once per angles array."""
        if self._beam_cs is None or self._beam_cs[0] is not angles:
            a = angles.numpy().astype(np.float64)
            cs = np.stack([np.cos(a), np.sin(a)], 1).astype(np.float32)
            self._beam_cs = (angles, wp.array(cs, dtype=wp.vec2, device=self.device))
        return self._beam_cs[1]

    def _run_blocks(self, run, P: int) -> None:
        """``run(p0, p1)`` launches particles p0..p1-1: once for all of them with one host thread (and on a GPU),
        else as blocks of particles from ``threads`` host threads (blocks of candidates, each holding every
        particle, measured 1.6x slower on 2 cores: each core then reads all maps)."""
        if self.threads == 1:
            run(0, P)
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="slam-score")
        cuts = np.linspace(0, P, min(self.threads, P) + 1).astype(int)
        for f in [self._pool.submit(run, int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:])]:
            f.result()


class GmappingMotion:
    def __init__(self, srr: float = 0.1, srt: float = 0.2, str_: float = 0.1, stt: float = 0.2, device: str = "auto"):
        self.noise, self.device = (float(srr), float(srt), float(str_), float(stt)), pick_device(device)
        self._staged = None  # on a GPU: (device buffer, pinned host buffer, its numpy view) for the steps

    def __call__(self, poses: wp.array, deltas, seed: int) -> None:
        """Moves the poses by the odometry steps ``deltas`` ([K, 3] or one [3]), in order."""
        d = np.asarray(deltas, np.float32).reshape(-1, 3)
        wp.launch(
            motion_kernel, poses.shape[0], [poses, self._on_device(d), *self.noise, int(seed)], device=self.device
        )

    def _on_device(self, d: np.ndarray) -> wp.array:
        """The steps on the device. On a GPU through a pinned buffer kept between calls (a new device array from
        numpy would allocate and copy through pageable memory at every processed scan)."""
        if not wp.get_device(self.device).is_cuda:
            return wp.array(d, dtype=wp.vec3, device=self.device)
        if self._staged is None or self._staged[0].shape[0] < len(d):
            n = max(64, 2 * len(d))
            host = wp.empty(n, dtype=wp.vec3, device="cpu", pinned=True)
            self._staged = (wp.empty(n, dtype=wp.vec3, device=self.device), host, host.numpy())
        buf, host, view = self._staged
        wp.synchronize_stream(wp.get_stream(self.device))  # the last call's copy has run (the stream is idle here)
        view[: len(d)] = d
        wp.copy(buf, host, count=len(d))
        return buf[: len(d)]


SLAM.register("integrate")(lambda **kw: Integrator(**kw))
SLAM.register("score")(lambda **kw: Scorer(**kw))
SLAM.register("motion")(lambda **kw: GmappingMotion(**kw))
