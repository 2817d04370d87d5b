"""Particle weighting for MCL: ``WEIGHTING["nog_raymarch"]`` (IR-MCL's observation model on the NOG) and
the grid baselines ``likelihood_field`` and ``beam_model``.

``nog_raymarch``: for every particle and beam (one thread each), march ``num_samples`` fixed depths over
[near, far] from the particle's laser pose, read the nearest NOG node (occupancy 0 outside the grid), and
composite as in training (kernels/render.py, normalised weights) into the rendered ranges [P, B]. A
second kernel, one thread per particle, adds |r_rendered - r_measured| over the valid beams in beam order
(the same bits on every device and run) and turns the sum into (IR-MCL eq. 6)

    D = mean over valid beams of |r_rendered - r_measured|,   log w = -0.5 * D^2 / sigma^2

Two exact shortcuts, both off with their setting at 0 (the authors' formulation):
* ``t_min``: stop once the transmittance is below t_min (early termination);
* ``empty_below``: nodes with p_occ < empty_below read as 0 ("empty"), and the march jumps over empty
  space: a sample in an empty node whose centre lies D from the nearest non-empty node centre skips every
  sample closer than D - res * sqrt(2) (no point that near can round to a non-empty node).
Samples outside the grid are skipped by clipping the march to the grid's extent (slab test).
Numpy twin: irmcl_warp/reference/weighting.py (all samples, the same "empty" rule).

``nog_table``: the same march run once from every NOG node at evenly spread headings (a range table), so
that a filter step reads two table entries per beam instead of marching (``NogTable``; an approximation).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.raycast import dda_range, distance_to_occupied
from irmcl_warp.kernels.registry import WEIGHTING, pick_device


@wp.func
def nearest_node(grid: wp.array2d(dtype=wp.float32), origin: wp.vec2, res: float, x: float, y: float) -> float:
    ix = int(wp.round((x - origin[0]) / res))
    iy = int(wp.round((y - origin[1]) / res))
    if ix < 0 or iy < 0 or ix >= grid.shape[1] or iy >= grid.shape[0]:
        return 0.0
    return grid[iy, ix]


@wp.func
def laser_pose(base: wp.vec3, T_base_laser: wp.vec3) -> wp.vec3:
    c = wp.cos(base[2])
    s = wp.sin(base[2])
    return wp.vec3(
        base[0] + c * T_base_laser[0] - s * T_base_laser[1],
        base[1] + s * T_base_laser[0] + c * T_base_laser[1],
        base[2] + T_base_laser[2],
    )


@wp.func
def beam_origin(particle: wp.vec3, T_base_laser: wp.vec3) -> wp.vec2:
    pose = laser_pose(particle, T_base_laser)
    return wp.vec2(pose[0], pose[1])


@wp.func
def beam_direction(particle: wp.vec3, T_base_laser: wp.vec3, angle: float) -> wp.vec2:
    """Unit direction in the map frame of the beam at ``angle`` in the laser frame."""
    a = particle[2] + T_base_laser[2] + angle
    return wp.vec2(wp.cos(a), wp.sin(a))


@wp.func
def slab(o: float, d: float, lo: float, hi: float) -> wp.vec2:
    """Ray parameters (enter, exit) of o + t d within [lo, hi] on one axis."""
    if wp.abs(d) < 1.0e-12:
        if o < lo or o > hi:
            return wp.vec2(1.0e30, -1.0e30)
        return wp.vec2(-1.0e30, 1.0e30)
    a = (lo - o) / d
    b = (hi - o) / d
    return wp.vec2(wp.min(a, b), wp.max(a, b))


@wp.func
def mean_l1_log_weight(err: float, n: float, sigma2: float) -> float:
    """IR-MCL eq. 6 from the summed |r_rendered - r_measured| of the n valid beams: D = err / n (0 without a
    valid beam), log w = -0.5 D^2 / sigma^2."""
    D = err / wp.max(n, 1.0)
    return -0.5 * D * D / sigma2


def make_likelihood_kernel(sigma: float):
    """IR-MCL eq. 6 from the rendered ranges [P, B]: D = sum over the valid beams of |r_rendered - r_measured|
    / their number, log w = -0.5 D^2 / sigma^2. One thread per particle adds its beams in beam order, so the
    weights are the same bits on every device and every run (atomic adds from the march threads were not:
    on CUDA their order varied, and resampling could amplify the last-bit differences). Shared by
    nog_raymarch and nof_direct."""

    @wp.kernel(module="unique")
    def likelihood(
        rendered: wp.array2d(dtype=wp.float32),
        measured: wp.array(dtype=wp.float32),
        log_weights: wp.array(dtype=wp.float32),
    ):
        p = wp.tid()
        n = float(0.0)
        err = float(0.0)
        for b in range(measured.shape[0]):
            m = measured[b]
            if m == m:  # NaN: invalid beam
                n += 1.0
                err += wp.abs(rendered[p, b] - m)
        log_weights[p] = mean_l1_log_weight(err, n, wp.static(sigma * sigma))

    return likelihood


def make_render_kernel(
    num_samples: int,
    near: float,
    far_m: float,
    t_min: float,
    empty_below: float,
    eps: float = 1e-10,
    batch: int = 1,
    beam_major: bool = False,
):
    """Two ways to the same march, for speed:

    * ``batch``: samples whose nodes are loaded together before they are composited one by one (the loads
      of a batch are independent, so they are in flight at once; compositing stops at the same sample as
      one at a time, and the result is the same bit for bit). With ``empty_below`` the next sample depends
      on the node just read (the jump), so the march loads one at a time.
    * ``beam_major``: threads (beam, particle) instead of (particle, beam), so that the 32 threads of a
      GPU warp march one beam of 32 particles (after resampling, copies of the same few poses: they read
      the same nodes) rather than the 32 beams of one particle (32 directions, 32 cache lines). The
      rendered ranges are the same either way."""
    step = (far_m - near) / float(num_samples - 1)
    skip = empty_below > 0.0
    batched = batch > 1 and not skip
    batch = max(1, int(batch))

    @wp.kernel(module="unique")
    def render(
        grid: wp.array2d(dtype=wp.float32),
        origin: wp.vec2,
        res: float,
        particles: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        angles: wp.array(dtype=wp.float32),
        out: wp.array2d(dtype=wp.float32),
    ):
        i, j = wp.tid()
        p = i
        b = j
        if wp.static(beam_major):
            p = j
            b = i
        o = beam_origin(particles[p], T_base_laser)
        d = beam_direction(particles[p], T_base_laser, angles[b])
        # the samples whose point can round to a node: the grid's extent plus one node of margin
        sx = slab(o[0], d[0], origin[0] - 1.5 * res, origin[0] + (float(grid.shape[1]) + 0.5) * res)
        sy = slab(o[1], d[1], origin[1] - 1.5 * res, origin[1] + (float(grid.shape[0]) + 0.5) * res)
        t0 = wp.max(sx[0], sy[0])
        t1 = wp.min(sx[1], sy[1])
        k = int(0)
        k_end = int(-1)
        if t1 >= t0:
            k = int(wp.max(wp.floor((t0 - wp.static(near)) / wp.static(step)), 0.0))
            k_end = int(wp.min(wp.ceil((t1 - wp.static(near)) / wp.static(step)), float(wp.static(num_samples - 1))))
        T = float(1.0)
        A = float(0.0)
        W = float(0.0)
        if wp.static(batched):
            occ = wp.vector(length=wp.static(batch), dtype=wp.float32)
            while k <= k_end and T >= wp.static(t_min):
                for j in range(wp.static(batch)):
                    occ[j] = 0.0
                    if k + j <= k_end:
                        zj = wp.static(near) + wp.static(step) * float(k + j)
                        occ[j] = nearest_node(grid, origin, res, o[0] + zj * d[0], o[1] + zj * d[1])
                for j in range(wp.static(batch)):
                    if k + j <= k_end and T >= wp.static(t_min):
                        z = wp.static(near) + wp.static(step) * float(k + j)
                        w = occ[j] * T
                        A += w * z
                        W += w
                        T *= 1.0 - occ[j]
                k += wp.static(batch)
        else:
            while k <= k_end:
                if T < wp.static(t_min):
                    break
                z = wp.static(near) + wp.static(step) * float(k)
                occ1 = nearest_node(grid, origin, res, o[0] + z * d[0], o[1] + z * d[1])
                jump = int(1)
                if wp.static(skip):
                    if occ1 < 0.0:  # an empty node holds -(the distance it lets the ray jump); outside reads 0
                        jump = wp.max(1, int(-occ1 * wp.static(1.0 / step)))
                        occ1 = 0.0
                w1 = occ1 * T
                A += w1 * z
                W += w1
                T *= 1.0 - occ1
                k += jump
        out[p, b] = A / (W + wp.static(eps))

    return render


def pack_empty_space(occupancy: np.ndarray, res: float, empty_below: float) -> np.ndarray:
    """The grid the kernel reads (one load per sample): p_occ at non-empty nodes, and at an empty node
    (p_occ < empty_below) minus how far a ray may advance from any point rounding to it without reaching a
    point that rounds to a non-empty node: its centre distance to the nearest one - res * sqrt(2) (-0 - 1e-6
    when that is not positive, so that every empty node is negative)."""
    occupancy = np.asarray(occupancy, np.float32)
    if empty_below <= 0:
        return occupancy
    dist = distance_to_occupied(occupancy, res, empty_below)
    jump = np.maximum(dist - res * np.sqrt(2.0) - 1e-4, 0.0) + 1e-6
    return np.where(occupancy < empty_below, -jump, occupancy).astype(np.float32)


class NogRaymarch:
    """Holds the NOG (with its empty-space jumps packed in) on the device and [P, B] / [P] scratch arrays;
    ``__call__`` only launches (``capturable``: a filter step may capture it in a graph)."""

    capturable = True

    def __init__(
        self,
        nog,
        num_particles: int,
        num_beams: int,
        num_samples: int = 256,
        near_m: float = 0.02,
        far_m: float = 40.0,
        t_min: float = 0.0,
        sigma_m: float = 0.5,
        empty_below: float = 0.0,
        batch: int = 1,
        beam_major: bool = False,
        device: str = "auto",
    ):
        if nog.occupancy.size == 0 or nog.occupancy.ndim != 2:
            raise ValueError(f"nog_raymarch: the NOG is empty (shape {nog.occupancy.shape})")
        if num_samples < 2 or not far_m > near_m:
            raise ValueError(
                f"nog_raymarch: need num_samples >= 2 and far > near, got {num_samples}, [{near_m}, {far_m}]"
            )
        self.device = pick_device(device)
        self.grid = wp.array(
            pack_empty_space(nog.occupancy, float(nog.resolution_m), empty_below), dtype=wp.float32, device=self.device
        )
        self.origin, self.res = wp.vec2(*map(float, nog.origin_xy)), float(nog.resolution_m)
        self.num_beams = num_beams
        self.rendered = wp.zeros((num_particles, num_beams), dtype=wp.float32, device=self.device)
        self.render_kernel = make_render_kernel(
            num_samples, near_m, far_m, t_min, empty_below, batch=batch, beam_major=beam_major
        )
        self.beam_major = beam_major
        self.likelihood_kernel = make_likelihood_kernel(sigma_m)

    def render(self, particles: wp.array, T_base_laser, angles: wp.array) -> wp.array:
        """Rendered ranges [P, B] (the first P rows of the scratch array)."""
        if particles.shape[0] > self.rendered.shape[0]:
            raise ValueError(f"nog_raymarch: {particles.shape[0]} particles, built for {self.rendered.shape[0]}")
        dims = (particles.shape[0], angles.shape[0])
        wp.launch(
            self.render_kernel,
            dims[::-1] if self.beam_major else dims,
            [self.grid, self.origin, self.res, particles, wp.vec3(*map(float, T_base_laser)), angles, self.rendered],
            device=self.device,
        )
        return self.rendered

    def __call__(
        self, particles: wp.array, T_base_laser, angles: wp.array, measured: wp.array, log_weights: wp.array
    ) -> None:
        if angles.shape[0] != self.num_beams or measured.shape[0] != self.num_beams:
            raise ValueError(
                f"nog_raymarch: {measured.shape[0]} measured ranges / {angles.shape[0]} angles, "
                f"built for {self.num_beams} beams"
            )
        self.render(particles, T_base_laser, angles)
        wp.launch(
            self.likelihood_kernel, particles.shape[0], [self.rendered, measured, log_weights], device=self.device
        )


@WEIGHTING.register("nog_raymarch")
def make_nog_raymarch(**settings) -> NogRaymarch:
    return NogRaymarch(**settings)


TABLE_LEVELS = 65535  # a range table entry: round(range / (far / TABLE_LEVELS)) in a uint16
TABLE_MAX_BYTES = 4 << 30  # a larger table is refused (fewer headings or a coarser NOG)
TABLE_BUILD_FLOATS = 1 << 25  # rendered ranges per build launch (128 MB of float32 scratch)


@wp.kernel
def quantize_ranges(
    rendered: wp.array2d(dtype=wp.float32), first_node: int, inv_quantum: float, table: wp.array2d(dtype=wp.uint16)
):
    i, k = wp.tid()
    table[first_node + i, k] = wp.uint16(
        wp.clamp(wp.round(rendered[i, k] * inv_quantum), 0.0, wp.static(float(TABLE_LEVELS)))
    )


@wp.func
def table_range(
    table: wp.array2d(dtype=wp.uint16),
    width: int,
    height: int,
    origin: wp.vec2,
    res: float,
    quantum: float,
    pose: wp.vec3,
    angle: float,
) -> float:
    """The range the march renders from the laser's nearest node, linear in heading between the table's two
    nearest headings, moved by the laser's offset from that node along the beam (exact for a wall across the
    beam); ``pose``: the laser's, ``angle``: the beam's in the laser frame."""
    a = pose[2] + angle
    n = table.shape[1]
    u = a * (float(n) / (2.0 * wp.pi))
    u = u - wp.floor(u / float(n)) * float(n)
    k0 = int(wp.floor(u))
    f = u - float(k0)
    k0 = k0 % n
    k1 = (k0 + 1) % n
    ix = wp.clamp(int(wp.round((pose[0] - origin[0]) / res)), 0, width - 1)
    iy = wp.clamp(int(wp.round((pose[1] - origin[1]) / res)), 0, height - 1)
    node = iy * width + ix
    r = ((1.0 - f) * float(table[node, k0]) + f * float(table[node, k1])) * quantum
    if r > 0.0:  # 0: no wall rendered (the beam leaves the grid)
        along = (pose[0] - origin[0] - float(ix) * res) * wp.cos(a) + (pose[1] - origin[1] - float(iy) * res) * wp.sin(
            a
        )
        r = wp.max(r - along, 0.0)
    return r


@wp.kernel
def table_ranges(
    table: wp.array2d(dtype=wp.uint16),
    width: int,
    height: int,
    origin: wp.vec2,
    res: float,
    quantum: float,
    particles: wp.array(dtype=wp.vec3),
    T_base_laser: wp.vec3,
    angles: wp.array(dtype=wp.float32),
    out: wp.array2d(dtype=wp.float32),
):
    """The ranges alone [P, B], one thread per (beam, particle)."""
    b, p = wp.tid()
    out[p, b] = table_range(
        table, width, height, origin, res, quantum, laser_pose(particles[p], T_base_laser), angles[b]
    )


def make_table_likelihood_kernel(sigma: float):
    """IR-MCL eq. 6 on the table's ranges, one thread per particle: its beams read one node's row of the
    table (nearby headings), added in beam order as ``make_likelihood_kernel`` adds them; no [P, B] array."""

    @wp.kernel(module="unique")
    def likelihood(
        table: wp.array2d(dtype=wp.uint16),
        width: int,
        height: int,
        origin: wp.vec2,
        res: float,
        quantum: float,
        particles: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        angles: wp.array(dtype=wp.float32),
        measured: wp.array(dtype=wp.float32),
        log_weights: wp.array(dtype=wp.float32),
    ):
        p = wp.tid()
        pose = laser_pose(particles[p], T_base_laser)
        n = float(0.0)
        err = float(0.0)
        for b in range(measured.shape[0]):
            m = measured[b]
            if m == m:  # NaN: invalid beam
                n += 1.0
                err += wp.abs(table_range(table, width, height, origin, res, quantum, pose, angles[b]) - m)
        log_weights[p] = mean_l1_log_weight(err, n, wp.static(sigma * sigma))

    return likelihood


class NogTable:
    """IR-MCL's observation model read from a table instead of marched per particle (an approximation of
    ``nog_raymarch``, made for speed, in the spirit of the lookup tables of range-based particle filters):
    at start the march renders, from every NOG node, the range at ``num_angles`` headings evenly spread over
    the circle (``table``: [nodes, headings] uint16, range / (far / 65535)); a particle's beam then reads its
    laser's nearest node at the two nearest headings, interpolates linearly and moves the range by the
    laser's offset from the node along the beam. A laser off the grid reads the nearest edge node. The
    likelihood is ``nog_raymarch``'s (IR-MCL eq. 6). Numpy twin: irmcl_warp/reference/weighting.py
    ``nog_table_build`` and ``nog_table_ranges``; what the approximation costs in accuracy is measured by the
    localize runs (docs/benchmarks.md)."""

    capturable = True

    def __init__(
        self,
        nog,
        num_particles: int,
        num_beams: int,
        num_angles: int = 720,
        num_samples: int = 256,
        near_m: float = 0.02,
        far_m: float = 40.0,
        t_min: float = 0.0,
        sigma_m: float = 0.5,
        empty_below: float = 0.0,
        table=None,
        device: str = "auto",
    ):
        H, W = nog.occupancy.shape
        self.device = pick_device(device)
        self.shape, self.num_beams, self.quantum = (H, W), num_beams, float(far_m) / TABLE_LEVELS
        self.origin, self.res = wp.vec2(*map(float, nog.origin_xy)), float(nog.resolution_m)
        if table is None:
            table = self.build(nog, num_angles, num_samples, near_m, far_m, t_min, empty_below, self.device)
        elif tuple(table.shape) != (H * W, num_angles):
            raise ValueError(f"nog_table: a table of {tuple(table.shape)} for {H * W} nodes x {num_angles} headings")
        self.table = table
        self.num_particles = num_particles
        self._rendered = None  # [P, B] for render() only: a filter step never fills it
        self.likelihood_kernel = make_table_likelihood_kernel(sigma_m)

    @staticmethod
    def build(nog, num_angles, num_samples, near_m, far_m, t_min, empty_below, device) -> wp.array:
        """The table, rendered by ``nog_raymarch``'s march from the nodes (heading 0, beams at the table's
        headings), a block of nodes per launch."""
        H, W = nog.occupancy.shape
        if num_angles < 4:
            raise ValueError(f"nog_table: mcl.table_angles={num_angles}; need at least 4 headings")
        if H * W * num_angles * 2 > TABLE_MAX_BYTES:
            raise ValueError(
                f"nog_table: {H}x{W} nodes x {num_angles} headings need "
                f"{H * W * num_angles * 2 / 2**30:.1f} GiB (at most {TABLE_MAX_BYTES / 2**30:.0f}); "
                "lower mcl.table_angles or raise mcl.map_resolution_m"
            )
        block = max(1, min(H * W, TABLE_BUILD_FLOATS // num_angles))
        march = NogRaymarch(
            nog, block, num_angles, num_samples, near_m, far_m, t_min, empty_below=empty_below, device=device
        )
        iy, ix = np.divmod(np.arange(H * W), W)
        nodes = np.stack(
            [nog.origin_xy[0] + ix * nog.resolution_m, nog.origin_xy[1] + iy * nog.resolution_m, np.zeros(H * W)], -1
        ).astype(np.float32)
        headings = wp.array(table_headings(num_angles), dtype=wp.float32, device=device)
        table = wp.zeros((H * W, num_angles), dtype=wp.uint16, device=device)
        from tqdm import tqdm  # minutes on a CPU for a building's NOG (fr079 at 720 headings: ~80 s on 2 cores)

        for first in tqdm(
            range(0, H * W, block),
            desc=f"nog_table: {H}x{W} nodes x {num_angles} headings",
            unit="block",
            disable=H * W <= 4 * block,
            leave=False,
        ):
            chunk = wp.array(nodes[first : first + block], dtype=wp.vec3, device=device)
            rendered = march.render(chunk, (0.0, 0.0, 0.0), headings)
            wp.launch(
                quantize_ranges,
                (chunk.shape[0], num_angles),
                [rendered, first, TABLE_LEVELS / float(far_m), table],
                device=device,
            )
        return table

    def render(self, particles: wp.array, T_base_laser, angles: wp.array) -> wp.array:
        """The ranges read from the table [P, B] (for tests and diagnostics; the weighting never stores them)."""
        if particles.shape[0] > self.num_particles:
            raise ValueError(f"nog_table: {particles.shape[0]} particles, built for {self.num_particles}")
        if self._rendered is None or self._rendered.shape != (particles.shape[0], angles.shape[0]):
            self._rendered = wp.zeros((particles.shape[0], angles.shape[0]), dtype=wp.float32, device=self.device)
        wp.launch(
            table_ranges,
            (angles.shape[0], particles.shape[0]),
            self._args(particles, T_base_laser, angles) + [self._rendered],
            device=self.device,
        )
        return self._rendered

    def _args(self, particles, T_base_laser, angles) -> list:
        return [
            self.table,
            self.shape[1],
            self.shape[0],
            self.origin,
            self.res,
            self.quantum,
            particles,
            wp.vec3(*map(float, T_base_laser)),
            angles,
        ]

    def __call__(
        self, particles: wp.array, T_base_laser, angles: wp.array, measured: wp.array, log_weights: wp.array
    ) -> None:
        if angles.shape[0] != self.num_beams or measured.shape[0] != self.num_beams:
            raise ValueError(
                f"nog_table: {measured.shape[0]} measured ranges / {angles.shape[0]} angles, "
                f"built for {self.num_beams} beams"
            )
        wp.launch(
            self.likelihood_kernel,
            particles.shape[0],
            self._args(particles, T_base_laser, angles) + [measured, log_weights],
            device=self.device,
        )


def table_headings(num_angles: int) -> np.ndarray:
    """The table's headings: 2 pi k / num_angles, k = 0 .. num_angles - 1 (float32, as the kernels read them)."""
    return (2.0 * np.pi * np.arange(num_angles) / num_angles).astype(np.float32)


