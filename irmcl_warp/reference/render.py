"""Torch twin of kernels/render.py, and the ablation ``render=torch_ref`` (autograd does the backward).

    T = cumprod([1, 1 - p_0, ..., 1 - p_{N-2}]);  alpha = p * T;  r = sum(alpha * z) / (sum(alpha) + eps)

>>> composite_torch(torch.tensor([[0.4, 0.3, 0.8]]), torch.tensor([[1.0, 2.0, 3.0]]), normalize=False)[0]
tensor([1.7680])
"""

from __future__ import annotations

import torch


def termination_weights(p: torch.Tensor, t_min: float = 0.0) -> torch.Tensor:
    """alpha_k = p_k prod_{j<k}(1 - p_j) for p [..., N]; samples with transmittance below t_min get 0."""
    T = torch.cumprod(torch.cat([torch.ones_like(p[..., :1]), 1.0 - p[..., :-1]], dim=-1), dim=-1)
    alpha = p * T
    if t_min > 0.0:
        alpha = alpha * (T >= t_min).to(p.dtype)
    return alpha


def composite_torch(p: torch.Tensor, z: torch.Tensor, normalize: bool = True, t_min: float = 0.0,
                    eps: float = 1e-10):
    """p, z [R, N] -> (ranges [R], opacity [R]); the same formula as the Warp kernels."""
    alpha = termination_weights(p, t_min)
    opacity = alpha.sum(-1)
    depth = (alpha * z.to(p.dtype)).sum(-1)
    return (depth / (opacity + eps) if normalize else depth), opacity
