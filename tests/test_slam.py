"""GMapping's RBPF: kernels against their numpy twins, the matcher, the proposal, weights, and SLAM on the
simulator against its exact ground truth."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import warp as wp
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import SlamConfig, register
from irmcl_warp.reference import slam as twin
from irmcl_warp.sim import simulate
from irmcl_warp.reference.resample import low_variance_indices
from irmcl_warp.slam import RBPF
from irmcl_warp.slam.rbpf import fit_gaussian
from irmcl_warp.kernels import SLAM
from irmcl_warp.kernels.slam import ParticleMaps
from tests.devices import DEVICE

CONF = Path(__file__).resolve().parents[1] / "conf"


def _sim(duration_s=20.0, **extra):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[
                f"sim.duration_s={duration_s}",
                "sim.width_m=14",
                "sim.height_m=10",
                *[f"{k}={v}" for k, v in extra.items()],
            ],
        )
    return simulate(cfg.sim, DEVICE)[0]


def _maps_numpy(maps: ParticleMaps, p: int) -> dict:
    return {f: a.astype(np.float64) for f, a in maps.fields(p).items()}


def _integrate_both(
    log,
    scans,
    res=0.1,
    origin=(-1.0, -1.0),
    shape=(120, 160),
    P=2,
    jitter=0.0,
    rng=None,
    line="bresenham",
    free_space=True,
):
    maps = ParticleMaps(P, shape, origin, res, device=DEVICE)
    ref = [{f: np.zeros(shape) for f in ParticleMaps.FIELDS} for _ in range(P)]
    integ = SLAM.build("integrate", far_m=8.0, line=line, free_space=free_space, device=DEVICE)
    angles = wp.array(log.info.angles_rad, dtype=wp.float32, device=DEVICE)
    for k in scans:
        poses = np.tile(log.ground_truth[k], (P, 1))
        if jitter:
            poses = poses + rng.normal(0, jitter, poses.shape)
        integ(
            maps,
            wp.array(poses.astype(np.float32), dtype=wp.vec3, device=DEVICE),
            log.T_base_laser,
            wp.array(log.ranges_m[k], dtype=wp.float32, device=DEVICE),
            angles,
        )
        for p in range(P):
            twin.integrate(
                ref[p],
                poses[p].astype(np.float32),
                log.T_base_laser,
                log.ranges_m[k],
                log.info.angles_rad,
                8.0,
                origin,
                res,
                line=line,
                free_space=free_space,
            )
    return maps, ref


def _score_against_twin(maps, log, k, cands, origin, free_check, rng, res=0.1):
    """Scan k scored at ``cands`` on map 0 by the kernel and by the twin; asserts they agree and returns the
    kernel's scores."""
    scorer = SLAM.build(
        "score", far_m=8.0, kernel_size=1, free_delta_m=res * np.sqrt(2), free_check=free_check, device=DEVICE
    )
    cw = wp.array(cands[None].astype(np.float32), dtype=wp.vec3, device=DEVICE)
    score = wp.zeros((1, len(cands)), dtype=wp.float32, device=DEVICE)
    loglik = wp.zeros((1, len(cands)), dtype=wp.float32, device=DEVICE)
    scorer(
        maps,
        cw,
        log.T_base_laser,
        wp.array(log.ranges_m[k], dtype=wp.float32, device=DEVICE),
        wp.array(log.info.angles_rad, dtype=wp.float32, device=DEVICE),
        score,
        loglik,
    )
    want = np.array(
        [
            twin.score(
                _maps_numpy(maps, 0),
                c.astype(np.float32),
                log.T_base_laser,
                log.ranges_m[k],
                log.info.angles_rad,
                8.0,
                origin,
                res,
                free_delta=res * np.sqrt(2),
                free_check=free_check,
            )
            for c in cands
        ]
    )
    assert np.allclose(score.numpy()[0], want[:, 0], rtol=1e-3, atol=1e-2), f"seed {rng.seed}"
    assert np.allclose(loglik.numpy()[0], want[:, 1], rtol=1e-3, atol=1e-1), f"seed {rng.seed}"
    return score.numpy()[0]


@pytest.mark.parametrize("line", ["bresenham", "dda"])
def test_integrate_matches_twin(rng, line):
    log = _sim(5.0)
    maps, ref = _integrate_both(log, [0, 7, 14], P=2, jitter=0.2, rng=rng, line=line)
    for p in range(2):
        got = _maps_numpy(maps, p)
        same = (got["visits"] == ref[p]["visits"]).mean()
        assert same > 0.998, f"seed {rng.seed}: {same:.4f} of cells agree"  # float32 poses at cell borders
        assert (got["hits"] == ref[p]["hits"]).mean() > 0.998
        assert got["hits"].sum() > 500 and got["visits"].sum() > 20 * got["hits"].sum()  # walls seen, space crossed
    hits_only, ref_h = _integrate_both(log, [0, 7, 14], P=1, rng=rng, line=line, free_space=False)
    got = _maps_numpy(hits_only, 0)  # end points only (the ROS wrapper's particles): every visited cell was hit
    assert np.array_equal(got["visits"], got["hits"]) and (got["hits"] == ref_h[0]["hits"]).mean() > 0.998
    assert got["hits"].sum() == ref_h[0]["hits"].sum() > 500
    if line == "bresenham":  # one cell per step along the major axis: fewer visits than every crossed cell
        dda, _ = _integrate_both(log, [0, 7, 14], P=2, jitter=0.0, rng=rng, line="dda")
        assert (
            dda.fields(0)["visits"].sum()
            > 1.2 * _maps_numpy(_integrate_both(log, [0, 7, 14], P=2)[0], 0)["visits"].sum()
        )


