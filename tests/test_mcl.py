"""The particle filter on the simulator: pose tracking stays locked, and bad input gives clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from scipy.ndimage import binary_dilation

from irmcl_warp.config import register
from irmcl_warp.mcl import MCLConfig, ParticleFilter
from irmcl_warp.mcl.filter import pick_beams
from irmcl_warp.nog import NOG
from irmcl_warp.services.filters import WeightingMaps, build_filter
from irmcl_warp.sim import simulate
from irmcl_warp.kernels import SIM
from irmcl_warp.kernels.motion import odometry_step
from tests.devices import DEVICE

CONF = Path(__file__).resolve().parents[1] / "conf"


def _world_and_map(duration_s=30.0, res=0.1, extra=()):
    """The simulated log and a stand-in NOG: the true walls rasterised (one cell thicker, as a NOF learns them)."""
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=[f"sim.duration_s={duration_s}", *extra])
    log, world = simulate(cfg.sim, DEVICE)
    lo = world.segments.reshape(-1, 2).min(0) - 1.0
    hi = world.segments.reshape(-1, 2).max(0) + 1.0
    shape = tuple(np.ceil((hi - lo) / res).astype(int)[::-1])
    walls = SIM.build("rasterize", device=DEVICE)(world.segments, tuple(lo), res, shape) > 0
    nog = NOG(binary_dilation(walls).astype(np.float32), (float(lo[0] + res / 2), float(lo[1] + res / 2)), res)
    nog.walls = walls.astype(np.float32)  # the thin rasterised walls, for the grid baselines
    return log, nog


def _filter(nog, cfg, log, weighting=None):
    """The filter on the stand-in NOG (its zero nodes: free space), weighted by ``weighting`` when given,
    else by the NOG weighting ``cfg`` names (IR-MCL's range table, nog_table, by default); 10 m far bound."""
    if weighting is None:
        return build_filter(cfg, nog, log.T_base_laser, log.info.angles_rad, 10.0, DEVICE, WeightingMaps(nog=nog))
    return ParticleFilter(nog, cfg, log.T_base_laser, log.info.angles_rad, 10.0, lambda n, b: weighting, DEVICE)


def test_kld_sampling_shrinks_a_converged_set_keeps_tracking_and_a_global_start_gets_every_particle_back():
    """mcl.kld_sampling: tracking from a loose start, the count falls from 2000 to a smaller level once the set
    has gathered (never below kld_min_particles, always one of the levels), the estimate stays within the tracking
    test's bounds, and a global start spreads the full count again; without the setting the count never moves."""
    from irmcl_warp.kernels.kld import levels

    log, nog = _world_and_map()
    runs = {}
    for kld in (False, True):
        pf = _filter(
            nog, MCLConfig(num_particles=2000, num_samples=128, seed=3, kld_sampling=kld, kld_min_particles=100), log
        )
        pf.init_gaussian(log.ground_truth[0], (0.3, 0.3, 0.1))
        counts, errors = [], []
        for k in range(1, len(log)):
            pose, _ = pf.step(odometry_step(log.odom[k - 1], log.odom[k]), log.ranges_m[k])
            counts.append(pf.num_particles)
            errors.append(np.hypot(*(pose[:2] - log.ground_truth[k, :2])))
        runs[kld] = np.array(counts), np.array(errors), pf
    counts, errors, pf = runs[True]
    assert set(counts) <= set(levels(2000, 100)) and counts[-1] < 2000 and counts.min() >= 100, set(counts)
    assert pf.bins > 0 and np.median(errors[20:]) < 0.15 and errors[20:].max() < 0.5, (np.median(errors), errors.max())
    assert set(runs[False][0]) == {2000}
    pf.init_uniform()
    assert pf.num_particles == 2000
    pose, _ = pf.step((0.0, 0.05, 0.0), log.ranges_m[1])
    assert np.all(np.isfinite(pose))
    with pytest.raises(ValueError, match="kld_min_particles"):
        _filter(nog, MCLConfig(num_particles=50, num_samples=32, kld_sampling=True, kld_min_particles=100), log)


@pytest.mark.parametrize("weighting", ["nog_raymarch", "nog_table", "likelihood_field"])
def test_pose_tracking_stays_within_a_bound(weighting):
    from irmcl_warp.kernels import WEIGHTING

    log, nog = _world_and_map()
    lf = None
    if weighting == "likelihood_field":  # the grid baseline on the same walls (cells: corner origin)
        corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
        lf = WEIGHTING.build(
            "likelihood_field",
            occupancy=nog.walls,
            origin_xy=corner,
            resolution_m=nog.resolution_m,
            far_m=20.0,
            device=DEVICE,
        )
    table = dict(weighting="nog_table", table_angles=120) if weighting == "nog_table" else {}
    pf = _filter(nog, MCLConfig(num_particles=1000, num_samples=128, seed=3, **table), log, lf)
    pf.init_gaussian(log.ground_truth[0], (0.3, 0.3, 0.1))
    errors, neffs = [], []
    for k in range(1, len(log)):
        pose, neff = pf.step(odometry_step(log.odom[k - 1], log.odom[k]), log.ranges_m[k])
        errors.append(np.hypot(*(pose[:2] - log.ground_truth[k, :2])))
        neffs.append(neff)
    errors = np.array(errors)
    # selective resampling: some steps fall below N/2 (and resample), others keep their weights
    assert min(neffs) < 500 < max(neffs), (min(neffs), max(neffs))
    assert np.median(errors[20:]) < 0.15 and errors[20:].max() < 0.5, (np.median(errors), errors.max())


@pytest.mark.slow
def test_global_localization_converges_in_a_small_world():
    """5k particles spread over a 14 x 10 m office find the robot within 12 s and stay within 0.3 m."""
    log, nog = _world_and_map(duration_s=30.0, extra=("sim.width_m=14", "sim.height_m=10"))
    pf = _filter(nog, MCLConfig(num_particles=5000, num_samples=128, seed=1), log)
    pf.init_uniform()
    errors = []
    for k in range(1, len(log)):
        pose, _ = pf.step(odometry_step(log.odom[k - 1], log.odom[k]), log.ranges_m[k])
        errors.append(np.hypot(*(pose[:2] - log.ground_truth[k, :2])))
    errors = np.array(errors)
    assert errors[:5].min() > 1.0  # it did start lost
    assert errors[60:].max() < 0.3, errors[60:].max()


def test_bad_input_gives_clear_errors():
    log, nog = _world_and_map(duration_s=2.0)
    pf = _filter(nog, MCLConfig(num_particles=16, num_samples=32), log)
    with pytest.raises(ValueError, match="scan of 180 beams, the filter was built for a sensor of 360"):
        pf.step((0.0, 0.0, 0.0), np.ones(180))
    with pytest.raises(ValueError, match="16 of 16 particles lie outside the map"):
        pf.set_particles(np.array([[1e4, 0.0, 0.0]] * 16))
    empty = NOG(np.ones((20, 20), np.float32), nog.origin_xy, nog.resolution_m)
    pf_full = _filter(empty, MCLConfig(num_particles=16, num_samples=32), log)
    with pytest.raises(ValueError, match="no free space"):
        pf_full.init_uniform()


def test_odometry_step_treats_reversing_as_negative_translation():
    r1, t, r2 = odometry_step((0.0, 0.0, 0.0), (-0.5, 0.0, 0.0))
    assert (r1, t, r2) == pytest.approx((0.0, -0.5, 0.0))
    assert odometry_step((0.0, 0.0, 0.0), (0.005, 0.0, 0.2)) == pytest.approx((0.0, 0.005, 0.2))  # a turn in place


def test_without_data_far_m_the_far_bound_is_the_sensors_range_max(tmp_path, monkeypatch):
    """Issue 35: every stage reads data.far_m, else floor(range_max) of the log (localize stopped with 'set
    data.far_m' although the README promises the sensor's range_max)."""
    import json

    monkeypatch.chdir(tmp_path)
    out = sim_tracking_run(
        duration_s=20, starts=1, run_s=10, particles=300, extra=("data.far_m=null", "sim.range_max_m=12.5")
    )
    assert json.loads((out / "metrics.json").read_text())["settings"]["far_m"] == 12.0


def sim_tracking_run(duration_s: float, starts: int, run_s: float, particles: int, extra=()):
    """The localize stage on the simulator (likelihood field, pose tracking, 10 cm map) in the current folder."""
    from irmcl_warp.mcl.stage import run_localize

    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[
                "+exp=sim_office",
                f"device={DEVICE}",
                f"sim.duration_s={duration_s}",
                "mcl.weighting=likelihood_field",
                "localize.mode=tracking",
                f"localize.num_starts={starts}",
                f"localize.run_s={run_s}",
                f"mcl.num_particles={particles}",
                "mcl.map_resolution_m=0.1",
                *extra,
            ],
        )
    return run_localize(cfg)


