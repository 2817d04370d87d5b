"""Rendering for NOF training: the hand-computed case, Warp kernels vs the torch twin, gradients."""

from __future__ import annotations

import numpy as np
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


# --- occupancy-guided sampling (RENDER["occupied_samples"], train.sampler=occupancy) ---------------------------


def _random_grid(rng, H=23, W=31):
    values = torch.from_numpy(rng.uniform(0.0, 1.0, (H, W)) ** 2).float()
    occupied = torch.from_numpy(rng.uniform(0.0, 1.0, (H, W)) < 0.6)
    return values.to(DEV), occupied.to(DEV)


@pytest.mark.parametrize("t_min", [0.0, 1e-2, 0.3])
def test_occupied_samples_match_the_twin(rng, t_min):
    from irmcl_warp.reference.render import occupied_samples_torch
    from irmcl_warp.kernels import RENDER

    values, occupied = _random_grid(rng)
    origin, res = (-1.3, 0.7), 0.1
    # beams from inside the grid, many of them leaving it (those samples are never kept)
    o = torch.from_numpy(np.stack([rng.uniform(-1.2, 1.7, 200), rng.uniform(0.8, 2.9, 200)], 1)).float()
    a = torch.from_numpy(rng.uniform(-np.pi, np.pi, 200)).float()
    d = torch.stack([torch.cos(a), torch.sin(a)], 1)
    z = sample_depths(200, 40, 0.02, 4.0, perturb=True, generator=torch.Generator().manual_seed(rng.seed))
    points = (o[:, None] + d[:, None] * z[..., None]).to(DEV)
    keep = RENDER.build("occupied_samples", origin_xy=origin, resolution_m=res, t_min=t_min)(points, values, occupied)
    twin = occupied_samples_torch(points.cpu(), values.cpu(), occupied.cpu(), origin, res, t_min)
    assert keep.dtype == torch.bool and keep.shape == (200, 40)
    assert torch.equal(keep.cpu(), twin), f"seed {rng.seed}: {(keep.cpu() != twin).sum()} samples differ"
    assert 0 < int(twin.sum()) < twin.numel()  # the inputs exercise both answers


def test_a_masked_field_reads_the_cells_the_sampler_keeps(rng):
    """train.grid_masks_field: MaskedField answers the field's p in exactly the cells the sampler's kernel keeps
    (t_min 0: every sample in an occupied cell) and 0 elsewhere, off the grid included, on fresh random points."""
    from irmcl_warp.kernels import RENDER
    from irmcl_warp.nof.occupancy import MaskedField

    values, occupied = _random_grid(rng)
    origin, res = (-1.3, 0.7), 0.1
    points = torch.from_numpy(np.stack([rng.uniform(-1.6, 2.1, (50, 30)), rng.uniform(0.4, 3.3, (50, 30))], -1))
    points = points.float().to(DEV)  # about a fifth of them off the grid
    keep = RENDER.build("occupied_samples", origin_xy=origin, resolution_m=res, t_min=0.0)(points, values, occupied)

    class Field(torch.nn.Module):  # a field whose p is never 0, so every 0 comes from the mask
        def forward(self, xy):
            return 0.25 + 0.5 * torch.sigmoid(xy[:, 0] * xy[:, 1])

    masked = MaskedField(Field(), occupied, origin, res).to(DEV)
    flat = points.reshape(-1, 2)
    assert torch.equal(masked.cell_occupied(flat).reshape(keep.shape), keep), f"seed {rng.seed}"
    p = masked(flat).reshape(keep.shape)
    assert torch.equal(p, torch.where(keep, Field()(flat).reshape(keep.shape), torch.zeros(())))
    assert 0 < int(keep.sum()) < keep.numel()


def test_occupied_samples_by_hand():
    from irmcl_warp.kernels import RENDER

    # one row of cells at x in [0, 0.4): free, then occupied with values 0.5, 0.9, 0.9
    values = torch.tensor([[0.0, 0.5, 0.9, 0.9]], device=DEV)
    occupied = torch.tensor([[False, True, True, True]], device=DEV)
    points = torch.tensor([[[0.05, 0.05], [0.15, 0.05], [0.25, 0.05], [0.35, 0.05], [0.45, 0.05]]], device=DEV)
    keep = RENDER.build("occupied_samples", origin_xy=(0.0, 0.0), resolution_m=0.1, t_min=0.1)(points, values, occupied)
    # T before each: 1, 1, 0.5, 0.05 (< 0.1: the beam has ended), and the last point is off the grid
    assert keep.cpu().tolist() == [[False, True, True, False, False]]
    no_end = RENDER.build("occupied_samples", origin_xy=(0.0, 0.0), resolution_m=0.1, t_min=0.0)(
        points, values, occupied
    )
    assert no_end.cpu().tolist() == [[False, True, True, True, False]]