@pytest.mark.parametrize("free_check", [True, False])
def test_score_matches_twin_and_peaks_at_the_true_pose(rng, free_check):
    log = _sim(5.0)
    maps, ref = _integrate_both(log, [0, 5, 10], P=1)
    k = 12
    true = log.ground_truth[k]
    far_m = np.array([[0.25, 0.0, 0.0], [0.0, -0.25, 0.0], [0.0, 0.0, 0.2]])
    cands = true + np.concatenate([np.zeros((1, 3)), far_m, rng.normal(0, [0.1, 0.1, 0.05], (5, 3))])
    got = _score_against_twin(maps, log, k, cands, (-1.0, -1.0), free_check, rng)
    assert got[0] > got[1:4].max() and got[0] > 0.8 * got.max()  # the true pose beats poses 0.25 m / 0.2 rad off


def test_motion_kernel_noise_follows_the_gmapping_model(rng):
    n, delta = 40000, np.array([0.4, 0.05, 0.2])
    start = np.array([1.0, -2.0, 0.7])
    poses = wp.array(np.tile(start, (n, 1)).astype(np.float32), dtype=wp.vec3, device=DEVICE)
    SLAM.build("motion", device=DEVICE)(poses, delta, seed=int(rng.integers(1 << 30)))
    from irmcl_warp.geometry import relative

    steps = relative(np.tile(start, (n, 1)), poses.numpy().astype(np.float64))
    want = twin.motion_std(delta)
    assert np.allclose(steps.mean(0), delta, atol=3 * want / np.sqrt(n) + 1e-4)
    assert np.allclose(steps.std(0), want, rtol=0.03), (steps.std(0), want)


def _matcher(log, P=4, proposal="gmapping_code", **kw):
    cfg = SlamConfig(num_particles=P, proposal=proposal, resolution_m=0.05, map_margin_m=2.0, **kw)
    lo = log.ground_truth[:, :2].min(0) - 12.0
    shape = tuple((np.ceil((log.ground_truth[:, :2].max(0) + 12.0 - lo) / 0.05).astype(int) + 1)[::-1])
    rbpf = RBPF(cfg, shape, lo, log.T_base_laser, log.info.angles_rad, 8.0, device=DEVICE)
    return rbpf


def _map_from_true_poses(rbpf, log):
    """Every particle's map from scans 0, 5 and 10 at their true poses (the matcher tests' map)."""
    rbpf.start(log.ground_truth[0], log.ranges_m[0])
    for k in (5, 10):
        rbpf.poses.assign(
            wp.array(np.tile(log.ground_truth[k], (rbpf.P, 1)).astype(np.float32), dtype=wp.vec3, device=DEVICE)
        )
        rbpf._set_ranges(log.ranges_m[k])
        rbpf.integrator(rbpf.maps, rbpf.poses, rbpf.T_base_laser, rbpf.ranges, rbpf.angles)


def test_scan_matcher_recovers_a_known_offset():
    log = _sim(10.0)
    rbpf = _matcher(log)
    _map_from_true_poses(rbpf, log)
    k = 20
    offsets = np.array([[0.15, -0.10, 0.05], [-0.12, 0.08, -0.04], [0.0, 0.18, 0.0], [0.1, 0.1, -0.06]])
    rbpf._set_ranges(log.ranges_m[k])
    matched, score, rounds = rbpf.match(log.ground_truth[k] + offsets)
    err = matched - log.ground_truth[k]
    dist = np.hypot(err[:, 0], err[:, 1])  # started 0.14-0.21 m off
    assert np.median(dist) < 0.02 and dist.max() < 0.05 and np.all(np.abs(err[:, 2]) < 0.01), err
    assert rounds >= 5 and np.all(score > 100)


def test_gaussian_fit_matches_brute_force(rng):
    cand = np.array([0.3, -0.2, 3.1]) + rng.normal(0, [0.05, 0.05, 0.03], (27, 3))
    log_tau = rng.normal(0, 2, 27) - 500.0  # far below exp's range: only the normalised values matter
    mu, cov, log_eta = fit_gaussian(cand[None], log_tau[None], floor=(0, 0, 0))
    w = np.exp(log_tau - log_tau.max())
    w /= w.sum()
    ang = np.unwrap(cand[:, 2])  # yaw near pi: offsets relative to one pose, no wrap-around
    x = np.column_stack([cand[:, :2], ang])
    m = w @ x
    c = sum(wi * np.outer(xi - m, xi - m) for wi, xi in zip(w, x))
    assert np.allclose(mu[0, :2], m[:2]) and np.isclose(np.cos(mu[0, 2] - m[2]), 1.0)
    assert np.allclose(cov[0], c, atol=1e-12)
    assert np.isclose(log_eta[0], np.log(np.exp(log_tau - log_tau.max()).sum()) + log_tau.max())


