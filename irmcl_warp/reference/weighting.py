"""Numpy twin of kernels/weighting.py (``nog_raymarch``, ``nog_table``): the same steps, vectorised over particles and beams."""

from __future__ import annotations

import numpy as np
from irmcl_warp.reference.raycast import dda_range


def laser_poses(particles, T_base_laser):
    x, y, t = (np.asarray(particles, np.float64)[:, i] for i in range(3))
    c, s = np.cos(t), np.sin(t)
    return np.stack(
        [
            x + c * T_base_laser[0] - s * T_base_laser[1],
            y + s * T_base_laser[0] + c * T_base_laser[1],
            t + T_base_laser[2],
        ],
        -1,
    )


def nog_render(
    grid, origin, res, particles, T_base_laser, angles, num_samples, near, far_m, t_min=0.0, empty_below=0.0, eps=1e-10
):
    """Rendered ranges [P, B] from nearest-node lookups along num_samples fixed depths, every sample evaluated
    (the kernel's jumps over empty space must not change this); nodes below ``empty_below`` read as 0."""
    pose = laser_poses(particles, T_base_laser)
    a = pose[:, 2:3] + np.asarray(angles)[None, :]  # [P, B]
    z = near + (far_m - near) / (num_samples - 1) * np.arange(num_samples)  # [N]
    x = pose[:, 0, None, None] + z * np.cos(a)[..., None]
    y = pose[:, 1, None, None] + z * np.sin(a)[..., None]
    ix = np.rint((x - origin[0]) / res).astype(int)
    iy = np.rint((y - origin[1]) / res).astype(int)
    H, W = grid.shape
    inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
    occ = np.where(inside, grid[np.clip(iy, 0, H - 1), np.clip(ix, 0, W - 1)], 0.0)
    occ = np.where(occ < empty_below, 0.0, occ)
    T = np.cumprod(np.concatenate([np.ones_like(occ[..., :1]), 1.0 - occ[..., :-1]], -1), -1)
    w = occ * T * (T >= t_min)
    return (w * z).sum(-1) / (w.sum(-1) + eps)


def nog_table_build(grid, origin, res, num_angles, num_samples, near, far_m, t_min=0.0, empty_below=0.0):
    """``nog_table``'s table [nodes, headings] (uint16, range / (far / 65535)): ``nog_render`` from every node
    (row-major, x fastest) at headings 2 pi k / num_angles."""
    H, W = grid.shape
    iy, ix = np.divmod(np.arange(H * W), W)
    nodes = np.stack([origin[0] + ix * res, origin[1] + iy * res, np.zeros(H * W)], -1)
    headings = (2.0 * np.pi * np.arange(num_angles) / num_angles).astype(np.float32)
    r = nog_render(grid, origin, res, nodes, (0.0, 0.0, 0.0), headings, num_samples, near, far_m, t_min, empty_below)
    return np.clip(np.rint(r * (65535 / far_m)), 0, 65535).astype(np.uint16)


def nog_table_ranges(table, shape, origin, res, far_m, particles, T_base_laser, angles):
    """Ranges [P, B] read from the table: the laser's nearest node (clamped to the grid), linear between the two
    nearest headings, moved by the laser's offset from the node along the beam (0 stays 0: no wall)."""
    H, W = shape
    pose = laser_poses(particles, T_base_laser)
    a = pose[:, 2:3] + np.asarray(angles, np.float64)[None, :]
    n = table.shape[1]
    u = np.mod(a * (n / (2.0 * np.pi)), n)
    k0 = np.floor(u).astype(int)
    f = u - k0
    k0 %= n
    k1 = (k0 + 1) % n
    ix = np.clip(np.rint((pose[:, 0] - origin[0]) / res).astype(int), 0, W - 1)[:, None]
    iy = np.clip(np.rint((pose[:, 1] - origin[1]) / res).astype(int), 0, H - 1)[:, None]
    node = iy * W + ix
    r = ((1.0 - f) * table[node, k0] + f * table[node, k1]) * (far_m / 65535)
    along = (pose[:, :1] - origin[0] - ix * res) * np.cos(a) + (pose[:, 1:2] - origin[1] - iy * res) * np.sin(a)
    return np.where(r > 0, np.maximum(r - along, 0.0), r)


def nog_log_weights(rendered, measured, sigma):
    """-0.5 D^2 / sigma^2 with D the mean absolute error over the valid (non-NaN) measured beams."""
    valid = np.isfinite(measured)
    D = np.abs(rendered[:, valid] - measured[valid]).sum(1) / max(valid.sum(), 1)
    return -0.5 * D**2 / sigma**2