@pytest.mark.parametrize("end, atol", [("none", 1e-5), ("field", 2e-3)])
def test_guided_rendering_equals_full_rendering_where_the_grid_is_right(rng, end, atol):
    """A field that is exactly 0 outside two walls, a grid read from it: the samples skipped in free space
    are exactly p = 0 (the same ranges to float rounding); ending beams where the grid's transmittance is
    below t_min drops only weight of that order."""
    from types import SimpleNamespace

    from irmcl_warp.nof.occupancy import OccupancyGrid
    from irmcl_warp.nof.render import render_rays

    class Walls(torch.nn.Module):  # p = 0.95 in the walls x in [2, 2.3] and x in [3.5, 3.8], else 0
        def forward(self, xy):
            x = xy[:, 0]
            return 0.95 * (((x >= 2.0) & (x <= 2.3)) | ((x >= 3.5) & (x <= 3.8))).float()

    n = 300
    o = np.stack([rng.uniform(0.0, 1.5, n), rng.uniform(-1.0, 1.0, n)], 1).astype(np.float32)
    a = rng.uniform(-0.6, 0.6, n)
    d = np.stack([np.cos(a), np.sin(a)], 1).astype(np.float32)
    ends = o + d * ((4.5 - o[:, :1]) / d[:, :1])
    tc = SimpleNamespace(
        grid_resolution_m=0.1, grid_threshold=0.01, grid_decay=0.8, grid_dilate=1, grid_end=end, grid_t_min=1e-4
    )
    grid = OccupancyGrid(o, ends, tc, DEV)
    for _ in range(4):  # a random point per cell: a few readings find every wall cell
        grid.update(Walls())
    o_t, d_t = torch.from_numpy(o).to(DEV), torch.from_numpy(d).to(DEV)
    z = sample_depths(n, 128, 0.02, 5.0, perturb=True, device=DEV)
    keep = grid.keep(o_t[:, None] + d_t[:, None] * z[..., None], Walls())
    render = make_renderer("warp")
    full, _, _ = render_rays(Walls(), render, o_t, d_t, z)
    guided, _, _ = render_rays(Walls(), render, o_t, d_t, z, keep)
    assert keep.float().sum(1).mean() < (0.2 if end == "field" else 0.4) * z.shape[1]  # most samples skipped
    assert torch.allclose(guided, full, atol=atol), f"seed {rng.seed}: {(guided - full).abs().max()}"
    assert abs(grid.occupied_share() - 0.2) < 0.15  # two walls and their dilation, not the whole grid


def test_a_fixed_count_of_samples_keeps_the_kept_ones_and_renders_the_same(rng):
    """train.fixed_samples (render_rays' count): exactly ``count`` samples go through the model, every kept one
    among them when there is room (the rest drawn from the skipped ones), a random ``count`` of the kept ones when
    there is not; where the field is 0 outside the grid's cells, the ranges are those of the variable count."""
    from irmcl_warp.nof.render import fixed_sample_index, render_rays, sample_points

    R, N = int(rng.integers(20, 60)), 64
    keep = torch.from_numpy(rng.uniform(size=(R, N)) < rng.uniform(0.1, 0.4)).to(DEV)
    kept = int(keep.sum())
    for count in (kept, kept + int(rng.integers(1, 200)), max(2, kept - int(rng.integers(1, 20)))):
        idx = fixed_sample_index(keep, count)
        assert len(idx) == count and torch.all(idx[1:] > idx[:-1])  # ascending, no sample twice
        chosen = keep.reshape(-1)[idx]
        assert int(chosen.sum()) == min(count, kept)  # the kept ones first

    class Bands(torch.nn.Module):  # p > 0 exactly on points in bands of x (a rule of the point, no lookup)
        def forward(self, xy):
            inside = torch.remainder(3.0 * xy[:, 0], 1.0) < 0.25
            return torch.where(inside, 0.3 + 0.6 * torch.sigmoid(xy[:, 1]), torch.zeros_like(xy[:, 0]))

    o = torch.from_numpy(rng.uniform(-1, 1, (R, 2)).astype(np.float32)).to(DEV)
    a = torch.from_numpy(rng.uniform(-3, 3, R).astype(np.float32)).to(DEV)
    d = torch.stack([torch.cos(a), torch.sin(a)], 1)
    z = sample_depths(R, N, 0.02, 5.0, perturb=True, device=DEV)
    model = Bands()
    keep = (model(sample_points(o, d, z).reshape(-1, 2)) > 0).reshape(R, N)  # the grid right about the field
    kept = int(keep.sum())
    render = make_renderer("warp")
    variable, _, _ = render_rays(model, render, o, d, z, keep)
    for count in (kept, kept + 50):
        fixed, _, _ = render_rays(model, render, o, d, z, keep, count)
        assert torch.allclose(fixed, variable, atol=1e-6), f"seed {rng.seed}, count {count}"
    fewer, _, p = render_rays(model, render, o, d, z, keep, kept // 2)
    assert int((p > 0).sum()) == kept // 2  # half the kept samples counted as free
