"""``WEIGHTING["beam_model"]``: the beam model on an occupancy grid (Thrun et al. Table 6.1, AMCL's
``beam``), ray cast with the DDA of kernels/raycast.py.
"""

from __future__ import annotations

import warp as wp

from irmcl_warp.kernels.raycast import dda_range
from irmcl_warp.kernels.registry import WEIGHTING
from irmcl_warp.kernels.weighting.common import GridModel, beam_direction, beam_origin


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


class BeamModel(GridModel):
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
        cpu_threads: int | None = None,
        device: str = "auto",
    ):
        occupancy = self._setup(occupancy, origin_xy, resolution_m, occ_threshold, device, cpu_threads)
        self.grid = wp.array(occupancy, dtype=wp.float32, device=self.device)
        self.kernel = make_beam_model_kernel(
            z_hit, z_short, z_max, z_rand, sigma_hit_m, lambda_short, far_m, occ_threshold
        )


@WEIGHTING.register("beam_model")
def make_beam_model(**settings) -> BeamModel:
    return BeamModel(**settings)