def test_localize_stage_on_the_simulator_writes_trajectories_and_metrics(tmp_path, monkeypatch):
    import json

    monkeypatch.chdir(tmp_path)
    out = sim_tracking_run(duration_s=60, starts=2, run_s=15, particles=500)
    result = json.loads((out / "metrics.json").read_text())
    assert result["summary"]["starts"] == 2 and result["summary"]["success_rate"] == 1.0
    assert all(r["location_rmse_cm"] < 25 for r in result["runs"])
    # every filter step timed: at most one per scan
    steps, scans = sum(r["steps"] for r in result["runs"]), sum(r["poses"] for r in result["runs"])
    assert 0 < steps <= scans and result["summary"]["ms_per_step_median"] > 0
    rows = np.loadtxt(out / "start1.tum")
    assert rows.shape[1] == 8 and rows[0, 0] >= 1000.0 + 30.0  # TUM rows, second start half-way
    assert (out / "start0.png").is_file()


def test_recovery_injects_only_when_the_likelihood_drops():
    """Augmented MCL's injection probability: 0 while the likelihood holds or rises, > 0 after a sudden drop."""
    import warp as wp

    log, nog = _world_and_map(duration_s=2.0)
    cfg = MCLConfig(num_particles=64, num_samples=32, recovery_alpha_slow=0.01, recovery_alpha_fast=0.5)
    pf = _filter(nog, cfg, log)
    probabilities = []
    for level in [-1.0] * 10 + [-0.5] * 5 + [-6.0] * 3:
        pf.log_lik.assign(wp.array(np.full(64, level, np.float32), dtype=wp.float32, device=DEVICE))
        probabilities.append(pf.recovery_probability())
    assert max(probabilities[:15]) == 0.0 and probabilities[-1] > 0.5
    off = _filter(nog, MCLConfig(num_particles=64, num_samples=32), log)
    assert off.recovery_probability() == 0.0


