"""Weights and resampling of a particle set, all on the device: ``RESAMPLE["low_variance"]`` (systematic:
one random offset, N evenly spaced pointers; Thrun et al. Table 4.4) and ``RESAMPLE["multinomial"]``
(N independent draws). Both draw from the cumulative weights by binary search, a thread per pointer; on a
CPU the low-variance draw walks the cumulative weights once in one thread instead (the same particles).

``ParticleWeights`` turns log-weights into weights (subtracting their maximum, found by atomic max),
their cumulative sum (``ordered_scan`` on a GPU, Warp's array_scan on a CPU), the effective sample size 1 / sum(w_norm^2), and the
weighted mean pose (circular mean for yaw). Numpy twins: irmcl_warp/reference/resample.py.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from irmcl_warp.kernels.radix import SELECT_BINS, first_digit
from irmcl_warp.kernels.registry import (
    RESAMPLE,
    PartialSums,
    launch_reduction,
    pick_device,
    reduction_threads,
    sums_array,
)


@wp.kernel
def accumulate_kernel(log_w: wp.array(dtype=wp.float32), log_likelihood: wp.array(dtype=wp.float32), temper: float):
    """Importance weights multiply across steps until the set is resampled: log w += temper * log p(z | x)
    (temper 1: the likelihood as the model gives it; below 1 a likelihood tempered to fewer independent beams)."""
    i = wp.tid()
    log_w[i] = log_w[i] + temper * log_likelihood[i]


@wp.kernel
def max_kernel(log_w: wp.array(dtype=wp.float32), out: wp.array(dtype=wp.float32), stride: int):
    top = float(-3.0e38)
    for i in range(wp.tid(), log_w.shape[0], stride):
        top = wp.max(top, log_w[i])
    wp.atomic_max(out, 0, top)


TILE = 256  # threads per block of a tiled launch on a GPU (a CPU runs blocks of one thread)


def tile_block(size: int, device: str) -> int:
    """Threads per block of a tiled launch of ``size`` on ``device``: ``size`` on a GPU, 1 on a CPU (Warp runs a CPU
    block as one thread)."""
    return size if wp.get_device(device).is_cuda else 1


@wp.kernel
def accumulate_max_kernel(
    log_w: wp.array(dtype=wp.float32),
    log_likelihood: wp.array(dtype=wp.float32),
    temper: float,
    top: wp.array(dtype=wp.float32),
    keys: wp.array(dtype=wp.float32),
    values: wp.array(dtype=wp.int32),
    rank: int,
    first_hist: wp.array(dtype=int),
):
    """``accumulate_kernel`` and ``max_kernel`` in one tiled launch (a GPU's step, one launch and one pass over the
    log-weights fewer): each block's largest new log-weight by a tile reduction, then one atomic max per block (a
    maximum: the same bits in any order). With ``rank``, also the top-share estimate's sort keys -log w and
    indices (``rank_keys_kernel`` in kernels/estimate.py). Given ``first_hist`` (SELECT_BINS counts, zero before),
    also the radix select's first pass: each block counts its new keys' first digits in shared memory and adds the
    counts into ``first_hist`` (integers: the same counts in any order; ``select_histogram_kernel`` pass 0)."""
    b, lane = wp.tid()
    i = b * wp.block_dim() + lane
    v = float(-3.0e38)
    if i < log_w.shape[0]:
        v = log_w[i] + temper * log_likelihood[i]
        log_w[i] = v
        if rank != 0:
            keys[i] = -v
            values[i] = i
    m = wp.tile_max(wp.tile(v))
    if lane == 0:
        wp.atomic_max(top, 0, m[0])
    if first_hist.shape[0] > 0:  # the same in every thread of the block
        bins = wp.tile_zeros(shape=SELECT_BINS, dtype=int, storage="shared")
        digit = int(0)
        if i < log_w.shape[0]:
            digit = first_digit(-keys[i])  # the key's bits as the select reads them (-(-v): v's bits)
        wp.tile_scatter_add(bins, digit, 1, i < log_w.shape[0])
        for t in range(SELECT_BINS // wp.block_dim()):
            d = t * wp.block_dim() + lane
            c = bins[d]
            if c != 0:
                wp.atomic_add(first_hist, d, c)


SCAN_TILE = 1024  # elements a block scans at once on a GPU (``ordered_scan``)
# Every tile scan of the cdf is followed by a running maximum (``wp.tile_scan_max_inclusive``). A GPU's tile scan adds
# each element's prefix in its own order (a tree of warp shuffles), so for non-negative terms a sum can round below the
# one before it where the next term is tiny against it (H200, 39,511 weights exp(N(0, 2)): the cdf stepped down by a
# last bit). The maximum is exact in any order, so the scan keeps the same bits on every run and never decreases.
# (Inlined: a generic wp.func holding the two failed to build on the H200 once, a 1024-wide tile in a 256-wide build.)


@wp.kernel
def block_scan_kernel(
    w: wp.array(dtype=wp.float32), cdf: wp.array(dtype=wp.float32), totals: wp.array(dtype=wp.float32)
):
    """Each block's inclusive prefix sums of ``w`` into ``cdf`` (a tile scan: a fixed order, then its running maximum:
    SCAN_TILE's note) and its total."""
    b, lane = wp.tid()
    i = b * wp.block_dim() + lane
    v = float(0.0)
    if i < w.shape[0]:
        v = w[i]
    mine = wp.untile(wp.tile_scan_max_inclusive(wp.tile_scan_inclusive(wp.tile(v))))
    if i < w.shape[0]:
        cdf[i] = mine
    if lane == wp.block_dim() - 1:
        totals[b] = mine


