"""Numpy twins of kernels/estimate.py: IR-MCL's weighted mean of the top share of particles by weight, and the
weighted mean of the heaviest cluster."""

from __future__ import annotations

import numpy as np


def top_share_mean(particles, log_w, share: float = 0.8) -> np.ndarray:
    k = max(1, int(np.ceil(share * len(log_w))))
    idx = np.argsort(-np.asarray(log_w), kind="stable")[:k]
    w = np.exp(np.asarray(log_w, np.float64)[idx] - np.max(log_w))
    p = np.asarray(particles, np.float64)[idx]
    return np.array(
        [w @ p[:, 0] / w.sum(), w @ p[:, 1] / w.sum(), np.arctan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))]
    )


def heavy_first_keys(log_w) -> np.ndarray:
    """Twin of kernels/estimate.py ``heavy_first``: uint32 keys whose ascending order is log w's descending order
    (-0 as +0)."""
    x = np.asarray(log_w, np.float32) + np.float32(0.0)  # -0 + 0 = +0
    bits = x.view(np.uint32)
    return np.where(bits >> 31, bits, bits ^ np.uint32(0x7FFFFFFF)).astype(np.uint32)


def best_cluster_mean(particles, log_w, bounds, cell_m: float = 0.5, yaw_bins: int = 8) -> np.ndarray:
    """Bin the weights on an (x, y, yaw) histogram, take the bin whose 3x3x3 neighbourhood (yaw wraps) is
    heaviest, and average the particles within 1.5 cells / 1.5 yaw bins of its centre."""
    p = np.asarray(particles, np.float64)
    w = np.exp(np.asarray(log_w, np.float64) - np.max(log_w))
    xmin, ymin, xmax, ymax = bounds
    nx, ny = int(np.ceil((xmax - xmin) / cell_m)) + 1, int(np.ceil((ymax - ymin) / cell_m)) + 1
    ix = np.clip(np.floor((p[:, 0] - xmin) / cell_m).astype(int), 0, nx - 1)
    iy = np.clip(np.floor((p[:, 1] - ymin) / cell_m).astype(int), 0, ny - 1)
    yaw = np.arctan2(np.sin(p[:, 2]), np.cos(p[:, 2])) + np.pi
    ia = np.clip((yaw / (2 * np.pi / yaw_bins)).astype(int), 0, yaw_bins - 1)
    hist = np.zeros((yaw_bins, ny, nx))
    np.add.at(hist, (ia, iy, ix), w)
    padded = np.pad(hist, ((1, 1), (0, 0), (0, 0)), mode="wrap")
    padded = np.pad(padded, ((0, 0), (1, 1), (1, 1)))
    smooth = sum(padded[a : a + yaw_bins, b : b + ny, c : c + nx] for a in range(3) for b in range(3) for c in range(3))
    ba, by, bx = np.unravel_index(np.argmax(smooth), hist.shape)
    bin_yaw = 2 * np.pi / yaw_bins
    cx, cy, ca = xmin + (bx + 0.5) * cell_m, ymin + (by + 0.5) * cell_m, -np.pi + (ba + 0.5) * bin_yaw
    da = np.arctan2(np.sin(p[:, 2] - ca), np.cos(p[:, 2] - ca))
    near = (np.hypot(p[:, 0] - cx, p[:, 1] - cy) <= 1.5 * cell_m) & (np.abs(da) <= 1.5 * bin_yaw)
    wn, pn = w[near], p[near]
    return np.array(
        [wn @ pn[:, 0] / wn.sum(), wn @ pn[:, 1] / wn.sum(), np.arctan2(wn @ np.sin(pn[:, 2]), wn @ np.cos(pn[:, 2]))]
    )