@WEIGHTING.register("nog_table")
def make_nog_table(**settings) -> NogTable:
    return NogTable(**settings)


def make_log_q_kernel(z_hit: float, z_rand: float, sigma_hit: float, far_m: float, max_dist: float):
    """Per cell of the distance map, the likelihood field's log q = log(z_hit exp(-d^2 / 2 sigma^2) + z_rand /
    max_range), d capped at ``max_dist``: the expression the field's kernel once evaluated per beam, evaluated once
    per cell by the same code on the same device, so the same bits (tests/test_weighting.py checks them)."""

    @wp.kernel(module="unique")
    def log_q(dist: wp.array2d(dtype=wp.float32), out: wp.array2d(dtype=wp.float32)):
        iy, ix = wp.tid()
        d = wp.min(dist[iy, ix], wp.static(max_dist))
        q = wp.static(z_hit) * wp.exp(-d * d / wp.static(2.0 * sigma_hit * sigma_hit)) + wp.static(z_rand / far_m)
        out[iy, ix] = wp.log(q)

    return log_q


@wp.kernel
def likelihood_field(
    log_q: wp.array2d(dtype=wp.float32),
    origin: wp.vec2,
    res: float,
    particles: wp.array(dtype=wp.vec3),
    T_base_laser: wp.vec3,
    angles: wp.array(dtype=wp.float32),
    measured: wp.array(dtype=wp.float32),
    log_lik: wp.array(dtype=wp.float32),
):
    """log w = sum over valid beams of log q at the end point's cell (``log_q``: the map's cells, then one more
    row whose first entry is log q at the capped distance, for end points off the map)."""
    p = wp.tid()
    pose = particles[p]
    o = beam_origin(pose, T_base_laser)  # once per particle, not per beam
    H = log_q.shape[0] - 1
    off_map = log_q[H, 0]
    s = float(0.0)
    for b in range(angles.shape[0]):
        m = measured[b]
        if m == m:  # NaN: invalid beam
            end = o + m * beam_direction(pose, T_base_laser, angles[b])
            ix = int(wp.floor((end[0] - origin[0]) / res))
            iy = int(wp.floor((end[1] - origin[1]) / res))
            if ix >= 0 and iy >= 0 and ix < log_q.shape[1] and iy < H:
                s += log_q[iy, ix]
            else:
                s += off_map
    log_lik[p] = s


