"""Motion, weights and resampling kernels: statistics against the numpy twins, and resampling invariants."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from irmcl_warp.reference.motion import sample_odometry
from irmcl_warp.reference.resample import (
    effective_sample_size,
    low_variance_indices,
    multinomial_indices,
    weighted_mean,
    weighted_spread,
)
from irmcl_warp.kernels import MOTION, RESAMPLE
from irmcl_warp.kernels.motion import odometry_step
from irmcl_warp.kernels.resample import ParticleWeights
from tests.devices import DEVICE

ALPHAS = (0.1, 0.02, 0.08, 0.01)


def test_odometry_step_decomposes_a_motion():
    r1, t, r2 = odometry_step((1.0, 2.0, 0.5), (1.0 + np.cos(1.0), 2.0 + np.sin(1.0), 1.6))
    assert (r1, t, r2) == pytest.approx((0.5, 1.0, 0.6))
    assert odometry_step((0, 0, 0), (0, 0, 0.3)) == pytest.approx((0.0, 0.0, 0.3))  # turning in place


def test_motion_kernel_statistics_match_the_twin(rng):
    n, step = 40000, (0.3, 0.8, -0.2)
    start = np.tile(np.array([[1.0, -2.0, 0.4]], np.float32), (n, 1))
    p = wp.array(start, dtype=wp.vec3, device=DEVICE)
    MOTION.build("odometry", alphas=ALPHAS, device=DEVICE)(p, step, seed=int(rng.integers(1 << 30)))
    ours = p.numpy().astype(np.float64)
    twin = sample_odometry(start.astype(np.float64), step, ALPHAS, rng)
    assert np.allclose(ours.mean(0), twin.mean(0), atol=0.01), f"seed {rng.seed}"
    assert np.allclose(np.cov(ours.T), np.cov(twin.T), atol=2e-3, rtol=0.1), f"seed {rng.seed}"
    # noiseless odometry moves every particle exactly
    q = wp.array(start[:3], dtype=wp.vec3, device=DEVICE)
    MOTION.build("odometry", alphas=(0, 0, 0, 0), device=DEVICE)(q, step, seed=1)
    x = 1.0 + 0.8 * np.cos(0.7)
    assert np.allclose(q.numpy()[0], [x, -2.0 + 0.8 * np.sin(0.7), 0.5], atol=1e-5)
    with pytest.raises(ValueError, match="4 non-negative alphas"):
        MOTION.build("odometry", alphas=(0.1, 0.1), device=DEVICE)


def _weights(rng, n):
    log_w = rng.normal(0, 2, n).astype(np.float32)
    particles = np.stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-np.pi, np.pi, n)], -1).astype(
        np.float32
    )
    pw = wp.array(particles, dtype=wp.vec3, device=DEVICE)
    weights = ParticleWeights(n, device=DEVICE, keep_cos_sin=True)
    weights.update(wp.array(log_w, dtype=wp.float32, device=DEVICE), pw)
    return log_w, particles, pw, weights


def test_neff_and_mean_match_the_twin(rng):
    log_w, particles, _, weights = _weights(rng, 500)
    pose, neff, spread = weights.summary()
    assert neff == pytest.approx(effective_sample_size(log_w), rel=1e-4)
    assert np.allclose(pose, weighted_mean(particles.astype(np.float64), log_w), atol=1e-4)
    assert spread == pytest.approx(weighted_spread(particles, log_w), rel=1e-3)
    # far from the origin the centred sums keep the spread of a tight cluster
    tight = np.column_stack([rng.normal(0, 0.05, (500, 2)) + [300.0, -250.0], np.zeros(500)]).astype(np.float32)
    off_centre = ParticleWeights(500, device=DEVICE, centre=(299.0, -251.0))
    off_centre.update(wp.array(log_w, dtype=wp.float32, device=DEVICE), wp.array(tight, dtype=wp.vec3, device=DEVICE))
    assert off_centre.summary()[2] == pytest.approx(weighted_spread(tight, log_w), rel=1e-2)


def test_low_variance_keeps_each_particle_floor_or_ceil_of_its_share(rng):
    n = 1000
    log_w, particles, pw, weights = _weights(rng, n)
    dst = wp.zeros(n, dtype=wp.vec3, device=DEVICE)
    offset = float(rng.uniform())
    RESAMPLE.build("low_variance", device=DEVICE)(weights.cdf, pw, dst, offset)
    out = dst.numpy()
    # map drawn particles back to their index (positions are unique)
    index = {tuple(p): i for i, p in enumerate(particles)}
    drawn = np.array([index[tuple(p)] for p in out])
    counts = np.bincount(drawn, minlength=n)
    share = n * np.exp(log_w - log_w.max()) / np.exp(log_w - log_w.max()).sum()
    assert np.all((counts >= np.floor(share) - 1) & (counts <= np.ceil(share) + 1)), f"seed {rng.seed}"
    twin = low_variance_indices(log_w, offset)
    assert (drawn == twin).mean() > 0.99, f"seed {rng.seed}"  # float32 vs float64 cumulative sums at edges


def test_multinomial_draws_follow_the_weights(rng):
    n = 4000
    log_w = np.log(np.where(np.arange(n) < n // 4, 3.0, 1.0)).astype(np.float32)  # first quarter: 3x weight
    particles = np.stack([np.arange(n), np.zeros(n), np.zeros(n)], -1).astype(np.float32)
    pw = wp.array(particles, dtype=wp.vec3, device=DEVICE)
    weights = ParticleWeights(n, device=DEVICE)
    weights.update(wp.array(log_w, dtype=wp.float32, device=DEVICE), pw)
    dst = wp.zeros(n, dtype=wp.vec3, device=DEVICE)
    RESAMPLE.build("multinomial", device=DEVICE)(weights.cdf, pw, dst, float(rng.uniform()))
    share_first = (dst.numpy()[:, 0] < n // 4).mean()
    twin_share = (multinomial_indices(log_w, rng) < n // 4).mean()
    assert abs(share_first - 0.5) < 0.03 and abs(twin_share - 0.5) < 0.03, f"seed {rng.seed}"


def test_top_share_estimate_matches_twin_and_ignores_the_light_tail(rng):
    from irmcl_warp.reference.estimate import top_share_mean
    from irmcl_warp.kernels import ESTIMATE

    n = 1000
    particles = np.column_stack([rng.normal(2.0, 0.1, n), rng.normal(-1.0, 0.1, n), rng.normal(3.1, 0.05, n)])
    log_w = rng.normal(0, 1, n)
    particles[800:, :2] += 20.0  # a far-off tail ...
    log_w[800:] -= 30.0  # ... of the lightest particles
    est = ESTIMATE.build("top_share", num_particles=n, share=0.8, device=DEVICE)
    ours = est(
        wp.array(particles.astype(np.float32), dtype=wp.vec3, device=DEVICE),
        wp.array(log_w.astype(np.float32), dtype=wp.float32, device=DEVICE),
    )
    twin = top_share_mean(particles.astype(np.float32), log_w.astype(np.float32), 0.8)
    assert np.allclose(ours, twin, atol=1e-4), f"seed {rng.seed}"
    assert abs(ours[0] - 2.0) < 0.05 and abs(abs(ours[2]) - 3.1) < 0.1  # yaw near +-pi: circular mean
    with pytest.raises(ValueError, match="share must lie"):
        ESTIMATE.build("top_share", num_particles=10, share=0.0, device=DEVICE)


def test_best_cluster_picks_the_heavier_of_two_places_and_matches_twin(rng):
    """60 % of the mass near A, 40 % near B: the cluster estimate lands on A, the plain mean between them."""
    from irmcl_warp.reference.estimate import best_cluster_mean
    from irmcl_warp.kernels import ESTIMATE

    n = 3000
    a, b = np.array([2.0, 3.0, 0.5]), np.array([-4.0, 1.0, -2.5])
    which = rng.uniform(size=n) < 0.5
    particles = np.where(which[:, None], a, b) + rng.normal(0, 1, (n, 3)) * [0.15, 0.15, 0.05]
    log_w = np.where(which, np.log(0.6), np.log(0.4)) + rng.normal(0, 0.1, n)
    bounds = (-6.0, -2.0, 5.0, 6.0)
    est = ESTIMATE.build("best_cluster", num_particles=n, bounds=bounds, cell_m=0.5, yaw_bins=8, device=DEVICE)
    p32, w32 = particles.astype(np.float32), log_w.astype(np.float32)
    ours = est(wp.array(p32, dtype=wp.vec3, device=DEVICE), wp.array(w32, dtype=wp.float32, device=DEVICE))
    twin = best_cluster_mean(p32, w32, bounds, 0.5, 8)
    assert np.allclose(ours, twin, atol=1e-4), f"seed {rng.seed}: {ours} vs {twin}"
    assert np.hypot(*(ours[:2] - a[:2])) < 0.1 and abs(ours[2] - a[2]) < 0.05, f"seed {rng.seed}: {ours}"
    assert np.hypot(*(weighted_mean(particles, log_w)[:2] - a[:2])) > 1.0  # the plain mean is lost between them
    with pytest.raises(ValueError, match="do not make a histogram"):
        ESTIMATE.build("best_cluster", num_particles=n, bounds=(0, 0, -1, 1), device=DEVICE)


def test_the_cpu_walk_draws_the_particles_the_search_draws(rng):
    """Low-variance resampling: the one-thread walk over the cdf (a CPU's ``systematic_merge_kernel``) and the
    binary search per pointer (``systematic_kernel``) give the same particles and log-weights bit for bit, on fresh
    weights with runs of zero weight (a cdf with flat stretches) and a few dominant particles."""
    from irmcl_warp.kernels.resample import systematic_kernel, systematic_merge_kernel

    n = int(rng.integers(500, 3000))
    log_w = rng.normal(0, 3, n).astype(np.float32)
    log_w[rng.random(n) < 0.3] = -200.0  # exp underflows to 0: the cdf stays flat there
    log_w[rng.integers(0, n, 3)] = 8.0
    particles = rng.normal(0, 5, (n, 3)).astype(np.float32)
    pw = wp.array(particles, dtype=wp.vec3, device=DEVICE)
    weights = ParticleWeights(n, device=DEVICE)
    weights.update(wp.array(log_w, dtype=wp.float32, device=DEVICE), pw)
    offset = wp.array([rng.uniform()], dtype=wp.float32, device=DEVICE)
    out = {}
    for kernel, dim in ((systematic_kernel, n), (systematic_merge_kernel, 1)):
        dst = wp.zeros(n, dtype=wp.vec3, device=DEVICE)
        lw = wp.array(log_w, dtype=wp.float32, device=DEVICE)
        wp.launch(kernel, dim, [weights.cdf, offset, pw, dst, weights.sums, 3.0e38, lw], device=DEVICE)
        out[dim] = (dst.numpy(), lw.numpy())
    assert np.array_equal(out[n][0], out[1][0]) and np.array_equal(out[n][1], out[1][1]), f"seed {rng.seed}"
    assert np.all(out[1][1] == 0.0) and len(np.unique(out[1][0], axis=0)) < n  # resampled: heavy ones repeat


def test_top_share_reading_the_weights_gives_the_bits_it_computes_itself(rng):
    """The top-share estimate with ParticleWeights' w and (cos, sin) shared (as a CPU filter builds it), and with w
    given to its sums (as a GPU filter does), against the estimate computing exp and the yaw's cos and sin itself:
    the same five sums to the bit (top_sums_kernel's three sources)."""
    from irmcl_warp.kernels import ESTIMATE

    n = int(rng.integers(300, 5000))
    log_w, particles, pw, weights = _weights(rng, n)
    lw = wp.array(log_w, dtype=wp.float32, device=DEVICE)
    alone = ESTIMATE.build("top_share", num_particles=n, share=0.8, device=DEVICE)
    shared = ESTIMATE.build("top_share", num_particles=n, share=0.8, device=DEVICE)
    shared.share_weights(weights)
    alone.launch(pw, lw)
    shared.launch(pw, lw)
    assert np.array_equal(alone.sums.numpy(), shared.sums.numpy()), f"seed {rng.seed}"
    given_w = ESTIMATE.build("top_share", num_particles=n, share=0.8, device=DEVICE)  # a GPU filter's way: w given
    given_w.rank(lw)
    given_w.order()
    given_w.sum(pw, lw, weights.w)
    assert np.array_equal(alone.sums.numpy(), given_w.sums.numpy()), f"seed {rng.seed}"
    with pytest.raises(ValueError, match="built for"):
        ESTIMATE.build("top_share", num_particles=n + 1, device=DEVICE).share_weights(weights)
    with pytest.raises(ValueError, match="do not keep"):
        shared.share_weights(ParticleWeights(n, device=DEVICE, keep_cos_sin=False))


@pytest.mark.parametrize("tiled", [False, True])
def test_accumulate_fused_with_the_maximum_keeps_the_bits_of_two_launches(rng, monkeypatch, tiled):
    """ParticleWeights.accumulate (log w += temper log p, the maximum; a GPU's one tiled launch, which also writes the
    top-share sort keys) against accumulate_kernel, max_kernel and rank_keys_kernel launched one after another: the
    same log-weights, maximum, keys and indices to the bit, and the maximum the numpy one."""
    from irmcl_warp.kernels.estimate import rank_keys_kernel
    from irmcl_warp.kernels.resample import accumulate_kernel, max_kernel
    from irmcl_warp.kernels import launch_reduction

    monkeypatch.setattr(ParticleWeights, "TILED", tiled)
    n, temper = int(rng.integers(300, 3000)), float(rng.uniform(0.1, 1.0))
    log_w, log_lik = rng.normal(0, 3, (2, n)).astype(np.float32)
    weights = ParticleWeights(n, device=DEVICE)
    assert weights.tiled == tiled
    keys, values = wp.zeros(2 * n, dtype=wp.float32, device=DEVICE), wp.zeros(2 * n, dtype=wp.int32, device=DEVICE)
    ours = wp.array(log_w, dtype=wp.float32, device=DEVICE)
    lik = wp.array(log_lik, dtype=wp.float32, device=DEVICE)
    weights.accumulate(ours, lik, temper, (keys, values) if tiled else None)
    theirs, top = wp.array(log_w, dtype=wp.float32, device=DEVICE), wp.full(1, -3.0e38, dtype=wp.float32, device=DEVICE)
    their_keys, their_values = wp.zeros_like(keys), wp.zeros_like(values)
    wp.launch(accumulate_kernel, n, [theirs, lik, temper], device=DEVICE)
    launch_reduction(max_kernel, n, [theirs, top], DEVICE)
    wp.launch(rank_keys_kernel, n, [theirs, their_keys, their_values], device=DEVICE)
    assert np.array_equal(ours.numpy(), theirs.numpy()) and weights.top.numpy()[0] == top.numpy()[0]
    assert top.numpy()[0] == pytest.approx(float(np.max(log_w + np.float32(temper) * log_lik)), abs=1e-5)
    if tiled:
        assert np.array_equal(keys.numpy()[:n], their_keys.numpy()[:n])
        assert np.array_equal(values.numpy()[:n], their_values.numpy()[:n])
    else:
        with pytest.raises(ValueError, match="tiled launch only"):
            weights.accumulate(ours, lik, temper, (keys, values))


def test_sums_over_more_particles_than_a_reduction_has_threads_match_the_twins(rng):
    """Above GPU_WIDE_FROM particles a GPU's reductions give each thread 16 items (more rows, summed in about
    sqrt(rows) groups): the weights' sums, N_eff, the spread and the top-share estimate still match the numpy twins
    (on a CPU the same sizes, on 4096 threads); the grouping covers every row once."""
    from irmcl_warp.kernels import ESTIMATE, reduction_threads
    from irmcl_warp.kernels.registry import GPU_WIDE_FROM, REDUCE_THREADS, row_groups
    from irmcl_warp.reference.estimate import top_share_mean

    for rows in (1, 100, REDUCE_THREADS, REDUCE_THREADS + 1, int(rng.integers(5000, 1 << 16)), 1 << 16):
        groups, size = row_groups(rows)
        assert groups * size >= rows and (rows <= REDUCE_THREADS or (groups - 1) * size < rows)
    assert row_groups(REDUCE_THREADS) == (64, 64)  # the grouping up to 4096 rows: as it always was
    assert reduction_threads(100_000, DEVICE) == REDUCE_THREADS  # 100k particles keep their bits
    n = GPU_WIDE_FROM + int(rng.integers(1, 50_000))
    log_w, particles, pw, weights = _weights(rng, n)
    pose, neff, spread = weights.summary()
    assert neff == pytest.approx(effective_sample_size(log_w), rel=1e-3), f"seed {rng.seed}"
    assert np.allclose(pose, weighted_mean(particles.astype(np.float64), log_w), atol=1e-3), f"seed {rng.seed}"
    assert spread == pytest.approx(weighted_spread(particles, log_w), rel=1e-2), f"seed {rng.seed}"
    est = ESTIMATE.build("top_share", num_particles=n, share=0.8, device=DEVICE)
    ours = est(pw, wp.array(log_w, dtype=wp.float32, device=DEVICE))
    twin = top_share_mean(particles, log_w, 0.8)
    assert np.allclose(ours[:2], twin[:2], atol=2e-3), f"seed {rng.seed}"
    assert abs(np.angle(np.exp(1j * (ours[2] - twin[2])))) < 2e-3, f"seed {rng.seed}"


def test_the_ordered_scan_is_the_cumulative_sum_and_repeats_itself_bit_for_bit(rng):
    """ordered_scan (the cdf a GPU resamples from): the numpy cumulative sum within float32 rounding, never
    decreasing for non-negative weights, and the same bits on every call (CUB's scan was not: its tiles' partial sums
    are added in the order the tiles finish). Sizes around the block size, and a set of nearly equal weights, where a
    last-bit difference moves low-variance pointers across particles, and weights over many orders of magnitude, where
    a GPU's tile scan rounded a sum below the one before it (H200, 39,511 weights exp(N(0, 2)))."""
    from irmcl_warp.kernels.resample import SCAN_TILE, ordered_scan

    large = int(rng.integers(3 * SCAN_TILE, 40 * SCAN_TILE))
    for n, spread in ((1, 0), (SCAN_TILE - 1, 0), (SCAN_TILE, 0), (SCAN_TILE + 1, 0), (large, 0), (large, 4.0)):
        if spread:
            w = np.exp(rng.normal(0, spread, n)).astype(np.float32)
        elif n > SCAN_TILE:
            w = (1.0 + 1e-3 * rng.random(n)).astype(np.float32)
        else:
            w = rng.random(n).astype(np.float32)
        wd = wp.array(w, dtype=wp.float32, device=DEVICE)
        totals = wp.zeros(n, dtype=wp.float32, device=DEVICE)
        outs = []
        for _ in range(3):
            cdf = wp.zeros(n, dtype=wp.float32, device=DEVICE)
            ordered_scan(wd, cdf, totals, DEVICE)
            outs.append(cdf.numpy())
        twin = np.cumsum(w.astype(np.float64))
        # float32 running sums: a CPU's (blocks of one) lose up to ~n ulp over n terms, a GPU's blocks far less
        assert np.allclose(outs[0], twin, rtol=max(1e-5, 2 * n * 6e-8), atol=1e-6), f"n {n}, seed {rng.seed}"
        assert np.all(np.diff(outs[0]) >= 0), f"n {n}, seed {rng.seed}"
        assert all(np.array_equal(outs[0], o) for o in outs[1:]), f"n {n} on {DEVICE}, seed {rng.seed}"
    with pytest.raises(ValueError, match="block totals"):
        ordered_scan(wd, cdf, wp.zeros(0, dtype=wp.float32, device=DEVICE), DEVICE)


def test_the_fused_weighing_matches_the_twins_and_keeps_the_scans_bits(rng, monkeypatch):
    """ParticleWeights.weigh in one pass (weigh_scan_kernel + weigh_finish_kernel, a GPU's step) against the launches
    apart (exp_kernel, then ordered_scan): the same w and cdf to the bit, never decreasing; the eight sums,
    N_eff, the mean and the spread those of the numpy twins; the same bits on every call. Sizes around the scan's
    block and above 1024 blocks (more blocks than the finishing block has threads, on a GPU)."""
    from irmcl_warp.kernels.resample import SCAN_TILE

    monkeypatch.setattr(ParticleWeights, "ORDERED_SCAN", True)
    sizes = (1, SCAN_TILE - 1, SCAN_TILE + 1, int(rng.integers(3 * SCAN_TILE, 40 * SCAN_TILE)))
    if wp.get_device(DEVICE).is_cuda:
        sizes += (SCAN_TILE * SCAN_TILE + int(rng.integers(1, 5 * SCAN_TILE)),)
    for n in sizes:
        log_w = rng.normal(0, 2, n).astype(np.float32)
        particles = np.stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-np.pi, np.pi, n)], -1).astype(
            np.float32
        )
        pw, lw = wp.array(particles, dtype=wp.vec3, device=DEVICE), wp.array(log_w, dtype=wp.float32, device=DEVICE)
        done = {}
        for fused in (False, True):
            monkeypatch.setattr(ParticleWeights, "FUSED", fused)
            weights = ParticleWeights(n, device=DEVICE, keep_cos_sin=False, centre=(0.5, -0.5))
            assert weights.fused == fused
            runs = []
            for _ in range(2):
                weights.update(lw, pw)
                runs.append((weights.w.numpy().copy(), weights.cdf.numpy().copy(), weights.sums.numpy().copy()))
            assert all(np.array_equal(a, b) for a, b in zip(*runs)), f"n {n}, fused {fused} on {DEVICE}"
            done[fused] = (runs[0], weights.summary())
        (w_f, cdf_f, sums_f), (pose, neff, spread) = done[True]
        (w_a, cdf_a, sums_a), _ = done[False]
        assert np.array_equal(w_f, w_a) and np.array_equal(cdf_f, cdf_a), f"n {n}, seed {rng.seed}"
        assert np.all(np.diff(cdf_f) >= 0), f"n {n}, seed {rng.seed}"
        assert np.allclose(sums_f, sums_a, rtol=1e-4, atol=1e-3), f"n {n}, seed {rng.seed}"
        assert neff == pytest.approx(effective_sample_size(log_w), rel=1e-3), f"n {n}, seed {rng.seed}"
        assert np.allclose(pose[:2], weighted_mean(particles.astype(np.float64), log_w)[:2], atol=1e-3)
        assert spread == pytest.approx(weighted_spread(particles, log_w), rel=1e-2, abs=2e-3), f"n {n}, seed {rng.seed}"


