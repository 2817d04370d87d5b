"""Numpy twins of kernels/motion.py (Thrun's sample_motion_model_odometry; IR-MCL's code's model), with numpy's
generator."""

from __future__ import annotations

import numpy as np


def sample_odometry(particles, step, alphas, rng):
    a1, a2, a3, a4 = alphas
    r1, t, r2 = step
    n = len(particles)
    r1h = r1 - np.sqrt(a1 * r1**2 + a2 * t**2) * rng.standard_normal(n)
    th = t - np.sqrt(a3 * t**2 + a4 * (r1**2 + r2**2)) * rng.standard_normal(n)
    r2h = r2 - np.sqrt(a1 * r2**2 + a2 * t**2) * rng.standard_normal(n)
    x, y, yaw = particles.T
    out = np.stack([x + th * np.cos(yaw + r1h), y + th * np.sin(yaw + r1h), yaw + r1h + r2h], -1)
    out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
    return out


def sample_irmcl(particles, step, noise, rng):
    """IR-MCL's code: u = (dx, dy, dtheta) in the robot frame, u + N(0, diag(C |u|)), composed onto each pose."""
    r1, t, r2 = step
    u = np.array([t * np.cos(r1), t * np.sin(r1), r1 + r2])
    std = np.sqrt(np.asarray(noise, float).reshape(3, 3) @ np.abs(u))
    n = len(particles)
    du = u + std * rng.standard_normal((n, 3))
    x, y, yaw = np.asarray(particles, float).T
    out = np.stack(
        [
            x + np.cos(yaw) * du[:, 0] - np.sin(yaw) * du[:, 1],
            y + np.sin(yaw) * du[:, 0] + np.cos(yaw) * du[:, 1],
            yaw + du[:, 2],
        ],
        -1,
    )
    out[:, 2] = np.arctan2(np.sin(out[:, 2]), np.cos(out[:, 2]))
    return out