@wp.kernel
def totals_scan_kernel(totals: wp.array(dtype=wp.float32), count: int):
    """The blocks' totals into their running sums, one after another in one thread."""
    s = float(0.0)
    for j in range(count):
        s += totals[j]
        totals[j] = s


@wp.kernel
def totals_tile_scan_kernel(totals: wp.array(dtype=wp.float32), count: int):
    """``totals_scan_kernel`` for at most a block's worth of totals (a GPU, up to SCAN_TILE^2 elements): one tile scan."""
    _b, lane = wp.tid()
    v = float(0.0)
    if lane < count:
        v = totals[lane]
    mine = wp.untile(wp.tile_scan_max_inclusive(wp.tile_scan_inclusive(wp.tile(v))))
    if lane < count:
        totals[lane] = mine


@wp.kernel
def add_block_offsets_kernel(cdf: wp.array(dtype=wp.float32), totals: wp.array(dtype=wp.float32), block: int):
    """Each block's prefix sums moved by the running sum of the blocks before it, and kept at most its own running
    sum: the two are rounded apart (the block's last sum plus the offset, against the totals' scan), and a block's
    last element above the next block's offset would step the cdf down at the join."""
    i = wp.tid()
    b = i // block
    if b > 0:
        cdf[i] = wp.min(cdf[i] + totals[b - 1], totals[b])


