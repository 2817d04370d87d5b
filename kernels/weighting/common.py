"""What every observation model shares: the laser's pose and a beam's ray from a particle, the nearest
NOG node, the slab test that clips a march to the grid, IR-MCL's likelihood (eq. 6) from the summed range
errors, and ``GridModel``, the launch of the grid baselines (likelihood field, beam model).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import CPU_MIN_BLOCK, ParticleBlocks, pick_device


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


class GridModel:
    """Shared by the grid baselines: the grid on the device, its frame, and one launch, a thread per
    particle adding its valid beams' log q in beam order into ``log_lik`` (no atomics: the same bits on
    every run). On the CPU the particles are split into a block per core (``cpu_threads``, default: the
    process's cores; ``ParticleBlocks``, from 2 x ``CPU_MIN_BLOCK`` particles), which changes no bit."""

    name = "grid model"
    capturable = True  # launches only: a filter step may capture it in a graph (captured, it is one launch)

    def _setup(self, occupancy, origin_xy, resolution_m, occ_threshold, device, cpu_threads=None):
        occupancy = np.asarray(occupancy, np.float32)
        if occupancy.ndim != 2 or occupancy.size == 0 or not (occupancy >= occ_threshold).any():
            raise ValueError(f"{self.name}: the map is empty (shape {occupancy.shape}, no occupied cell)")
        self.device = pick_device(device)
        self.origin, self.res = wp.vec2(*map(float, origin_xy)), float(resolution_m)
        # on the CPU a block per core from 2 x CPU_MIN_BLOCK particles (kernels/registry.py says why)
        self.blocks = ParticleBlocks(self.device, cpu_threads, min_block=CPU_MIN_BLOCK)
        return occupancy

    def beams(self, angles: wp.array) -> wp.array:
        """What the kernel reads per beam: the angles (the likelihood field reads their cosines and sines)."""
        return angles

    def __call__(self, particles, T_base_laser, angles, measured, log_lik) -> None:
        self.blocks.run(self.block(particles, T_base_laser, angles, measured, log_lik), particles.shape[0])

    def block(self, particles, T_base_laser, angles, measured, log_lik):
        """The call for one block of particles: a function (p0, p1) -> None (``ParticleBlocks.block``)."""
        T = wp.vec3(*map(float, T_base_laser))
        inputs = [self.grid, self.origin, self.res, particles, T, self.beams(angles), measured, log_lik]
        return self.blocks.block(self.kernel, particles.shape[0], inputs, per_particle=(3, 7))
