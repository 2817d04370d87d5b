"""IR-MCL's observation model on the NOG: the Warp kernel against its numpy twin, and hand cases."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
import warp as wp

from irmcl_warp.nog import NOG, evaluate_grid
from irmcl_warp.services.nog import bake_nog
from irmcl_warp.reference.weighting import nog_log_weights, nog_render
from irmcl_warp.kernels import WEIGHTING
from tests.devices import DEVICE


def _wall_nog(x_wall=2.0, res=0.05):
    occ = np.zeros((81, 121), np.float32)  # nodes over x in [-1, 5], y in [-2, 2]
    occ[:, int(round((x_wall + 1.0) / res))] = 1.0
    return NOG(occ, (-1.0, -2.0), res)


def test_pose_two_metres_before_a_wall_renders_two_metres():
    nog = _wall_nog()
    w = WEIGHTING.build(
        "nog_raymarch", nog=nog, num_particles=1, num_beams=1, num_samples=256, near_m=0.0, far_m=10.0, device=DEVICE
    )
    particles = wp.array(np.array([[0.0, 0.0, 0.0]], np.float32), dtype=wp.vec3, device=DEVICE)
    angles = wp.array(np.zeros(1, np.float32), dtype=wp.float32, device=DEVICE)
    r = w.render(particles, (0.0, 0.0, 0.0), angles).numpy()[0, 0]
    assert abs(r - 2.0) <= 0.5 * nog.resolution_m


def _random_nog_grid(rng, kind):
    if kind == "noise":  # mostly free, some walls, every level of occupancy
        return (rng.uniform(0, 1, (60, 80)) ** 6).astype(np.float32)
    from scipy.ndimage import gaussian_filter  # "rooms": blurred random walls over a faint background, as a NOF

    occ = np.zeros((60, 80), np.float32)
    for _ in range(14):
        x0, y0 = rng.integers(0, 80), rng.integers(0, 60)
        if rng.uniform() < 0.5:
            occ[y0, x0 : x0 + rng.integers(5, 40)] = 1.0
        else:
            occ[y0 : y0 + rng.integers(5, 30), x0] = 1.0
    return np.clip(gaussian_filter(occ, 0.8) * 2.5 + rng.uniform(0, 2e-3, occ.shape), 0, 1).astype(np.float32)


@pytest.mark.parametrize(
    "kind, t_min, empty_below, batch, beam_major",
    [
        ("noise", 0.0, 0.0, 1, False),
        ("noise", 1e-3, 0.0, 4, True),
        ("noise", 0.0, 0.01, 1, True),
        ("rooms", 0.0, 0.0, 4, False),
        ("rooms", 1e-3, 0.01, 1, True),
        ("rooms", 0.0, 0.05, 1, False),
        ("rooms", 1e-3, 0.0, 3, False),
        ("rooms", 1e-3, 0.0, 1, True),
    ],
)
def test_kernel_matches_numpy_twin(rng, kind, t_min, empty_below, batch, beam_major):
    """Every sample in the twin; the kernel's grid clipping, jumps over empty space, batched node loads and
    thread order (by beam or by particle) must give the same."""
    occ = _random_nog_grid(rng, kind)
    nog = NOG(occ, (rng.uniform(-2, 2), rng.uniform(-2, 2)), 0.1)
    P, B = 60, 16
    particles = np.stack([rng.uniform(-3, 7, P), rng.uniform(-3, 5, P), rng.uniform(-np.pi, np.pi, P)], -1).astype(
        np.float32
    )
    angles = np.linspace(-2.0, 2.0, B).astype(np.float32)
    T_bl = (0.1, -0.05, 0.02)
    measured = rng.uniform(0.5, 6.0, B).astype(np.float32)
    measured[3] = np.nan
    w = WEIGHTING.build(
        "nog_raymarch",
        nog=nog,
        num_particles=P,
        num_beams=B,
        num_samples=128,
        near_m=0.02,
        far_m=12.0,
        t_min=t_min,
        sigma_m=0.5,
        empty_below=empty_below,
        batch=batch,
        beam_major=beam_major,
        device=DEVICE,
    )
    pw = wp.array(particles, dtype=wp.vec3, device=DEVICE)
    aw = wp.array(angles, dtype=wp.float32, device=DEVICE)
    logw = wp.zeros(P, dtype=wp.float32, device=DEVICE)
    w(pw, T_bl, aw, wp.array(measured, dtype=wp.float32, device=DEVICE), logw)
    ours = w.rendered.numpy()
    twin = nog_render(
        occ, nog.origin_xy, nog.resolution_m, particles, T_bl, angles, 128, 0.02, 12.0, t_min, empty_below
    )
    close = np.abs(ours - twin) < 1e-3
    assert close.mean() > 0.99, (
        f"seed {rng.seed}: {close.mean():.3f} of beams agree"
    )  # float32 rounding at node borders
    assert (twin > 0.1).mean() > 0.15  # the case has walls to hit
    twin_logw = nog_log_weights(ours.astype(np.float64), measured.astype(np.float64), 0.5)
    assert np.allclose(logw.numpy(), twin_logw, rtol=1e-4, atol=1e-4), f"seed {rng.seed}"
    w(pw, T_bl, aw, wp.array(measured, dtype=wp.float32, device=DEVICE), logw)  # the per-particle sums were reset
    assert np.allclose(logw.numpy(), twin_logw, rtol=1e-4, atol=1e-4)


def test_beam_count_mismatch_is_a_clear_error():
    w = WEIGHTING.build("nog_raymarch", nog=_wall_nog(), num_particles=2, num_beams=32, device=DEVICE)
    p = wp.zeros(2, dtype=wp.vec3, device=DEVICE)
    with pytest.raises(ValueError, match="31 measured ranges / 31 angles, built for 32 beams"):
        w(
            p,
            (0, 0, 0),
            wp.zeros(31, dtype=wp.float32, device=DEVICE),
            wp.zeros(31, dtype=wp.float32, device=DEVICE),
            wp.zeros(2, dtype=wp.float32, device=DEVICE),
        )
    with pytest.raises(ValueError, match="NOG is empty"):
        WEIGHTING.build(
            "nog_raymarch",
            nog=NOG(np.zeros((0, 0), np.float32), (0, 0), 0.05),
            num_particles=1,
            num_beams=1,
            device=DEVICE,
        )


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
    a = bake_nog(ckpt, (0, 0, 1, 1), 40.0, 0.1, cache_dir=tmp_path / "nog")
    assert len(list((tmp_path / "nog").glob("nog-*.npz"))) == 1
    b = bake_nog(ckpt, (0, 0, 1, 1), 40.0, 0.1, cache_dir=tmp_path / "nog")
    assert np.array_equal(a.occupancy, b.occupancy)
    bake_nog(ckpt, (0, 0, 1, 1), 40.0, 0.05, cache_dir=tmp_path / "nog")
    assert len(list((tmp_path / "nog").glob("nog-*.npz"))) == 2


def test_likelihood_field_matches_twin_and_prefers_the_true_pose(rng):
    from irmcl_warp.reference.weighting import likelihood_field_log_weights
    from irmcl_warp.kernels.raycast import distance_to_occupied

    occ = np.zeros((60, 80), np.float32)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1.0  # a 8 x 6 m room at 0.1 m
    occ[20:40, 50] = 1.0
    origin, res = (0.0, 0.0), 0.1
    true = np.array([3.0, 3.0, 0.3])
    angles = np.linspace(-np.pi, np.pi, 24, endpoint=False).astype(np.float32)
    from irmcl_warp.kernels import RAYCAST

    caster = RAYCAST.build("dda", occupancy=occ, origin_xy=origin, resolution_m=res, far_m=20.0, device=DEVICE)
    # +half a cell: end points inside the wall cell, not on its border (where float32 and float64 floor differ)
    measured = (caster.cast_numpy(true[None], angles)[0] + 0.05).astype(np.float32)
    measured[5] = np.nan
    particles = np.vstack(
        [
            true,
            true + [0.5, 0.0, 0.0],
            true + [0.0, 0.0, 0.3],
            np.column_stack([rng.uniform(1, 7, 20), rng.uniform(1, 5, 20), rng.uniform(-3, 3, 20)]),
        ]
    ).astype(np.float32)
    lf = WEIGHTING.build("likelihood_field", occupancy=occ, origin_xy=origin, resolution_m=res, device=DEVICE)
    out = wp.zeros(len(particles), dtype=wp.float32, device=DEVICE)
    lf(
        wp.array(particles, dtype=wp.vec3, device=DEVICE),
        (0, 0, 0),
        wp.array(angles, dtype=wp.float32, device=DEVICE),
        wp.array(measured, dtype=wp.float32, device=DEVICE),
        out,
    )
    ours = out.numpy()
    twin = likelihood_field_log_weights(
        distance_to_occupied(occ, res, 0.65),
        origin,
        res,
        particles.astype(np.float64),
        (0, 0, 0),
        angles,
        measured,
        0.95,
        0.05,
        0.2,
        30.0,
        2.0,
    )
    assert np.allclose(ours, twin, rtol=1e-4, atol=1e-3), f"seed {rng.seed}"
    assert ours[0] > ours[1] and ours[0] > ours[2] and ours[0] >= ours[3:].max()
    with pytest.raises(ValueError, match="map is empty"):
        WEIGHTING.build(
            "likelihood_field", occupancy=np.zeros((5, 5)), origin_xy=origin, resolution_m=res, device=DEVICE
        )


def test_beam_model_matches_twin_and_prefers_the_true_pose(rng):
    from irmcl_warp.reference.weighting import beam_model_log_weights
    from irmcl_warp.kernels import RAYCAST

    occ = np.zeros((40, 50), np.float32)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1.0  # a 5 x 4 m room at 0.1 m
    occ[10:25, 30] = 1.0
    origin, res = (0.0, 0.0), 0.1
    true = np.array([2.0, 2.0, 0.3])
    angles = np.linspace(-np.pi, np.pi, 12, endpoint=False).astype(np.float32)
    caster = RAYCAST.build("dda", occupancy=occ, origin_xy=origin, resolution_m=res, far_m=8.0, device=DEVICE)
    measured = (caster.cast_numpy(true[None], angles)[0] + rng.normal(0, 0.02, len(angles))).astype(np.float32)
    measured[4] = np.nan
    particles = np.vstack(
        [
            true,
            true + [0.4, 0.0, 0.0],
            true + [0.0, 0.0, 0.25],
            np.column_stack([rng.uniform(1, 4, 6), rng.uniform(1, 3, 6), rng.uniform(-3, 3, 6)]),
        ]
    ).astype(np.float32)
    bm = WEIGHTING.build("beam_model", occupancy=occ, origin_xy=origin, resolution_m=res, far_m=8.0, device=DEVICE)
    out = wp.zeros(len(particles), dtype=wp.float32, device=DEVICE)
    bm(
        wp.array(particles, dtype=wp.vec3, device=DEVICE),
        (0, 0, 0),
        wp.array(angles, dtype=wp.float32, device=DEVICE),
        wp.array(measured, dtype=wp.float32, device=DEVICE),
        out,
    )
    twin = beam_model_log_weights(
        occ,
        origin,
        res,
        particles.astype(np.float32),
        (0, 0, 0),
        angles,
        measured,
        0.95,
        0.1,
        0.05,
        0.05,
        0.2,
        0.1,
        8.0,
        0.5,
    )
    assert np.allclose(out.numpy(), twin, rtol=1e-3, atol=1e-2), f"seed {rng.seed}"
    assert out.numpy()[0] > out.numpy()[1:].max()


def test_torch_formulation_of_the_bench_matches_the_twin(rng):
    """The speed reference of eval.bench mcl computes the same log-weights as the numpy twin."""
    from irmcl_warp.reference.weighting import nog_log_weights_torch

    occ = _random_nog_grid(rng, "rooms")
    origin = (rng.uniform(-2, 2), rng.uniform(-2, 2))
    P, B = 37, 8
    particles = np.stack([rng.uniform(-1, 6, P), rng.uniform(-1, 4, P), rng.uniform(-np.pi, np.pi, P)], -1)
    angles = np.linspace(-1.5, 1.5, B)
    measured = rng.uniform(0.5, 6.0, B)
    measured[2] = np.nan
    T_bl = (0.1, -0.05, 0.02)
    ours = nog_log_weights_torch(
        torch.tensor(occ, dtype=torch.float64),
        origin,
        0.1,
        torch.tensor(particles),
        T_bl,
        torch.tensor(angles),
        torch.tensor(measured),
        64,
        0.02,
        8.0,
        0.5,
        chunk=10,
    ).numpy()
    twin = nog_log_weights(nog_render(occ, origin, 0.1, particles, T_bl, angles, 64, 0.02, 8.0), measured, 0.5)
    assert np.allclose(ours, twin, atol=1e-9), f"seed {rng.seed}"
    assert twin.std() > 0.01  # the particles are told apart


def test_nof_direct_matches_its_twin_and_prefers_the_true_pose(rng):
    import irmcl_warp.nof.direct  # noqa: F401  (registers nof_direct)

    """The MLP queried at every sample: the twin composites in torch; a small NOF trained on nothing still
    gives the same numbers, and a field that is one wall weighs the pose that sees it right the highest."""
    from irmcl_warp.config import ModelConfig
    from irmcl_warp.nof.model import NOF
    from irmcl_warp.reference.render import composite_torch

    torch.manual_seed(int(rng.integers(1 << 30)))
    model = NOF(ModelConfig(width=32, depth=2, skip_after=1, num_freqs=4)).eval()
    P, B, S = 7, 5, 48
    particles = np.column_stack([rng.uniform(-2, 2, (P, 2)), rng.uniform(-np.pi, np.pi, P)]).astype(np.float32)
    angles = np.linspace(-1.0, 1.0, B).astype(np.float32)
    measured = rng.uniform(1, 5, B).astype(np.float32)
    measured[1] = np.nan
    T_bl = (0.1, 0.0, 0.05)
    twin_model = copy.deepcopy(model)  # nof_direct moves its model to the device it runs on
    w = WEIGHTING.build(
        "nof_direct",
        model=model,
        num_particles=P,
        num_beams=B,
        num_samples=S,
        near_m=0.02,
        far_m=6.0,
        sigma_m=0.5,
        chunk_rays=8,
        device=DEVICE,
    )
    logw = wp.zeros(P, dtype=wp.float32, device=DEVICE)
    w(
        wp.array(particles, dtype=wp.vec3, device=DEVICE),
        T_bl,
        wp.array(angles, dtype=wp.float32, device=DEVICE),
        wp.array(measured, dtype=wp.float32, device=DEVICE),
        logw,
    )
    # twin: the same points, the MLP, composite_torch, the Gaussian on the mean L1 error
    yaw = particles[:, 2:3].astype(np.float64) + T_bl[2] + angles[None, :]
    c, s = np.cos(particles[:, 2]), np.sin(particles[:, 2])
    o = np.stack([particles[:, 0] + c * T_bl[0], particles[:, 1] + s * T_bl[0]], -1)
    z = np.linspace(0.02, 6.0, S)
    pts = o[:, None, None, :] + np.stack([np.cos(yaw), np.sin(yaw)], -1)[:, :, None, :] * z[:, None]
    with torch.no_grad():
        occ = twin_model(torch.tensor(pts.reshape(-1, 2), dtype=torch.float32)).reshape(P * B, S)
        r = composite_torch(occ.double(), torch.tensor(z).expand(P * B, S))[0].numpy().reshape(P, B)
    assert np.allclose(logw.numpy(), nog_log_weights(r, measured.astype(np.float64), 0.5), atol=1e-4), (
        f"seed {rng.seed}"
    )

    class Wall(torch.nn.Module):  # p_occ = 1 beyond x = 2
        def forward(self, xy):
            return (xy[:, 0] > 2.0).float()

    wall = WEIGHTING.build(
        "nof_direct", model=Wall(), num_particles=2, num_beams=1, num_samples=256, near_m=0.0, far_m=10.0, device=DEVICE
    )
    two = wp.array(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], np.float32), dtype=wp.vec3, device=DEVICE)
    lw = wp.zeros(2, dtype=wp.float32, device=DEVICE)
    wall(
        two,
        (0, 0, 0),
        wp.zeros(1, dtype=wp.float32, device=DEVICE),
        wp.array([2.0], dtype=wp.float32, device=DEVICE),
        lw,
    )
    assert lw.numpy()[0] > -0.01 > lw.numpy()[1]  # 2 m before the wall: right; 1 m before: 1 m off


@pytest.mark.parametrize("kind, t_min, empty_below", [("noise", 0.0, 0.0), ("rooms", 1e-3, 0.0), ("rooms", 1e-3, 0.01)])
def test_range_table_matches_numpy_twin(rng, kind, t_min, empty_below):
    """nog_table: the table built by the march on the device against the twin's march from every node, and
    the reads (nearest node, two headings, the move along the beam) against the twin on the same table."""
    from irmcl_warp.reference.weighting import nog_table_build, nog_table_ranges

    occ = _random_nog_grid(rng, kind)[:30, :45]
    occ[[0, -1], :] = occ[:, [0, -1]] = 1.0  # a room around it all: most rays from inside meet a wall
    nog = NOG(occ, (rng.uniform(-2, 2), rng.uniform(-2, 2)), 0.1)
    P, B, A, far_m = 70, 12, int(rng.integers(16, 40)), 8.0
    w = WEIGHTING.build(
        "nog_table",
        nog=nog,
        num_particles=P,
        num_beams=B,
        num_angles=A,
        num_samples=64,
        near_m=0.02,
        far_m=far_m,
        t_min=t_min,
        empty_below=empty_below,
        device=DEVICE,
    )
    table = w.table.numpy()
    twin = nog_table_build(occ, nog.origin_xy, nog.resolution_m, A, 64, 0.02, far_m, t_min, empty_below)
    off = np.abs(table.astype(int) - twin.astype(int))
    # float32 against float64 marches: a sample on a node's half-cell border reads the other node now and then, which
    # moves an entry by millimetres (on the "noise" fields, where every node holds some occupancy, 1.1 % of the
    # entries for seed 1274824087, 0-0.7 % for 40 others); the table is read at centimetres
    assert (off <= 1).mean() > 0.98, f"seed {rng.seed}: {(off <= 1).mean():.4f} of entries within a quantum"
    assert (off * far_m / 65535 <= 0.01).mean() > 0.995, f"seed {rng.seed}: entries beyond 1 cm"
    assert (twin > 0).mean() > 0.5  # walls to hit
    # particles partly off the grid (they read its edge); headings anywhere, past +-pi included
    particles = np.stack([rng.uniform(-3, 4, P), rng.uniform(-3, 2, P), rng.uniform(-7, 7, P)], -1).astype(np.float32)
    angles = np.sort(rng.uniform(-2.0, 2.0, B)).astype(np.float32)
    T_bl = (0.1, -0.05, 0.02)
    measured = rng.uniform(0.5, 6.0, B).astype(np.float32)
    measured[2] = np.nan
    logw = wp.zeros(P, dtype=wp.float32, device=DEVICE)
    pw, aw = wp.array(particles, dtype=wp.vec3, device=DEVICE), wp.array(angles, dtype=wp.float32, device=DEVICE)
    w(pw, T_bl, aw, wp.array(measured, dtype=wp.float32, device=DEVICE), logw)  # ranges and likelihood in one kernel
    ours = w.render(pw, T_bl, aw).numpy()  # the ranges alone
    twin_r = nog_table_ranges(table, occ.shape, nog.origin_xy, nog.resolution_m, far_m, particles, T_bl, angles)
    assert np.allclose(ours, twin_r, atol=2e-4), f"seed {rng.seed}: {np.abs(ours - twin_r).max()}"
    assert np.allclose(logw.numpy(), nog_log_weights(twin_r, measured.astype(np.float64), 0.5), rtol=1e-4, atol=1e-4)


def test_range_table_reads_what_the_march_renders():
    """At a node and one of the table's headings the table gives the march's range (to a quantum); off the
    node, moving along the beam shortens the range by the move (a wall across the beam); between headings
    the range of a straight wall stays close to the march's."""
    from irmcl_warp.kernels.weighting import TABLE_LEVELS, table_headings

    nog, far_m = _wall_nog(x_wall=2.0), 10.0
    A = 72
    table = WEIGHTING.build(
        "nog_table",
        nog=nog,
        num_particles=64,
        num_beams=1,
        num_angles=A,
        num_samples=256,
        near_m=0.0,
        far_m=far_m,
        device=DEVICE,
    )
    march = WEIGHTING.build(
        "nog_raymarch", nog=nog, num_particles=64, num_beams=1, num_samples=256, near_m=0.0, far_m=far_m, device=DEVICE
    )
    beam = wp.array(np.zeros(1, np.float32), dtype=wp.float32, device=DEVICE)
    at_nodes = np.array(
        [[x, y, h] for x, y in [(0.0, 0.0), (0.5, -0.3), (1.2, 0.65)] for h in table_headings(A)[[0, 3, 69]]],
        np.float32,
    )
    pw = wp.array(at_nodes, dtype=wp.vec3, device=DEVICE)
    got, want = table.render(pw, (0, 0, 0), beam).numpy()[:9, 0], march.render(pw, (0, 0, 0), beam).numpy()[:9, 0]
    assert np.all(np.abs(got - want) <= far_m / TABLE_LEVELS), (got, want)
    xs = np.linspace(0.0, 0.5, 41)  # along the beam (heading 0) through nodes and between them
    along = wp.array(
        np.stack([xs, np.full_like(xs, 0.01), np.zeros_like(xs)], -1).astype(np.float32), dtype=wp.vec3, device=DEVICE
    )
    r = table.render(along, (0, 0, 0), beam).numpy()[:41, 0]
    assert np.all(np.abs(r - (2.0 - xs)) < 0.05), np.abs(r - (2.0 - xs)).max()
    assert np.all(np.diff(r) < 0)  # smooth: the march itself moves in steps of its samples
    tilted = np.deg2rad(np.linspace(-20, 20, 17))  # between the table's 5-degree headings
    pt = wp.array(np.stack([np.zeros(17), np.zeros(17), tilted], -1).astype(np.float32), dtype=wp.vec3, device=DEVICE)
    r = table.render(pt, (0, 0, 0), beam).numpy()[:17, 0]
    assert np.all(np.abs(r - 2.0 / np.cos(tilted)) < 0.06), np.abs(r - 2.0 / np.cos(tilted)).max()