def test_low_variance_resampling_keeps_floor_or_ceil_of_each_share(rng):
    w = rng.gamma(0.5, 1.0, 30)
    w /= w.sum()
    parents = low_variance_indices(np.log(w), rng.uniform())
    counts = np.bincount(parents, minlength=30)
    assert counts.sum() == 30 and np.all(np.abs(counts - 30 * w) < 1.0 + 1e-9), f"seed {rng.seed}"
    cfg = SlamConfig(num_particles=30)
    rbpf_like = type("R", (), {"cfg": cfg, "P": 30, "log_w": np.log(w) * 200})
    from irmcl_warp.slam.rbpf import RBPF as R

    smooth = R.smoothed_weights(rbpf_like)  # tempered by 1 / (ogain N): flatter than the raw weights
    want = np.exp((rbpf_like.log_w - rbpf_like.log_w.max()) / (3.0 * 30))
    assert np.allclose(smooth, want / want.sum(), rtol=1e-12)


def test_a_scan_of_another_beam_count_is_a_clear_error():
    log = _sim(3.0)
    rbpf = _matcher(log, P=2)
    rbpf.start(log.ground_truth[0], log.ranges_m[0])
    with pytest.raises(ValueError, match="a scan of 180 beams, the filter was built for 360"):
        rbpf.step(1, log.odom[1] + [5.0, 0, 0], log.ranges_m[1][::2])


def test_slam_on_the_simulator_beats_odometry(tmp_path, monkeypatch):
    from irmcl_warp.slam.stage import run_slam

    monkeypatch.chdir(tmp_path)
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config", overrides=["+exp=gmapping_sim", f"device={DEVICE}", "sim.duration_s=60", "slam.num_particles=10"]
        )
    out = run_slam(cfg)
    m = json.loads((out / "metrics.json").read_text())
    assert m["processed_scans"] > 20
    assert m["trajectory"]["ate_rmse_m"] < 0.1, m["trajectory"]
    assert m["trajectory"]["ate_rmse_m"] < 0.25 * m["trajectory_odometry"]["ate_rmse_m"], m
    assert m["scan_lag"]["warned"] is False, m["scan_lag"]  # the simulator's scans and odometry share a clock
    rows = np.loadtxt(out / "trajectory.tum")
    assert rows.shape == (300, 8)
    for f in ("map.pgm", "map.yaml", "map.png", "neff.csv", "config.yaml", "manifest.json"):
        assert (out / f).is_file(), f


def test_the_laser_frame_carries_laser_poses_and_writes_the_base_path(tmp_path, monkeypatch):
    """slam.frame=laser (the released code's way): the particles follow the laser's odometry with no
    extrinsic, and the trajectory written is still the base's: on the simulator with the laser 0.3 m ahead
    it beats the odometry like the default frame does, and its folder says which frame it ran in."""
    from irmcl_warp.geometry import compose as compose_poses
    from irmcl_warp.slam.stage import filter_frame, run_slam

    monkeypatch.chdir(tmp_path)
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[
                "+exp=gmapping_sim",
                f"device={DEVICE}",
                "sim.duration_s=60",
                "sim.laser_x_m=0.3",
                "slam.num_particles=10",
                "slam.frame=laser",
            ],
        )
    log = _sim(10.0, **{"sim.laser_x_m": 0.3})
    odom, T = filter_frame(cfg, log)
    assert np.allclose(odom, compose_poses(log.odom, log.T_base_laser)) and not T.any()
    out = run_slam(cfg)
    assert OmegaConf.load(out / "config.yaml").slam.frame == "laser"  # the run records the frame it ran in
    m = json.loads((out / "metrics.json").read_text())
    # the base's path against the base's ground truth: carrying the laser's poses through would be 0.3 m off
    assert m["trajectory"]["ate_rmse_m"] < 0.1, m["trajectory"]
    assert m["trajectory"]["ate_rmse_m"] < 0.25 * m["trajectory_odometry"]["ate_rmse_m"], m


def test_device_hill_climbing_matches_the_host_twin(rng):
    log = _sim(10.0)
    rbpf = _matcher(log, P=6)
    _map_from_true_poses(rbpf, log)
    rbpf._set_ranges(log.ranges_m[20])
    start = (log.ground_truth[20] + rng.normal(0, [0.1, 0.1, 0.04], (6, 3))).astype(np.float32).astype(np.float64)
    ours, score, _ = rbpf.match(start)
    want, want_score, rounds = twin.hill_climb(lambda c: rbpf.evaluate(c)[0], start, 0.05, 0.05, 5)
    close = np.all(np.abs(ours - want) < [1e-3, 1e-3, 1e-3], axis=1)
    assert close.sum() >= 5, f"seed {rng.seed}: {ours - want}"  # float32 poses may tip one tie
    assert np.allclose(score[close], want_score[close], rtol=1e-4)


