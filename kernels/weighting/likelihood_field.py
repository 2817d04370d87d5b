"""``WEIGHTING["likelihood_field"]``: the likelihood-field model on an occupancy grid (Thrun et al.
Table 6.3; AMCL's default), the grid baseline IR-MCL is compared with.
"""

from __future__ import annotations

import weakref

import numpy as np
import warp as wp

from irmcl_warp.kernels.raycast import distance_to_occupied
from irmcl_warp.kernels.registry import WEIGHTING
from irmcl_warp.kernels.weighting.common import GridModel, beam_origin


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


@wp.func
def field_log_weight(
    log_q: wp.array2d(dtype=wp.float32),
    origin: wp.vec2,
    res: float,
    pose: wp.vec3,
    T_base_laser: wp.vec3,
    beam_cs: wp.array(dtype=wp.vec2),
    measured: wp.array(dtype=wp.float32),
) -> float:
    """log w of one particle: the sum over valid beams of log q at the end point's cell (``log_q``: the map's cells,
    then one more row whose first entry is log q at the capped distance, for end points off the map). A beam's
    direction is its precomputed (cos, sin) in the laser frame (``beam_cs``) turned by the laser's heading: one
    cosine and one sine per particle instead of per beam."""
    o = beam_origin(pose, T_base_laser)  # once per particle, not per beam
    heading = pose[2] + T_base_laser[2]
    c = wp.cos(heading)
    s_ = wp.sin(heading)
    H = log_q.shape[0] - 1
    off_map = log_q[H, 0]
    s = float(0.0)
    for b in range(beam_cs.shape[0]):
        m = measured[b]
        if m == m:  # NaN: invalid beam
            cs = beam_cs[b]
            ex = o[0] + m * (c * cs[0] - s_ * cs[1])
            ey = o[1] + m * (s_ * cs[0] + c * cs[1])
            ix = int(wp.floor((ex - origin[0]) / res))
            iy = int(wp.floor((ey - origin[1]) / res))
            if ix >= 0 and iy >= 0 and ix < log_q.shape[1] and iy < H:
                s += log_q[iy, ix]
            else:
                s += off_map
    return s


@wp.kernel
def likelihood_field_kernel(
    log_q: wp.array2d(dtype=wp.float32),
    origin: wp.vec2,
    res: float,
    particles: wp.array(dtype=wp.vec3),
    T_base_laser: wp.vec3,
    beam_cs: wp.array(dtype=wp.vec2),
    measured: wp.array(dtype=wp.float32),
    log_lik: wp.array(dtype=wp.float32),
):
    """``field_log_weight`` of each particle, a thread per particle."""
    p = wp.tid()
    log_lik[p] = field_log_weight(log_q, origin, res, particles[p], T_base_laser, beam_cs, measured)


def make_move_field_kernel(move):
    """``likelihood_field_kernel`` after moving each particle by ``move`` (a motion model's per-particle function,
    kernels/motion.py ``Motion.move``) and writing it back: one launch and one pass over the particles fewer."""

    @wp.kernel(module="unique")
    def move_and_weigh(
        log_q: wp.array2d(dtype=wp.float32),
        origin: wp.vec2,
        res: float,
        particles: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        beam_cs: wp.array(dtype=wp.vec2),
        measured: wp.array(dtype=wp.float32),
        log_lik: wp.array(dtype=wp.float32),
        step: wp.array(dtype=wp.float32),
        seed: wp.array(dtype=wp.int32),
    ):
        p = wp.tid()
        moved = move(particles[p], step, seed, p)
        particles[p] = moved
        log_lik[p] = field_log_weight(log_q, origin, res, moved, T_base_laser, beam_cs, measured)

    return move_and_weigh


class LikelihoodField(GridModel):
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
        cpu_threads: int | None = None,
        device: str = "auto",
    ):
        occupancy = self._setup(occupancy, origin_xy, resolution_m, occ_threshold, device, cpu_threads)
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
        self.kernel = likelihood_field_kernel

    def moving(self, motion):
        """A launch that moves each particle by ``motion`` (kernels/motion.py) and weighs it in one kernel: a function
        (particles, step, seed, T_base_laser, angles, measured, log_lik) -> None, the same particles and weights as
        ``motion.launch`` then this call, one launch fewer (a GPU filter's step: ParticleFilter._move_and_observe).
        One block of all the particles: the motion's random numbers are those of its own launch (index = particle)."""
        kernel = make_move_field_kernel(motion.move)

        def launch(particles, step, seed, T_base_laser, angles, measured, log_lik) -> None:
            T = wp.vec3(*map(float, T_base_laser))
            inputs = [self.grid, self.origin, self.res, particles, T, self.beams(angles), measured, log_lik, step, seed]
            wp.launch(kernel, particles.shape[0], inputs, device=self.device)

        return launch

    def beams(self, angles: wp.array) -> wp.array:
        """The beams' (cos, sin) in the laser frame, computed on the device once per angles array and shared by
        every field built later (a filter rebuilds its weighting when it reduces its particles, and may then be
        capturing a graph, where neither a copy to the host nor an allocation may happen)."""
        kept = _BEAM_CS.get(id(angles))
        if kept is None or kept[0]() is not angles:
            cs = wp.empty(angles.shape[0], dtype=wp.vec2, device=angles.device)
            wp.launch(beam_cos_sin, angles.shape[0], [angles, cs], device=angles.device)
            for key in [k for k, (ref, _) in _BEAM_CS.items() if ref() is None]:
                del _BEAM_CS[key]  # (arrays gone since)
            kept = _BEAM_CS[id(angles)] = (weakref.ref(angles), cs)
        return kept[1]


_BEAM_CS: dict = {}  # id(angles array) -> (a weak reference to it, its beams' (cos, sin))


@wp.kernel
def beam_cos_sin(angles: wp.array(dtype=wp.float32), out: wp.array(dtype=wp.vec2)):
    """(cos a, sin a) of each beam angle, in float64 and then rounded."""
    b = wp.tid()
    a = wp.float64(angles[b])
    out[b] = wp.vec2(wp.float32(wp.cos(a)), wp.float32(wp.sin(a)))


@WEIGHTING.register("likelihood_field")
def make_likelihood_field(**settings) -> LikelihoodField:
    return LikelihoodField(**settings)
