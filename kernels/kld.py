"""KLD-sampling's count (Fox, "Adapting the sample size in particle filters through KLD-sampling", IJRR 2003; the
adaptive particle count of ROS AMCL): how many particles keep the error of the sample-based posterior, measured by
the Kullback-Leibler distance, below ``err`` with probability given by the normal quantile ``z``, when the particles
occupy ``k`` bins of a coarse (x, y, yaw) histogram:

    n = (k - 1) / (2 err) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z) ^ 3

(the Wilson-Hilferty approximation of the chi-square quantile with k - 1 degrees of freedom, over 2 err).

``OccupiedBins`` counts the bins a particle set occupies on the device: a kernel marks each particle's bin (an atomic
max on a mark per bin; the particle that finds its bin unmarked adds one to the count), a second clears the marks
the particles set, so the next count starts from zero without touching the whole histogram. The bins are AMCL's
kd-tree cells (0.5 m, 0.5 m, 10 deg by default) over the map's bounds, found as best_cluster's histogram finds them
(``pose_bin``, kernels/estimate.py). Numpy twins: irmcl_warp/reference/kld.py.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from irmcl_warp.kernels.estimate import pose_bin
from irmcl_warp.kernels.registry import pick_device


def kld_count(k: int, err: float, z: float) -> int:
    """The particles KLD-sampling asks for when they occupy ``k`` bins (Fox 2003, eq. 13): 1 for k <= 1."""
    if err <= 0:
        raise ValueError(f"KLD-sampling: err={err} must be > 0")
    if k <= 1:
        return 1
    a = 2.0 / (9.0 * (k - 1))
    return int(math.ceil((k - 1) / (2.0 * err) * (1.0 - a + math.sqrt(a) * z) ** 3))


@wp.kernel
def mark_bins_kernel(
    particles: wp.array(dtype=wp.vec3),
    lo: wp.vec2,
    cell: float,
    nx: int,
    ny: int,
    nyaw: int,
    marks: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    b = pose_bin(particles[i], lo, cell, nx, ny, nyaw)
    if wp.atomic_max(marks, b, 1) == 0:  # the first particle in this bin
        wp.atomic_add(count, 0, 1)


@wp.kernel
def clear_bins_kernel(
    particles: wp.array(dtype=wp.vec3),
    lo: wp.vec2,
    cell: float,
    nx: int,
    ny: int,
    nyaw: int,
    marks: wp.array(dtype=wp.int32),
):
    i = wp.tid()
    marks[pose_bin(particles[i], lo, cell, nx, ny, nyaw)] = 0


class OccupiedBins:
    """``OccupiedBins(bounds, cell_m, yaw_deg)(particles) -> k``: the bins of the (x, y, yaw) histogram over
    ``bounds`` = (xmin, ymin, xmax, ymax) that the particles occupy (one read-back of one integer)."""

    def __init__(self, bounds, cell_m: float = 0.5, yaw_deg: float = 10.0, device: str = "auto"):
        xmin, ymin, xmax, ymax = map(float, bounds)
        if not (xmax > xmin and ymax > ymin and cell_m > 0 and 0 < yaw_deg <= 360):
            raise ValueError(f"KLD-sampling: bounds {bounds}, cell {cell_m} m, {yaw_deg} deg do not make a histogram")
        self.device = pick_device(device)
        self.lo, self.cell = wp.vec2(xmin, ymin), float(cell_m)
        self.nyaw = int(math.ceil(360.0 / yaw_deg))
        self.nx = int(math.floor((xmax - xmin) / cell_m)) + 1
        self.ny = int(math.floor((ymax - ymin) / cell_m)) + 1
        self.marks = wp.zeros(self.nyaw * self.ny * self.nx, dtype=wp.int32, device=self.device)
        self.count = wp.zeros(1, dtype=wp.int32, device=self.device)

    def shape(self) -> tuple[int, int, int]:
        """(yaw bins, y bins, x bins)."""
        return self.nyaw, self.ny, self.nx

    def __call__(self, particles: wp.array) -> int:
        n, d = particles.shape[0], self.device
        args = [particles, self.lo, self.cell, self.nx, self.ny, self.nyaw, self.marks]
        self.count.zero_()
        wp.launch(mark_bins_kernel, n, args + [self.count], device=d)
        k = int(self.count.numpy()[0])
        wp.launch(clear_bins_kernel, n, args, device=d)
        return k


def levels(most: int, least: int) -> np.ndarray:
    """The particle counts an adaptive filter moves between: ``most`` halved while at least ``least`` (and
    ``least`` itself), ascending. Few counts, so the arrays (and a step's captured graph) change seldom."""
    if not 1 <= least <= most:
        raise ValueError(f"KLD-sampling: min particles {least} must lie in [1, {most}]")
    out, n = {least, most}, most
    while n // 2 >= least:
        n //= 2
        out.add(n)
    return np.array(sorted(out))


def next_count(current: int, k: int, err: float, z: float, counts: np.ndarray, margin: float = 2.0) -> int:
    """The count for the next steps, from ``k`` occupied bins: grow to the smallest level that holds KLD's count
    at once; shrink only when the smallest level that holds ``margin`` x KLD's count lies below ``current`` (a
    count near a level's edge does not move the filter back and forth)."""
    need = kld_count(k, err, z)
    grow = counts[np.searchsorted(counts, min(need, counts[-1]))]
    if grow > current:
        return int(grow)
    shrink = counts[np.searchsorted(counts, min(margin * need, counts[-1]))]
    return int(shrink) if shrink < current else int(current)