@pytest.mark.parametrize("recovery", [True, False])
def test_kidnapped_robot_is_recovered_only_with_recovery_on(recovery):
    """Teleport the robot 15 s into a tracking run (the scans jump to a place over 3 m away, the odometry sees
    nothing): augmented MCL's injection finds it again; without recovery the filter stays lost. The slow
    average here learns the likelihood level within ~100 updates (alpha_slow 0.01; AMCL's 0.001 suits
    runs of thousands of updates)."""
    from irmcl_warp.mcl.track import follow

    log, nog = _world_and_map(duration_s=60.0, extra=("sim.width_m=14", "sim.height_m=10"))
    rates = dict(recovery_alpha_slow=0.01, recovery_alpha_fast=0.2) if recovery else {}
    cfg = MCLConfig(num_particles=2000, num_samples=128, seed=5, **rates)
    t = log.stamps - log.stamps[0]
    first = np.flatnonzero(t < 15.0)
    away = np.flatnonzero(
        (t >= 19.0) & (np.hypot(*(log.ground_truth[:, :2] - log.ground_truth[first[-1], :2]).T) > 3.0)
    )
    idx = np.concatenate([first, np.arange(away[0], len(log))])
    pf = _filter(nog, cfg, log)
    pf.init_gaussian(log.ground_truth[0], (0.2, 0.2, 0.1))
    est = follow(pf, log, idx, cfg)
    err = np.hypot(*(est[:, :2] - log.ground_truth[idx, :2]).T)
    cut = len(first)
    assert err[cut - 5 : cut].max() < 0.3  # tracked before the kidnapping
    assert np.hypot(*(log.ground_truth[idx[cut], :2] - log.ground_truth[idx[cut - 1], :2])) > 3.0  # teleported ...
    assert err[cut] > 2.0  # ... and the filter did not see it
    end = err[-25:]  # the last 5 s
    if recovery:
        assert end.max() < 0.3, end.max()
    else:
        assert end.min() > 1.0, end.min()


