"""Pose estimates from a weighted particle set (both return [x, y, yaw], circular mean for yaw):

* ``ESTIMATE["top_share"]``: IR-MCL's estimate, the weighted mean of the particles with the highest
  weights (80 % of them; ties by index, as a stable sort orders them). On a CPU the particles are ranked by
  Warp's radix sort of their log-weights and the sums are partial sums over the first K ranks, added in a
  fixed order (PartialSums). On a GPU no sort: a radix select finds the K-th heaviest particle (the
  "threshold") in a few histogram passes of 11 bits over the log-weights' bits and then the indices, and
  one tiled pass sums the particles at or above it (``TopShareMean.SELECT``).
* ``ESTIMATE["best_cluster"]``: the weighted mean of the heaviest cluster, in the spirit of AMCL (which
  reports the mean of its heaviest kd-tree cluster): weights are binned on a coarse (x, y, yaw) histogram
  (``cell_m``, ``yaw_bins``), each bin's mass is summed with its 26 neighbours (yaw wraps), and the
  particles within 1.5 cells and 1.5 yaw bins of the heaviest bin's centre are averaged. Robust when the
  set is still split between look-alike places, where the mean of all particles lies between them.

(The plain weighted mean of all particles comes with ``ParticleWeights`` in kernels/resample.py.)
Numpy twins: irmcl_warp/reference/estimate.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.radix import SELECT_BINS, SELECT_BITS, heavy_first
from irmcl_warp.kernels.resample import max_kernel, tile_block
from irmcl_warp.kernels.registry import (
    ESTIMATE,
    PartialSums,
    launch_reduction,
    pick_device,
    reduction_threads,
    sums_array,
)


@wp.kernel
def rank_keys_kernel(
    log_w: wp.array(dtype=wp.float32), keys: wp.array(dtype=wp.float32), values: wp.array(dtype=wp.int32)
):
    i = wp.tid()
    keys[i] = -log_w[i]  # ascending sort: the heaviest particle first
    values[i] = i


vec5 = wp.types.vector(length=5, dtype=wp.float32)


@wp.func
def moments_of(w: float, p: wp.vec3, cos_yaw: float, sin_yaw: float) -> vec5:
    """(w, w x, w y, w cos yaw, w sin yaw): what a weighted mean pose with a circular yaw sums."""
    return vec5(w, w * p[0], w * p[1], w * cos_yaw, w * sin_yaw)


@wp.func
def pose_moments(w: float, p: wp.vec3) -> vec5:
    """``moments_of`` with the yaw's cos and sin computed here."""
    return moments_of(w, p, wp.cos(p[2]), wp.sin(p[2]))


def mean_pose(sums: np.ndarray) -> np.ndarray:
    """[x, y, yaw] from the five pose moments (w, w x, w y, w cos, w sin), in float64 on Python floats (a GPU step's
    host time; the division by a float64 weight keeps numpy's inf and nan)."""
    s = np.asarray(sums).tolist()
    total = np.float64(s[0])
    return np.array([s[1] / total, s[2] / total, np.arctan2(s[4], s[3])])


@wp.func
def leave_moments(partials: wp.array2d(dtype=wp.float32), t: int, acc: vec5):
    """Thread t's five partial sums into row t (PartialSums adds the rows in a fixed order)."""
    for c in range(5):
        partials[t, c] = acc[c]


# where top_sums_kernel reads a particle's weight and yaw from
FROM_LOG_W, FROM_W, FROM_W_COS_SIN = wp.constant(0), wp.constant(1), wp.constant(2)


@wp.func
def rank_moments(
    order: wp.array(dtype=wp.int32),
    sorted_keys: wp.array(dtype=wp.float32),
    log_w: wp.array(dtype=wp.float32),
    w: wp.array(dtype=wp.float32),
    cos_sin: wp.array(dtype=wp.vec2),
    particles: wp.array(dtype=wp.vec3),
    source: int,
    r: int,
) -> vec5:
    """The five pose moments of the particle at rank r, its weight and yaw read as ``source`` says (top_sums_kernel)."""
    j = order[r]
    weight = float(0.0)
    if source == FROM_LOG_W:
        weight = wp.exp(log_w[j] + sorted_keys[0])
    else:
        weight = w[j]
    return particle_moments(j, weight, cos_sin, particles, source)