def ordered_scan(w: wp.array, cdf: wp.array, totals: wp.array, device: str) -> None:
    """cdf = the inclusive prefix sums of w, the same bits on every run: blocks of SCAN_TILE scanned as tiles, their
    totals summed in order, each block's elements moved by the totals before it. (CUB's scan, which
    ``wp.utils.array_scan`` runs on a GPU, adds its tiles' partial sums in the order the tiles finish: two runs
    can round a float differently, and resampling then draws other particles: found in the twenty-first session,
    a 100k worlds run on an H100 parting from itself at its first resampling.) ``totals``: ceil(n / SCAN_TILE)."""
    n = w.shape[0]
    block = tile_block(SCAN_TILE, device)
    blocks = -(-n // block)
    if totals.shape[0] < blocks:
        raise ValueError(f"ordered_scan: room for {totals.shape[0]} block totals, {blocks} needed")
    wp.launch_tiled(block_scan_kernel, dim=[blocks], inputs=[w, cdf, totals], block_dim=block, device=device)
    if block > 1 and blocks <= block:  # a GPU's totals fit one tile (up to SCAN_TILE^2 = 1M elements)
        wp.launch_tiled(totals_tile_scan_kernel, dim=[1], inputs=[totals, blocks], block_dim=block, device=device)
    else:
        wp.launch(totals_scan_kernel, 1, [totals, blocks], device=device)
    wp.launch(add_block_offsets_kernel, n, [cdf, totals, block], device=device)


vec8 = wp.types.vector(length=8, dtype=wp.float32)


@wp.kernel
def exp_kernel(
    log_w: wp.array(dtype=wp.float32),
    top: wp.array(dtype=wp.float32),
    w: wp.array(dtype=wp.float32),
    partials: wp.array2d(dtype=wp.float32),
    particles: wp.array(dtype=wp.vec3),
    centre: wp.vec2,
    cos_sin: wp.array(dtype=wp.vec2),
    keep_cos_sin: int,
    stride: int,
):
    """w = exp(log_w - max); sums = [sum w^2, sum w x, sum w y, sum w cos, sum w sin, sum w, sum w x^2,
    sum w y^2], x and y taken relative to ``centre`` (so that the spread does not cancel in float32).
    With ``keep_cos_sin``, each particle's (cos yaw, sin yaw) is kept in ``cos_sin`` for an estimator to reuse."""
    acc = vec8()
    for i in range(wp.tid(), log_w.shape[0], stride):
        v = wp.exp(log_w[i] - top[0])
        w[i] = v
        p = particles[i]
        x = p[0] - centre[0]
        y = p[1] - centre[1]
        c = wp.cos(p[2])
        s = wp.sin(p[2])
        if keep_cos_sin != 0:
            cos_sin[i] = wp.vec2(c, s)
        acc += vec8(v * v, v * x, v * y, v * c, v * s, v, v * x * x, v * y * y)
    for c in range(8):
        partials[wp.tid(), c] = acc[c]


@wp.kernel
def weigh_scan_kernel(
    log_w: wp.array(dtype=wp.float32),
    top: wp.array(dtype=wp.float32),
    particles: wp.array(dtype=wp.vec3),
    centre: wp.vec2,
    w: wp.array(dtype=wp.float32),
    cdf: wp.array(dtype=wp.float32),
    totals: wp.array(dtype=wp.float32),
    partials: wp.array(dtype=vec8),
):
    """``exp_kernel`` and ``block_scan_kernel`` in one tiled pass over SCAN_TILE particles a block (a GPU's step):
    w = exp(log_w - max) (the same expression: the same bits), the block's inclusive prefix sums of w into ``cdf``
    and its total into ``totals[b]`` (the same tile scan: the same bits), and the block's eight sums (exp_kernel's)
    into ``partials[b]`` by a tile reduction (a fixed order; ``weigh_finish_kernel`` adds the blocks)."""
    b, lane = wp.tid()
    i = b * wp.block_dim() + lane
    v = float(0.0)
    acc = vec8()
    if i < log_w.shape[0]:
        v = wp.exp(log_w[i] - top[0])
        w[i] = v
        p = particles[i]
        x = p[0] - centre[0]
        y = p[1] - centre[1]
        acc = vec8(v * v, v * x, v * y, v * wp.cos(p[2]), v * wp.sin(p[2]), v, v * x * x, v * y * y)
    mine = wp.untile(wp.tile_scan_max_inclusive(wp.tile_scan_inclusive(wp.tile(v))))
    if i < log_w.shape[0]:
        cdf[i] = mine
    if lane == wp.block_dim() - 1:
        totals[b] = mine
    block_sums = wp.tile_sum(wp.tile(acc, preserve_type=True))
    if lane == 0:
        partials[b] = block_sums[0]


@wp.kernel
def weigh_finish_kernel(
    totals: wp.array(dtype=wp.float32),
    partials: wp.array(dtype=vec8),
    count: int,
    sums: wp.array(dtype=wp.float32),
    top: wp.array(dtype=wp.float32),
):
    """One block after ``weigh_scan_kernel``: the ``count`` blocks' totals into their running sums, and their eight
    sums into ``sums``; ``top`` (the maximum ``weigh_scan_kernel`` read, read by nothing after it) back to -3e38 for
    the next ``accumulate`` (its fill is one launch fewer). The running sums are ``ordered_scan``'s to the bit: one tile scan while each thread holds at
    most one block (a GPU, up to SCAN_TILE^2 particles), else one thread adding them in order (runs joined by a tile
    scan were tried: their float rounding let the cdf step down at a join). For the eight sums a thread adds a run
    of ceil(count / threads) blocks in order and the runs are joined by a tile reduction (a fixed order)."""
    _b, lane = wp.tid()
    run = (count + wp.block_dim() - 1) // wp.block_dim()
    lo = wp.min(lane * run, count)
    hi = wp.min(lo + run, count)
    own = float(0.0)
    acc = vec8()
    for j in range(lo, hi):
        own += totals[j]
        acc += partials[j]
    if run == 1:  # one block a thread: an inclusive tile scan of the totals themselves
        mine = wp.untile(wp.tile_scan_max_inclusive(wp.tile_scan_inclusive(wp.tile(own))))
        if lo < hi:
            totals[lo] = mine
    elif lane == 0:  # more blocks than threads: one thread adds them in order (``totals_scan_kernel``, to the bit)
        s = float(0.0)
        for j in range(count):
            s += totals[j]
            totals[j] = s
    total = wp.tile_sum(wp.tile(acc, preserve_type=True))
    if lane == 0:
        for c in range(8):
            sums[c] = total[0][c]
        top[0] = -3.0e38


@wp.func
def search(cdf: wp.array(dtype=wp.float32), u: float) -> int:
    """Smallest j with cdf[j] > u."""
    lo = int(0)
    hi = cdf.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[mid] > u:
            hi = mid
        else:
            lo = mid + 1
    return lo


@wp.func
def resample_now(sums: wp.array(dtype=wp.float32), limit: float) -> bool:
    """Selective resampling decided on the device: N_eff = (sum w)^2 / sum w^2 < limit (sums of ParticleWeights)."""
    return sums[5] * sums[5] / sums[0] < limit


@wp.func
def systematic_pointer(offset: float, i: int, n: int, total: float) -> float:
    """The i-th of n low-variance pointers into a cdf ending at ``total`` (offset in [0, 1)); one expression for
    both draws, so that the walk and the search see the same pointers to the bit."""
    return (offset + float(i)) / float(n) * total


@wp.kernel
def systematic_kernel(
    cdf: wp.array(dtype=wp.float32),
    offset: wp.array(dtype=wp.float32),
    src: wp.array(dtype=wp.vec3),
    dst: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=wp.float32),
    limit: float,
    log_w: wp.array(dtype=wp.float32),
):
    """dst = the low-variance draw from src (pointer offset ``offset[0]`` in [0, 1)) and log_w = 0 when
    N_eff < limit, else dst = src (weights kept)."""
    i = wp.tid()
    if resample_now(sums, limit):
        u = systematic_pointer(offset[0], i, dst.shape[0], cdf[cdf.shape[0] - 1])
        dst[i] = src[search(cdf, u)]
        log_w[i] = 0.0
    else:
        dst[i] = src[i]