def _sim_cfg(*overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(
            "config",
            overrides=[
                "+exp=sim_office",
                f"device={DEVICE}",
                "sim.duration_s=60",
                "mcl.map_resolution_m=0.1",
                *overrides,
            ],
        )


def test_grid_maps_treat_unknown_as_amcl_does(tmp_path, monkeypatch):
    """The beam model's rays stop in unknown cells; the likelihood field's distances count occupied cells
    only (with unknown as an obstacle every beam ending beyond a wall scored as a hit)."""
    from irmcl_warp.mcl.stage import build_maps
    from irmcl_warp.services.filters import make_weighting

    monkeypatch.chdir(tmp_path)
    cfg = _sim_cfg("mcl.weighting=likelihood_field")
    view, maps, image = build_maps(cfg, DEVICE, None)
    lf = make_weighting(cfg.mcl, 20.0, DEVICE, maps, 1, 32)
    unknown = image == 0.5
    assert unknown.mean() > 0.05  # the training scans leave parts of the office unseen
    dist = lf.distance
    assert dist[unknown].max() > 0.5 and np.median(dist[unknown]) > 0.0
    cfg = _sim_cfg("mcl.weighting=beam_model")
    beam = make_weighting(cfg.mcl, 20.0, DEVICE, build_maps(cfg, DEVICE, None)[1], 1, 32)
    assert np.all(beam.grid.numpy()[unknown] == 1.0)
    assert np.all(view.occupancy[unknown] == 1.0)  # and no particle starts there


def test_stream_cache_serves_the_log_without_reading_it_again(tmp_path, monkeypatch):
    from omegaconf import open_dict

    import irmcl_warp.services.data as loc

    monkeypatch.chdir(tmp_path)
    cfg = _sim_cfg()
    first = loc.load_stream(cfg)
    monkeypatch.setattr(loc, "read_log", lambda cfg: (_ for _ in ()).throw(AssertionError("read the source again")))
    again = loc.load_stream(cfg)
    assert np.array_equal(first.ranges_m, again.ranges_m, equal_nan=True) and np.array_equal(first.odom, again.odom)
    assert np.array_equal(first.ground_truth, again.ground_truth) and again.info == first.info
    assert again.source == first.source  # messages name the log, not its cache
    # the beam geometry is applied to the cached log: the cache serves other angles and mountings too
    with open_dict(cfg):
        cfg.data.fov_rad, cfg.data.laser_offset = 1.0, [0.1, 0.0, 0.0]
    moved = loc.load_stream(cfg)
    assert np.allclose(moved.T_base_laser, [0.1, 0.0, 0.0]) and moved.info.fov_rad == pytest.approx(1.0)


def test_kidnapping_outside_the_run_is_a_clear_error(tmp_path, monkeypatch):
    from irmcl_warp.mcl.stage import run_localize

    monkeypatch.chdir(tmp_path)
    cfg = _sim_cfg(
        "mcl.weighting=likelihood_field",
        "localize.mode=tracking",
        "localize.run_s=10",
        "localize.kidnap_at_s=12",
        "mcl.num_particles=100",
    )
    with pytest.raises(ValueError, match="kidnap_at_s=12.0 must lie inside the run"):
        run_localize(cfg)
    assert not list((tmp_path / "outputs").glob("*/localize-*"))  # a failed stage leaves no empty folder behind


def test_a_tracking_start_without_ground_truth_is_a_clear_error(tmp_path, monkeypatch):
    """A log whose ground truth begins after a tracking run's window (mit_csail's corrected poses start late) names
    the log, the start and the seconds its ground truth covers, instead of an IndexError."""
    import dataclasses

    import irmcl_warp.mcl.stage as stage

    monkeypatch.chdir(tmp_path)
    cfg = _sim_cfg(
        "mcl.weighting=likelihood_field", "localize.mode=tracking", "localize.run_s=5", "mcl.num_particles=100"
    )
    real = stage.load_stream

    def late_truth(cfg):
        log = real(cfg)
        truth = log.ground_truth.copy()
        truth[(log.stamps - log.stamps[0]) < 8.0] = np.nan
        return dataclasses.replace(log, ground_truth=truth)

    monkeypatch.setattr(stage, "load_stream", late_truth)
    with pytest.raises(ValueError, match=r"tracking start 0 at 0.0 s has no ground-truth pose .* covers 8\.\d-"):
        stage.run_localize(cfg)


def test_reduce_keeps_the_heaviest_particles_and_their_weights():
    import warp as wp

    log, nog = _world_and_map(duration_s=2.0)
    pf = _filter(nog, MCLConfig(num_particles=400, num_samples=32), log)
    pf.init_uniform()
    before, log_w = pf.particles.numpy().copy(), np.random.default_rng(0).normal(0, 3, 400).astype(np.float32)
    pf.log_w.assign(wp.array(log_w, dtype=wp.float32, device=DEVICE))
    pf.reduce(50)
    best = np.argsort(-log_w)[:50]
    assert pf.num_particles == 50 and np.allclose(pf.particles.numpy(), before[best])
    assert np.allclose(pf.log_w.numpy(), log_w[best] - log_w.max())
    pose, neff = pf.step((0.0, 0.05, 0.0), log.ranges_m[1])  # the smaller set steps on
    assert np.all(np.isfinite(pose)) and 0 < neff <= 50
    pf.init_uniform()  # a new run gets the full set back
    assert pf.num_particles == 400


@pytest.mark.parametrize("weighting", ["nog_raymarch", "nog_table", "likelihood_field"])
def test_step_graph_replays_exactly_what_launching_one_by_one_does(weighting, rng):
    """mcl.step_graph=on (one captured graph per step; Warp's CPU graph here, a CUDA graph on a GPU) against
    off: the same estimates, N_eff and particles bit for bit, through selective resampling (both ways) and a
    reduce() that reallocates every array the graphs were captured on."""
    from eval.analyses.determinism import run

    log, nog = _world_and_map(duration_s=4.0)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.walls, origin_xy=corner, resolution_m=nog.resolution_m)
    seed = int(rng.integers(1 << 16))
    runs = {}
    table = dict(table_angles=48) if weighting == "nog_table" else {}
    for mode in ("off", "on"):
        poses, neffs, pf = run(
            log, nog, maps, weighting, seed, mode, DEVICE, **table
        )  # the run eval.determinism repeats
        assert pf.use_graph == (mode == "on") and len(pf.graphs) == (2 if mode == "on" else 0)
        runs[mode] = (poses, neffs, pf.particles.numpy())
        if weighting == "nog_table":  # built once: the second run and every reduce() read the first table
            assert list(maps.built.values()) == [pf.weighting.table]
    neffs = runs["off"][1]
    assert (neffs < 0.5 * 600).any() and (neffs >= 0.5 * 300).any(), "both resampling decisions taken"
    # no float atomics in a step (sums in a fixed order, PartialSums): bit for bit on a GPU as on the CPU
    for graph, eager in zip(runs["on"], runs["off"]):
        assert np.array_equal(graph, eager), f"seed {seed} on {DEVICE}"