@pytest.mark.parametrize("how", ["threads", "blocks"])
def test_the_climb_in_one_launch_equals_the_launched_rounds(rng, monkeypatch, how):
    """Scorer.climb (a particle's whole climb in one thread, the CPU's default) and Scorer.climb_blocks (a block
    per particle, a thread per beam, the GPU's) against the rounds launched over particles x moves x beams:
    the same poses and scores bit for bit, from starts off the true pose so that the climbs take different
    numbers of rounds. On the CPU the blocks run with Warp's CPU blocks switched on."""
    log = _sim(10.0)
    P = 8
    rbpf = _matcher(log, P=P)
    _map_from_true_poses(rbpf, log)
    rbpf._set_ranges(log.ranges_m[20])
    start = log.ground_truth[20] + rng.normal(0, [0.12, 0.12, 0.05], (P, 3))
    launched, launched_score, launched_rounds = rbpf.match(start, how="rounds")
    if how == "blocks" and not wp.get_device(rbpf.device).is_cuda:
        with pytest.raises(ValueError, match="enable_cpu_blocks"):  # a CPU block would be one thread: wrong sums
            rbpf.match(start, how=how)
        monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    fused, fused_score, fused_rounds = rbpf.match(start, how=how)
    assert np.array_equal(fused, launched), f"seed {rng.seed}: {fused - launched}"
    assert np.array_equal(fused_score, launched_score)
    assert np.abs(fused[:, :2] - start[:, :2]).max() > 0.05  # the climbs moved
    per_particle = rbpf._climb["rounds"].numpy()
    assert fused_rounds == per_particle.max() and len(set(per_particle.tolist())) > 1  # climbs of different lengths
    assert launched_rounds >= fused_rounds and launched_rounds % 8 == 0  # the host checked every 8 rounds


def test_a_gpu_climbs_a_scan_too_long_for_one_block_in_launched_rounds():
    """A thread per beam fits a block up to MAX_BLOCK_BEAMS beams; a longer scan (a 1081-beam Hokuyo's) climbs in
    launched rounds by default, and asking for blocks says why not."""
    from irmcl_warp.slam.rbpf import default_climb
    from irmcl_warp.kernels.slam import MAX_BLOCK_BEAMS, block_dim_for

    assert default_climb(False, 180) == "threads" and default_climb(False, 1081) == "threads"
    assert default_climb(True, 180) == "blocks" and default_climb(True, MAX_BLOCK_BEAMS) == "blocks"
    assert default_climb(True, MAX_BLOCK_BEAMS + 57) == "rounds"
    assert [block_dim_for(b) for b in (1, 180, 181, 360, 1024)] == [32, 192, 192, 384, 1024]
    with pytest.raises(ValueError, match="how='rounds'"):
        block_dim_for(1081)


def test_paper_proposal_keeps_the_sample_where_the_match_scores_too_low(rng):
    """slam.minimum_score: a particle whose match scores at or below it keeps its motion-model sample, weighted
    by the sample's own likelihood; above it the pose is drawn around the match."""
    log = _sim(10.0)
    moved = np.array([0.3, 0.0, 0.05])
    for minimum, kept in ((1e9, True), (0.0, False)):
        rbpf = _matcher(log, P=4, proposal="paper", minimum_score=minimum)
        _map_from_true_poses(rbpf, log)
        rbpf._set_ranges(log.ranges_m[20])
        sampled = log.ground_truth[20] + rng.normal(0, [0.08, 0.08, 0.03], (4, 3))
        new, gain, _ = rbpf.propose_paper(sampled, moved)
        if kept:
            assert np.array_equal(new, sampled) and np.array_equal(gain, rbpf.evaluate(sampled[:, None])[1][:, 0])
        else:
            assert not np.allclose(new, sampled, atol=1e-3) and np.all(np.isfinite(gain))


def test_score_of_windows_at_the_map_edge_matches_twin(rng):
    """End points on the map's border (read cell by cell with a bounds check) and inside it (read without
    one) against the twin, on a map cut smaller than the world whose first row and column hold the world's
    walls at x = 0 and y = 0."""
    log = _sim(5.0)
    origin, res, shape = (-0.05, -0.05), 0.1, (45, 70)
    maps, ref = _integrate_both(log, [0, 5, 10], P=1, shape=shape, origin=origin)
    k = 12
    cands = log.ground_truth[k] + rng.normal(0, [0.1, 0.1, 0.05], (6, 3))
    lp = twin.laser_pose(log.ground_truth[k], log.T_base_laser)
    ok = np.isfinite(log.ranges_m[k]) & (log.ranges_m[k] > 0) & (log.ranges_m[k] <= 8.0)
    a = lp[2] + log.info.angles_rad[ok]
    ix = np.floor((lp[0] + log.ranges_m[k][ok] * np.cos(a) - origin[0]) / res)
    iy = np.floor((lp[1] + log.ranges_m[k][ok] * np.sin(a) - origin[1]) / res)
    edge = (ix < 1) | (iy < 1) | (ix > shape[1] - 2) | (iy > shape[0] - 2)
    assert 10 < edge.sum() < len(edge) - 10, edge.sum()  # both kinds of window are scored
    _score_against_twin(maps, log, k, cands, origin, True, rng)