def test_the_tiled_top_share_sums_match_the_twin_and_repeat_themselves(rng, monkeypatch):
    """TopShareMean's sums by tiled launches (a GPU's) against the strided reduction and the numpy twin: the same
    estimate within float32 rounding, from the log-weights and from the weights given, the same bits on every call;
    k around the tile size and above 1024 tiles on a GPU."""
    from irmcl_warp.kernels import ESTIMATE
    from irmcl_warp.kernels.estimate import TOP_TILE, TopShareMean
    from irmcl_warp.reference.estimate import top_share_mean

    sizes = [2, TOP_TILE + 3, int(rng.integers(5 * TOP_TILE, 30 * TOP_TILE))]
    if wp.get_device(DEVICE).is_cuda:
        sizes.append(int(1.25 * TOP_TILE * TOP_TILE) + int(rng.integers(1, 5000)))
    for n in sizes:
        log_w = rng.normal(0, 2, n).astype(np.float32)
        particles = np.stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-np.pi, np.pi, n)], -1).astype(
            np.float32
        )
        pw, lw = wp.array(particles, dtype=wp.vec3, device=DEVICE), wp.array(log_w, dtype=wp.float32, device=DEVICE)
        w = wp.array(np.exp(log_w - log_w.max()).astype(np.float32), dtype=wp.float32, device=DEVICE)
        got = {}
        for tiled in (False, True):
            monkeypatch.setattr(TopShareMean, "TILED", tiled)
            monkeypatch.setattr(TopShareMean, "SELECT", False)  # the sort's sums (a selection: its own test)
            est = ESTIMATE.build("top_share", num_particles=n, share=0.8, device=DEVICE)
            assert est.tiled == tiled
            first = est(pw, lw)
            sums = est.sums.numpy().copy()
            assert np.array_equal(sums, (est(pw, lw), est.sums.numpy())[1]), f"n {n} on {DEVICE}"
            est.sum(pw, lw, w)  # the weights given (a GPU filter's way): the same weights, the same estimate
            assert np.allclose(est.sums.numpy(), sums, rtol=1e-5, atol=1e-4), f"n {n}, seed {rng.seed}"
            got[tiled] = first
        twin = top_share_mean(particles, log_w, 0.8)
        for tiled, ours in got.items():
            assert np.allclose(ours[:2], twin[:2], atol=2e-3), f"n {n}, tiled {tiled}, seed {rng.seed}"
            assert abs(np.angle(np.exp(1j * (ours[2] - twin[2])))) < 2e-3, f"n {n}, tiled {tiled}, seed {rng.seed}"