@pytest.mark.parametrize("graph", ["on", "off"])
def test_a_tiled_step_keeps_every_bit(graph, rng, monkeypatch):
    """The log-weights accumulated in one tiled launch with their maximum and the top-share estimate's sort keys,
    the estimate summing the weights already computed, against accumulate, max, rank and sums launched apart: the
    same estimates, N_eff and particles."""
    from eval.analyses.determinism import run
    from irmcl_warp.kernels.resample import ParticleWeights

    log, nog = _world_and_map(duration_s=4.0)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.walls, origin_xy=corner, resolution_m=nog.resolution_m)
    seed = int(rng.integers(1 << 16))
    runs = {}
    monkeypatch.setattr(
        ParticleWeights, "ORDERED_SCAN", False
    )  # the same scan both ways (its own test: test_particles)
    for tiled in (False, True):
        monkeypatch.setattr(ParticleWeights, "TILED", tiled)
        poses, neffs, pf = run(log, nog, maps, "likelihood_field", seed, graph, DEVICE)
        assert pf.weights.tiled == tiled
        runs[tiled] = (poses, neffs, pf.particles.numpy())
    for fused, apart in zip(runs[True], runs[False]):
        assert np.array_equal(fused, apart), f"seed {seed} on {DEVICE}"


@pytest.mark.parametrize("graph", ["on", "off"])
def test_the_estimate_on_a_second_stream_keeps_every_bit(graph, rng, monkeypatch):
    """On a GPU the top-share estimate's sort and sums run on a stream of their own beside the weights' sums, the
    scan and the resampling (ParticleFilter._normalise): the same estimates, N_eff and particles as on one stream,
    in a graph and launched one by one. On a CPU there is no second stream."""
    from eval.analyses.determinism import run
    from irmcl_warp.mcl.filter import ParticleFilter

    log, nog = _world_and_map(duration_s=4.0)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.walls, origin_xy=corner, resolution_m=nog.resolution_m)
    seed = int(rng.integers(1 << 16))
    runs = {}
    for second in (False, True):
        monkeypatch.setattr(ParticleFilter, "SECOND_STREAM", second)
        poses, neffs, pf = run(log, nog, maps, "likelihood_field", seed, graph, DEVICE)
        assert (pf._side is not None) == (second and DEVICE.startswith("cuda")), "a second stream only on a GPU"
        runs[second] = (poses, neffs, pf.particles.numpy())
    for forked, one in zip(runs[True], runs[False]):
        assert np.array_equal(forked, one), f"seed {seed} on {DEVICE}"


@pytest.mark.parametrize("graph", ["on", "off"])
def test_a_gpus_step_counting_the_selects_first_pass_in_the_accumulate_keeps_every_bit(graph, rng, monkeypatch):
    """A GPU filter's step as a GPU builds it (the motion inside the weighting's kernel, tiled accumulate, fused
    weigh, ordered scan, no cos and sin kept, the top share by a radix select), here on any device: the accumulate counting the selection's first pass (one
    launch fewer) against the selection counting all its passes, the same estimates, N_eff and particles; and within
    float32 rounding of the default build of this device (the fused weigh's maximum set back for the next step, the
    sums read back in one copy)."""
    from eval.analyses.determinism import run
    from irmcl_warp.kernels.estimate import TopShareMean
    from irmcl_warp.kernels.resample import ParticleWeights
    from irmcl_warp.mcl.filter import ParticleFilter

    log, nog = _world_and_map(duration_s=4.0)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.walls, origin_xy=corner, resolution_m=nog.resolution_m)
    seed = int(rng.integers(1 << 16))
    default = run(log, nog, maps, "likelihood_field", seed, graph, DEVICE)
    for switch in ("TILED", "ORDERED_SCAN", "FUSED"):
        monkeypatch.setattr(ParticleWeights, switch, True)
    monkeypatch.setattr(ParticleWeights, "KEEP_COS_SIN", False)
    monkeypatch.setattr(TopShareMean, "SELECT", True)
    monkeypatch.setattr(ParticleFilter, "MOVE_IN_WEIGHTING", True)
    runs = {}
    for first in (False, True):
        monkeypatch.setattr(TopShareMean, "FIRST_IN_ACCUMULATE", first)
        poses, neffs, pf = run(log, nog, maps, "likelihood_field", seed, graph, DEVICE)
        assert pf.weights.fused and pf.estimator.selects and pf._moving is not None
        assert len(pf.estimator.rank_buffers()) == (3 if first else 2)
        runs[first] = (poses, neffs, pf.particles.numpy())
    for counted, apart in zip(runs[True], runs[False]):
        assert np.array_equal(counted, apart), f"seed {seed} on {DEVICE}"
    assert np.allclose(runs[True][0][:, :2], default[0][:, :2], atol=1e-3), f"seed {seed} on {DEVICE}"
    assert np.allclose(runs[True][1], default[1], rtol=1e-3), f"seed {seed} on {DEVICE}"


