"""SE(2) helpers on numpy arrays of poses ``[..., 3] = (x, y, yaw)``.

Naming follows ``T_a_b``: the pose of frame b expressed in frame a, so
``T_world_laser = compose(T_world_base, T_base_laser)``.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(a):
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def compose(T_a_b, T_b_c):
    """T_a_c = T_a_b * T_b_c, broadcasting over leading dimensions."""
    T_a_b = np.asarray(T_a_b, dtype=np.float64)
    T_b_c = np.asarray(T_b_c, dtype=np.float64)
    c, s = np.cos(T_a_b[..., 2]), np.sin(T_a_b[..., 2])
    x = T_a_b[..., 0] + c * T_b_c[..., 0] - s * T_b_c[..., 1]
    y = T_a_b[..., 1] + s * T_b_c[..., 0] + c * T_b_c[..., 1]
    return np.stack([x, y, wrap_angle(T_a_b[..., 2] + T_b_c[..., 2])], axis=-1)


def inverse(T_a_b):
    """T_b_a = T_a_b^-1."""
    T_a_b = np.asarray(T_a_b, dtype=np.float64)
    c, s = np.cos(T_a_b[..., 2]), np.sin(T_a_b[..., 2])
    x = -(c * T_a_b[..., 0] + s * T_a_b[..., 1])
    y = -(-s * T_a_b[..., 0] + c * T_a_b[..., 1])
    return np.stack([x, y, wrap_angle(-T_a_b[..., 2])], axis=-1)


def relative(T_w_i, T_w_j):
    """T_i_j = T_w_i^-1 * T_w_j: the motion from pose i to pose j, in frame i."""
    return compose(inverse(T_w_i), T_w_j)


def transform_points(T_a_b, points_b):
    """Map points ``[..., K, 2]`` in frame b into frame a; ``T_a_b`` is ``[..., 3]`` (one pose per point set)."""
    T = np.asarray(T_a_b, dtype=np.float64)[..., None, :]
    p = np.asarray(points_b, dtype=np.float64)
    c, s = np.cos(T[..., 2]), np.sin(T[..., 2])
    return np.stack([T[..., 0] + c * p[..., 0] - s * p[..., 1], T[..., 1] + s * p[..., 0] + c * p[..., 1]], -1)


def interpolate_poses(stamps_src, poses_src, stamps_query):
    """Linear interpolation of poses [M,3] given at increasing ``stamps_src`` at ``stamps_query``.

    Yaw is unwrapped before interpolating so a crossing of +-pi does not sweep through 0.
    Queries outside the source span are clamped to the end poses (and reported by the caller).
    """
    stamps_src = np.asarray(stamps_src, dtype=np.float64)
    if stamps_src.size == 0:
        raise ValueError("cannot interpolate poses: no source poses")
    if np.any(np.diff(stamps_src) < 0):
        raise ValueError("interpolate_poses needs non-decreasing source stamps")
    poses_src = np.asarray(poses_src, dtype=np.float64)
    yaw = np.unwrap(poses_src[:, 2])
    out = np.empty((len(stamps_query), 3))
    for k, col in enumerate((poses_src[:, 0], poses_src[:, 1], yaw)):
        out[:, k] = np.interp(stamps_query, stamps_src, col)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def align_rigid(est, ref):
    """T_ref_est [3]: the rigid 2D motion that best maps the positions of ``est`` [N, 3] onto ``ref`` [N, 3]
    in the least-squares sense (Horn / Umeyama without scale, as evo's --align), over rows where both are
    finite; ``compose(T_ref_est, est)`` then lies on ``ref``."""
    est, ref = np.asarray(est, np.float64), np.asarray(ref, np.float64)
    ok = np.all(np.isfinite(est), 1) & np.all(np.isfinite(ref), 1)
    if ok.sum() < 2:
        raise ValueError(f"rigid alignment needs two poses known in both trajectories, got {int(ok.sum())}")
    a, b = est[ok, :2], ref[ok, :2]
    ca, cb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((a - ca).T @ (b - cb))
    D = np.diag([1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    t = cb - R @ ca
    return np.array([t[0], t[1], np.arctan2(R[1, 0], R[0, 0])])
