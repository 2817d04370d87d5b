"""Numpy twins of kernels/resample.py: normalisation, N_eff, weighted mean, low-variance and multinomial draws."""

from __future__ import annotations

import numpy as np


def normalise(log_w):
    w = np.exp(np.asarray(log_w, np.float64) - np.max(log_w))
    return w / w.sum()


def effective_sample_size(log_w) -> float:
    return 1.0 / np.sum(normalise(log_w) ** 2)


def weighted_mean(particles, log_w):
    w = normalise(log_w)
    return np.array(
        [w @ particles[:, 0], w @ particles[:, 1], np.arctan2(w @ np.sin(particles[:, 2]), w @ np.cos(particles[:, 2]))]
    )


def weighted_spread(particles, log_w) -> float:
    """sqrt(var x + var y) of the weighted positions."""
    w = normalise(log_w)
    p = np.asarray(particles, np.float64)
    return float(np.sqrt(sum(w @ (p[:, i] - w @ p[:, i]) ** 2 for i in range(2))))


def low_variance_indices(log_w, offset: float) -> np.ndarray:
    """Thrun et al. Table 4.4: pointers (offset + i) / N into the cumulative weights."""
    cdf = np.cumsum(normalise(log_w))
    u = (offset + np.arange(len(cdf))) / len(cdf)
    return np.minimum(np.searchsorted(cdf, u, side="right"), len(cdf) - 1)


def multinomial_indices(log_w, rng) -> np.ndarray:
    cdf = np.cumsum(normalise(log_w))
    return np.minimum(np.searchsorted(cdf, rng.uniform(size=len(cdf)), side="right"), len(cdf) - 1)
