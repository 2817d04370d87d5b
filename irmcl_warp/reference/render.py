"""Torch twin of kernels/render.py: the formula of the ablation ``render=torch_ref`` (autograd does the backward),
which lives with the renderers in irmcl_warp/nof/render.py and is named here for the parity tests.

    T = cumprod([1, 1 - p_0, ..., 1 - p_{N-2}]);  alpha = p * T;  r = sum(alpha * z) / (sum(alpha) + eps)

>>> composite_torch(torch.tensor([[0.4, 0.3, 0.8]]), torch.tensor([[1.0, 2.0, 3.0]]), normalize=False)[0]
tensor([1.7680])
"""

from __future__ import annotations

from irmcl_warp.nof.render import composite_torch, termination_weights  # noqa: F401