@pytest.mark.parametrize("kind", ["spread", "ties"])
def test_the_selected_top_share_is_the_sorted_ones(rng, monkeypatch, kind):
    """TopShareMean.SELECT (a GPU's way: a radix select, no sort): the particles at or before the threshold it finds
    are the first K of a stable sort of -log w (ties by index, -0 as +0), and the estimate is the numpy twin's, from the log-weights and
    from w given (numpy's exp: within rounding), the same bits on every call. Sizes around the tile and (on a GPU) above 1024 tiles, shares from
    0.05 to 1; "ties": log-weights drawn from five values, so that equal weights straddle the threshold."""
    from irmcl_warp.kernels import ESTIMATE
    from irmcl_warp.kernels.estimate import SELECT_TILE, TopShareMean, select_passes, select_per_thread
    from irmcl_warp.reference.estimate import heavy_first_keys, top_share_mean

    monkeypatch.setattr(TopShareMean, "SELECT", True)
    assert select_passes(100_000) == [(0, 21, 11), (0, 10, 11), (0, 0, 10), (1, 6, 11), (1, 0, 6)]
    assert (select_per_thread(100_000), select_per_thread(1_000_000)) == (1, 8)  # ~128 blocks of 1024 threads
    monkeypatch.setattr(TopShareMean, "SELECT_PER_THREAD", int(rng.choice([1, 4])))
    span = SELECT_TILE * TopShareMean.SELECT_PER_THREAD
    sizes = [1, 2, span - 1, span + 3, int(rng.integers(3 * span, 40 * span))]
    if wp.get_device(DEVICE).is_cuda:
        sizes.append(1025 * span + int(rng.integers(1, 5000)))
    for n in sizes:
        share = float(rng.choice([0.05, 0.5, 0.8, 1.0]))
        if kind == "ties":
            log_w = rng.choice(np.array([-3.0, -1.0, 0.0, -0.0, 2.5], np.float32), n)
        else:
            log_w = rng.normal(0, 2, n).astype(np.float32)
        particles = np.stack([rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), rng.uniform(-np.pi, np.pi, n)], -1).astype(
            np.float32
        )
        pw, lw = wp.array(particles, dtype=wp.vec3, device=DEVICE), wp.array(log_w, dtype=wp.float32, device=DEVICE)
        est = ESTIMATE.build("top_share", num_particles=n, share=share, device=DEVICE)
        assert est.selects
        ours = est(pw, lw)
        sums = est.sums.numpy().copy()
        top = np.zeros(n, bool)
        top[np.argsort(-log_w, kind="stable")[: est.k]] = True  # the sort's top share
        key, index = est.threshold()
        keys = heavy_first_keys(log_w)
        assert (np.argsort(keys, kind="stable") == np.argsort(-log_w, kind="stable")).all()  # the keys' order
        picked = (keys < key) | ((keys == key) & (np.arange(n) <= index))
        assert np.array_equal(picked, top), f"n {n}, share {share}, {kind}, seed {rng.seed}"
        assert np.array_equal(sums, (est(pw, lw), est.sums.numpy())[1]), f"n {n} on {DEVICE}"
        w = wp.array(np.exp(log_w - log_w.max()).astype(np.float32), dtype=wp.float32, device=DEVICE)
        est.sum(pw, lw, w)  # w given (a GPU filter's way): numpy's exp, so the same sums within rounding
        assert np.allclose(est.sums.numpy(), sums, rtol=1e-5, atol=1e-4), f"n {n}, seed {rng.seed}"
        twin = top_share_mean(particles, log_w, share)
        assert np.allclose(ours[:2], twin[:2], atol=2e-3), f"n {n}, share {share}, {kind}, seed {rng.seed}"
        assert abs(np.angle(np.exp(1j * (ours[2] - twin[2])))) < 2e-3, f"n {n}, share {share}, seed {rng.seed}"