@pytest.mark.parametrize(
    "weighting, motion, graph",
    [
        ("nog_table", "odometry", "on"),
        ("nog_table", "irmcl", "off"),
        ("likelihood_field", "odometry", "off"),
        ("likelihood_field", "irmcl", "on"),
    ],
)
def test_moving_the_particles_inside_the_weighting_keeps_every_bit(weighting, motion, graph, rng, monkeypatch):
    """The weighting's one kernel that moves each particle and weighs it (a GPU's step: ParticleFilter._moving)
    against the motion's launch and then the weighting's: the same estimates, N_eff and particles, for the range
    table and the likelihood field, either motion model, in a graph and launched one by one (through a reduce)."""
    from eval.analyses.determinism import run
    from irmcl_warp.mcl.filter import ParticleFilter

    log, nog = _world_and_map(duration_s=4.0)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.walls, origin_xy=corner, resolution_m=nog.resolution_m)
    seed = int(rng.integers(1 << 16))
    runs = {}
    for inside in (False, True):
        monkeypatch.setattr(ParticleFilter, "MOVE_IN_WEIGHTING", inside)
        poses, neffs, pf = run(log, nog, maps, weighting, seed, graph, DEVICE, motion=motion, table_angles=36)
        assert (pf._moving is not None) == inside
        runs[inside] = (poses, neffs, pf.particles.numpy())
    for one, two in zip(runs[True], runs[False]):
        assert np.array_equal(one, two), f"{weighting} {motion} seed {seed} on {DEVICE}"


@pytest.mark.cpu_only
def test_a_cpu_step_split_over_the_cores_then_replayed_as_a_graph_keeps_every_bit(rng):
    """On a CPU with two cores' blocks (mcl.cpu_threads=2, more than 2 x CPU_MIN_BLOCK particles) the motion and the
    likelihood field run split before the graph, which holds the rest of the step (``_replay``): the same estimates,
    N_eff and particles as launching everything one by one in one block."""
    from irmcl_warp.kernels.registry import CPU_MIN_BLOCK

    log, nog = _world_and_map(duration_s=3.0)
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.walls, origin_xy=corner, resolution_m=nog.resolution_m)
    seed, n = int(rng.integers(1 << 16)), 2 * CPU_MIN_BLOCK + int(rng.integers(1, 500))
    runs = {}
    for graph, threads in (("on", 2), ("off", 1)):
        cfg = MCLConfig(num_particles=n, weighting="likelihood_field", seed=seed, step_graph=graph, cpu_threads=threads)
        pf = build_filter(cfg, nog, log.T_base_laser, log.info.angles_rad, 10.0, DEVICE, maps)
        pf.init_gaussian(log.ground_truth[0], (0.3, 0.3, 0.1))  # 0.5 m once put a particle off the map
        out = [pf.step(odometry_step(log.odom[k - 1], log.odom[k]), log.ranges_m[k]) for k in range(1, len(log))]
        assert pf._splits_on_cpu() == (threads == 2) and len(pf.graphs) == (2 if graph == "on" else 0)
        runs[graph] = ([o[0] for o in out], [o[1] for o in out], pf.particles.numpy())
    for split, whole in zip(runs["on"], runs["off"]):
        assert np.array_equal(np.asarray(split), np.asarray(whole)), f"seed {seed}, {n} particles"


def test_a_tracking_start_at_the_maps_edge_draws_its_particles_on_the_map_and_one_off_it_is_refused():
    """A tracking start 0.1 m inside the map's edge with a 0.5 m spread once ended a run with "particles outside the
    map" (sim_office, seed 1): the draws off the map are drawn again, every particle lies on the map, and the spread
    on the map side is kept. A start off the map is an error naming the pose and the map's extent."""
    log, nog = _world_and_map(duration_s=1.0)
    pf = _filter(nog, MCLConfig(num_particles=4000, num_samples=32, seed=1), log)
    res, H = nog.resolution_m, nog.shape[0]
    left = nog.origin_xy[0] - res / 2
    start = np.array([left + 0.1, nog.origin_xy[1] + H * res / 2, 0.0])
    pf.init_gaussian(start, (0.5, 0.5, 0.3))
    p = pf.particles.numpy()
    assert not pf._outside(p).any() and p[:, 0].min() >= left
    assert p[:, 0].max() - start[0] > 0.8  # the side on the map keeps its spread
    with pytest.raises(ValueError, match=r"initial pose .* lies outside the map \(x "):
        pf.init_gaussian(start - np.array([1.0, 0.0, 0.0]), (0.5, 0.5, 0.3))
    with pytest.raises(ValueError, match="1 of 2 particles lie outside the map"):
        pf.set_particles(np.array([start, start - np.array([1.0, 0.0, 0.0])]))


