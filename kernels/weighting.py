"""Particle weighting for MCL: ``WEIGHTING["nog_raymarch"]`` (IR-MCL's observation model on the NOG).

For every particle and beam (one thread each), march ``num_samples`` fixed depths over [near, far] from
the particle's laser pose, read the nearest NOG node (occupancy 0 outside the grid), and composite as in
training (kernels/render.py, normalised weights); optionally stop once the transmittance is below
``t_min`` (early termination). A second kernel reduces per particle (IR-MCL eq. 6):

    D = mean over valid beams of |r_rendered - r_measured|,   log w = -0.5 * D^2 / sigma^2

Numpy twin: irmcl_warp/reference/weighting.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from kernels import WEIGHTING, pick_device


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
    return wp.vec3(base[0] + c * T_base_laser[0] - s * T_base_laser[1],
                   base[1] + s * T_base_laser[0] + c * T_base_laser[1], base[2] + T_base_laser[2])


@wp.func
def beam_origin(particle: wp.vec3, T_base_laser: wp.vec3) -> wp.vec2:
    pose = laser_pose(particle, T_base_laser)
    return wp.vec2(pose[0], pose[1])


@wp.func
def beam_direction(particle: wp.vec3, T_base_laser: wp.vec3, angle: float) -> wp.vec2:
    """Unit direction in the map frame of the beam at ``angle`` in the laser frame."""
    a = particle[2] + T_base_laser[2] + angle
    return wp.vec2(wp.cos(a), wp.sin(a))


def make_kernels(num_samples: int, near: float, far: float, t_min: float, sigma: float, eps: float = 1e-10):
    step = (far - near) / float(num_samples - 1)

    @wp.kernel(module="unique")
    def render(grid: wp.array2d(dtype=wp.float32), origin: wp.vec2, res: float, particles: wp.array(dtype=wp.vec3),
               T_base_laser: wp.vec3, angles: wp.array(dtype=wp.float32), out: wp.array2d(dtype=wp.float32)):
        p, b = wp.tid()
        o = beam_origin(particles[p], T_base_laser)
        d = beam_direction(particles[p], T_base_laser, angles[b])
        T = float(1.0)
        A = float(0.0)
        W = float(0.0)
        for k in range(wp.static(num_samples)):
            if T < wp.static(t_min):
                break
            z = wp.static(near) + wp.static(step) * float(k)
            occ = nearest_node(grid, origin, res, o[0] + z * d[0], o[1] + z * d[1])
            w = occ * T
            A += w * z
            W += w
            T *= 1.0 - occ
        out[p, b] = A / (W + wp.static(eps))

    @wp.kernel(module="unique")
    def likelihood(rendered: wp.array2d(dtype=wp.float32), measured: wp.array(dtype=wp.float32),
                   log_weights: wp.array(dtype=wp.float32)):
        p = wp.tid()
        total = float(0.0)
        n = float(0.0)
        for b in range(measured.shape[0]):
            m = measured[b]
            if m == m:  # NaN: invalid beam
                total += wp.abs(rendered[p, b] - m)
                n += 1.0
        D = total / wp.max(n, 1.0)
        log_weights[p] = -0.5 * D * D / wp.static(sigma * sigma)

    return render, likelihood


class NogRaymarch:
    """Holds the NOG on the device and a [P, B] scratch array; ``__call__`` only launches."""

    def __init__(self, nog, num_particles: int, num_beams: int, num_samples: int = 256, near_m: float = 0.02,
                 far_m: float = 40.0, t_min: float = 0.0, sigma_m: float = 0.5, device: str = "auto"):
        if nog.occupancy.size == 0 or nog.occupancy.ndim != 2:
            raise ValueError(f"nog_raymarch: the NOG is empty (shape {nog.occupancy.shape})")
        self.device = pick_device(device)
        self.grid = wp.array(np.asarray(nog.occupancy, np.float32), dtype=wp.float32, device=self.device)
        self.origin, self.res = wp.vec2(*map(float, nog.origin_xy)), float(nog.resolution_m)
        self.num_beams = num_beams
        self.rendered = wp.zeros((num_particles, num_beams), dtype=wp.float32, device=self.device)
        self.render_kernel, self.likelihood_kernel = make_kernels(num_samples, near_m, far_m, t_min, sigma_m)

    def render(self, particles: wp.array, T_base_laser, angles: wp.array) -> wp.array:
        wp.launch(self.render_kernel, (particles.shape[0], angles.shape[0]),
                  [self.grid, self.origin, self.res, particles, wp.vec3(*map(float, T_base_laser)), angles,
                   self.rendered], device=self.device)
        return self.rendered

    def __call__(self, particles: wp.array, T_base_laser, angles: wp.array, measured: wp.array,
                 log_weights: wp.array) -> None:
        if angles.shape[0] != self.num_beams or measured.shape[0] != self.num_beams:
            raise ValueError(f"nog_raymarch: {measured.shape[0]} measured ranges / {angles.shape[0]} angles, "
                             f"built for {self.num_beams} beams")
        self.render(particles, T_base_laser, angles)
        wp.launch(self.likelihood_kernel, particles.shape[0], [self.rendered, measured, log_weights], device=self.device)


@WEIGHTING.register("nog_raymarch")
def make_nog_raymarch(**settings) -> NogRaymarch:
    return NogRaymarch(**settings)


def make_likelihood_field_kernel(z_hit: float, z_rand: float, sigma_hit: float, max_range: float, max_dist: float):
    @wp.kernel(module="unique")
    def field(dist: wp.array2d(dtype=wp.float32), origin: wp.vec2, res: float, particles: wp.array(dtype=wp.vec3),
              T_base_laser: wp.vec3, angles: wp.array(dtype=wp.float32), measured: wp.array(dtype=wp.float32),
              log_lik: wp.array(dtype=wp.float32)):
        p, b = wp.tid()
        m = measured[b]
        if not (m == m):
            return
        end = beam_origin(particles[p], T_base_laser) + m * beam_direction(particles[p], T_base_laser, angles[b])
        ix = int(wp.floor((end[0] - origin[0]) / res))
        iy = int(wp.floor((end[1] - origin[1]) / res))
        d = wp.static(max_dist)
        if ix >= 0 and iy >= 0 and ix < dist.shape[1] and iy < dist.shape[0]:
            d = wp.min(dist[iy, ix], wp.static(max_dist))
        q = wp.static(z_hit) * wp.exp(-d * d / wp.static(2.0 * sigma_hit * sigma_hit)) + wp.static(z_rand / max_range)
        wp.atomic_add(log_lik, p, wp.log(q))

    return field


class _GridModel:
    """Shared by the grid baselines: the grid on the device, its frame, and one (particle x beam) launch
    that adds each valid beam's log q into ``log_lik``."""

    name = "grid model"

    def _setup(self, occupancy, origin_xy, resolution_m, occ_threshold, device):
        occupancy = np.asarray(occupancy, np.float32)
        if occupancy.ndim != 2 or occupancy.size == 0 or not (occupancy >= occ_threshold).any():
            raise ValueError(f"{self.name}: the map is empty (shape {occupancy.shape}, no occupied cell)")
        self.device = pick_device(device)
        self.origin, self.res = wp.vec2(*map(float, origin_xy)), float(resolution_m)
        return occupancy

    def __call__(self, particles, T_base_laser, angles, measured, log_lik) -> None:
        log_lik.zero_()
        wp.launch(self.kernel, (particles.shape[0], angles.shape[0]),
                  [self.grid, self.origin, self.res, particles, wp.vec3(*map(float, T_base_laser)), angles, measured,
                   log_lik], device=self.device)