def test_resampling_decision_on_the_device_copies_when_neff_is_high(rng):
    n = 300
    log_w, particles, pw, weights = _weights(rng, n)
    neff = effective_sample_size(log_w)
    lw = wp.array(log_w, dtype=wp.float32, device=DEVICE)
    dst = wp.zeros(n, dtype=wp.vec3, device=DEVICE)
    resample = RESAMPLE.build("low_variance", device=DEVICE)
    resample(weights.cdf, pw, dst, 0.3, weights.sums, neff * 0.99, lw)  # N_eff above the limit: keep
    assert np.array_equal(dst.numpy(), particles) and np.array_equal(lw.numpy(), log_w)
    resample(weights.cdf, pw, dst, 0.3, weights.sums, neff * 1.01, lw)  # below: draw, weights reset
    index = {tuple(p): i for i, p in enumerate(particles)}
    drawn = np.array([index[tuple(p)] for p in dst.numpy()])
    assert (drawn == low_variance_indices(log_w, 0.3)).mean() > 0.99, f"seed {rng.seed}"
    assert np.all(lw.numpy() == 0.0)


def test_irmcl_motion_kernel_statistics_match_the_twin(rng):
    """IR-MCL's code's model: u = (dx, dy, dtheta) in the robot frame, variance C |u|, composed onto the pose."""
    from irmcl_warp.reference.motion import sample_irmcl
    from irmcl_warp.kernels.motion import IRMCL_NOISE

    n = 40000
    step = (rng.uniform(-0.4, 0.4), rng.uniform(0.05, 0.5), rng.uniform(-0.4, 0.4))
    start = np.tile(np.array([[1.0, -2.0, rng.uniform(-3, 3)]], np.float32), (n, 1))
    p = wp.array(start, dtype=wp.vec3, device=DEVICE)
    MOTION.build("irmcl", noise=IRMCL_NOISE, device=DEVICE)(p, step, seed=int(rng.integers(1 << 30)))
    ours = p.numpy().astype(np.float64)
    twin = sample_irmcl(start.astype(np.float64), step, IRMCL_NOISE, rng)
    centre = lambda a: np.column_stack([a[:, :2], np.angle(np.exp(1j * (a[:, 2] - start[0, 2])))])  # noqa: E731
    ours, twin = centre(ours), centre(twin)
    assert np.allclose(ours.mean(0), twin.mean(0), atol=0.01), f"seed {rng.seed}: {ours.mean(0)} vs {twin.mean(0)}"
    # two samples' covariances differ by sampling alone: a Gaussian sample covariance's standard error is
    # sqrt((s_ii s_jj + s_ij^2) / n) an entry, the difference of two sqrt(2) of it; five of those is a
    # 1-in-10^6 miss (a fixed 2e-4 was about two for the cross terms: seed 3590347608 missed by 2.4e-4)
    c_ours, c_twin = np.cov(ours.T), np.cov(twin.T)
    d = np.diag(c_twin)
    se = np.sqrt(2.0 * (np.outer(d, d) + c_twin**2) / n)
    assert np.all(np.abs(c_ours - c_twin) <= 5.0 * se), (
        f"seed {rng.seed}: {(np.abs(c_ours - c_twin) / se).max():.1f} se"
    )
    # the heading's variance is 0.001 |dx| + 1e-5 |dy| + 0.05 |dtheta|: wide for a small turn
    u = np.array([step[1] * np.cos(step[0]), step[1] * np.sin(step[0]), step[0] + step[2]])
    assert ours[:, 2].var() == pytest.approx(np.array(IRMCL_NOISE[6:]) @ np.abs(u), rel=0.05), f"seed {rng.seed}"
    # noiseless: the step is composed exactly
    q = wp.array(start[:2], dtype=wp.vec3, device=DEVICE)
    MOTION.build("irmcl", noise=(0,) * 9, device=DEVICE)(q, (0.5, 1.0, 0.1), seed=1)
    yaw0 = float(start[0, 2])
    assert np.allclose(
        q.numpy()[0],
        [1.0 + np.cos(yaw0 + 0.5), -2.0 + np.sin(yaw0 + 0.5), np.angle(np.exp(1j * (yaw0 + 0.6)))],
        atol=1e-5,
    )
    with pytest.raises(ValueError, match="9 non-negative noise coefficients"):
        MOTION.build("irmcl", noise=(0.1, 0.1), device=DEVICE)


