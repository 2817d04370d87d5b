"""Rendering for NOF training: the hand-computed case, Warp kernels vs the torch twin, gradients."""

from __future__ import annotations

import pytest
import torch

from irmcl_warp.nof.render import make_renderer, sample_depths
from irmcl_warp.reference.render import composite_torch, termination_weights
from tests.devices import DEVICE

DEV = torch.device(DEVICE)  # the tensors live where the kernel runs (Warp follows them)


def test_hand_computed_weights_and_range():
    p = torch.tensor([[0.4, 0.3, 0.8]], dtype=torch.float64, device=DEV)
    z = torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64, device=DEV)
    assert torch.allclose(termination_weights(p).cpu(), torch.tensor([[0.4, 0.18, 0.336]], dtype=torch.float64))
    for name in ("warp", "torch_ref"):
        r, w = make_renderer(name, normalize=False)(p, z)
        assert r.item() == pytest.approx(0.4 * 1 + 0.18 * 2 + 0.336 * 3)
        assert w.item() == pytest.approx(0.916)
        r, _ = make_renderer(name, normalize=True)(p, z)
        assert r.item() == pytest.approx((0.4 + 0.36 + 1.008) / 0.916)


def _random_beams(rng, R=64, N=48, dtype=torch.float32):
    p = torch.from_numpy(rng.uniform(0.0, 1.0, (R, N)) ** 3).to(dtype)  # mostly free, some walls
    p[:, -1] = torch.from_numpy(rng.uniform(0.0, 1.0, R)).to(dtype)
    z = sample_depths(R, N, 0.02, 20.0, perturb=True, generator=torch.Generator().manual_seed(rng.seed)).to(dtype)
    return p.to(DEV), z.to(DEV)


@pytest.mark.parametrize("normalize", [True, False])
@pytest.mark.parametrize("t_min", [0.0, 1e-2])
def test_warp_matches_torch_twin(rng, normalize, t_min):
    p, z = _random_beams(rng)
    p_w, p_t = p.clone().requires_grad_(), p.clone().requires_grad_()
    r_w, w_w = make_renderer("warp", normalize=normalize, t_min=t_min)(p_w, z)
    r_t, w_t = composite_torch(p_t, z, normalize=normalize, t_min=t_min)
    assert torch.allclose(r_w, r_t, atol=1e-5, rtol=1e-5), f"seed {rng.seed}"
    assert torch.allclose(w_w, w_t, atol=1e-5), f"seed {rng.seed}"
    g_r, g_w = torch.randn(len(p), device=DEV), torch.randn(len(p), device=DEV)
    (r_w * g_r + w_w * g_w).sum().backward()
    (r_t * g_r + w_t * g_w).sum().backward()
    scale = p_t.grad.abs().max().item()
    assert torch.allclose(p_w.grad, p_t.grad, atol=1e-5 * max(scale, 1.0)), f"seed {rng.seed}"


@pytest.mark.parametrize("normalize", [True, False])
def test_warp_backward_passes_gradcheck_in_float64(rng, normalize):
    p, z = _random_beams(rng, R=6, N=10, dtype=torch.float64)
    p = (0.05 + 0.9 * p).requires_grad_()  # away from 0 and 1, where finite differences leave [0, 1]
    render = make_renderer("warp", normalize=normalize, eps=1e-10)
    assert torch.autograd.gradcheck(lambda q: render(q, z), (p,), eps=1e-6, atol=1e-6)
    twin = make_renderer("torch_ref", normalize=normalize)
    assert torch.autograd.gradcheck(lambda q: twin(q, z), (p,), eps=1e-6, atol=1e-6)


def test_opaque_wall_renders_its_depth():
    """A beam that meets a fully occupied sample ends there: range = that sample's depth."""
    z = torch.linspace(0.02, 10.0, 100, device=DEV).expand(3, 100).contiguous()
    p = torch.zeros(3, 100, device=DEV)
    for i, k in enumerate((10, 50, 99)):
        p[i, k:] = 1.0
    r, w = make_renderer("warp")(p, z)
    assert torch.allclose(r, z[0, [10, 50, 99]], atol=1e-5)
    assert torch.allclose(w, torch.ones(3, device=DEV))


def test_sample_depths_stay_in_their_bins(rng):
    g = torch.Generator().manual_seed(rng.seed)
    z = sample_depths(200, 16, 0.5, 8.0, perturb=True, generator=g)
    grid = torch.linspace(0.5, 8.0, 16)
    mid = 0.5 * (grid[1:] + grid[:-1])
    lower, upper = torch.cat([grid[:1], mid]), torch.cat([mid, grid[-1:]])
    assert torch.all(z >= lower) and torch.all(z <= upper)
    assert torch.all(z[:, 1:] >= z[:, :-1])
    assert torch.equal(sample_depths(3, 16, 0.5, 8.0, perturb=False), grid.expand(3, 16))


def test_renderer_rejects_unknown_names_and_dtypes():
    with pytest.raises(KeyError, match="torch_ref"):
        make_renderer("cuda_magic")
    with pytest.raises(TypeError, match="float32 or float64"):
        make_renderer("warp")(torch.zeros(2, 3, dtype=torch.float16), torch.zeros(2, 3))