def test_range_table_too_large_or_too_coarse_is_a_clear_error(monkeypatch):
    import irmcl_warp.kernels.weighting.nog_table as kw

    nog = _wall_nog()
    monkeypatch.setattr(kw, "TABLE_MAX_BYTES", 1 << 20)
    with pytest.raises(ValueError, match=r"81x121 nodes x 720 headings need .*mcl.table_angles"):
        WEIGHTING.build("nog_table", nog=nog, num_particles=1, num_beams=1, num_angles=720, device=DEVICE)
    with pytest.raises(ValueError, match="at least 4 headings"):
        WEIGHTING.build("nog_table", nog=nog, num_particles=1, num_beams=1, num_angles=2, device=DEVICE)


def _per_beam_field_kernel(z_hit, z_rand, sigma_hit, far_m, max_dist):
    """The likelihood field as it was computed before the per-cell table (commit 3319b3a): log q per beam, with
    the beam's direction turned from its (cos, sin) as the kernel does since (one cosine and sine per
    particle); what differs is only where log q comes from."""
    from irmcl_warp.kernels.weighting import beam_origin

    @wp.kernel(module="unique")
    def field(
        dist: wp.array2d(dtype=wp.float32),
        origin: wp.vec2,
        res: float,
        particles: wp.array(dtype=wp.vec3),
        T_base_laser: wp.vec3,
        beam_cs: wp.array(dtype=wp.vec2),
        measured: wp.array(dtype=wp.float32),
        log_lik: wp.array(dtype=wp.float32),
    ):
        p = wp.tid()
        s = float(0.0)
        heading = particles[p][2] + T_base_laser[2]
        c = wp.cos(heading)
        sn = wp.sin(heading)
        for b in range(beam_cs.shape[0]):
            m = measured[b]
            if m == m:
                o = beam_origin(particles[p], T_base_laser)
                cs = beam_cs[b]
                ex = o[0] + m * (c * cs[0] - sn * cs[1])
                ey = o[1] + m * (sn * cs[0] + c * cs[1])
                ix = int(wp.floor((ex - origin[0]) / res))
                iy = int(wp.floor((ey - origin[1]) / res))
                d = wp.static(max_dist)
                if ix >= 0 and iy >= 0 and ix < dist.shape[1] and iy < dist.shape[0]:
                    d = wp.min(dist[iy, ix], wp.static(max_dist))
                q = wp.static(z_hit) * wp.exp(-d * d / wp.static(2.0 * sigma_hit * sigma_hit)) + wp.static(
                    z_rand / far_m
                )
                s += wp.log(q)
        log_lik[p] = s

    return field