def likelihood_field_log_weights(
    dist, origin, res, particles, T_base_laser, angles, measured, z_hit, z_rand, sigma_hit, far_m, max_dist
):
    """Thrun et al. Table 6.3 in logs: sum over valid beams of log(z_hit exp(-d^2 / 2 s^2) + z_rand / max_range)."""
    pose = laser_poses(particles, T_base_laser)
    valid = np.isfinite(measured)
    a = pose[:, 2:3] + np.asarray(angles)[None, valid]
    m = np.asarray(measured)[None, valid]
    ix = np.floor((pose[:, :1] + m * np.cos(a) - origin[0]) / res).astype(int)
    iy = np.floor((pose[:, 1:2] + m * np.sin(a) - origin[1]) / res).astype(int)
    H, W = dist.shape
    inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
    d = np.where(inside, np.minimum(dist[np.clip(iy, 0, H - 1), np.clip(ix, 0, W - 1)], max_dist), max_dist)
    return np.log(z_hit * np.exp(-(d**2) / (2 * sigma_hit**2)) + z_rand / far_m).sum(1)


def beam_model_log_weights(
    occ,
    origin,
    res,
    particles,
    T_base_laser,
    angles,
    measured,
    z_hit,
    z_short,
    z_max,
    z_rand,
    sigma_hit,
    lambda_short,
    far_m,
    occ_threshold,
):
    """Thrun et al. Table 6.1 in logs, expected ranges from the DDA twin (one Python loop per ray)."""
    pose = laser_poses(particles, T_base_laser)
    out = np.zeros(len(pose))
    for p, (x, y, yaw) in enumerate(pose):
        for a, z in zip(angles, measured):
            if not np.isfinite(z):
                continue
            d = np.array([np.cos(yaw + a), np.sin(yaw + a)], np.float32)
            exp_r = dda_range(
                occ, np.asarray(origin, np.float32), res, np.array([x, y], np.float32), d, far_m, occ_threshold
            )
            q = z_hit * np.exp(-((z - exp_r) ** 2) / (2 * sigma_hit**2))
            q += z_short * lambda_short * np.exp(-lambda_short * z) if z < exp_r else 0.0
            q += z_max if z >= far_m else z_rand / far_m
            out[p] += np.log(q)
    return out


def nog_log_weights_torch(
    grid,
    origin,
    res,
    particles,
    T_base_laser,
    angles,
    measured,
    num_samples: int,
    near: float,
    far_m: float,
    sigma: float,
    chunk: int = 500,
    eps: float = 1e-10,
):
    """IR-MCL's weighting as the authors formulate it, in torch: every sample of every beam of ``chunk``
    particles at a time, nearest-node lookups, the transmittance by a cumulative product, normalised
    weights, then the Gaussian on the mean L1 error. The speed reference of ``eval.bench mcl`` (all
    tensors on one device). Returns log-weights [P]."""
    import torch

    dev = grid.device
    z = torch.linspace(near, far_m, num_samples, device=dev, dtype=particles.dtype)  # not torch's float32 default
    valid = torch.isfinite(measured)
    H, W = grid.shape
    c, s = torch.cos(particles[:, 2]), torch.sin(particles[:, 2])
    ox = particles[:, 0] + c * T_base_laser[0] - s * T_base_laser[1]
    oy = particles[:, 1] + s * T_base_laser[0] + c * T_base_laser[1]
    yaw = particles[:, 2] + T_base_laser[2]
    out = []
    for a in range(0, len(particles), chunk):
        b = slice(a, a + chunk)
        ang = yaw[b, None] + angles[None, :]  # [p, B]
        x = ox[b, None, None] + z * torch.cos(ang)[..., None]  # [p, B, S]
        y = oy[b, None, None] + z * torch.sin(ang)[..., None]
        ix = torch.round((x - origin[0]) / res).long()
        iy = torch.round((y - origin[1]) / res).long()
        inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
        occ = torch.where(inside, grid[iy.clamp(0, H - 1), ix.clamp(0, W - 1)], torch.zeros((), device=dev))
        T = torch.cumprod(torch.cat([torch.ones_like(occ[..., :1]), 1.0 - occ[..., :-1]], -1), -1)
        w = occ * T
        r = (w * z).sum(-1) / (w.sum(-1) + eps)  # [p, B]
        D = (r[:, valid] - measured[valid]).abs().mean(1)
        out.append(-0.5 * D**2 / sigma**2)
    return torch.cat(out)