@pytest.mark.parametrize("model", ["odometry", "irmcl"])
def test_motion_split_over_cpu_cores_draws_the_same_numbers(rng, model):
    """mcl.cpu_threads: the motion launched as a block of particles per core seeds each particle's generator
    with its index in the whole set, so the particles move exactly as in one launch."""
    P = int(rng.integers(3 * 16384 + 1, 60000))  # at least 3 of the motion's blocks
    start = np.column_stack([rng.uniform(-5, 5, P), rng.uniform(-5, 5, P), rng.uniform(-3, 3, P)]).astype(np.float32)
    step, seed = (float(rng.uniform(-0.3, 0.3)), float(rng.uniform(0, 0.5)), float(rng.uniform(-0.3, 0.3))), 1234
    moved = []
    for threads in (1, 3):
        p = wp.array(start, dtype=wp.vec3, device=DEVICE)
        MOTION.build(model, device=DEVICE, cpu_threads=threads)(p, step, seed=seed)
        moved.append(p.numpy())
    assert not np.array_equal(moved[0], start)
    assert np.array_equal(moved[0], moved[1]), f"seed {rng.seed}"


@pytest.mark.cpu_only
def test_particle_blocks_cover_the_particles_once_and_stay_whole_in_a_captured_graph():
    """ParticleBlocks: consecutive blocks of at least min_block particles, one per thread, covering 0..n-1 once;
    one launch below two blocks' worth, and one launch while a CPU graph is captured (it records one thread)."""
    import threading

    from irmcl_warp.kernels.registry import ParticleBlocks

    calls, lock = [], threading.Lock()

    def launch(p0, p1):
        with lock:
            calls.append((p0, p1))

    blocks = ParticleBlocks("cpu", threads=3, min_block=10)
    blocks.run(launch, 100)
    assert sorted(calls) == [(0, 33), (33, 66), (66, 100)]
    calls.clear()
    blocks.run(launch, 25)  # two blocks of 12-13
    assert sorted(calls) == [(0, 12), (12, 25)]
    calls.clear()
    blocks.run(launch, 15)
    assert calls == [(0, 15)]
    calls.clear()
    with wp.ScopedCapture(device="cpu"):
        blocks.run(launch, 100)
    assert calls == [(0, 100)]
    assert ParticleBlocks("cpu", threads=None).threads >= 1