def test_the_likelihood_field_s_table_of_log_q_gives_the_per_beam_bits(rng):
    """log q read per cell from the table made at start is what computing it per beam gave, bit for bit, on
    fresh random maps, poses (end points on and off the map) and settings."""
    from irmcl_warp.kernels.raycast import distance_to_occupied

    H, W, res = int(rng.integers(20, 60)), int(rng.integers(20, 60)), float(rng.uniform(0.03, 0.2))
    occ = (rng.random((H, W)) < 0.05).astype(np.float32)
    occ[0, 0] = 1.0
    origin = (float(rng.uniform(-2, 2)), float(rng.uniform(-2, 2)))
    z_hit, sigma, far_m, max_dist = float(rng.uniform(0.3, 0.95)), float(rng.uniform(0.05, 0.5)), 20.0, 2.0
    P, B = 300, 40
    lo, hi = np.array(origin) - 1.0, np.array(origin) + [W * res + 1.0, H * res + 1.0]
    particles = np.column_stack([rng.uniform(lo[0], hi[0], P), rng.uniform(lo[1], hi[1], P), rng.uniform(-4, 4, P)])
    angles = np.sort(rng.uniform(-np.pi, np.pi, B)).astype(np.float32)
    measured = rng.uniform(0.1, 6.0, B).astype(np.float32)
    measured[rng.integers(0, B, 4)] = np.nan
    T = (float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.1, 0.1)))
    args = [
        wp.array(particles.astype(np.float32), dtype=wp.vec3, device=DEVICE),
        wp.vec3(*T),
        wp.array(angles, dtype=wp.float32, device=DEVICE),
        wp.array(measured, dtype=wp.float32, device=DEVICE),
    ]
    lf = WEIGHTING.build(
        "likelihood_field",
        occupancy=occ,
        origin_xy=origin,
        resolution_m=res,
        z_hit=z_hit,
        z_rand=1.0 - z_hit,
        sigma_hit_m=sigma,
        far_m=far_m,
        max_dist_m=max_dist,
        device=DEVICE,
    )
    ours = wp.zeros(P, dtype=wp.float32, device=DEVICE)
    lf(args[0], T, args[2], args[3], ours)
    before = wp.zeros(P, dtype=wp.float32, device=DEVICE)
    dist = wp.array(distance_to_occupied(occ, res, 0.65).astype(np.float32), dtype=wp.float32, device=DEVICE)
    wp.launch(
        _per_beam_field_kernel(z_hit, 1.0 - z_hit, sigma, far_m, max_dist),
        P,
        [dist, wp.vec2(*origin), res, args[0], args[1], lf.beams(args[2]), args[3], before],
        device=DEVICE,
    )
    assert np.array_equal(ours.numpy(), before.numpy()), (
        f"seed {rng.seed}: {np.abs(ours.numpy() - before.numpy()).max()}"
    )


