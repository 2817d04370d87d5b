"""``WEIGHTING["nog_table"]``: ``nog_raymarch``'s march run once from every NOG node at evenly spread
headings (a range table), so that a filter step reads two table entries per beam instead of marching
(``NogTable``; an approximation, measured in docs/benchmarks.md).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import CPU_MIN_BLOCK, WEIGHTING, ParticleBlocks, pick_device
from irmcl_warp.kernels.weighting.common import laser_pose, mean_l1_log_weight
from irmcl_warp.kernels.weighting.nog_raymarch import NogRaymarch


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


def make_table_likelihood_kernel(sigma: float, move=None):
    """IR-MCL eq. 6 on the table's ranges, one thread per particle: its beams read one node's row of the
    table (nearby headings), added in beam order as ``make_likelihood_kernel`` adds them; no [P, B] array. With
    ``move`` (a motion model's per-particle function, kernels/motion.py ``Motion.move``) the thread first moves its
    particle and writes it back: the motion kernel's launch and its pass over the particles fewer (``moving``)."""

    @wp.func
    def log_weight(
        table: wp.array2d(dtype=wp.uint16),
        width: int,
        height: int,
        origin: wp.vec2,
        res: float,
        quantum: float,
        particle: wp.vec3,
        T_base_laser: wp.vec3,
        angles: wp.array(dtype=wp.float32),
        measured: wp.array(dtype=wp.float32),
    ) -> float:
        pose = laser_pose(particle, T_base_laser)
        n = float(0.0)
        err = float(0.0)
        for b in range(measured.shape[0]):
            m = measured[b]
            if m == m:  # NaN: invalid beam
                n += 1.0
                err += wp.abs(table_range(table, width, height, origin, res, quantum, pose, angles[b]) - m)
        return mean_l1_log_weight(err, n, wp.static(sigma * sigma))

    if move is None:

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
            log_weights[p] = log_weight(
                table, width, height, origin, res, quantum, particles[p], T_base_laser, angles, measured
            )

        return likelihood

    @wp.kernel(module="unique")
    def move_and_weigh(
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
        step: wp.array(dtype=wp.float32),
        seed: wp.array(dtype=wp.int32),
    ):
        p = wp.tid()
        moved = move(particles[p], step, seed, p)
        particles[p] = moved
        log_weights[p] = log_weight(table, width, height, origin, res, quantum, moved, T_base_laser, angles, measured)

    return move_and_weigh


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
        cpu_threads: int | None = None,
        device: str = "auto",
    ):
        H, W = nog.occupancy.shape
        self.device = pick_device(device)
        # on the CPU a block of particles per core, as the grid models (kernels/registry.py ParticleBlocks)
        self.blocks = ParticleBlocks(self.device, cpu_threads, min_block=CPU_MIN_BLOCK)
        self.shape, self.num_beams, self.quantum = (H, W), num_beams, float(far_m) / TABLE_LEVELS
        self.origin, self.res = wp.vec2(*map(float, nog.origin_xy)), float(nog.resolution_m)
        if table is None:
            table = self.build(nog, num_angles, num_samples, near_m, far_m, t_min, empty_below, self.device)
        elif tuple(table.shape) != (H * W, num_angles):
            raise ValueError(f"nog_table: a table of {tuple(table.shape)} for {H * W} nodes x {num_angles} headings")
        self.table = table
        self.num_particles = num_particles
        self._rendered = None  # [P, B] for render() only: a filter step never fills it
        self.sigma_m = float(sigma_m)
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
                "lower mcl.table_angles, raise mcl.map_resolution_m, or march instead (mcl.weighting=nog_raymarch)"
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
        self._check(angles, measured)
        self.blocks.run(self.block(particles, T_base_laser, angles, measured, log_weights), particles.shape[0])

    def _check(self, angles: wp.array, measured: wp.array) -> None:
        if angles.shape[0] != self.num_beams or measured.shape[0] != self.num_beams:
            raise ValueError(
                f"nog_table: {measured.shape[0]} measured ranges / {angles.shape[0]} angles, "
                f"built for {self.num_beams} beams"
            )

    def block(self, particles: wp.array, T_base_laser, angles: wp.array, measured: wp.array, log_weights: wp.array):
        """The call for one block of particles: a function (p0, p1) -> None (``ParticleBlocks.block``)."""
        inputs = self._args(particles, T_base_laser, angles) + [measured, log_weights]
        return self.blocks.block(self.likelihood_kernel, particles.shape[0], inputs, per_particle=(6, 10))

    def moving(self, motion):
        """A launch that moves each particle by ``motion`` (kernels/motion.py) and weighs it in one kernel: a function
        (particles, step, seed, T_base_laser, angles, measured, log_weights) -> None, the same particles and weights
        as ``motion.launch`` then this call, one launch fewer (a GPU filter's step: ParticleFilter._move_and_observe).
        One block of all the particles: the motion's random numbers are those of its own launch (index = particle)."""
        kernel = make_table_likelihood_kernel(self.sigma_m, motion.move)

        def launch(particles, step, seed, T_base_laser, angles, measured, log_weights) -> None:
            self._check(angles, measured)
            inputs = self._args(particles, T_base_laser, angles) + [measured, log_weights, step, seed]
            wp.launch(kernel, particles.shape[0], inputs, device=self.device)

        return launch


def table_headings(num_angles: int) -> np.ndarray:
    """The table's headings: 2 pi k / num_angles, k = 0 .. num_angles - 1 (float32, as the kernels read them)."""
    return (2.0 * np.pi * np.arange(num_angles) / num_angles).astype(np.float32)


@WEIGHTING.register("nog_table")
def make_nog_table(**settings) -> NogTable:
    return NogTable(**settings)