def test_occupied_bins_kernel_matches_the_twin_and_leaves_its_marks_clear(rng):
    """kernels/kld.py OccupiedBins against irmcl_warp/reference/kld.occupied_bins on fresh random sets: particles at
    random bins' centres (jittered within 0.4 of a cell, so float32 and float64 agree on the bin), some bins shared,
    some outside the bounds (the edge bins); a second count of another set starts from clear marks."""
    from irmcl_warp.kernels.kld import OccupiedBins
    from irmcl_warp.reference.kld import occupied_bins

    bounds = (-3.0, 1.0, float(rng.uniform(5, 20)), float(rng.uniform(8, 15)))
    cell, deg = float(rng.choice([0.25, 0.5, 1.0])), float(rng.choice([10.0, 22.5, 45.0]))
    bins = OccupiedBins(bounds, cell, deg, device=DEVICE)
    nyaw, ny, nx = bins.shape()
    for n in (int(rng.integers(1, 50)), int(rng.integers(500, 5000))):
        ix, iy, ia = rng.integers(-2, nx + 2, n), rng.integers(-2, ny + 2, n), rng.integers(0, nyaw, n)
        jitter = rng.uniform(-0.4, 0.4, (n, 3))
        p = np.column_stack(
            [
                bounds[0] + (ix + 0.5 + jitter[:, 0]) * cell,
                bounds[1] + (iy + 0.5 + jitter[:, 1]) * cell,
                -np.pi + (ia + 0.5 + jitter[:, 2]) * (2 * np.pi / nyaw) + 2 * np.pi * rng.integers(-1, 2, n),
            ]
        ).astype(np.float32)
        ours = bins(wp.array(p, dtype=wp.vec3, device=DEVICE))
        twin = occupied_bins(p, bounds, cell, deg)
        assert ours == twin and 1 <= twin <= n, f"seed {rng.seed}: {ours} vs {twin}"
        assert not bins.marks.numpy().any()  # cleared for the next count