def test_map_resampling_keeps_survivors_in_place_and_copies_the_rest(rng):
    P, shape = 7, (5, 6)
    maps = ParticleMaps(P, shape, (0.0, 0.0), 0.1, device=DEVICE)
    before = rng.uniform(0, 1, (P, *shape, 4)).astype(np.float32)
    maps.cells.assign(before)
    parents = np.sort(rng.integers(0, P, P))
    order = maps.resample(parents)
    assert sorted(order) == sorted(parents)  # the same multiset of parents
    assert np.all(order[np.unique(parents)] == np.unique(parents))  # survivors keep their slot
    assert np.array_equal(maps.cells.numpy(), before[order])
    assert maps.fields(3)["sx"].tolist() == before[order[3], ..., 2].tolist()


def test_growing_the_maps_keeps_every_cell_where_it_was(rng):
    """ParticleMaps.cover against its twin, a numpy slice: the old cells land at the same world position in
    the larger frame, the new ones are empty, and a box already inside changes nothing."""
    P, (H, W), res = 3, (5, 6), 0.1
    maps = ParticleMaps(P, (H, W), (1.0, -2.0), res, device=DEVICE)
    before = rng.uniform(0, 1, (P, H, W, 4)).astype(np.float32)
    maps.cells.assign(before)
    assert not maps.cover((1.05, -1.95), (1.55, -1.55), slack_m=0.2)  # inside: no growth
    assert maps.cover((0.93, -2.01), (1.61, -1.45), slack_m=0.2)  # out on the left, below and right
    left, down = round((1.0 - maps.origin_xy[0]) / res), round((-2.0 - maps.origin_xy[1]) / res)
    assert left >= 1 and down >= 1 and maps.grown == 1
    expect = np.zeros(maps.cells.shape + (4,), np.float32)
    expect[:, down : down + H, left : left + W] = before  # the twin
    assert np.array_equal(maps.cells.numpy(), expect)
    x1 = maps.origin_xy[0] + maps.shape[2] * res
    assert x1 >= 1.61 + 0.2 and maps.origin_xy[0] <= 0.93 - 0.2  # the slack beyond the box on both sides


def test_hits_far_from_the_origin_keep_their_mean_to_a_millimetre():
    """A wall 600 m from the origin (MIT Killian's scale), hit 3000 times: the cell's mean hit point, which
    the matcher compares to its 5 cm sigma, stays within a millimetre (float32 sums of world coordinates
    drift by centimetres there)."""
    res, P = 0.1, 1
    maps = ParticleMaps(P, (40, 40), (598.0, -402.0), res, device=DEVICE)
    integ = SLAM.build("integrate", far_m=8.0, free_space=False, device=DEVICE)
    angles = wp.array(np.zeros(1), dtype=wp.float32, device=DEVICE)
    ranges = wp.array(np.array([1.2345], np.float32), dtype=wp.float32, device=DEVICE)
    pose = np.array([[599.0126, -400.0128, 0.0]], np.float32)
    for _ in range(3000):
        integ(maps, wp.array(pose, dtype=wp.vec3, device=DEVICE), (0.0, 0.0, 0.0), ranges, angles)
    c = maps.fields(0)
    iy, ix = np.argwhere(c["hits"] > 0)[0]
    assert c["hits"][iy, ix] == 3000
    mean_x = 598.0 + ix * res + c["sx"][iy, ix] / 3000
    mean_y = -402.0 + iy * res + c["sy"][iy, ix] / 3000
    assert abs(mean_x - (float(pose[0, 0]) + 1.2345)) < 1e-3 and abs(mean_y - float(pose[0, 1])) < 1e-3


def test_a_frame_holds_exactly_the_boxes_it_would_not_grow_for(rng):
    """ParticleMaps.holds, which lets RBPF skip computing a scan's end points, says yes exactly where cover()
    would not grow, on fresh random boxes in, across and beyond a frame (and at its edges)."""
    for _ in range(200):
        maps = ParticleMaps(1, (8, 12), tuple(rng.uniform(-5, 5, 2)), 0.25, device=DEVICE)
        (ox, oy), (x1, y1) = maps.origin_xy, (maps.origin_xy[0] + 3.0, maps.origin_xy[1] + 2.0)
        edge = rng.integers(0, 3)
        if edge == 0:  # exactly on the frame's sides
            lo, hi = (ox, oy), (x1, y1)
        else:
            lo = (rng.uniform(ox - 1, x1), rng.uniform(oy - 1, y1))
            hi = (lo[0] + rng.uniform(0, 2), lo[1] + rng.uniform(0, 2))
        held = maps.holds(lo, hi)
        assert held == (not maps.cover(lo, hi, 0.5)), (lo, hi, maps.origin_xy)


def test_the_filter_grows_its_maps_and_drops_no_end_point():
    """A filter whose first map is smaller than the scans: every end point within the usable range is
    added (the released code's maps grow alike), none is lost at a border drawn in advance."""
    log = _sim(6.0)
    cfg = SlamConfig(num_particles=2, resolution_m=0.1, map_margin_m=1.0)
    pose = log.odom[0]
    rbpf = RBPF(cfg, (20, 20), (pose[0] - 1.0, pose[1] - 1.0), log.T_base_laser, log.info.angles_rad, 8.0, DEVICE)
    rbpf.start(pose, log.ranges_m[0])
    r = log.ranges_m[0]
    valid = int(np.sum(np.isfinite(r) & (r > 0) & (r <= 8.0)))
    assert rbpf.maps.grown >= 1 and rbpf.maps.shape[1] * rbpf.maps.shape[2] > 400
    for p in range(2):
        assert rbpf.maps.fields(p)["hits"].sum() == valid