class LikelihoodField(_GridModel):
    """The likelihood-field model (Thrun et al. Table 6.3; AMCL's default): each beam's end point scores by
    its distance d to the nearest occupied cell, q = z_hit N(d; 0, sigma_hit) + z_rand / max_range (the
    Gaussian unnormalised, as AMCL), d capped at ``max_dist_m``; log w = sum over valid beams of log q.
    End points off the map count as ``max_dist_m`` away. One thread per (particle, beam), atomic sums."""

    name = "likelihood_field"

    def __init__(self, occupancy, origin_xy, resolution_m: float, z_hit: float = 0.95, z_rand: float = 0.05,
                 sigma_hit_m: float = 0.2, max_range_m: float = 30.0, max_dist_m: float = 2.0,
                 occ_threshold: float = 0.65, device: str = "auto"):
        from kernels.raycast import distance_to_occupied

        occupancy = self._setup(occupancy, origin_xy, resolution_m, occ_threshold, device)
        self.grid = wp.array(distance_to_occupied(occupancy, resolution_m, occ_threshold), dtype=wp.float32,
                             device=self.device)
        self.kernel = make_likelihood_field_kernel(z_hit, z_rand, sigma_hit_m, max_range_m, max_dist_m)


@WEIGHTING.register("likelihood_field")
def make_likelihood_field(**settings) -> LikelihoodField:
    return LikelihoodField(**settings)