def test_kld_count_follows_the_chi_square_quantile_and_the_levels_move_with_a_margin(rng):
    """Fox's count (Wilson-Hilferty) within 1 % of chi2_{k-1}(q) / (2 err) with z the normal quantile of q, for
    k >= 10; 1 particle for one bin; more bins ask for more particles. next_count grows at once to a level that
    holds the count, and shrinks only when twice the count fits a smaller level."""
    from scipy.stats import norm

    from irmcl_warp.kernels.kld import kld_count, levels, next_count
    from irmcl_warp.reference.kld import kld_count_exact

    err, q = float(rng.uniform(0.005, 0.05)), float(rng.uniform(0.9, 0.999))
    z = float(norm.ppf(q))
    for k in rng.integers(10, 20000, 20):
        assert kld_count(int(k), err, z) == pytest.approx(kld_count_exact(int(k), err, q), rel=0.01)
    assert kld_count(1, err, z) == 1 and kld_count(50, err, z) < kld_count(500, err, z)
    with pytest.raises(ValueError, match="err"):
        kld_count(10, 0.0, z)
    counts = levels(100_000, 500)
    assert counts[0] == 500 and counts[-1] == 100_000 and np.all(np.diff(counts) > 0)
    assert set(counts[1:-1]) == {100_000 >> s for s in range(1, 8)}  # 50k ... 781
    with pytest.raises(ValueError, match="min particles"):
        levels(100, 200)

    def bins_for(need):  # the fewest bins whose count reaches ``need``
        return next(k for k in range(2, 10**6) if kld_count(k, 0.01, 0.99) >= need)

    k = bins_for(3000)
    assert next_count(781, k, 0.01, 0.99, counts) == 3125  # grows at once to the level holding 3000
    assert next_count(12500, k, 0.01, 0.99, counts) == 6250  # 2 x 3000 fits 6250: shrinks
    assert next_count(6250, k, 0.01, 0.99, counts) == 6250  # 2 x 3000 needs 6250: stays
    assert next_count(3125, k, 0.01, 0.99, counts) == 3125  # 3000 fits: no growth, and no shrink below it
    assert next_count(500, 10**6, 0.01, 0.99, counts) == 100_000  # capped at the most