class _GridModel:
    """Shared by the grid baselines: the grid on the device, its frame, and one launch, a thread per
    particle adding its valid beams' log q in beam order into ``log_lik`` (no atomics: the same bits on
    every run; on the CPU the order the earlier thread-per-beam atomics took, so results are unchanged)."""

    name = "grid model"
    capturable = True  # launches only: a filter step may capture it in a graph

    def _setup(self, occupancy, origin_xy, resolution_m, occ_threshold, device):
        occupancy = np.asarray(occupancy, np.float32)
        if occupancy.ndim != 2 or occupancy.size == 0 or not (occupancy >= occ_threshold).any():
            raise ValueError(f"{self.name}: the map is empty (shape {occupancy.shape}, no occupied cell)")
        self.device = pick_device(device)
        self.origin, self.res = wp.vec2(*map(float, origin_xy)), float(resolution_m)
        return occupancy

    def __call__(self, particles, T_base_laser, angles, measured, log_lik) -> None:
        wp.launch(
            self.kernel,
            particles.shape[0],
            [
                self.grid,
                self.origin,
                self.res,
                particles,
                wp.vec3(*map(float, T_base_laser)),
                angles,
                measured,
                log_lik,
            ],
            device=self.device,
        )


class LikelihoodField(_GridModel):
    """The likelihood-field model (Thrun et al. Table 6.3; AMCL's default): each beam's end point scores by
    its distance d to the nearest occupied cell, q = z_hit N(d; 0, sigma_hit) + z_rand / max_range (the
    Gaussian unnormalised, as AMCL), d capped at ``max_dist_m``; log w = sum over valid beams of log q.
    End points off the map count as ``max_dist_m`` away. log q is computed once per cell at start (AMCL keeps the
    distance per cell; the table of log q is the same bits as computing it per beam, and a third of the work on a
    CPU). One thread per particle, beams in order."""

    name = "likelihood_field"

    def __init__(
        self,
        occupancy,
        origin_xy,
        resolution_m: float,
        z_hit: float = 0.95,
        z_rand: float = 0.05,
        sigma_hit_m: float = 0.2,
        far_m: float = 30.0,
        max_dist_m: float = 2.0,
        occ_threshold: float = 0.65,
        device: str = "auto",
    ):
        occupancy = self._setup(occupancy, origin_xy, resolution_m, occ_threshold, device)
        dist = distance_to_occupied(occupancy, resolution_m, occ_threshold).astype(np.float32)
        self.distance = dist  # to the nearest occupied cell, per cell (m; for inspection, the kernel reads log q)
        padded = np.full((dist.shape[0] + 1, dist.shape[1]), max_dist_m, np.float32)  # + the off-map row
        padded[:-1] = dist
        self.grid = wp.empty(padded.shape, dtype=wp.float32, device=self.device)  # log q per cell
        wp.launch(
            make_log_q_kernel(z_hit, z_rand, sigma_hit_m, far_m, max_dist_m),
            padded.shape,
            [wp.array(padded, dtype=wp.float32, device=self.device), self.grid],
            device=self.device,
        )
        self.kernel = likelihood_field


