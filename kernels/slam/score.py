"""``SLAM["score"]``: the scan matcher's measurement model at candidate poses, summed in beam order, and
the ``Scorer`` that launches it and the hill climbs of climb.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import SLAM, ParticleBlocks, pick_device
from irmcl_warp.kernels.weighting.common import laser_pose
from irmcl_warp.kernels.slam.climb import block_dim_for, make_block_climb_kernel, make_thread_climb_kernel
from irmcl_warp.kernels.slam.maps import ParticleMaps, cell_at, cell_of


@wp.func
def window_inside(c: wp.vec2i, k: int, x_hi: int, y_hi: int) -> bool:
    """Whether the (2k+1)^2 window around cell c lies in the map (x_hi, y_hi: the largest centre that fits)."""
    return c[0] >= k and c[1] >= k and c[0] <= x_hi and c[1] <= y_hi


@wp.func
def cell_inside(cells: wp.array3d(dtype=wp.vec4), p: int, ix: int, iy: int) -> wp.vec4:
    """The cell, read without a bounds check (the caller has checked the whole window)."""
    return cells[p, iy, ix]


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

    return score, make_thread_climb_kernel(score_beams), make_block_climb_kernel(score_beams)


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
        self.far_m, self.device = float(far_m), pick_device(device)
        cuda = wp.get_device(self.device).is_cuda
        self.per_thread = 1 if cuda else 1 << 16
        # on the CPU a block of particles per core (blocks of candidates, each holding every particle, were measured
        # 1.6x slower on 2 cores: each core then reads all maps)
        self.blocks = ParticleBlocks(self.device, cpu_threads)
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

        self.blocks.run(run, P)
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

        self.blocks.run(run, start.shape[0])

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


SLAM.register("score")(lambda **kw: Scorer(**kw))
