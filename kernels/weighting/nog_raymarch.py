"""``WEIGHTING["nog_raymarch"]``: IR-MCL's observation model on the NOG (the default).

For every particle and beam (one thread each), march ``num_samples`` fixed depths over [near, far] from the
particle's laser pose, read the nearest NOG node (occupancy 0 outside the grid), and composite as in training
(kernels/render.py, normalised weights) into the rendered ranges [P, B]. A second kernel, one thread per
particle, adds |r_rendered - r_measured| over the valid beams in beam order (the same bits on every device and
run) and turns the sum into (IR-MCL eq. 6)

    D = mean over valid beams of |r_rendered - r_measured|,   log w = -0.5 * D^2 / sigma^2

Two exact shortcuts, both off with their setting at 0 (the authors' formulation):
* ``t_min``: stop once the transmittance is below t_min (early termination);
* ``empty_below``: nodes with p_occ < empty_below read as 0 ("empty"), and the march jumps over empty
  space: a sample in an empty node whose centre lies D from the nearest non-empty node centre skips every
  sample closer than D - res * sqrt(2) (no point that near can round to a non-empty node).
Samples outside the grid are skipped by clipping the march to the grid's extent (slab test).
Numpy twin: irmcl_warp/reference/weighting.py (all samples, the same "empty" rule).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.raycast import distance_to_occupied
from irmcl_warp.kernels.registry import WEIGHTING, pick_device
from irmcl_warp.kernels.weighting.common import beam_direction, beam_origin, make_likelihood_kernel, nearest_node, slab


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