@pytest.mark.parametrize("model", ["likelihood_field", "beam_model"])
def test_grid_models_split_over_cpu_cores_give_the_same_bits(rng, model):
    """mcl.cpu_threads: a grid model's launch split into a block of particles per core (ParticleBlocks) gives
    every particle the bits one launch gives (on a GPU both are one launch)."""
    occ = (rng.random((50, 70)) < 0.04).astype(np.float32)
    occ[0, :] = 1.0
    from irmcl_warp.kernels.registry import CPU_MIN_BLOCK

    P = int(rng.integers(3 * CPU_MIN_BLOCK + 1, 4 * CPU_MIN_BLOCK))  # 3 blocks
    particles = np.column_stack([rng.uniform(0, 7, P), rng.uniform(0, 5, P), rng.uniform(-3, 3, P)])
    angles = np.sort(rng.uniform(-np.pi, np.pi, 20)).astype(np.float32)
    measured = rng.uniform(0.2, 6.0, 20).astype(np.float32)
    inputs = (
        wp.array(particles.astype(np.float32), dtype=wp.vec3, device=DEVICE),
        (0.1, 0.0, 0.02),
        wp.array(angles, dtype=wp.float32, device=DEVICE),
        wp.array(measured, dtype=wp.float32, device=DEVICE),
    )
    outs = []
    for threads in (1, 3):
        m = WEIGHTING.build(
            model, occupancy=occ, origin_xy=(0.0, 0.0), resolution_m=0.1, cpu_threads=threads, device=DEVICE
        )
        outs.append(wp.zeros(P, dtype=wp.float32, device=DEVICE))
        m(*inputs, outs[-1])
    assert np.isfinite(outs[0].numpy()).all()
    assert np.array_equal(outs[0].numpy(), outs[1].numpy()), f"seed {rng.seed}"


