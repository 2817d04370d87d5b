"""Rendering ranges from a NOF: depth sampling along beams and compositing by a chosen renderer.

``make_renderer(name, ...)`` is asked once; both renderers take occupancies p [R, N] at depths z [R, N]
and return (ranges [R], opacity [R]):
* ``warp``: the Warp kernels of kernels/render.py behind a torch.autograd.Function (hand-written adjoint);
* ``torch_ref``: the same formula in torch (``composite_torch`` below), differentiated by autograd; it is
  also the twin the RENDER kernel is tested against (irmcl_warp/reference/render.py names it).
"""

from __future__ import annotations

import numpy as np
import torch

from irmcl_warp.kernels import RENDER


class _WarpComposite(torch.autograd.Function):
    @staticmethod
    def forward(ctx, p, z, compositor):
        ranges, opacity = compositor.forward(p, z)
        ctx.save_for_backward(p, z, ranges, opacity)
        ctx.compositor = compositor
        return ranges, opacity

    @staticmethod
    def backward(ctx, grad_r, grad_w):
        p, z, ranges, opacity = ctx.saved_tensors
        grad_r = torch.zeros_like(ranges) if grad_r is None else grad_r
        grad_w = torch.zeros_like(opacity) if grad_w is None else grad_w
        return ctx.compositor.backward(p, z, ranges, opacity, grad_r, grad_w), None, None


def termination_weights(p: torch.Tensor, t_min: float = 0.0) -> torch.Tensor:
    """alpha_k = p_k prod_{j<k}(1 - p_j) for p [..., N]; samples with transmittance below t_min get 0."""
    T = torch.cumprod(torch.cat([torch.ones_like(p[..., :1]), 1.0 - p[..., :-1]], dim=-1), dim=-1)
    alpha = p * T
    if t_min > 0.0:
        alpha = alpha * (T >= t_min).to(p.dtype)
    return alpha


def composite_torch(p: torch.Tensor, z: torch.Tensor, normalize: bool = True, t_min: float = 0.0, eps: float = 1e-10):
    """p, z [R, N] -> (ranges [R], opacity [R]); the same formula as the Warp kernels."""
    alpha = termination_weights(p, t_min)
    opacity = alpha.sum(-1)
    depth = (alpha * z.to(p.dtype)).sum(-1)
    return (depth / (opacity + eps) if normalize else depth), opacity


def _warp_renderer(normalize: bool, t_min: float, eps: float):
    compositor = RENDER.build("composite", normalize=normalize, t_min=t_min, eps=eps)
    return lambda p, z: _WarpComposite.apply(p, z, compositor)


def _torch_renderer(normalize: bool, t_min: float, eps: float):
    return lambda p, z: composite_torch(p, z, normalize=normalize, t_min=t_min, eps=eps)


RENDERERS = {"warp": _warp_renderer, "torch_ref": _torch_renderer}  # render.name -> factory


def make_renderer(name: str = "warp", normalize: bool = True, t_min: float = 0.0, eps: float = 1e-10):
    """A function (p, z) -> (ranges, opacity). ``normalize`` divides by the accumulated opacity (authors' code)."""
    if name not in RENDERERS:
        raise KeyError(f"render: unknown renderer {name!r}; choose one of {sorted(RENDERERS)}")
    return RENDERERS[name](normalize, t_min, eps)


def sample_depths(
    num_rays: int,
    num_samples: int,
    near_m: float,
    far_m: float,
    perturb: bool,
    device=None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Depths [R, N]: N values spread uniformly over [near, far] (both ends included, as the authors'
    linspace), each moved uniformly within its bin when ``perturb`` (bins end at the midpoints)."""
    z = torch.linspace(near_m, far_m, num_samples, device=device).expand(num_rays, num_samples)
    if not perturb:
        return z.contiguous()
    mid = 0.5 * (z[:, 1:] + z[:, :-1])
    lower = torch.cat([z[:, :1], mid], -1)
    upper = torch.cat([mid, z[:, -1:]], -1)
    u = torch.rand(z.shape, device=device, generator=generator)
    return lower + (upper - lower) * u


def sample_points(origins: torch.Tensor, dirs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """origins + z * dirs: sample points [R, N, 2] of beams [R, 2] at depths [R, N]."""
    return origins[:, None, :] + dirs[:, None, :] * z[..., None]


def render_rays(
    model,
    renderer,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    z: torch.Tensor,
    keep: torch.Tensor | None = None,
    count: int = 0,
):
    """Query the model at the sample points and composite: (ranges [R], opacity [R], p [R, N]).

    ``keep`` [R, N] (occupancy-guided sampling): only those samples go through the model; the others
    count as p = 0 (free), which leaves the compositing formula unchanged. (Fewer than two kept: every
    sample goes through, as batch norm needs two.) With ``count`` > 0 exactly that many go through
    (``fixed_sample_index``): the same shapes at every step, no wait for the host, so the model may be
    compiled for them.
    """
    R, N = z.shape
    points = sample_points(origins, dirs, z).reshape(-1, 2)
    if keep is not None and count > 0:
        flat = fixed_sample_index(keep, count)
    else:
        flat = None if keep is None else keep.reshape(-1).nonzero().squeeze(1)
    if flat is None or len(flat) < 2:
        p = model(points).reshape(R, N).float()
    else:
        p_kept = model(points[flat]).float()
        p = torch.zeros(R * N, dtype=p_kept.dtype, device=p_kept.device).index_copy(0, flat, p_kept).reshape(R, N)
    ranges, opacity = renderer(p, z)
    return ranges, opacity, p


def fixed_sample_index(keep: torch.Tensor, count: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``count`` flat indices of the samples [R, N] the model is asked about (``train.fixed_samples``): every kept
    sample first, topped up with samples the grid skipped, drawn at random (they go through the model and
    count with what it says, like any sample of the uniform sampler); when more are kept than ``count``, a
    random ``count`` of them (the others count as free, as the grid's skipped ones do). Ascending, so the
    model sees the samples in the order the variable-count path gives them."""
    score = keep.reshape(-1).float() + 0.5 * torch.rand(keep.numel(), device=keep.device, generator=generator)
    return torch.topk(score, min(count, keep.numel()), sorted=False).indices.sort().values


@torch.no_grad()
def render_scans(
    model, beams, renderer, num_samples: int, near_m: float, far_m: float, chunk_rays: int = 2048, device="cpu"
) -> np.ndarray:
    """Ranges [S, B] rendered for every beam of a BeamSet (evaluation: fixed depths, model in eval mode)."""

    was_training = model.training
    model.eval()
    origins, dirs, _, _ = beams.rays(valid_only=False)
    out = np.empty(len(origins), dtype=np.float32)
    for s in range(0, len(origins), chunk_rays):
        o = torch.from_numpy(origins[s : s + chunk_rays]).to(device)
        d = torch.from_numpy(dirs[s : s + chunk_rays]).to(device)
        z = sample_depths(len(o), num_samples, near_m, far_m, perturb=False, device=device)
        out[s : s + chunk_rays] = render_rays(model, renderer, o, d, z)[0].cpu().numpy()
    model.train(was_training)
    return out.reshape(beams.ranges_m.shape)
