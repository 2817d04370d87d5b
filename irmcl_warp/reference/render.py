"""Torch twin of kernels/render.py: the formula of the ablation ``render=torch_ref`` (autograd does the backward),
which lives with the renderers in irmcl_warp/nof/render.py and is named here for the parity tests.

    T = cumprod([1, 1 - p_0, ..., 1 - p_{N-2}]);  alpha = p * T;  r = sum(alpha * z) / (sum(alpha) + eps)

>>> composite_torch(torch.tensor([[0.4, 0.3, 0.8]]), torch.tensor([[1.0, 2.0, 3.0]]), normalize=False)[0]
tensor([1.7680])
"""

from __future__ import annotations

from irmcl_warp.nof.render import composite_torch, termination_weights  # noqa: F401


def occupied_samples_torch(points, values, occupied, origin_xy, resolution_m: float, t_min: float = 0.0):
    """Twin of RENDER["occupied_samples"]: keep [R, N] (bool) for sample points [R, N, 2] along beams.

    A sample is kept when its cell of the grid (cell (i, j) spans x0 + [j, j + 1) res, y0 + [i, i + 1) res)
    is ``occupied`` and the grid's transmittance before it, the product of (1 - value) over the beam's
    earlier kept samples, is at least ``t_min`` (0: no termination). Points off the grid are never kept.
    """
    import torch

    H, W = occupied.shape
    x0, y0 = (float(c) for c in origin_xy)
    inv_res = 1.0 / float(resolution_m)  # multiplied in float32, as the kernel does
    ix = torch.floor((points[..., 0] - x0) * inv_res).long()
    iy = torch.floor((points[..., 1] - y0) * inv_res).long()
    inside = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
    ixc, iyc = ix.clamp(0, W - 1), iy.clamp(0, H - 1)
    occ = inside & occupied[iyc, ixc].bool()
    v = torch.where(occ, values[iyc, ixc], torch.zeros((), dtype=values.dtype))
    T = torch.cumprod(torch.cat([torch.ones_like(v[:, :1]), 1.0 - v[:, :-1]], 1), 1)
    return occ & (T >= t_min)
