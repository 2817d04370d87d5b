"""Pose estimates from a weighted particle set: ``ESTIMATE["top_share"]``, IR-MCL's estimate (the weighted
mean of the particles with the highest weights, 80 % of them; circular mean for yaw). The particles are
ranked by Warp's radix sort of their log-weights; the sums are atomic adds over the first K ranks.
(The plain weighted mean of all particles comes with ``ParticleWeights`` in kernels/resample.py.)
Numpy twin: irmcl_warp/reference/estimate.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from kernels import ESTIMATE, pick_device


@wp.kernel
def rank_keys_kernel(log_w: wp.array(dtype=wp.float32), keys: wp.array(dtype=wp.float32),
                     values: wp.array(dtype=wp.int32)):
    i = wp.tid()
    keys[i] = -log_w[i]  # ascending sort: the heaviest particle first
    values[i] = i


@wp.kernel
def top_sums_kernel(order: wp.array(dtype=wp.int32), sorted_keys: wp.array(dtype=wp.float32),
                    log_w: wp.array(dtype=wp.float32), particles: wp.array(dtype=wp.vec3), sums: wp.array(dtype=wp.float32)):
    r = wp.tid()
    j = order[r]
    w = wp.exp(log_w[j] + sorted_keys[0])  # sorted_keys[0] = -(largest log-weight): a stable exp
    p = particles[j]
    wp.atomic_add(sums, 0, w)
    wp.atomic_add(sums, 1, w * p[0])
    wp.atomic_add(sums, 2, w * p[1])
    wp.atomic_add(sums, 3, w * wp.cos(p[2]))
    wp.atomic_add(sums, 4, w * wp.sin(p[2]))


class TopShareMean:
    def __init__(self, num_particles: int, share: float = 0.8, device: str = "auto"):
        if not 0.0 < share <= 1.0:
            raise ValueError(f"top_share: share must lie in (0, 1], got {share}")
        self.device, self.n = pick_device(device), num_particles
        self.k = max(1, int(np.ceil(share * num_particles)))
        self.keys = wp.zeros(2 * num_particles, dtype=wp.float32, device=self.device)  # radix sort needs 2N
        self.values = wp.zeros(2 * num_particles, dtype=wp.int32, device=self.device)
        self.sums = wp.zeros(5, dtype=wp.float32, device=self.device)

    def __call__(self, particles: wp.array, log_w: wp.array) -> np.ndarray:
        """[x, y, yaw] from the top ``share`` of the particles by weight."""
        wp.launch(rank_keys_kernel, self.n, [log_w, self.keys, self.values], device=self.device)
        wp.utils.radix_sort_pairs(self.keys, self.values, self.n)
        self.sums.zero_()
        wp.launch(top_sums_kernel, self.k, [self.values, self.keys, log_w, particles, self.sums], device=self.device)
        s = self.sums.numpy().astype(np.float64)
        return np.array([s[1] / s[0], s[2] / s[0], np.arctan2(s[4], s[3])])


@ESTIMATE.register("top_share")
def make_top_share(**settings) -> TopShareMean:
    return TopShareMean(**settings)
