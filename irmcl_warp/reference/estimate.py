"""Numpy twin of kernels/estimate.py: IR-MCL's weighted mean of the top share of particles by weight."""

from __future__ import annotations

import numpy as np


def top_share_mean(particles, log_w, share: float = 0.8) -> np.ndarray:
    k = max(1, int(np.ceil(share * len(log_w))))
    idx = np.argsort(-np.asarray(log_w), kind="stable")[:k]
    w = np.exp(np.asarray(log_w, np.float64)[idx] - np.max(log_w))
    p = np.asarray(particles, np.float64)[idx]
    return np.array([w @ p[:, 0] / w.sum(), w @ p[:, 1] / w.sum(), np.arctan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))])
