"""Numpy twin of kernels/motion.py (Thrun's sample_motion_model_odometry), with numpy's generator."""

from __future__ import annotations

import numpy as np


def sample_odometry(particles, step, alphas, rng):
    a1, a2, a3, a4 = alphas
    r1, t, r2 = step
    n = len(particles)
    r1h = r1 - np.sqrt(a1 * r1 ** 2 + a2 * t ** 2) * rng.standard_normal(n)
    th = t - np.sqrt(a3 * t ** 2 + a4 * (r1 ** 2 + r2 ** 2)) * rng.standard_normal(n)
    r2h = r2 - np.sqrt(a1 * r2 ** 2 + a2 * t ** 2) * rng.standard_normal(n)
    x, y, yaw = particles.T
    out = np.stack([x + th * np.cos(yaw + r1h), y + th * np.sin(yaw + r1h), yaw + r1h + r2h], -1)
    out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
    return out