@wp.func
def particle_moments(
    j: int, weight: float, cos_sin: wp.array(dtype=wp.vec2), particles: wp.array(dtype=wp.vec3), source: int
) -> vec5:
    """The five pose moments of particle j with its weight, its yaw's (cos, sin) read from ``cos_sin``
    (``FROM_W_COS_SIN``) or computed."""
    if source == FROM_W_COS_SIN:
        cs = cos_sin[j]
        return moments_of(weight, particles[j], cs[0], cs[1])
    return pose_moments(weight, particles[j])


@wp.kernel
def top_sums_kernel(
    order: wp.array(dtype=wp.int32),
    sorted_keys: wp.array(dtype=wp.float32),
    log_w: wp.array(dtype=wp.float32),
    w: wp.array(dtype=wp.float32),
    cos_sin: wp.array(dtype=wp.vec2),
    particles: wp.array(dtype=wp.vec3),
    partials: wp.array2d(dtype=wp.float32),
    source: int,
    k: int,
    stride: int,
):
    """The five pose moments summed over the first k ranks. A particle's weight is exp(log w - max) computed here
    (``FROM_LOG_W``: sorted_keys[0] = -(largest log-weight) makes the exp stable, and is exact), or read from
    ParticleWeights' ``w`` (``FROM_W``, ``FROM_W_COS_SIN``), which computed it from the same values with the same
    expression: the same bits for less work. With ``FROM_W_COS_SIN`` the yaw's (cos, sin) are read from ``cos_sin``
    too (kept by ParticleWeights on a CPU); otherwise they are computed here. The arrays a source does not read
    may be empty."""
    acc = vec5()
    for r in range(wp.tid(), k, stride):
        acc += rank_moments(order, sorted_keys, log_w, w, cos_sin, particles, source, r)
    leave_moments(partials, wp.tid(), acc)


TOP_TILE = 1024  # ranks a block sums at once on a GPU (``top_sums_tiled_kernel``)


@wp.kernel
def top_sums_tiled_kernel(
    order: wp.array(dtype=wp.int32),
    sorted_keys: wp.array(dtype=wp.float32),
    log_w: wp.array(dtype=wp.float32),
    w: wp.array(dtype=wp.float32),
    cos_sin: wp.array(dtype=wp.vec2),
    particles: wp.array(dtype=wp.vec3),
    source: int,
    k: int,
    partials: wp.array(dtype=vec5),
):
    """``top_sums_kernel`` as a tiled launch (a GPU): a thread per rank below k, the block's five sums by a tile
    reduction into ``partials[b]`` (a fixed order; ``moments_finish_kernel`` adds the blocks)."""
    b, lane = wp.tid()
    r = b * wp.block_dim() + lane
    acc = vec5()
    if r < k:
        acc = rank_moments(order, sorted_keys, log_w, w, cos_sin, particles, source, r)
    block_sums = wp.tile_sum(wp.tile(acc, preserve_type=True))
    if lane == 0:
        partials[b] = block_sums[0]


@wp.kernel
def moments_finish_kernel(
    partials: wp.array(dtype=vec5), count: int, sums: wp.array(dtype=wp.float32), hist: wp.array(dtype=int)
):
    """One block: the ``count`` blocks' five sums into ``sums``, each thread adding a run of ceil(count / threads)
    blocks in order and the threads' runs joined by a tile reduction (a fixed order). ``hist``: the selection's
    histograms, read by nothing after its sums kernel, set back to zero for the next selection (or empty: the
    sort's sums); that saves the next step a memset launch, and the accumulate that counts the first pass
    (kernels/resample.py ``accumulate_max_kernel``) finds them zero."""
    _b, lane = wp.tid()
    run = (count + wp.block_dim() - 1) // wp.block_dim()
    lo = wp.min(lane * run, count)
    acc = vec5()
    for j in range(lo, wp.min(lo + run, count)):
        acc += partials[j]
    total = wp.tile_sum(wp.tile(acc, preserve_type=True))
    if lane == 0:
        for c in range(5):
            sums[c] = total[0][c]
    for j in range(lane, hist.shape[0], wp.block_dim()):
        hist[j] = 0


