"""GMapping's hill climbing: the 6 moves, the per-round candidate and update kernels (the GPU's launched
rounds), a whole climb in one thread (the CPU's way) and in one block of threads (the GPU's way). All three
give the same poses, bit for bit.
"""

from __future__ import annotations

import warp as wp


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


def make_thread_climb_kernel(score_beams):
    """GMapping's hill climbing for the CPU, a particle's whole climb in one thread (``score_beams``: the
    score's wp.func of make_score_kernel)."""

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

    return climb


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