def test_step_graph_refuses_what_it_cannot_capture():
    log, nog = _world_and_map(duration_s=2.0)
    for extra, why in [
        (dict(recovery_alpha_slow=0.001, recovery_alpha_fast=0.1), "recovery is on"),
        (dict(estimate="best_cluster"), "finds its cluster on the host"),
    ]:
        with pytest.raises(ValueError, match=why):
            _filter(nog, MCLConfig(num_particles=16, num_samples=32, step_graph="on", **extra), log)
        pf = _filter(nog, MCLConfig(num_particles=16, num_samples=32, step_graph="auto", **extra), log)
        assert not pf.use_graph  # auto falls back to launching one by one
    with pytest.raises(ValueError, match="choose auto, on or off"):
        _filter(nog, MCLConfig(num_particles=16, num_samples=32, step_graph="yes"), log)


def test_rescore_recomputes_a_runs_metrics_from_its_trajectories(tmp_path, monkeypatch):
    import json

    from eval.analyses.rescore import rescore

    monkeypatch.chdir(tmp_path)
    out = sim_tracking_run(duration_s=30, starts=1, run_s=10, particles=200)
    original = json.loads((out / "metrics.json").read_text())
    spoiled = json.loads(json.dumps(original))
    spoiled["runs"][0]["success"], spoiled["runs"][0]["location_rmse_cm"] = False, 99.0
    spoiled["summary"]["successes"] = 0
    from irmcl_warp import runs

    runs.amend(out, spoiled, "the figures of an older scoring rule")  # as a run scored before today's rules
    changed = rescore(out)
    again = json.loads((out / "metrics.json").read_text())
    assert "successes" in changed and again["summary"]["successes"] == original["summary"]["successes"] == 1
    manifest = json.loads((out / "manifest.json").read_text())
    assert runs.intact(out)[0] and [a["why"][:20] for a in manifest["amended"]][-1] == "eval.analyses.rescor"
    # from the TUM files (positions to 0.1 mm): the same figures to rounding
    assert again["runs"][0]["location_rmse_cm"] == pytest.approx(original["runs"][0]["location_rmse_cm"], abs=0.01)
    assert again["runs"][0]["ms_per_step_median"] == original["runs"][0]["ms_per_step_median"]


def test_beams_are_spread_over_the_scan_or_strided_as_the_authors_code_does():
    spread = pick_beams(180, 32, "spread")
    assert len(spread) == 32 and spread[0] == 0 and spread[-1] == 179 and np.all(np.diff(spread) > 0)
    stride = pick_beams(180, 32, "stride")  # intel: every 5th from the first, -90 to +65 deg of its 1-deg beams
    assert stride.tolist() == list(range(0, 160, 5))
    assert pick_beams(360, 32, "stride")[-1] == 341  # fr079: every 11th, its last 18 beams left out
    assert pick_beams(20, 32, "stride").tolist() == pick_beams(20, 32, "spread").tolist() == list(range(20))
    with pytest.raises(ValueError, match="beam_pick"):
        pick_beams(180, 32, "every")
    from irmcl_warp import runs
    from irmcl_warp.config import compose_config

    # their settings are runs of their own, never the default run's folder
    base = ["+exp=sim_office", "device=cpu", "mcl.weighting=likelihood_field", "localize.mode=tracking"]
    ids = {
        runs.identify(compose_config(base + ov), "localize").id
        for ov in ([], ["mcl.beam_pick=stride"], ["mcl.resample_threshold=1.0"])
    }
    assert len(ids) == 3


def test_systematic_draw_gives_each_candidate_its_share_of_the_draws():
    """filter.systematic_draw (the candidates' draw of mcl.global_candidates): on fresh random log-weights, each
    index is drawn floor(n w) or ceil(n w) times, and -inf weights never."""
    from irmcl_warp.mcl.filter import systematic_draw

    rng = np.random.default_rng()
    log_w = rng.normal(0.0, 3.0, 5000)
    log_w[rng.choice(5000, 500, replace=False)] = -np.inf
    n = 2000
    counts = np.bincount(systematic_draw(log_w, n, float(rng.uniform())), minlength=5000)
    w = np.exp(log_w - log_w.max())
    share = n * w / w.sum()
    assert counts.sum() == n and np.all(counts >= np.floor(share) - 1e-9) and np.all(counts <= np.ceil(share) + 1e-9)
    assert counts[~np.isfinite(log_w)].sum() == 0
    with pytest.raises(ValueError, match="no candidate has a finite log-weight"):
        systematic_draw(np.full(4, -np.inf), 2, 0.5)