@WEIGHTING.register("likelihood_field")
def make_likelihood_field(**settings) -> LikelihoodField:
    return LikelihoodField(**settings)


def make_beam_model_kernel(z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short, far_m, occ_threshold):
    @wp.kernel(module="unique")
    def beam(
        occ: wp.array2d(dtype=wp.float32),
        origin: wp.vec2,
        res: float,
        particles: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        angles: wp.array(dtype=wp.float32),
        measured: wp.array(dtype=wp.float32),
        log_lik: wp.array(dtype=wp.float32),
    ):
        p = wp.tid()
        s = float(0.0)
        for b in range(angles.shape[0]):
            z = measured[b]
            if z == z:  # NaN: invalid beam
                expected = dda_range(
                    occ,
                    origin,
                    res,
                    beam_origin(particles[p], T_base_laser),
                    beam_direction(particles[p], T_base_laser, angles[b]),
                    wp.static(far_m),
                    wp.static(occ_threshold),
                )
                e = z - expected
                q = wp.static(z_hit) * wp.exp(-e * e / wp.static(2.0 * sigma_hit * sigma_hit))
                if z < expected:
                    q += wp.static(z_short) * wp.static(lambda_short) * wp.exp(-wp.static(lambda_short) * z)
                if z >= wp.static(far_m):
                    q += wp.static(z_max)
                else:
                    q += wp.static(z_rand / far_m)
                s += wp.log(q)
        log_lik[p] = s

    return beam