@wp.kernel
def systematic_merge_kernel(
    cdf: wp.array(dtype=wp.float32),
    offset: wp.array(dtype=wp.float32),
    src: wp.array(dtype=wp.vec3),
    dst: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=wp.float32),
    limit: float,
    log_w: wp.array(dtype=wp.float32),
):
    """``systematic_kernel`` in one thread, for the CPU: the pointers u_i grow with i, so the smallest j with
    cdf[j] > u_i is found by walking j forward from the last one (Thrun et al. Table 4.4 as written) instead
    of a binary search per pointer. The same u_i, the same j (the cdf never decreases): the same bits, in a
    sixth of the time on a CPU core at 10k particles (a GPU keeps the search, one thread per pointer)."""
    n = dst.shape[0]
    if resample_now(sums, limit):
        last = cdf.shape[0] - 1
        total = cdf[last]
        j = int(0)
        for i in range(n):
            u = systematic_pointer(offset[0], i, n, total)
            while j < last and cdf[j] <= u:
                j += 1
            dst[i] = src[j]
            log_w[i] = 0.0
    else:
        for i in range(n):
            dst[i] = src[i]


@wp.kernel
def multinomial_kernel(
    cdf: wp.array(dtype=wp.float32),
    seed: wp.array(dtype=wp.int32),
    src: wp.array(dtype=wp.vec3),
    dst: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=wp.float32),
    limit: float,
    log_w: wp.array(dtype=wp.float32),
):
    i = wp.tid()
    if resample_now(sums, limit):
        state = wp.rand_init(seed[0], i)
        dst[i] = src[search(cdf, wp.randf(state) * cdf[cdf.shape[0] - 1])]
        log_w[i] = 0.0
    else:
        dst[i] = src[i]