def test_accumulate_counts_the_selects_first_pass_as_the_twin_does(rng, monkeypatch):
    """The tiled accumulate given the selection's first histogram (a GPU filter's step: one histogram pass fewer)
    counts each new log-weight's first digit, the top SELECT_BITS bits of its heavy-first key, as numpy counts them
    (ties, +0 and -0 among them); the estimate that starts from those counts (``order(counted=True)``) finds the
    threshold and the five sums of the one that counted all its passes itself, to the bit."""
    from irmcl_warp.kernels import ESTIMATE
    from irmcl_warp.kernels.estimate import TopShareMean
    from irmcl_warp.kernels.radix import FIRST_SHIFT, SELECT_BINS
    from irmcl_warp.reference.estimate import heavy_first_keys

    monkeypatch.setattr(ParticleWeights, "TILED", True)
    monkeypatch.setattr(TopShareMean, "SELECT", True)
    n, temper = int(rng.integers(300, 3000)), float(rng.uniform(0.1, 1.0))
    log_w = rng.normal(0, 30, n).astype(np.float32)
    log_lik = rng.normal(0, 3, n).astype(np.float32)
    log_w[rng.random(n) < 0.2], log_lik[rng.random(n) < 0.2] = -0.0, 0.0  # ties, and -0 beside +0
    particles = rng.normal(0, 5, (n, 3)).astype(np.float32)
    pw = wp.array(particles, dtype=wp.vec3, device=DEVICE)
    counted = ESTIMATE.build("top_share", num_particles=n, share=float(rng.uniform(0.05, 1.0)), device=DEVICE)
    keys, values, first = counted.rank_buffers()
    assert first.shape == (SELECT_BINS,) and not first.numpy().any()
    weights = ParticleWeights(n, device=DEVICE)
    lw = wp.array(log_w, dtype=wp.float32, device=DEVICE)
    weights.accumulate(lw, wp.array(log_lik, dtype=wp.float32, device=DEVICE), temper, (keys, values, first))
    new = lw.numpy()
    twin = np.bincount(heavy_first_keys(new) >> FIRST_SHIFT, minlength=SELECT_BINS)
    assert np.array_equal(first.numpy(), twin), f"seed {rng.seed}"
    weights.weigh(lw, pw)  # w, as a GPU filter's estimate sums it
    counted.order(counted=True)
    counted.sum(pw, lw, weights.w)
    alone = ESTIMATE.build("top_share", num_particles=n, share=counted.k / n, device=DEVICE)
    assert alone.k == counted.k
    alone.rank(lw)
    alone.order()
    alone.sum(pw, lw, weights.w)
    assert counted.threshold() == alone.threshold(), f"seed {rng.seed}"
    assert np.array_equal(counted.sums.numpy(), alone.sums.numpy()), f"seed {rng.seed}"
    assert not counted.hist.numpy().any() and not alone.hist.numpy().any()  # the finish left them zero


def test_the_fused_weigh_leaves_the_maximum_ready_for_the_next_accumulate(rng, monkeypatch):
    """The fused weigh (a GPU's) sets the maximum back to -3e38 for the next accumulate, which then launches no
    fill: over steps whose log-weights fall far below the last step's maximum, every step's maximum and weights are
    still those of a fill before each accumulate."""
    monkeypatch.setattr(ParticleWeights, "TILED", True)
    monkeypatch.setattr(ParticleWeights, "ORDERED_SCAN", True)
    monkeypatch.setattr(ParticleWeights, "FUSED", True)
    n = int(rng.integers(300, 3000))
    particles = wp.array(rng.normal(0, 5, (n, 3)).astype(np.float32), dtype=wp.vec3, device=DEVICE)
    weights = ParticleWeights(n, device=DEVICE, keep_cos_sin=False)
    assert weights.fused
    lw = wp.zeros(n, dtype=wp.float32, device=DEVICE)
    for step in range(4):
        lik = rng.normal(-40.0 * (step + 1), 2.0, n).astype(np.float32)  # each step far below the one before
        before = lw.numpy().copy()
        weights.accumulate(lw, wp.array(lik, dtype=wp.float32, device=DEVICE), 1.0)
        assert weights.top.numpy()[0] == np.max(before + lik), f"step {step}, seed {rng.seed}"
        weights.weigh(lw, particles)
        assert weights.top.numpy()[0] == np.float32(-3.0e38)
        assert np.allclose(weights.w.numpy(), np.exp(lw.numpy() - lw.numpy().max()), rtol=1e-5), f"step {step}"
