"""Numpy twins of kernels/kld.py: the bins a particle set occupies, and KLD-sampling's count from the chi-square
quantile itself (scipy), which the kernels' Wilson-Hilferty formula approximates."""

from __future__ import annotations

import numpy as np


def occupied_bins(particles, bounds, cell_m: float = 0.5, yaw_deg: float = 10.0) -> int:
    """The distinct (x, y, yaw) cells of ``particles`` [n, 3] on a histogram over ``bounds`` (xmin, ymin, xmax,
    ymax): positions clamped into the edge cells, yaw wrapped into [-pi, pi)."""
    p = np.asarray(particles, np.float64)
    xmin, ymin, xmax, ymax = map(float, bounds)
    nx, ny = int(np.floor((xmax - xmin) / cell_m)) + 1, int(np.floor((ymax - ymin) / cell_m)) + 1
    nyaw = int(np.ceil(360.0 / yaw_deg))
    ix = np.clip(np.floor((p[:, 0] - xmin) / cell_m), 0, nx - 1).astype(np.int64)
    iy = np.clip(np.floor((p[:, 1] - ymin) / cell_m), 0, ny - 1).astype(np.int64)
    a = np.arctan2(np.sin(p[:, 2]), np.cos(p[:, 2])) + np.pi
    ia = np.clip(np.floor(a / (2 * np.pi / nyaw)), 0, nyaw - 1).astype(np.int64)
    return len(np.unique((ia * ny + iy) * nx + ix))


def kld_count_exact(k: int, err: float, delta_quantile: float) -> float:
    """chi2_{k-1}(quantile) / (2 err): the count KLD-sampling's formula approximates (Fox 2003, eq. 12)."""
    from scipy.stats import chi2

    return float(chi2.ppf(delta_quantile, k - 1) / (2.0 * err)) if k > 1 else 1.0