def test_scans_are_processed_by_distance_turn_or_time_and_steps_queued_exactly():
    """The update rule, on the simulator's odometry against a direct count: a scan is processed once the path
    since the last processed one reaches linear_update, its turns angular_update, or (temporal_update) more
    than that many seconds have passed. The queued steps of the scans between are geometry.relative's, bit for
    bit. Without stamps a temporal update is an error, not a silent 'never'."""
    from irmcl_warp.geometry import relative, wrap_angle

    log = _sim(30.0)
    for temporal in (-1.0, 2.0):
        cfg = SlamConfig(
            num_particles=2,
            resolution_m=0.1,
            map_margin_m=2.0,
            linear_update=1.5,
            angular_update=0.7,
            temporal_update=temporal,
        )
        rbpf = RBPF(
            cfg,
            (40, 40),
            (log.odom[0, 0] - 2.0, log.odom[0, 1] - 2.0),
            log.T_base_laser,
            log.info.angles_rad,
            8.0,
            DEVICE,
        )
        rbpf.start(log.odom[0], log.ranges_m[0], float(log.stamps[0]))
        want, got, timed, path, turn, last = [], [], set(), 0.0, 0.0, 0
        for k in range(1, len(log)):
            path += float(np.hypot(*(log.odom[k, :2] - log.odom[k - 1, :2])))
            turn += abs(float(wrap_angle(log.odom[k, 2] - log.odom[k - 1, 2])))
            due = path >= 1.5 or turn >= 0.7 or (temporal >= 0 and log.stamps[k] - log.stamps[last] > temporal)
            if not due and k - last == 3:  # the steps queued so far, before this one is added
                steps = relative(log.odom[last : k - 1], log.odom[last + 1 : k])
                assert np.array_equal(np.array(rbpf.pending), steps[np.any(steps != 0, axis=1)])
            if due:
                want.append(k)
                if path < 1.5 and turn < 0.7:
                    timed.add(k)
                path, turn, last = 0.0, 0.0, k
            if rbpf.step(k, log.odom[k], log.ranges_m[k], float(log.stamps[k])).processed:
                got.append(k)
        assert got == want and len(got) >= 5
        by_time = sum(1 for k in got if k in timed)
        assert (by_time > 0) == (temporal > 0), (temporal, by_time)
    rbpf = RBPF(
        cfg, (40, 40), (log.odom[0, 0] - 2.0, log.odom[0, 1] - 2.0), log.T_base_laser, log.info.angles_rad, 8.0, DEVICE
    )
    rbpf.start(log.odom[0], log.ranges_m[0])
    with pytest.raises(ValueError, match="temporal_update needs each scan's stamp"):
        rbpf.step(1, log.odom[1], log.ranges_m[1])


def test_an_odometry_jump_is_counted_and_run_through(tmp_path, monkeypatch):
    """Documented handling: the jump is reported in metrics.json and the filter takes it as motion."""
    import irmcl_warp.slam.stage as stage
    from irmcl_warp.slam.stage import run_slam

    monkeypatch.chdir(tmp_path)
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config", overrides=["+exp=gmapping_sim", f"device={DEVICE}", "sim.duration_s=20", "slam.num_particles=4"]
        )
    real = stage.load_stream

    def jumping(cfg):
        log = real(cfg)
        log.odom[50:, 0] += 3.0  # 3 m in one step
        return log

    monkeypatch.setattr(stage, "load_stream", jumping)
    m = json.loads((run_slam(cfg) / "metrics.json").read_text())
    assert m["odometry_jumps"] == 1 and m["processed_scans"] > 5


def test_g2o_keyframes_give_true_stamps_by_their_ranges(rng):
    """MIT Killian: the bag's stamps are synthetic; the g2o keyframes carry the true ones and the same
    ranges (printed to 2 decimals, 50 m = no echo)."""
    from irmcl_warp.io.groundtruth import G2oGraph, g2o_scan_stamps

    ranges = np.round(rng.uniform(0.5, 40.0, (30, 12)), 2)
    ranges[4, 3] = np.nan  # no echo in the bag ...
    keys = [4, 9, 17]
    g2o = [ranges[k].copy() for k in keys]
    g2o[0][3] = 50.0  # ... is the maximum range in the g2o file
    g2o[1] = g2o[1] + 0.001  # below the printed precision
    graph = G2oGraph(np.arange(3), np.zeros((3, 3)), np.zeros((0, 5)), np.array([100.5, 200.25, 300.125]), g2o, 50.0)
    stamps = g2o_scan_stamps(graph, ranges)
    assert np.flatnonzero(np.isfinite(stamps)).tolist() == keys
    assert stamps[keys].tolist() == [100.5, 200.25, 300.125]
    g2o[2] = g2o[2] + 0.02  # another scan: no match
    assert np.isfinite(g2o_scan_stamps(graph, ranges)).sum() == 2