def test_global_candidates_cover_the_robot_more_often_at_a_global_start():
    """mcl.global_candidates = 16: the first update after a uniform start keeps 200 of 3,200 weighed candidates,
    with equal weights. Over 10 seeds, a particle lies within 0.5 m and 0.2 rad of the true pose after that update
    in clearly more starts than after the plain first update of 200 (1 of 10 when this test was written, against 8);
    the next update is a plain one, and a relocalization (init_uniform) draws candidates again."""
    log, nog = _world_and_map(duration_s=4.0, extra=("sim.width_m=14", "sim.height_m=10"))
    gt = log.ground_truth[1]
    covered = {}
    for k in (1, 16):
        covered[k] = 0
        for seed in range(10):
            pf = _filter(nog, MCLConfig(num_particles=200, num_samples=64, seed=seed, global_candidates=k), log)
            pf.init_uniform()
            assert pf.global_start
            pf.step(odometry_step(log.odom[0], log.odom[1]), log.ranges_m[1])
            p = pf.particles.numpy()
            d_yaw = np.abs(np.angle(np.exp(1j * (p[:, 2] - gt[2]))))
            covered[k] += bool(np.any((np.hypot(*(p[:, :2] - gt[:2]).T) < 0.5) & (d_yaw < 0.2)))
            assert pf.num_particles == 200 and not pf.global_start
            if k > 1 and seed == 0:
                assert np.all(pf.log_w.numpy() == 0.0) and pf.plain_steps == 0
                pf.step(odometry_step(log.odom[1], log.odom[2]), log.ranges_m[2])
                assert pf.plain_steps == 1
                pf.init_uniform()
                pf.step(odometry_step(log.odom[2], log.odom[3]), log.ranges_m[3])
                assert pf.plain_steps == 1 and np.all(pf.log_w.numpy() == 0.0)
    assert covered[16] >= covered[1] + 4, covered


def test_a_steps_inputs_go_in_one_buffer_and_its_sums_come_back_in_one(rng):
    """StepInputs: the odometry step, the draw, a scan's chosen beams (masked at near and far as chosen_ranges masks
    them) and the two int32 seeds written into one host buffer and sent in one copy are what the kernels' views of the
    device buffer read (seeds beyond float32's integers too);
    the filter's weights and estimator write their sums into views of one buffer, read back in one copy, and a sums
    array of the wrong size is refused by name."""
    from irmcl_warp.kernels import ESTIMATE
    from irmcl_warp.mcl.filter import StepInputs

    sensor = 100
    index = np.r_[0, 1, 2, np.sort(rng.choice(np.arange(3, sensor), int(rng.integers(1, 40)), replace=False))]
    inputs = StepInputs(len(index), DEVICE)
    odom, draw = rng.normal(size=3).astype(np.float32), float(rng.uniform())
    scan = rng.uniform(0.0, 12.0, sensor).astype(np.float32)
    scan[rng.random(sensor) < 0.1] = np.nan
    scan[:3] = (0.05, 10.0, 9.99)  # at near, at far, just inside
    seeds = (int(rng.integers(1 << 24, 1 << 31)), -int(rng.integers(1, 1 << 31)))
    inputs.upload_scan(odom, draw, scan, index, 0.05, 10.0, *seeds)
    inputs.send()
    assert np.array_equal(inputs.odom.numpy(), odom) and inputs.draw.numpy()[0] == np.float32(draw)
    picked = scan[index]
    twin = np.where((picked > 0.05) & (picked < 10.0), picked, np.nan)  # ParticleFilter.chosen_ranges' rule
    assert np.array_equal(inputs.measured.numpy(), twin, equal_nan=True), f"seed {rng.seed}"
    assert (int(inputs.motion_seed.numpy()[0]), int(inputs.resample_seed.numpy()[0])) == seeds
    log, nog = _world_and_map(duration_s=2.0)
    pf = _filter(nog, MCLConfig(num_particles=64, num_samples=32, seed=int(rng.integers(1 << 16))), log)
    pf.init_gaussian(log.ground_truth[0], (0.2, 0.2, 0.1))
    pf.step(odometry_step(log.odom[0], log.odom[1]), log.ranges_m[1])
    both = pf.sums.numpy()
    assert np.array_equal(both[:8], pf.weights.sums.numpy()) and np.array_equal(both[8:], pf.estimator.sums.numpy())
    assert np.array_equal(pf._readback, both) and both[5] > 0  # (sum w > 0: the weights' sums were written)
    with pytest.raises(ValueError, match="top_share: sums must be 5 float32"):
        ESTIMATE.build("top_share", num_particles=8, device=DEVICE, sums=pf.sums)