def test_the_range_table_split_over_cpu_cores_gives_the_same_bits(rng):
    """nog_table with mcl.cpu_threads: its likelihood launched in a block of particles per core (as the filter's
    step runs it on a CPU, each core moving and weighing its block) gives every particle the bits of one launch."""
    from irmcl_warp.kernels.registry import CPU_MIN_BLOCK

    occ = _random_nog_grid(rng, "walls")[:30, :45]
    occ[[0, -1], :] = occ[:, [0, -1]] = 1.0
    nog = NOG(occ, (0.0, 0.0), 0.1)
    P, B = int(rng.integers(3 * CPU_MIN_BLOCK + 1, 4 * CPU_MIN_BLOCK)), 12
    particles = np.stack([rng.uniform(0, 4.5, P), rng.uniform(0, 3, P), rng.uniform(-4, 4, P)], -1).astype(np.float32)
    inputs = (
        wp.array(particles, dtype=wp.vec3, device=DEVICE),
        (0.1, -0.05, 0.02),
        wp.array(np.sort(rng.uniform(-2.0, 2.0, B)).astype(np.float32), dtype=wp.float32, device=DEVICE),
        wp.array(rng.uniform(0.5, 4.0, B).astype(np.float32), dtype=wp.float32, device=DEVICE),
    )
    table, outs = None, []
    for threads in (1, 3):
        w = WEIGHTING.build(
            "nog_table", nog=nog, num_particles=P, num_beams=B, num_angles=24, num_samples=64, far_m=8.0,
            table=table, cpu_threads=threads, device=DEVICE,
        )  # fmt: skip
        table = w.table
        assert w.blocks.blocks_for(P) == (1 if threads == 1 or DEVICE.startswith("cuda") else 3)
        outs.append(wp.zeros(P, dtype=wp.float32, device=DEVICE))
        w(*inputs, outs[-1])
    assert np.isfinite(outs[0].numpy()).all() and np.array_equal(outs[0].numpy(), outs[1].numpy()), f"seed {rng.seed}"