def test_relations_are_scored_in_the_laser_frame(rng):
    """The relations are motions of the scans: a laser mounted off the axis moves when the robot turns in
    place, and only the laser's path scores zero against such relations."""
    from irmcl_warp.services.metrics import relations_error
    from irmcl_warp.geometry import compose, relative
    from irmcl_warp.io.groundtruth import Relations

    T = np.array([rng.uniform(0.1, 0.4), rng.uniform(-0.1, 0.1), 0.0])
    base = np.column_stack(
        [np.full(6, rng.uniform(-5, 5)), np.full(6, rng.uniform(-5, 5)), np.cumsum(rng.uniform(0.3, 0.8, 6))]
    )  # turning on the spot
    stamps = np.arange(6, dtype=float)
    laser = compose(base, np.broadcast_to(T, base.shape))
    rel = Relations(stamps[:-1], stamps[1:], relative(laser[:-1], laser[1:]))
    assert relations_error(stamps, compose(base, T), rel)["trans_abs_mean_m"] < 1e-9
    # the robot's own path has not moved at all: its error is the laser's travel, a chord of the mounting's circle
    travel = 2 * np.hypot(T[0], T[1]) * np.abs(np.sin(np.diff(base[:, 2]) / 2))
    assert relations_error(stamps, base, rel)["trans_abs_mean_m"] == pytest.approx(travel.mean(), rel=1e-6), rng.seed


def test_runs_of_other_settings_are_runs_of_their_own_and_tables_read_their_settings():
    """A run with non-default settings has its own identity (runs of different settings never share a folder),
    and the tables group it apart from the default runs by its settings; the rot2x preset changes only the noise."""
    from eval.results.queries import slam_variant
    from irmcl_warp import runs
    from irmcl_warp.runs import Record

    def variant(cfg):  # what the tables group by, from a run's settings
        return slam_variant(Record({}, "slam", "gmapping_fr079", "", OmegaConf.to_container(cfg, resolve=True)))

    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        base = compose("config", overrides=["+exp=gmapping_fr079"])
        rot = compose("config", overrides=["+exp=gmapping_fr079", "slam=gmapping_rot2x"])
        odd = compose(
            "config",
            overrides=["+exp=gmapping_fr079", "slam.free_check=true", "slam.line=dda", "data.laser_offset=[0,0,0]"],
        )
    assert variant(base) == {} and runs.label_of("slam", base) == "paper-selective-30p-seed0"
    changed = {k for k in base.slam if base.slam[k] != rot.slam[k]}
    assert changed == {"stt", "srt"} and rot.slam.stt == 2 * base.slam.stt
    assert variant(rot) == {"slam.srt": 0.4, "slam.stt": 0.4}
    assert variant(odd) == {"slam.free_check": True, "slam.line": "dda", "data.laser_offset": [0, 0, 0]}
    assert OmegaConf.to_container(odd.data)["laser_offset"] == [0, 0, 0]
    assert len({runs.settings_id(OmegaConf.to_container(c, resolve=True), "slam") for c in (base, rot, odd)}) == 3


def test_the_trace_check_led_by_our_own_path_agrees_at_every_step():
    """eval.reference.gmapping's one-step check, fed our own noise-free one-particle run as the "released" poses:
    every step's match must come out the same (the check rebuilds the map and the odometry prediction as the
    filter did; a wrong prediction, frame or map order would part)."""
    from eval.reference.gmapping import one_step_check

    log = _sim(40.0, **{"sim.laser_x_m": 0.2})
    cfg = SlamConfig(
        num_particles=1,
        proposal="gmapping_code",
        srr=0.0,
        srt=0.0,
        str=0.0,
        stt=0.0,
        resolution_m=0.05,
        map_margin_m=2.0,
    )
    p0 = log.odom[0]
    rbpf = RBPF(cfg, (80, 80), (p0[0] - 2.0, p0[1] - 2.0), log.T_base_laser, log.info.angles_rad, 8.0, DEVICE)
    rbpf.start(log.odom[0], log.ranges_m[0])
    for k in range(1, len(log)):
        rbpf.step(k, log.odom[k], log.ranges_m[k])
    idx, poses = rbpf.trajectory(0)
    from irmcl_warp.geometry import compose as compose_poses

    laser = compose_poses(poses, log.T_base_laser)  # the check takes the released code's (laser) poses
    r = one_step_check(rbpf, log, log.odom, np.asarray(log.T_base_laser), np.asarray(idx), laser, 0.01, 0.5)
    assert r["steps"] == len(idx) - 1 > 10
    assert r["parted"] == 0 and r["d_m_quantiles"][-1] < 1e-4, r["d_m_quantiles"]


def test_kept_runs_are_made_again_with_their_own_settings():
    """eval.rerun: the overrides rebuilt from a kept record's settings compose to the same settings."""
    from eval.analyses.rerun import overrides
    from irmcl_warp import runs
    from irmcl_warp.config import compose_config

    line = [
        "+exp=gmapping_fr079",
        "slam.proposal=gmapping_code",
        "slam.seed=3",
        "slam.frame=laser",
        "slam.srt=0.4",
        "data.laser_offset=[0.0,0.0,0.0]",
    ]
    cfg = compose_config(line)
    kept = {"slam": OmegaConf.to_container(cfg.slam), "data": OmegaConf.to_container(cfg.data)}
    again = compose_config(overrides("gmapping_fr079", kept))
    assert OmegaConf.to_container(again.slam) == kept["slam"] and OmegaConf.to_container(again.data) == kept["data"]
    same = [runs.settings_id(OmegaConf.to_container(c, resolve=True), "slam") for c in (again, cfg)]
    assert same[0] == same[1]