class ParticleWeights:
    """Scratch arrays for N particles; ``update(log_w, particles)`` fills w, cdf and sums on the device.
    ``centre``: a point near the particles (the map's centre), subtracted before the squares are summed.
    ``keep_cos_sin`` (default: on a CPU) also keeps each particle's (cos yaw, sin yaw) for the top-share estimate
    (``TopShareMean.share_weights``): on a CPU that saves the estimate a third of its work; on an H100 writing them
    cost more than it saved (the step at 1M 0.80 against 0.77 ms, twentieth session)."""

    TILED = None  # accumulate in one tiled launch: None = on a GPU (tests set True or False on any device)
    ORDERED_SCAN = None  # the cdf by ordered_scan: None = on a GPU (tests set True or False on any device)
    FUSED = None  # w, the eight sums and the block scan in one pass (``weigh``): None = on a GPU (tests: any device)
    KEEP_COS_SIN = None  # keep_cos_sin's default: None = on a CPU (tests set False to build a GPU's weights on a CPU)

    def __init__(
        self,
        num_particles: int,
        device: str = "auto",
        centre=(0.0, 0.0),
        keep_cos_sin: bool | None = None,
        sums: wp.array | None = None,
    ):
        self.device = pick_device(device)
        d = self.device
        if keep_cos_sin is None:
            keep_cos_sin = not wp.get_device(d).is_cuda if self.KEEP_COS_SIN is None else self.KEEP_COS_SIN
        self.keeps_cos_sin = bool(keep_cos_sin)
        self.centre = wp.vec2(float(centre[0]), float(centre[1]))
        self.w = wp.zeros(num_particles, dtype=wp.float32, device=d)
        self.cdf = wp.zeros(num_particles, dtype=wp.float32, device=d)
        self.cos_sin = wp.zeros(num_particles, dtype=wp.vec2, device=d)  # (cos yaw, sin yaw) per particle
        self.top = wp.zeros(1, dtype=wp.float32, device=d)
        self.sums = sums_array(sums, 8, d, "ParticleWeights")  # (a filter's read-back buffer: one copy back a step)
        self.partial = PartialSums(8, d, reduction_threads(num_particles, d))
        on_gpu = wp.get_device(d).is_cuda
        self.tiled = on_gpu if self.TILED is None else bool(self.TILED)  # see ``accumulate``
        self.ordered = on_gpu if self.ORDERED_SCAN is None else bool(self.ORDERED_SCAN)  # see ``cumulate``
        self.block = tile_block(TILE, d)  # accumulate's tiled launch
        self.scan_totals = wp.zeros(-(-num_particles // tile_block(SCAN_TILE, d)), dtype=wp.float32, device=d)
        # (ordered_scan's block totals, one per block of the scan)
        # ``weigh`` in one pass (weigh_scan_kernel): needs the ordered scan's blocks and no cos/sin kept
        self.fused = (on_gpu if self.FUSED is None else bool(self.FUSED)) and self.ordered and not self.keeps_cos_sin
        self.block_sums = wp.zeros(self.scan_totals.shape[0], dtype=vec8, device=d)  # weigh_scan_kernel's, a block each
        self._no_hist = wp.zeros(0, dtype=int, device=d)  # accumulate's first_hist when no select is counted
        self._no_ranks = (  # accumulate's keys, values and first_hist when there are none to write
            wp.zeros(1, dtype=wp.float32, device=d),
            wp.zeros(1, dtype=wp.int32, device=d),
            self._no_hist,
        )
        self._top_reset = False  # ``top`` holds -3e38 already (the fused weigh left it so for the next accumulate)

    def accumulate(self, log_w: wp.array, log_lik: wp.array, temper: float, ranks=None) -> None:
        """log_w += temper * log_lik (``accumulate_kernel``) and the new maximum into ``top``; then ``weigh`` and
        ``cumulate`` finish what ``update`` does. On a GPU one tiled launch (``accumulate_max_kernel``), which also
        writes the top-share estimate's sort keys when given ``ranks`` = (keys, values) or (keys, values, first_hist),
        and with ``first_hist`` (an array of SELECT_BINS zeros, or empty) counts its radix select's first pass; on a
        CPU two launches, as before (``ranks`` must be None there: the estimate ranks its own keys). ``TILED``
        overrides the choice. The maximum starts from -3e38: filled here, unless the fused ``weigh`` of the step
        before left it so (``weigh_finish_kernel``: one launch fewer a step)."""
        self._check(log_w)
        if not self._top_reset:
            self.top.fill_(-3.0e38)
        self._top_reset = False
        n, d = log_w.shape[0], self.device
        if self.tiled:
            keys, values, first_hist = (*ranks, self._no_hist)[:3] if ranks is not None else self._no_ranks
            wp.launch_tiled(
                accumulate_max_kernel,
                dim=[-(-n // self.block)],
                inputs=[log_w, log_lik, float(temper), self.top, keys, values, int(ranks is not None), first_hist],
                block_dim=self.block,
                device=d,
            )
            return
        if ranks is not None:
            raise ValueError("ParticleWeights.accumulate: sort keys are written by the tiled launch only")
        wp.launch(accumulate_kernel, n, [log_w, log_lik, float(temper)], device=d)
        launch_reduction(max_kernel, n, [log_w, self.top], d)

    def update(self, log_w: wp.array, particles: wp.array) -> None:
        """w, the eight sums and the cdf of log-weights as they stand (the maximum found here)."""
        self._check(log_w)
        self.top.fill_(-3.0e38)
        launch_reduction(max_kernel, log_w.shape[0], [log_w, self.top], self.device)
        self.weigh(log_w, particles)
        self.cumulate()

    def weigh(self, log_w: wp.array, particles: wp.array) -> None:
        """w = exp(log_w - max) and the eight sums (``top`` holds the maximum: ``accumulate`` or ``update``). Fused
        (a GPU): two launches, which also scan w in blocks (``cumulate`` then only adds the blocks' offsets) and
        write the same w and cdf bits as the launches apart; the sums are added in another fixed order (tile
        reductions), so their last bits differ from ``exp_kernel``'s."""
        if self.fused:
            n, d = log_w.shape[0], self.device
            block = tile_block(SCAN_TILE, d)
            blocks = -(-n // block)
            inputs = [log_w, self.top, particles, self.centre, self.w, self.cdf, self.scan_totals, self.block_sums]
            wp.launch_tiled(weigh_scan_kernel, dim=[blocks], inputs=inputs, block_dim=block, device=d)
            finish = [self.scan_totals, self.block_sums, blocks, self.sums, self.top]
            wp.launch_tiled(weigh_finish_kernel, dim=[1], inputs=finish, block_dim=block, device=d)
            self._top_reset = True
            return
        threads = launch_reduction(
            exp_kernel,
            log_w.shape[0],
            [
                log_w,
                self.top,
                self.w,
                self.partial.partials,
                particles,
                self.centre,
                self.cos_sin,
                int(self.keeps_cos_sin),
            ],
            self.device,
        )
        self.partial.finish(threads, self.sums)

    def cumulate(self) -> None:
        """The cumulative weights, for resampling: on a GPU by ``ordered_scan`` (the same bits on every run), on a CPU
        by Warp's array_scan (a loop in order)."""
        if self.fused:  # the blocks scanned by ``weigh``
            n = self.w.shape[0]
            wp.launch(
                add_block_offsets_kernel,
                n,
                [self.cdf, self.scan_totals, tile_block(SCAN_TILE, self.device)],
                device=self.device,
            )
        elif self.ordered:
            ordered_scan(self.w, self.cdf, self.scan_totals, self.device)
        else:
            wp.utils.array_scan(self.w, self.cdf, inclusive=True)

    def _check(self, log_w: wp.array) -> None:
        if log_w.shape[0] != self.w.shape[0]:
            raise ValueError(f"ParticleWeights: {log_w.shape[0]} log-weights, built for {self.w.shape[0]}")

    def summary(self, sums: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
        """(weighted mean pose [x, y, yaw], N_eff, spread): the one small read back per step (eight sums;
        ``sums``: a copy already read back). spread = sqrt(var x + var y) of the weighted positions (m). In float64,
        on Python floats where numpy's small arrays would cost a GPU step's host time (the same bits: the divisions
        by a float64 total keep numpy's inf and nan, the yaw keeps numpy's arctan2)."""
        s = (self.sums.numpy() if sums is None else np.asarray(sums)).tolist()
        total = np.float64(s[5])
        mx, my = s[1] / total, s[2] / total
        pose = np.array([mx + self.centre[0], my + self.centre[1], np.arctan2(s[4], s[3])])
        spread = math.sqrt(max(s[6] / total - mx * mx + s[7] / total - my * my, 0.0))
        return pose, total * total / s[0], spread


class Resampler:
    """Draws dst from src by the cumulative weights. Given ParticleWeights' ``sums`` and ``neff_below``, the
    decision is taken on the device (no read back): below it, resample and zero ``log_w``; else copy.
    ``__call__`` takes the random draw from the host; ``launch`` reads it from device arrays (a captured
    filter step replays with each scan's draw)."""

    def __init__(self, method: str, device: str = "auto"):
        self.method, self.device = method, pick_device(device)
        # low_variance on a CPU: one thread walks the cdf (systematic_merge_kernel); on a GPU a search per pointer
        self.walk = method == "low_variance" and not wp.get_device(self.device).is_cuda
        self._always = wp.array(np.array([1, 0, 0, 0, 0, 1, 0, 0], np.float32), dtype=wp.float32, device=self.device)
        self._scratch = None
        self._offset = wp.zeros(1, dtype=wp.float32, device=self.device)
        self._seed = wp.zeros(1, dtype=wp.int32, device=self.device)

    @staticmethod
    def seed_of(draw: float) -> int:
        """multinomial's generator seed from the uniform draw."""
        return int(draw * 2**31)

    def __call__(
        self,
        cdf: wp.array,
        src: wp.array,
        dst: wp.array,
        draw: float,
        sums: wp.array | None = None,
        neff_below: float = np.inf,
        log_w: wp.array | None = None,
    ) -> None:
        """``draw``: a uniform number in [0, 1) (low_variance offset; multinomial derives its seed from it).
        Without ``sums`` every call resamples."""
        self._offset.assign(np.array([draw], np.float32))
        self._seed.assign(np.array([self.seed_of(draw)], np.int32))
        self.launch(cdf, src, dst, self._offset, self._seed, sums, neff_below, log_w)

    def launch(
        self,
        cdf: wp.array,
        src: wp.array,
        dst: wp.array,
        offset: wp.array,
        seed: wp.array,
        sums: wp.array | None = None,
        neff_below: float = np.inf,
        log_w: wp.array | None = None,
    ) -> None:
        """The same with the draw on the device: ``offset`` [1] (low_variance) and ``seed`` [1] (multinomial)."""
        if sums is None:
            sums, neff_below = self._always, np.inf
        if log_w is None:
            if self._scratch is None or self._scratch.shape[0] != dst.shape[0]:
                self._scratch = wp.zeros(dst.shape[0], dtype=wp.float32, device=self.device)
            log_w = self._scratch
        limit = float(min(neff_below, 3.0e38))
        inputs = [cdf, offset if self.method == "low_variance" else seed, src, dst, sums, limit, log_w]
        if self.method == "multinomial":
            wp.launch(multinomial_kernel, dst.shape[0], inputs, device=self.device)
        elif self.walk:  # one thread walking the pointers on a CPU
            wp.launch(systematic_merge_kernel, 1, inputs, device=self.device)
        else:
            wp.launch(systematic_kernel, dst.shape[0], inputs, device=self.device)


@RESAMPLE.register("low_variance")
def make_low_variance(device: str = "auto") -> Resampler:
    return Resampler("low_variance", device)


@RESAMPLE.register("multinomial")
def make_multinomial(device: str = "auto") -> Resampler:
    return Resampler("multinomial", device)


@wp.kernel
def masked_max_kernel(
    values: wp.array(dtype=wp.float32), skip: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.float32), stride: int
):
    top = float(-3.0e38)
    for i in range(wp.tid(), values.shape[0], stride):
        if skip[i] == 0:
            top = wp.max(top, values[i])
    wp.atomic_max(out, 0, top)


@wp.kernel
def log_mean_exp_kernel(
    log_lik: wp.array(dtype=wp.float32),
    skip: wp.array(dtype=wp.int32),
    top: wp.array(dtype=wp.float32),
    partials: wp.array2d(dtype=wp.float32),
    stride: int,
):
    """Row t of partials = [sum of exp(log_lik - top), count] over thread t's particles not marked in ``skip``."""
    total = float(0.0)
    count = float(0.0)
    for i in range(wp.tid(), log_lik.shape[0], stride):
        if skip[i] == 0:
            total += wp.exp(log_lik[i] - top[0])
            count += 1.0
    partials[wp.tid(), 0] = total
    partials[wp.tid(), 1] = count


@wp.kernel
def inject_kernel(
    particles: wp.array(dtype=wp.vec3),
    free_xy: wp.array(dtype=wp.vec2),
    jitter: float,
    probability: float,
    seed: int,
    injected: wp.array(dtype=wp.int32),
):
    """Replace each particle, with the given probability, by a random pose on a free node (recovery);
    ``injected`` marks the replaced ones."""
    i = wp.tid()
    state = wp.rand_init(seed, i)
    injected[i] = 0
    if wp.randf(state) < probability:
        j = int(wp.randf(state) * float(free_xy.shape[0])) % free_xy.shape[0]
        xy = free_xy[j]
        particles[i] = wp.vec3(
            xy[0] + jitter * (wp.randf(state) - 0.5),
            xy[1] + jitter * (wp.randf(state) - 0.5),
            (wp.randf(state) * 2.0 - 1.0) * 3.14159265,
        )
        injected[i] = 1


class LogMeanLikelihood:
    """log(mean(exp(log_lik))) over the particles not marked in ``skip`` (all when None), without
    underflow: max shift on the device, buffers allocated once, three floats read back."""

    def __init__(self, device: str = "auto"):
        self.device = pick_device(device)
        self.top = wp.zeros(1, dtype=wp.float32, device=self.device)
        self.acc = wp.zeros(2, dtype=wp.float32, device=self.device)
        self.partial = None  # sized for the first call's particles
        self.none = None

    def __call__(self, log_lik: wp.array, skip: wp.array | None = None) -> float:
        if skip is None:
            if self.none is None or self.none.shape[0] != log_lik.shape[0]:
                self.none = wp.zeros(log_lik.shape[0], dtype=wp.int32, device=self.device)
            skip = self.none
        rows = reduction_threads(log_lik.shape[0], self.device)
        if self.partial is None or self.partial.partials.shape[0] < rows:
            self.partial = PartialSums(2, self.device, rows)
        self.top.fill_(-3.0e38)
        launch_reduction(masked_max_kernel, log_lik.shape[0], [log_lik, skip, self.top], self.device)
        threads = launch_reduction(
            log_mean_exp_kernel, log_lik.shape[0], [log_lik, skip, self.top, self.partial.partials], self.device
        )
        self.partial.finish(threads, self.acc)
        acc = self.acc.numpy()
        if acc[1] == 0:
            return -np.inf
        return float(self.top.numpy()[0]) + float(np.log(acc[0] / acc[1]))
