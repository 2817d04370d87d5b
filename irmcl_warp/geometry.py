"""SE(2) helpers on numpy arrays of poses ``[..., 3] = (x, y, yaw)``.

Naming follows ``T_a_b``: the pose of frame b expressed in frame a, so
``T_world_laser = compose(T_world_base, T_base_laser)``.
"""

from __future__ import annotations

import math

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


def wrap_angle_one(a: float) -> float:
    """wrap_angle of one Python float, with the same operations."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def relative_one(T_w_i, T_w_j) -> tuple[float, float, float]:
    """relative() of one pair of poses as Python floats: the same operations in the same order, without numpy's
    cost per call (about 30 us) where a filter steps through thousands of scans one at a time. Bit for bit
    the same as relative() wherever math.cos/sin give numpy's values (tests/test_geometry.py checks a log)."""
    px, py, pa = T_w_i
    x, y, a = T_w_j
    c, s = math.cos(pa), math.sin(pa)
    ix, iy, ia = -(c * px + s * py), -(-s * px + c * py), wrap_angle_one(-pa)
    c, s = math.cos(ia), math.sin(ia)
    return ix + c * x - s * y, iy + s * x + c * y, wrap_angle_one(ia + a)


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


def _v_terms(theta):
    """A = sin(t)/t, B = (1 - cos(t))/t of SE(2)'s left Jacobian V = [[A, -B], [B, A]] (series near 0)."""
    theta = np.asarray(theta, dtype=np.float64)
    small = np.abs(theta) < 1e-6
    t = np.where(small, 1.0, theta)
    A = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t) / t)
    B = np.where(small, theta / 2.0, (1.0 - np.cos(t)) / t)
    return A, B


def se2_log(T):
    """Twist (v_x, v_y, omega) [N, 3] of motions ``T`` [N, 3] with |yaw| < pi: T = exp(twist)."""
    T = np.atleast_2d(np.asarray(T, dtype=np.float64))
    A, B = _v_terms(T[:, 2])
    det = A * A + B * B
    vx = (A * T[:, 0] + B * T[:, 1]) / det
    vy = (-B * T[:, 0] + A * T[:, 1]) / det
    return np.column_stack([vx, vy, T[:, 2]])


def se2_exp(xi):
    """Motion [N, 3] of twists ``xi`` [N, 3] (inverse of :func:`se2_log`)."""
    xi = np.atleast_2d(np.asarray(xi, dtype=np.float64))
    A, B = _v_terms(xi[:, 2])
    return np.column_stack([A * xi[:, 0] - B * xi[:, 1], B * xi[:, 0] + A * xi[:, 1], wrap_angle(xi[:, 2])])


def interpolate_se2(stamps_src, poses_src, stamps_query, max_gap_s: float, tol_s: float = 1e-4):
    """Poses [Q, 3] at ``stamps_query`` on the SE(2) geodesic between the two source poses around each query
    (T0 exp(s log(T0^-1 T1)), constant velocity along the arc), NaN where the query lies outside the source
    span or its two neighbours are more than ``max_gap_s`` apart. A query within ``tol_s`` of a source stamp
    takes that pose. Source stamps must increase strictly."""
    t = np.asarray(stamps_src, dtype=np.float64)
    P = np.asarray(poses_src, dtype=np.float64)
    q = np.asarray(stamps_query, dtype=np.float64)
    if t.size == 0 or np.any(np.diff(t) <= 0):
        raise ValueError("interpolate_se2 needs strictly increasing source stamps")
    out = np.full((len(q), 3), np.nan)
    hi = np.clip(np.searchsorted(t, q), 1, len(t) - 1) if len(t) > 1 else np.zeros(len(q), np.int64)
    lo = np.maximum(hi - 1, 0)
    if len(t) > 1:
        inside = (q >= t[lo]) & (q <= t[hi]) & (t[hi] - t[lo] <= max_gap_s)
        s = ((q - t[lo]) / (t[hi] - t[lo]))[inside]
        step = se2_log(relative(P[lo[inside]], P[hi[inside]]))
        out[inside] = compose(P[lo[inside]], se2_exp(step * s[:, None]))
    near = np.where(np.abs(t[lo] - q) <= np.abs(t[hi] - q), lo, hi)
    exact = np.abs(t[near] - q) <= tol_s
    out[exact] = P[near[exact]]
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