def test_rerun_compare_says_which_runs_made_again_give_their_kept_errors(tmp_path):
    """``python -m eval.analyses.rerun --compare``: a run made again is the same when its relations and trajectory errors are
    the kept ones to the last digit; one that differs (even in the 17th digit) fails the check, and runs whose
    settings were never kept are named, not counted."""
    from eval.analyses.rerun import compare
    from eval.results.records import keep
    from runfakes import composed, fake_run

    results, outputs = tmp_path / "results", tmp_path / "outputs"
    metrics = {"relations": {"trans_abs_mean_m": 0.06745453373839877}, "trajectory": {"ate_rmse_m": 0.113}}
    cfg = lambda k: composed("+exp=gmapping_fr079", f"slam.seed={k}")  # noqa: E731
    keep([fake_run(tmp_path / "gpu", "slam", cfg(k), metrics) for k in range(3)], results)
    again = {0: metrics, 1: {**metrics, "relations": {"trans_abs_mean_m": 0.06745453373839878}}, 7: metrics}
    made = {
        k: fake_run(outputs, "slam", cfg(k), {**m, "wall_s": 1.0 + k}) for k, m in again.items()
    }  # others may differ
    same, differ, not_kept = compare(outputs, results)
    assert same == ["gmapping_fr079/paper-selective-30p-seed0"]
    assert differ == ["gmapping_fr079/paper-selective-30p-seed1"]
    assert not_kept == ["gmapping_fr079/paper-selective-30p-seed7"]
    made[1].rename(tmp_path / "gone")
    assert compare(outputs, results)[1] == []


def test_slam_maps_that_cannot_fit_are_refused_before_the_first_scan(tmp_path, monkeypatch):
    """The particles' maps estimated from the box the log's scans span: over what is free, an error naming the
    estimate and a resolution that fits (before any scan is processed); the resolution it names then passes."""
    import re

    from irmcl_warp.slam import stage

    monkeypatch.chdir(tmp_path)
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=["+exp=gmapping_sim", "sim.duration_s=20", f"device={DEVICE}"])
    log = stage.load_stream(cfg)
    box, peak, (W, H) = stage.maps_memory(log, log.odom, 20.0, 0.05, 30)
    assert box == 30 * W * H * 16 and peak > 2 * box and W * 0.05 > 5 and H * 0.05 > 5
    monkeypatch.setattr(stage, "available_memory", lambda device: box // 2)
    started = []
    monkeypatch.setattr(stage.RBPF, "start", lambda *a, **k: started.append(1))
    with pytest.raises(
        ValueError,
        match=r"slam: 30 particle maps over the \d+ x \d+ cells .* need about .* GiB, .* free "
        rf"on {DEVICE}: set slam.resolution_m=",
    ) as refused:
        stage.start_filter(cfg, log, DEVICE)
    assert not started
    res = float(re.search(r"slam.resolution_m=([\d.]+)", str(refused.value))[1])
    assert stage.maps_memory(log, log.odom, 20.0, res, 30)[0] < 0.9 * (box // 2)


def test_slam_names_scans_stamped_late_from_its_own_matched_poses(rng):
    """A log without ground truth: the processed scans' matched poses stand in for it (slam/stage.py scan_lag). Poses
    where the scans were taken, odometry read at stamps ``lag`` late: warned, naming the log and the setting; with
    the offset applied, the odometry agrees and nothing is said."""
    from tests.test_ground_truth import late_scans

    from irmcl_warp.geometry import interpolate_poses
    from irmcl_warp.io import LogDefectWarning
    from irmcl_warp.slam.stage import scan_lag
    from irmcl_warp.types import LaserInfo, LaserLog

    lag = float(rng.uniform(0.08, 0.25))
    stamps, odom, taken = late_scans(rng, lag)
    processed = np.sort(rng.choice(len(stamps), 400, replace=False))  # GMapping processes some scans only
    cfg = OmegaConf.create({"data": {"name": "user", "path": "/logs/robot.bag", "scan_time_offset_s": 0.0}})
    log = LaserLog(stamps, np.ones((len(stamps), 4), np.float32), odom, LaserInfo(4, -1.0, 0.5, 0.0, 10.0, 10.0))
    with pytest.warns(
        LogDefectWarning, match=r"/logs/robot\.bag: GMapping's matched poses .*scan_time_offset_s=-0\."
    ) as w:
        got = scan_lag(cfg, log, processed, taken[processed])
    assert got["warned"] and abs(got["lag_s"] + lag) < 0.03, (got, lag, rng.seed)
    said = float(str(w[0].message).rsplit("=", 1)[1])
    cfg.data.scan_time_offset_s = said
    log.odom = interpolate_poses(stamps, odom, stamps + said)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LogDefectWarning)
        assert not scan_lag(cfg, log, processed, taken[processed])["warned"]
