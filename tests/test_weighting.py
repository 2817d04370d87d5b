"""IR-MCL's observation model on the NOG: the Warp kernel against its numpy twin, and hand cases."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import warp as wp

from irmcl_warp.nog import NOG, bake_nog, evaluate_grid
from irmcl_warp.reference.weighting import nog_log_weights, nog_render
from kernels import WEIGHTING


def _wall_nog(x_wall=2.0, res=0.05):
    occ = np.zeros((81, 121), np.float32)  # nodes over x in [-1, 5], y in [-2, 2]
    occ[:, int(round((x_wall + 1.0) / res))] = 1.0
    return NOG(occ, (-1.0, -2.0), res)


def test_pose_two_metres_before_a_wall_renders_two_metres():
    nog = _wall_nog()
    w = WEIGHTING.build("nog_raymarch", nog=nog, num_particles=1, num_beams=1, num_samples=256, near_m=0.0,
                        far_m=10.0, device="cpu")
    particles = wp.array(np.array([[0.0, 0.0, 0.0]], np.float32), dtype=wp.vec3, device="cpu")
    angles = wp.array(np.zeros(1, np.float32), dtype=wp.float32, device="cpu")
    r = w.render(particles, (0.0, 0.0, 0.0), angles).numpy()[0, 0]
    assert abs(r - 2.0) <= 0.5 * nog.resolution_m


@pytest.mark.parametrize("t_min", [0.0, 1e-3])
def test_kernel_matches_numpy_twin(rng, t_min):
    occ = (rng.uniform(0, 1, (60, 80)) ** 6).astype(np.float32)  # mostly free, some walls
    nog = NOG(occ, (rng.uniform(-2, 2), rng.uniform(-2, 2)), 0.1)
    P, B = 40, 16
    particles = np.stack([rng.uniform(-1, 6, P), rng.uniform(-1, 4, P), rng.uniform(-np.pi, np.pi, P)], -1).astype(np.float32)
    angles = np.linspace(-2.0, 2.0, B).astype(np.float32)
    T_bl = (0.1, -0.05, 0.02)
    measured = rng.uniform(0.5, 6.0, B).astype(np.float32)
    measured[3] = np.nan
    w = WEIGHTING.build("nog_raymarch", nog=nog, num_particles=P, num_beams=B, num_samples=64, near_m=0.02,
                        far_m=8.0, t_min=t_min, sigma_m=0.5, device="cpu")
    pw = wp.array(particles, dtype=wp.vec3, device="cpu")
    aw = wp.array(angles, dtype=wp.float32, device="cpu")
    logw = wp.zeros(P, dtype=wp.float32, device="cpu")
    w(pw, T_bl, aw, wp.array(measured, dtype=wp.float32, device="cpu"), logw)
    ours = w.rendered.numpy()
    twin = nog_render(occ, nog.origin_xy, nog.resolution_m, particles, T_bl, angles, 64, 0.02, 8.0, t_min)
    close = np.abs(ours - twin) < 1e-3
    assert close.mean() > 0.99, f"seed {rng.seed}: {close.mean():.3f} of beams agree"  # float32 rounding at node borders
    twin_logw = nog_log_weights(ours.astype(np.float64), measured.astype(np.float64), 0.5)
    assert np.allclose(logw.numpy(), twin_logw, rtol=1e-4, atol=1e-4), f"seed {rng.seed}"


def test_beam_count_mismatch_is_a_clear_error():
    w = WEIGHTING.build("nog_raymarch", nog=_wall_nog(), num_particles=2, num_beams=32, device="cpu")
    p = wp.zeros(2, dtype=wp.vec3, device="cpu")
    with pytest.raises(ValueError, match="31 measured ranges / 31 angles, built for 32 beams"):
        w(p, (0, 0, 0), wp.zeros(31, dtype=wp.float32, device="cpu"), wp.zeros(31, dtype=wp.float32, device="cpu"),
          wp.zeros(2, dtype=wp.float32, device="cpu"))
    with pytest.raises(ValueError, match="NOG is empty"):
        WEIGHTING.build("nog_raymarch", nog=NOG(np.zeros((0, 0), np.float32), (0, 0), 0.05), num_particles=1,
                        num_beams=1, device="cpu")


class _Disc(torch.nn.Module):
    """A stand-in field: occupied inside a disc of radius 1 m around (2, 0)."""

    def forward(self, xy):
        return ((xy - torch.tensor([2.0, 0.0])).norm(dim=-1) < 1.0).float()


def test_bake_evaluates_the_field_at_the_nodes_and_caches(tmp_path):
    nog = evaluate_grid(_Disc(), (0.0, -1.5, 4.0, 1.5), 0.1)
    assert nog.shape == (31, 41)
    ix, iy = nog.node_of([[2.0, 0.0], [0.2, 1.4]]).T
    assert nog.occupancy[iy[0], ix[0]] == 1.0 and nog.occupancy[iy[1], ix[1]] == 0.0
    assert abs(nog.occupancy.sum() * 0.01 - np.pi) < 0.2  # disc area
    with pytest.raises(ValueError, match="do not describe a grid"):
        evaluate_grid(_Disc(), (1.0, 0.0, 0.0, 1.0), 0.1)


def test_bake_from_a_checkpoint_is_cached_by_hash(tmp_path):
    from irmcl_warp.config import ModelConfig
    from irmcl_warp.nof.checkpoint import atomic_torch_save
    from irmcl_warp.nof.model import NOF

    model = NOF(ModelConfig(width=16, depth=2, skip_after=1, num_freqs=2)).eval()
    ckpt = tmp_path / "nof.pt"
    atomic_torch_save({"model": model.state_dict(), "model_config": model.config_dict()}, ckpt)
    a = bake_nog(ckpt, (0, 0, 1, 1), 0.1, cache_dir=tmp_path / "nog")
    assert len(list((tmp_path / "nog").glob("nog-*.npz"))) == 1
    b = bake_nog(ckpt, (0, 0, 1, 1), 0.1, cache_dir=tmp_path / "nog")
    assert np.array_equal(a.occupancy, b.occupancy)
    bake_nog(ckpt, (0, 0, 1, 1), 0.05, cache_dir=tmp_path / "nog")
    assert len(list((tmp_path / "nog").glob("nog-*.npz"))) == 2


def test_likelihood_field_matches_twin_and_prefers_the_true_pose(rng):
    from irmcl_warp.reference.weighting import likelihood_field_log_weights
    from kernels.raycast import distance_to_occupied

    occ = np.zeros((60, 80), np.float32)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1.0  # a 8 x 6 m room at 0.1 m
    occ[20:40, 50] = 1.0
    origin, res = (0.0, 0.0), 0.1
    true = np.array([3.0, 3.0, 0.3])
    angles = np.linspace(-np.pi, np.pi, 24, endpoint=False).astype(np.float32)
    from kernels import RAYCAST

    caster = RAYCAST.build("dda", occupancy=occ, origin_xy=origin, resolution_m=res, max_range_m=20.0, device="cpu")
    # +half a cell: end points inside the wall cell, not on its border (where float32 and float64 floor differ)
    measured = (caster.cast_numpy(true[None], angles)[0] + 0.05).astype(np.float32)
    measured[5] = np.nan
    particles = np.vstack([true, true + [0.5, 0.0, 0.0], true + [0.0, 0.0, 0.3],
                           np.column_stack([rng.uniform(1, 7, 20), rng.uniform(1, 5, 20), rng.uniform(-3, 3, 20)])]).astype(np.float32)
    lf = WEIGHTING.build("likelihood_field", occupancy=occ, origin_xy=origin, resolution_m=res, device="cpu")
    out = wp.zeros(len(particles), dtype=wp.float32, device="cpu")
    lf(wp.array(particles, dtype=wp.vec3, device="cpu"), (0, 0, 0), wp.array(angles, dtype=wp.float32, device="cpu"),
       wp.array(measured, dtype=wp.float32, device="cpu"), out)
    ours = out.numpy()
    twin = likelihood_field_log_weights(distance_to_occupied(occ, res, 0.65), origin, res, particles.astype(np.float64),
                                        (0, 0, 0), angles, measured, 0.95, 0.05, 0.2, 30.0, 2.0)
    assert np.allclose(ours, twin, rtol=1e-4, atol=1e-3), f"seed {rng.seed}"
    assert ours[0] > ours[1] and ours[0] > ours[2] and ours[0] >= ours[3:].max()
    with pytest.raises(ValueError, match="map is empty"):
        WEIGHTING.build("likelihood_field", occupancy=np.zeros((5, 5)), origin_xy=origin, resolution_m=res, device="cpu")


def test_beam_model_matches_twin_and_prefers_the_true_pose(rng):
    from irmcl_warp.reference.weighting import beam_model_log_weights
    from kernels import RAYCAST

    occ = np.zeros((40, 50), np.float32)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1.0  # a 5 x 4 m room at 0.1 m
    occ[10:25, 30] = 1.0
    origin, res = (0.0, 0.0), 0.1
    true = np.array([2.0, 2.0, 0.3])
    angles = np.linspace(-np.pi, np.pi, 12, endpoint=False).astype(np.float32)
    caster = RAYCAST.build("dda", occupancy=occ, origin_xy=origin, resolution_m=res, max_range_m=8.0, device="cpu")
    measured = (caster.cast_numpy(true[None], angles)[0] + rng.normal(0, 0.02, len(angles))).astype(np.float32)
    measured[4] = np.nan
    particles = np.vstack([true, true + [0.4, 0.0, 0.0], true + [0.0, 0.0, 0.25],
                           np.column_stack([rng.uniform(1, 4, 6), rng.uniform(1, 3, 6), rng.uniform(-3, 3, 6)])]).astype(np.float32)
    bm = WEIGHTING.build("beam_model", occupancy=occ, origin_xy=origin, resolution_m=res, max_range_m=8.0, device="cpu")
    out = wp.zeros(len(particles), dtype=wp.float32, device="cpu")
    bm(wp.array(particles, dtype=wp.vec3, device="cpu"), (0, 0, 0), wp.array(angles, dtype=wp.float32, device="cpu"),
       wp.array(measured, dtype=wp.float32, device="cpu"), out)
    twin = beam_model_log_weights(occ, origin, res, particles.astype(np.float32), (0, 0, 0), angles, measured,
                                  0.95, 0.1, 0.05, 0.05, 0.2, 0.1, 8.0, 0.5)
    assert np.allclose(out.numpy(), twin, rtol=1e-3, atol=1e-2), f"seed {rng.seed}"
    assert out.numpy()[0] > out.numpy()[1:].max()
