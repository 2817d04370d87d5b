"""A robot's path through a :class:`~irmcl_warp.sim.world.World`, and wheel odometry with Thrun's noise."""

from __future__ import annotations

import numpy as np

from irmcl_warp.geometry import compose, relative, wrap_angle


def waypoints(world, rng, visit_prob: float = 0.6) -> np.ndarray:
    """Down the corridor and back, stepping into a random subset of rooms (door -> centre -> door)."""
    y = world.corridor_y
    pts = [(1.0, y)]
    rooms = sorted(world.rooms, key=lambda r: r.door_x)
    for room in rooms:
        if rng.random() < visit_prob:
            pts += [
                (room.door_x, y),
                (room.door_x, room.door_y),
                tuple(room.centre),
                (room.door_x, room.door_y),
                (room.door_x, y),
            ]
    pts += [(world.width_m - 1.0, y), (1.0, y + 0.4)]
    return np.array(pts)


def follow(points, speed_mps: float, turn_rate_rps: float, rate_hz: float, duration_s: float | None = None):
    """Poses [N, 3] sampled at ``rate_hz``: drive straight between points, turn in place at each."""
    poses = [np.array([points[0][0], points[0][1], np.arctan2(*(points[1] - points[0])[::-1])])]
    dt = 1.0 / rate_hz
    for p, q in zip(points[:-1], points[1:]):
        heading = np.arctan2(q[1] - p[1], q[0] - p[0])
        cur = poses[-1]
        turn = wrap_angle(heading - cur[2])
        for k in range(1, int(np.ceil(abs(turn) / (turn_rate_rps * dt))) + 1):
            poses.append(
                np.array([cur[0], cur[1], wrap_angle(cur[2] + turn * min(1.0, k * turn_rate_rps * dt / abs(turn)))])
            )
        length = np.hypot(*(q - p))
        steps = int(np.ceil(length / (speed_mps * dt)))
        for k in range(1, steps + 1):
            f = k / steps
            poses.append(np.array([p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1]), heading]))
        if duration_s is not None and len(poses) * dt >= duration_s:
            break
    poses = np.array(poses)
    return poses[: int(duration_s * rate_hz)] if duration_s else poses


def noisy_odometry(T_world_base, alphas, rng) -> np.ndarray:
    """Odometry following Thrun et al., Probabilistic Robotics, Table 5.6 (sample_motion_model_odometry):
    each step is split into rot1, trans, rot2 and perturbed with variances
    a1 rot1^2 + a2 trans^2, a3 trans^2 + a4 (rot1^2 + rot2^2), a1 rot2^2 + a2 trans^2; then accumulated."""
    a1, a2, a3, a4 = alphas
    steps = relative(T_world_base[:-1], T_world_base[1:])
    trans = np.hypot(steps[:, 0], steps[:, 1])
    rot1 = np.where(trans > 1e-6, np.arctan2(steps[:, 1], steps[:, 0]), 0.0)
    rot2 = wrap_angle(steps[:, 2] - rot1)
    n = len(steps)
    r1 = rot1 + rng.normal(0, 1, n) * np.sqrt(a1 * rot1**2 + a2 * trans**2)
    tr = trans + rng.normal(0, 1, n) * np.sqrt(a3 * trans**2 + a4 * (rot1**2 + rot2**2))
    r2 = rot2 + rng.normal(0, 1, n) * np.sqrt(a1 * rot2**2 + a2 * trans**2)
    noisy = np.stack([tr * np.cos(r1), tr * np.sin(r1), wrap_angle(r1 + r2)], -1)
    odom = [np.zeros(3)]
    for step in noisy:
        odom.append(compose(odom[-1], step))
    return np.array(odom)