# The top share by a radix select (a GPU's way; ``TopShareMean.SELECT``). The particles' order is (key, index), key
# ascending from the heaviest log-weight (``heavy_first``): the order of a stable sort of -log w. The K-th pair of
# that order, the threshold, is found digit by digit, SELECT_BITS at a time: first the key's 32 bits, then the index's
# bits (which break ties, as the sort's stability does). Pass j counts, per digit, the particles whose bits above
# its digit equal the threshold's bits found so far (``select_histogram_kernel``); its histogram names the next
# digit: the one where the count of particles before the threshold crosses K (``pick_digit``). Once every particle
# of the picked digit is inside the top share, the threshold's lower bits are all ones and the remaining passes
# count nothing ("done": no tie straddles the threshold, the usual case). A particle is in the top share when its
# (key, index) is at or before the threshold (``select_sums_kernel``).
SELECT_TILE = 1024  # threads of a block of the selection's launches on a GPU
KEY_DIGIT, INDEX_DIGIT = wp.constant(0), wp.constant(1)
ALL_INDICES = 0x7FFFFFFF  # an index threshold that takes every tied particle


SELECT_BLOCKS = 128  # blocks the selection's launches aim at: about one per SM of an H100 (132)


def select_per_thread(num_particles: int) -> int:
    """Particles a thread of the selection covers: enough that about SELECT_BLOCKS blocks cover them all. On an H100
    (``python -m eval.bench estimate``, twenty-sixth session) one a thread was fastest at 100k particles (98 blocks)
    and eight at 1M (123 blocks); more blocks repeat the per-block work (each block picks the digit from the whole
    histogram), fewer leave SMs idle."""
    return max(1, -(-num_particles // (SELECT_TILE * SELECT_BLOCKS)))


def select_passes(num_particles: int) -> list[tuple[int, int, int]]:
    """(field, shift, width) of each histogram pass: the key's 32 bits from the top, then the index's."""
    passes = []
    for field, bits in ((0, 32), (1, max(1, (num_particles - 1).bit_length()))):
        top = bits
        while top > 0:
            shift = max(0, top - SELECT_BITS)
            passes.append((field, shift, top - shift))
            top = shift
    return passes


def select_pass_settings(passes: list[tuple[int, int, int]]) -> list[tuple[int, ...]]:
    """``select_histogram_kernel``'s settings of each pass after its index j: the previous pass's field and shift,
    this pass's field, shift and digit mask, and the masks of the key's and the index's bits found before it."""
    out, key_mask, index_mask = [], 0, 0
    for j, (field, shift, width) in enumerate(passes):
        prev_field, prev_shift = passes[j - 1][:2] if j else (0, 0)
        out.append((prev_field, prev_shift, field, shift, (1 << width) - 1, key_mask, index_mask))
        bits = ((1 << width) - 1) << shift
        if field == 0:
            key_mask |= bits
        else:
            index_mask |= bits
    return out


@wp.func
def before_rank(cum: int, rank: int) -> int:
    """1 where a digit's cumulative count lies below the rank sought (their sum is the digit that holds it)."""
    if cum < rank:
        return 1
    return 0


@wp.func
def count_before(cum: int, rank: int) -> int:
    """The cumulative count where it lies below the rank (their maximum: the particles before the digit)."""
    if cum < rank:
        return cum
    return 0


@wp.func
def pick_digit(hist: wp.array(dtype=int), row: int, rank: int, lane: int) -> wp.vec3i:
    """(digit, particles in the digits before it, particles in it) for the particle of rank ``rank`` (1 = first)
    among those a pass counted in ``hist`` row ``row``; every thread of the block gets them (tile reductions leave
    their result in thread 0, passed on through shared memory)."""
    counts = wp.tile_load(hist, shape=SELECT_BINS, offset=row * SELECT_BINS)
    cum = wp.tile_scan_inclusive(counts)
    digit = wp.tile_sum(wp.tile_map(before_rank, cum, rank))
    before = wp.tile_max(wp.tile_map(count_before, cum, rank))
    shared = wp.tile_zeros(shape=2, dtype=int, storage="shared")
    wp.tile_scatter_masked(shared, 0, digit[0], lane == 0)
    wp.tile_scatter_masked(shared, 1, before[0], lane == 0)
    d = shared[0]
    return wp.vec3i(d, shared[1], hist[row * SELECT_BINS + d])


@wp.func
def threshold_after(
    hist: wp.array(dtype=int),
    state_key: wp.array(dtype=wp.uint32),
    state_int: wp.array(dtype=int),
    j: int,
    field: int,
    shift: int,
    lane: int,
):
    """The threshold's key and index bits found before pass j, the rank still sought and whether the threshold is
    complete ("done"), from pass j-1's state and histogram (pass j-1 resolved ``field``'s digit at ``shift``)."""
    key = state_key[j - 1]
    index = state_int[3 * (j - 1)]
    rank = state_int[3 * (j - 1) + 1]
    done = state_int[3 * (j - 1) + 2]
    if done == 0:  # the same in every thread: a cooperative pick
        picked = pick_digit(hist, j - 1, rank, lane)
        low = (1 << shift) - 1
        if field == KEY_DIGIT:
            key = key | (wp.uint32(picked[0]) << wp.uint32(shift))
        else:
            index = index | (picked[0] << shift)
        rank = rank - picked[1]
        if rank == picked[2]:  # the whole digit is in: every bit below it is one
            done = 1
            if field == KEY_DIGIT:
                key = key | wp.uint32(low)
                index = ALL_INDICES
            else:
                index = index | low
    return key, index, rank, done


@wp.func
def keep_threshold(
    state_key: wp.array(dtype=wp.uint32),
    state_int: wp.array(dtype=int),
    j: int,
    key: wp.uint32,
    index: int,
    rank: int,
    done: int,
):
    """Row j of the selection's state (written once, by one thread: the next pass reads it)."""
    state_key[j] = key
    state_int[3 * j] = index
    state_int[3 * j + 1] = rank
    state_int[3 * j + 2] = done


@wp.kernel
def select_histogram_kernel(
    keys: wp.array(dtype=wp.float32),
    hist: wp.array(dtype=int),
    state_key: wp.array(dtype=wp.uint32),
    state_int: wp.array(dtype=int),
    span: int,
    j: int,
    prev_field: int,
    prev_shift: int,
    field: int,
    shift: int,
    digit_mask: int,
    key_mask: wp.uint32,
    index_mask: int,
):
    """Pass j of the radix select over ``keys`` = -log w, ``span`` particles a block: the threshold's bits so far
    (pass j-1's pick; block 0 keeps them in row j of the state), then the count per digit of the block's particles
    that agree with them above the digit (``key_mask``, ``index_mask``: the bits already found), in shared memory,
    added into ``hist`` row j (integers: any order gives the same counts). A thread adds a run of equal digits at
    once (the first passes see few digits: fewer atomic adds on the same bin)."""
    b, lane = wp.tid()
    key = state_key[0]
    index = int(0)
    rank = int(0)
    done = int(0)
    if j > 0:
        key, index, rank, done = threshold_after(hist, state_key, state_int, j, prev_field, prev_shift, lane)
        if b == 0 and lane == 0:
            keep_threshold(state_key, state_int, j, key, index, rank, done)
    if done == 0:
        bins = wp.tile_zeros(shape=SELECT_BINS, dtype=int, storage="shared")
        run_digit = int(-1)
        run = int(0)
        for t in range(span // wp.block_dim()):
            i = b * span + t * wp.block_dim() + lane
            digit = int(-1)
            if i < keys.shape[0]:
                k = heavy_first(-keys[i])
                if (k & key_mask) == (key & key_mask) and (i & index_mask) == (index & index_mask):
                    if field == KEY_DIGIT:
                        digit = int((k >> wp.uint32(shift)) & wp.uint32(digit_mask))
                    else:
                        digit = (i >> shift) & digit_mask
            wp.tile_scatter_add(bins, wp.max(run_digit, 0), run, run > 0 and digit != run_digit)
            if digit != run_digit:
                run_digit = digit
                run = 0
            if digit >= 0:
                run += 1
        wp.tile_scatter_add(bins, wp.max(run_digit, 0), run, run > 0)
        for t in range(SELECT_BINS // wp.block_dim()):
            d = t * wp.block_dim() + lane
            c = bins[d]
            if c != 0:
                wp.atomic_add(hist, j * SELECT_BINS + d, c)


@wp.kernel
def select_sums_kernel(
    keys: wp.array(dtype=wp.float32),
    top: wp.array(dtype=wp.float32),
    w: wp.array(dtype=wp.float32),
    cos_sin: wp.array(dtype=wp.vec2),
    particles: wp.array(dtype=wp.vec3),
    source: int,
    hist: wp.array(dtype=int),
    state_key: wp.array(dtype=wp.uint32),
    state_int: wp.array(dtype=int),
    span: int,
    last: int,
    prev_field: int,
    prev_shift: int,
    partials: wp.array(dtype=vec5),
):
    """The threshold (the last pass's pick; block 0 keeps it in row ``last`` of the state), then the five sums over
    the block's ``span`` particles at or before it by a tile reduction into ``partials[b]`` (``moments_finish_kernel``
    adds the blocks). ``keys`` hold -log w (a copy: the filter's stream may reset the log-weights meanwhile); a
    weight is w[j] or exp(log w - top[0]) (``FROM_LOG_W``: ``top`` holds the largest)."""
    b, lane = wp.tid()
    key, index, rank, done = threshold_after(hist, state_key, state_int, last, prev_field, prev_shift, lane)
    if b == 0 and lane == 0:
        keep_threshold(state_key, state_int, last, key, index, rank, done)
    neg_top = float(0.0)
    if source == FROM_LOG_W:
        neg_top = -top[0]
    acc = vec5()
    for t in range(span // wp.block_dim()):
        i = b * span + t * wp.block_dim() + lane
        if i < keys.shape[0]:
            k = heavy_first(-keys[i])
            if k < key or (k == key and i <= index):
                weight = float(0.0)
                if source == FROM_LOG_W:
                    weight = wp.exp(-keys[i] + neg_top)  # -keys[i] is log w: exp(log w - max)'s bits
                else:
                    weight = w[i]
                acc += particle_moments(i, weight, cos_sin, particles, source)
    block_sums = wp.tile_sum(wp.tile(acc, preserve_type=True))
    if lane == 0:
        partials[b] = block_sums[0]


class TopShareMean:
    TILED = None  # the sums by tiled launches (``top_sums_tiled_kernel``): None = on a GPU (tests: any device)
    SELECT = None  # the top share by a radix select instead of a sort: None = on a GPU (tests: any device)
    SELECT_PER_THREAD = None  # particles a thread of the selection covers; None: ``select_per_thread(n)``
    FIRST_IN_ACCUMULATE = True  # a filter's accumulate counts the selection's first pass (``rank_buffers``; tests: off)

    def __init__(self, num_particles: int, share: float = 0.8, device: str = "auto", sums: wp.array | None = None):
        """``sums``: where the five sums go (a view of a filter's read-back buffer: one copy back a step), else an
        array of its own."""
        if not 0.0 < share <= 1.0:
            raise ValueError(f"top_share: share must lie in (0, 1], got {share}")
        self.device, self.n = pick_device(device), num_particles
        self.k = max(1, int(np.ceil(share * num_particles)))
        on_gpu = wp.get_device(self.device).is_cuda
        self.selects = on_gpu if self.SELECT is None else bool(self.SELECT)
        self.tiled = (on_gpu if self.TILED is None else bool(self.TILED)) and not self.selects
        self.sums = sums_array(sums, 5, self.device, "top_share")
        self.weights = None
        self._counts = False  # counts left in the selection's histograms (``_clear_histograms``)
        self.nothing_int = wp.empty(0, dtype=int, device=self.device)
        self.nothing = (  # what a sums kernel is given for the arrays its source does not read
            wp.empty(0, dtype=wp.float32, device=self.device),
            wp.empty(0, dtype=wp.vec2, device=self.device),
        )
        if self.selects:
            self.passes = select_passes(num_particles)
            self.pass_settings = select_pass_settings(self.passes)
            self.hist = wp.zeros(len(self.passes) * SELECT_BINS, dtype=int, device=self.device)
            self.state_key = wp.zeros(len(self.passes) + 1, dtype=wp.uint32, device=self.device)
            first = np.zeros(3 * (len(self.passes) + 1), np.int32)
            first[1] = self.k  # before the first pass: no bit found, rank K sought, not done
            self.state_int = wp.array(first, dtype=int, device=self.device)
            self.top = wp.zeros(1, dtype=wp.float32, device=self.device)  # the largest log-weight (``rank``)
            self.keys = wp.zeros(num_particles, dtype=wp.float32, device=self.device)  # -log w, a copy
            self.values = wp.zeros(num_particles, dtype=wp.int32, device=self.device)  # (accumulate writes them)
            self.block = tile_block(SELECT_TILE, self.device)
            per_thread = self.SELECT_PER_THREAD or select_per_thread(num_particles)
            self.span = SELECT_TILE * max(1, int(per_thread))  # particles a block covers
            self.block_sums = wp.zeros(-(-num_particles // self.span), dtype=vec5, device=self.device)
            return
        self.keys = wp.zeros(2 * num_particles, dtype=wp.float32, device=self.device)  # radix sort needs 2N
        self.values = wp.zeros(2 * num_particles, dtype=wp.int32, device=self.device)
        self.partial = PartialSums(5, self.device, reduction_threads(self.k, self.device))
        self.block = tile_block(TOP_TILE, self.device)
        self.block_sums = wp.zeros(-(-self.k // self.block), dtype=vec5, device=self.device)  # the tiled sums' blocks

    def share_weights(self, weights) -> None:
        """Read each particle's weight and (cos, sin) of its yaw from ``weights`` (a ParticleWeights updated
        from the same log-weights and particles before every ``launch``) instead of computing them again."""
        if weights is not None and weights.w.shape[0] != self.n:
            raise ValueError(f"top_share: weights of {weights.w.shape[0]} particles, built for {self.n}")
        if weights is not None and not weights.keeps_cos_sin:
            raise ValueError(
                "top_share: these weights do not keep the yaws' cos and sin (ParticleWeights keep_cos_sin)"
            )
        self.weights = weights

    def __call__(self, particles: wp.array, log_w: wp.array) -> np.ndarray:
        """[x, y, yaw] from the top ``share`` of the particles by weight."""
        self.launch(particles, log_w)
        return self.result()

    def launch(self, particles: wp.array, log_w: wp.array) -> None:
        """Rank and sum on the device, nothing read back (the filter reads once per step)."""
        self.rank(log_w)
        self.order()
        self.sum(particles, log_w)

    def rank_buffers(self) -> tuple[wp.array, ...]:
        """(keys, values) to sort, or (keys, values, first_hist) to select from: ``rank`` fills them, or a GPU filter's
        ParticleWeights.accumulate (the keys are a copy of -log w that the filter's stream does not touch while the
        estimate's runs). ``first_hist`` is the selection's first histogram, zero now: the accumulate counts the first
        pass into it, and ``order(counted=True)`` starts from the second."""
        if not (self.selects and self.FIRST_IN_ACCUMULATE):
            return self.keys, self.values
        self._clear_histograms()
        self._counts = True
        return self.keys, self.values, self.hist[:SELECT_BINS]

    def _clear_histograms(self) -> None:
        """The histograms back to zero where counts are left in them (a selection not summed since: ``sum``'s finish
        zeroes them, so a filter's step launches no memset)."""
        if self._counts:
            self.hist.zero_()
            self._counts = False

    def rank(self, log_w: wp.array) -> None:
        """The keys -log w and the indices; when selecting, also the largest log-weight (for ``sum`` without w)."""
        wp.launch(rank_keys_kernel, self.n, [log_w, self.keys, self.values], device=self.device)
        if self.selects:
            self.top.fill_(-3.0e38)
            launch_reduction(max_kernel, self.n, [log_w, self.top], self.device)

    def order(self, counted: bool = False) -> None:
        """The particles by weight, heaviest first (Warp's radix sort of the keys ``rank`` wrote; ties keep their
        index order), or the selection's histogram passes over those keys; ``counted``: the first pass was counted
        with the keys (``rank_buffers``' first_hist), so the passes start from the second."""
        if not self.selects:
            wp.utils.radix_sort_pairs(self.keys, self.values, self.n)
            return
        if not counted:
            self._clear_histograms()
        self._counts = True
        blocks = self.block_sums.shape[0]
        for j, settings in enumerate(self.pass_settings):
            if counted and j == 0:
                continue
            inputs = [self.keys, self.hist, self.state_key, self.state_int, self.span, j, *settings]
            wp.launch_tiled(
                select_histogram_kernel, dim=[blocks], inputs=inputs, block_dim=self.block, device=self.device
            )

    def threshold(self) -> tuple[int, int]:
        """(key, index) after a selection's ``sum``: the particles at or before it are the top share (tests)."""
        last = len(self.passes)
        return int(self.state_key.numpy()[last]), int(self.state_int.numpy()[3 * last])

    def sum(self, particles: wp.array, log_w: wp.array, w: wp.array | None = None) -> None:
        """The five sums over the first k ranks: from ``share_weights``' weights and yaws (a CPU), from ``w`` (the
        weights exp(log w - max), ready), or from the log-weights and the largest (the sorted keys' first, or
        ``rank``'s maximum when selecting)."""
        nothing_f, nothing_cs = self.nothing
        if self.weights is not None:
            source, w, cos_sin = FROM_W_COS_SIN, self.weights.w, self.weights.cos_sin
        elif w is not None:
            source, cos_sin = FROM_W, nothing_cs
        else:
            source, w, cos_sin = FROM_LOG_W, nothing_f, nothing_cs
        if self.selects or self.tiled:  # the blocks' sums by one tiled launch, then one block adds them
            blocks = self.block_sums.shape[0]
            if self.selects:  # the threshold, then a pass over every particle
                if not self._counts:  # summed again: the last sums' finish zeroed the histograms, count them again
                    self.order()
                last = len(self.passes)
                prev_field, prev_shift = self.passes[-1][:2]
                kernel = select_sums_kernel
                inputs = [self.keys, self.top, w, cos_sin, particles, source, self.hist, self.state_key]
                inputs += [self.state_int, self.span, last, prev_field, prev_shift, self.block_sums]
            else:  # the first k ranks of the sort
                kernel = top_sums_tiled_kernel
                inputs = [self.values, self.keys, log_w, w, cos_sin, particles, source, self.k, self.block_sums]
            wp.launch_tiled(kernel, dim=[blocks], inputs=inputs, block_dim=self.block, device=self.device)
            finish = [self.block_sums, blocks, self.sums, self.hist if self.selects else self.nothing_int]
            wp.launch_tiled(moments_finish_kernel, dim=[1], inputs=finish, block_dim=self.block, device=self.device)
            self._counts = False  # (the finish zeroed the histograms)
            return
        inputs = [self.values, self.keys, log_w, w, cos_sin, particles, self.partial.partials, source, self.k]
        threads = launch_reduction(top_sums_kernel, self.k, inputs, self.device)
        self.partial.finish(threads, self.sums)

    def result(self, sums: np.ndarray | None = None) -> np.ndarray:
        """[x, y, yaw] from the five sums (``sums``: a copy already read back)."""
        return mean_pose(self.sums.numpy() if sums is None else sums)


@ESTIMATE.register("top_share")
def make_top_share(**settings) -> TopShareMean:
    return TopShareMean(**settings)


@wp.func
def pose_bin(p: wp.vec3, lo: wp.vec2, cell: float, nx: int, ny: int, nyaw: int) -> int:
    """A pose's cell of an (x, y, yaw) histogram, indexed [yaw, y, x]: positions outside clamped into the edge
    cells, yaw wrapped into [-pi, pi) and cut into ``nyaw`` bins (best_cluster's histogram, KLD-sampling's bins)."""
    ix = wp.clamp(int(wp.floor((p[0] - lo[0]) / cell)), 0, nx - 1)
    iy = wp.clamp(int(wp.floor((p[1] - lo[1]) / cell)), 0, ny - 1)
    a = wp.atan2(wp.sin(p[2]), wp.cos(p[2])) + 3.14159265358979
    ia = wp.clamp(int(a / (6.28318530717959 / float(nyaw))), 0, nyaw - 1)
    return (ia * ny + iy) * nx + ix


@wp.kernel
def histogram_kernel(
    particles: wp.array(dtype=wp.vec3),
    log_w: wp.array(dtype=wp.float32),
    top: wp.array(dtype=wp.float32),
    lo: wp.vec2,
    cell: float,
    nx: int,
    ny: int,
    nyaw: int,
    hist: wp.array(dtype=wp.float32),
):
    i = wp.tid()
    wp.atomic_add(hist, pose_bin(particles[i], lo, cell, nx, ny, nyaw), wp.exp(log_w[i] - top[0]))


@wp.kernel
def cluster_sums_kernel(
    particles: wp.array(dtype=wp.vec3),
    log_w: wp.array(dtype=wp.float32),
    top: wp.array(dtype=wp.float32),
    centre: wp.vec3,
    radius: float,
    yaw_radius: float,
    partials: wp.array2d(dtype=wp.float32),
    stride: int,
):
    acc = vec5()
    for i in range(wp.tid(), particles.shape[0], stride):
        p = particles[i]
        dx = p[0] - centre[0]
        dy = p[1] - centre[1]
        da = wp.atan2(wp.sin(p[2] - centre[2]), wp.cos(p[2] - centre[2]))
        if dx * dx + dy * dy <= radius * radius and wp.abs(da) <= yaw_radius:
            acc += pose_moments(wp.exp(log_w[i] - top[0]), p)
    leave_moments(partials, wp.tid(), acc)


def heaviest_bin(hist: np.ndarray) -> tuple[int, int, int]:
    """(yaw bin, iy, ix) of the largest 3x3x3 neighbourhood sum of a [yaw, y, x] histogram (yaw wraps)."""
    from scipy.ndimage import uniform_filter

    smooth = uniform_filter(hist.astype(np.float64), size=3, mode=("wrap", "constant", "constant"))
    return tuple(int(v) for v in np.unravel_index(np.argmax(smooth), hist.shape))


class BestCluster:
    def __init__(
        self,
        num_particles: int,
        bounds,
        cell_m: float = 0.5,
        yaw_bins: int = 8,
        device: str = "auto",
        sums: wp.array | None = None,
    ):
        xmin, ymin, xmax, ymax = map(float, bounds)
        if not (xmax > xmin and ymax > ymin and cell_m > 0 and yaw_bins >= 1):
            raise ValueError(
                f"best_cluster: bounds {bounds}, cell {cell_m} m, {yaw_bins} yaw bins do not make a histogram"
            )
        self.device = pick_device(device)
        self.lo, self.cell, self.nyaw = wp.vec2(xmin, ymin), float(cell_m), int(yaw_bins)
        self.nx, self.ny = int(np.ceil((xmax - xmin) / cell_m)) + 1, int(np.ceil((ymax - ymin) / cell_m)) + 1
        self.hist = wp.zeros(self.nyaw * self.ny * self.nx, dtype=wp.float32, device=self.device)
        self.top = wp.zeros(1, dtype=wp.float32, device=self.device)
        self.sums = sums_array(sums, 5, self.device, "best_cluster")
        self.partial = PartialSums(5, self.device, reduction_threads(num_particles, self.device))

    def __call__(self, particles: wp.array, log_w: wp.array) -> np.ndarray:
        n, d = particles.shape[0], self.device
        self.top.fill_(-3.0e38)
        self.hist.zero_()
        launch_reduction(max_kernel, n, [log_w, self.top], d)
        wp.launch(
            histogram_kernel,
            n,
            [particles, log_w, self.top, self.lo, self.cell, self.nx, self.ny, self.nyaw, self.hist],
            device=d,
        )
        ia, iy, ix = heaviest_bin(self.hist.numpy().reshape(self.nyaw, self.ny, self.nx))
        bin_yaw = 2 * np.pi / self.nyaw
        centre = wp.vec3(
            self.lo[0] + (ix + 0.5) * self.cell, self.lo[1] + (iy + 0.5) * self.cell, -np.pi + (ia + 0.5) * bin_yaw
        )
        threads = launch_reduction(
            cluster_sums_kernel,
            n,
            [particles, log_w, self.top, centre, 1.5 * self.cell, 1.5 * bin_yaw, self.partial.partials],
            d,
        )
        self.partial.finish(threads, self.sums)
        return self.result()

    def launch(self, particles: wp.array, log_w: wp.array) -> None:
        self(particles, log_w)  # the heaviest bin is found on the host: nothing to defer

    def result(self, sums: np.ndarray | None = None) -> np.ndarray:
        """[x, y, yaw] from the five sums (``sums``: a copy already read back)."""
        return mean_pose(self.sums.numpy() if sums is None else sums)


@ESTIMATE.register("best_cluster")
def make_best_cluster(**settings) -> BestCluster:
    return BestCluster(**settings)