def make_beam_model_kernel(z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short, max_range, occ_threshold):
    from kernels.raycast import dda_range

    @wp.kernel(module="unique")
    def beam(occ: wp.array2d(dtype=wp.float32), origin: wp.vec2, res: float, particles: wp.array(dtype=wp.vec3),
             T_base_laser: wp.vec3, angles: wp.array(dtype=wp.float32), measured: wp.array(dtype=wp.float32),
             log_lik: wp.array(dtype=wp.float32)):
        p, b = wp.tid()
        z = measured[b]
        if not (z == z):
            return
        expected = dda_range(occ, origin, res, beam_origin(particles[p], T_base_laser),
                             beam_direction(particles[p], T_base_laser, angles[b]),
                             wp.static(max_range), wp.static(occ_threshold))
        e = z - expected
        q = wp.static(z_hit) * wp.exp(-e * e / wp.static(2.0 * sigma_hit * sigma_hit))
        if z < expected:
            q += wp.static(z_short) * wp.static(lambda_short) * wp.exp(-wp.static(lambda_short) * z)
        if z >= wp.static(max_range):
            q += wp.static(z_max)
        else:
            q += wp.static(z_rand / max_range)
        wp.atomic_add(log_lik, p, wp.log(q))

    return beam


class BeamModel(_GridModel):
    """The beam model (Thrun et al. Table 6.1, as AMCL's ``beam`` model): ray cast the expected range on
    the grid (DDA), then q = z_hit exp(-(z - z*)^2 / 2 sigma^2) + z_short lambda exp(-lambda z) [z < z*]
    + z_max [z >= max] + z_rand / max [z < max]; log w = sum over valid beams of log q."""

    name = "beam_model"

    def __init__(self, occupancy, origin_xy, resolution_m: float, z_hit: float = 0.95, z_short: float = 0.1,
                 z_max: float = 0.05, z_rand: float = 0.05, sigma_hit_m: float = 0.2, lambda_short: float = 0.1,
                 max_range_m: float = 30.0, occ_threshold: float = 0.5, device: str = "auto"):
        occupancy = self._setup(occupancy, origin_xy, resolution_m, occ_threshold, device)
        self.grid = wp.array(occupancy, dtype=wp.float32, device=self.device)
        self.kernel = make_beam_model_kernel(z_hit, z_short, z_max, z_rand, sigma_hit_m, lambda_short, max_range_m,
                                             occ_threshold)


@WEIGHTING.register("beam_model")
def make_beam_model(**settings) -> BeamModel:
    return BeamModel(**settings)