class BeamModel(_GridModel):
    """The beam model (Thrun et al. Table 6.1, as AMCL's ``beam`` model): ray cast the expected range on
    the grid (DDA), then q = z_hit exp(-(z - z*)^2 / 2 sigma^2) + z_short lambda exp(-lambda z) [z < z*]
    + z_max [z >= max] + z_rand / max [z < max]; log w = sum over valid beams of log q."""

    name = "beam_model"

    def __init__(
        self,
        occupancy,
        origin_xy,
        resolution_m: float,
        z_hit: float = 0.95,
        z_short: float = 0.1,
        z_max: float = 0.05,
        z_rand: float = 0.05,
        sigma_hit_m: float = 0.2,
        lambda_short: float = 0.1,
        far_m: float = 30.0,
        occ_threshold: float = 0.5,
        device: str = "auto",
    ):
        occupancy = self._setup(occupancy, origin_xy, resolution_m, occ_threshold, device)
        self.grid = wp.array(occupancy, dtype=wp.float32, device=self.device)
        self.kernel = make_beam_model_kernel(
            z_hit, z_short, z_max, z_rand, sigma_hit_m, lambda_short, far_m, occ_threshold
        )


@WEIGHTING.register("beam_model")
def make_beam_model(**settings) -> BeamModel:
    return BeamModel(**settings)
