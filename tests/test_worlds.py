"""Issue 33: floors nobody tuned on, the AMCL habits of the global localizer, and the confidence."""

from __future__ import annotations

import json
import warnings
import numpy as np
import pytest

from irmcl_warp.config import MCLConfig, compose_config
from irmcl_warp.mcl.confidence import (
    FEATURES,
    Confidence,
    FeatureTracker,
    ScanAgreement,
    auroc,
    fit_logistic,
    modes,
    reliability,
    right,
)
from irmcl_warp.mcl.track import follow
from irmcl_warp.services.filters import WeightingMaps, build_filter, free_space_view
from irmcl_warp.sim import drive_log, floors
from irmcl_warp.types import LaserInfo, LaserLog
from tests.devices import DEVICE


# --- floors ----------------------------------------------------------------------------------------------


def test_the_split_keeps_tuning_and_test_worlds_apart():
    tuning, test = set(floors.SPLIT["tuning"]), set(floors.SPLIT["test"])
    assert tuning and test and not tuning & test
    assert {floors.split_of(n) for n in tuning} == {"tuning"} and {floors.split_of(n) for n in test} == {"test"}
    assert {floors.parse(n)[0] for n in test} == set(floors.KINDS)  # every kind of building is tested
    with pytest.raises(ValueError, match="kind one of"):
        floors.parse("castle-3")


@pytest.mark.parametrize("kind", floors.KINDS)
def test_every_kind_of_floor_gets_a_drive_clear_of_its_walls(kind):
    world = floors.build(f"{kind}-{np.random.randint(3, 900)}")
    points = floors.drive(world, np.random.default_rng(1), 40.0, clearance_m=0.3)
    assert np.sum(np.hypot(*np.diff(points, axis=0).T)) >= 40.0
    line = np.concatenate([p + np.linspace(0, 1, 400)[:, None] * (q - p) for p, q in zip(points[:-1], points[1:])])
    # the waypoints keep the whole clearance; a link between them is checked every 0.1 m, which bounds how
    # close it may come between checks by the clearance less half a step
    assert floors.distance_to_segments(points, world.segments).min() >= 0.3 - 1e-9
    assert floors.distance_to_segments(line, world.segments).min() >= 0.3 - 0.05 - 1e-9
    inside = (line[:, 0] > 0) & (line[:, 0] < world.width_m) & (line[:, 1] > 0) & (line[:, 1] < world.height_m)
    assert inside.all()


def test_a_twin_floors_walls_repeat_after_a_half_turn():
    world = floors.build("twin-1003")
    W, H = world.width_m, world.height_m
    walls = world.segments[: world.n_walls]
    turned = np.column_stack([W - walls[:, 0], H - walls[:, 1], W - walls[:, 2], H - walls[:, 3]])
    probe = np.random.default_rng(0).uniform([0, 0], [W, H], (300, 2))
    assert np.allclose(floors.distance_to_segments(probe, walls), floors.distance_to_segments(probe, turned))


def test_the_mapping_drive_passes_every_roadmap_node_and_its_map_holds_every_drive():
    """worlds.map_drive=cover: the mapping drive passes every node of its roadmap's largest part, and every test
    drive of a twin floor stays on cells its map knows. The random 400 m drive of the maps before left rooms out
    that drives entered (twin-1002 drive 7: 38 % of it), and the stage says so for such a drive."""
    from irmcl_warp.mcl.worlds import query_log, unmapped_share, world_map
    from scipy.sparse.csgraph import connected_components

    world = floors.build("twin-1002")
    points = floors.coverage_drive(world, np.random.default_rng(0))
    nodes, links = floors.roadmap(world, np.random.default_rng(0), 0.3, num_nodes=600)  # the drive's own roadmap
    _, label = connected_components(links, directed=False)
    part = nodes[label == np.bincount(label).argmax()]
    assert len(part) > 0.9 * len(nodes)
    assert all(np.any(np.all(points == p, axis=1)) for p in part)  # every node of the part is a waypoint
    cfg = compose_config(["+exp=worlds", "worlds.split=twin-1002", f"device={DEVICE}"])
    log, _ = query_log(world, cfg, 7, DEVICE)
    assert unmapped_share(world_map(world, cfg, DEVICE), log.ground_truth) == 0.0
    before = compose_config(["+exp=worlds", "worlds.map_drive=random", f"device={DEVICE}"])
    assert unmapped_share(world_map(world, before, DEVICE), log.ground_truth) > 0.3
    from irmcl_warp.config import ConfigError, validate

    with pytest.raises(ConfigError, match="map_drive='spiral': expected one of cover, random"):
        validate(compose_config(["+exp=worlds", "worlds.map_drive=spiral"]))


def test_a_loop_drive_never_enters_the_closed_core():
    world = floors.build("loop-1001")
    ((x0, y0, x1, y1),) = world.solid
    pts = floors.drive(world, np.random.default_rng(3), 120.0)
    assert not np.any((pts[:, 0] > x0) & (pts[:, 0] < x1) & (pts[:, 1] > y0) & (pts[:, 1] < y1))


# --- the confidence's parts -------------------------------------------------------------------------------


def test_modes_find_two_clouds_with_their_weights_and_poses():
    rng = np.random.default_rng()
    a, b = np.array([2.0, 3.0, 0.5]), np.array([12.0, -4.0, -2.0])
    n = 4000
    particles = np.vstack([a + rng.normal(0, [0.1, 0.1, 0.02], (n, 3)), b + rng.normal(0, [0.1, 0.1, 0.02], (n, 3))])
    share = rng.uniform(0.55, 0.8)
    log_w = np.log(np.r_[np.full(n, share / n), np.full(n, (1 - share) / n)])
    m = modes(particles, log_w)
    assert m.weights[0] == pytest.approx(share, abs=1e-6) and m.weights[1] == pytest.approx(1 - share, abs=1e-6)
    assert np.allclose(m.poses[0], a, atol=0.02) and np.allclose(m.poses[1], b, atol=0.02)


def test_a_cluster_on_cell_borders_outweighs_a_smaller_one_inside_a_cell():
    """The densest pose's start: a cluster of 3000 centred on a corner of the 0.25 m cells and on a heading bin's
    border (split over 8 cells) against one of 1500 inside one cell, 1.2 m away: the larger is the mode's pose (a cell
    alone would hold at most about 450 of it and start the mean shift at the smaller)."""
    from irmcl_warp.mcl.confidence import DENSEST_CELL_M, densest_pose

    rng = np.random.default_rng()
    a = np.array([4 * DENSEST_CELL_M, 4 * DENSEST_CELL_M, 0.0])  # a corner of four cells, on the 0 rad border
    b = np.array([a[0] + 1.2 + DENSEST_CELL_M / 2, a[1] + DENSEST_CELL_M / 2, 0.2])  # inside one cell and bin
    big = a + rng.normal(0, [0.06, 0.06, 0.02], (3000, 3))
    small = b + rng.normal(0, [0.02, 0.02, 0.005], (1500, 3))
    p = np.vstack([big, small])
    pose = densest_pose(p, np.full(len(p), 1.0 / len(p)))
    assert np.hypot(*(pose[:2] - a[:2])) < 0.05 and abs(np.angle(np.exp(1j * (pose[2] - a[2])))) < 0.02


def test_a_modes_pose_is_its_densest_cluster_not_the_mean_of_its_block():
    """Two clusters 1.2 m apart in one 3 x 3 m block (a resampled set's look-alike poses) and, at the heavier one,
    a share of particles turned 1 rad: the block's weighted mean lies between the clusters and between the headings,
    where no scan fits; the densest pose is the heavier cluster's. One cluster alone: both read the same pose."""
    rng = np.random.default_rng()
    a = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-3, 3)])
    b = a + [1.2 * np.cos(a[2] + 1), 1.2 * np.sin(a[2] + 1), 0.0]
    n = 3000
    heavy = a + rng.normal(0, [0.08, 0.08, 0.02], (n, 3))
    light = b + rng.normal(0, [0.08, 0.08, 0.02], (n // 2, 3))
    turned = a + [0, 0, 1.0] + rng.normal(0, [0.08, 0.08, 0.02], (n // 2, 3))
    both = np.vstack([heavy, light, turned])
    one_block = modes(both, np.zeros(len(both)), cell_m=2.0, k=1)  # cells of 2 m: one block holds both
    assert one_block.weights[0] == pytest.approx(1.0)
    densest = one_block.poses[0]
    block = modes(both, np.zeros(len(both)), cell_m=2.0, k=1, pose="block").poses[0]
    assert np.hypot(*(densest[:2] - a[:2])) < 0.05 and abs(np.angle(np.exp(1j * (densest[2] - a[2])))) < 0.02
    assert np.hypot(*(block[:2] - a[:2])) > 0.25 and abs(np.angle(np.exp(1j * (block[2] - a[2])))) > 0.15
    alone = np.vstack([heavy])
    assert np.allclose(modes(alone, np.zeros(n)).poses[0], modes(alone, np.zeros(n), pose="block").poses[0], atol=0.02)
    with pytest.raises(ValueError, match="pose 'mean'"):
        modes(alone, np.zeros(n), pose="mean")


def _box_map(res=0.05):
    occ = np.zeros((200, 300), np.float32)
    occ[[0, -1], :] = 1
    occ[:, [0, -1]] = 1
    occ[80:120, 150:154] = 1  # a pillar
    return occ, (0.0, 0.0), res


def _true_ranges(occ, res, pose, angles, laser_x=0.1):
    """The ranges from the laser pose (``laser_x`` ahead of ``pose``), marching the grid in 1 cm steps."""
    lx, ly = pose[0] + laser_x * np.cos(pose[2]), pose[1] + laser_x * np.sin(pose[2])
    r = np.full(len(angles), np.nan)
    for i, a in enumerate(angles):
        for d in np.arange(0.05, 20, 0.01):
            ix, iy = int((lx + d * np.cos(a + pose[2])) / res), int((ly + d * np.sin(a + pose[2])) / res)
            if occ[iy, ix] >= 0.65:
                r[i] = d
                break
    return r


def test_refining_a_hypothesis_brings_it_back_onto_the_scan():
    occ, origin, res = _box_map()
    pose, T, angles = np.array([5.0, 4.0, -0.4]), np.array([0.1, 0.0, 0.0]), np.linspace(-2.3, 2.3, 180)
    r = _true_ranges(occ, res, pose, angles)
    agree = ScanAgreement(occ, origin, res, tolerance_m=0.1, beam_step=1)
    off = pose + np.array([0.2, -0.1, 0.05])
    refined, score = agree.refine(off, r, angles, T)
    assert score > 0.95 > agree(off, r, angles, T)
    assert np.hypot(*(refined[:2] - pose[:2])) < 0.08 and abs(refined[2] - pose[2]) < 0.03
    assert np.allclose(
        agree.many(np.vstack([pose, off]), r, angles, T), [agree(pose, r, angles, T), agree(off, r, angles, T)]
    )


def test_the_scan_agrees_with_the_map_at_the_true_pose_and_not_beside_it():
    occ, origin, res = _box_map()
    pose, T = np.array([4.0, 5.0, 0.3]), np.array([0.1, 0.0, 0.0])
    angles = np.linspace(-2.3, 2.3, 360)
    r = _true_ranges(occ, res, pose, angles)
    agree = ScanAgreement(occ, origin, res, tolerance_m=0.1, beam_step=1)
    assert agree(pose, r, angles, T) > 0.97
    assert agree(pose + [0.6, 0.4, 0.0], r, angles, T) < 0.5
    assert agree(pose + [0.0, 0.0, 0.2], r, angles, T) < 0.5


def test_auroc_is_the_share_of_right_wrong_pairs_ordered_right():
    rng = np.random.default_rng()
    score, label = rng.integers(0, 6, 60).astype(float), rng.random(60) < 0.4
    pos, neg = score[label], score[~label]
    pairs = np.mean([(p > q) + 0.5 * (p == q) for p in pos for q in neg])
    assert auroc(score, label) == pytest.approx(pairs)
    assert auroc(np.arange(10.0), np.arange(10) >= 5) == 1.0


def test_a_logistic_fit_is_calibrated_on_data_drawn_from_a_logistic_model():
    rng = np.random.default_rng()
    X = rng.normal(0, 1, (20000, len(FEATURES)))
    truth = np.linspace(-1.5, 1.5, len(FEATURES))
    y = rng.random(len(X)) < 1 / (1 + np.exp(-(X @ truth + 0.3)))
    # unpenalised, the fit is the maximum-likelihood estimate: within 5 standard errors (from the Fisher
    # information at the truth) of the model that drew the data, a bound fresh draws break about once in 10^5
    free = fit_logistic(X, y, l2=0.0)
    X1 = np.column_stack([X, np.ones(len(X))])
    p = 1 / (1 + np.exp(-(X1 @ np.append(truth, 0.3))))
    se = np.sqrt(np.diag(np.linalg.inv((X1 * (p * (1 - p))[:, None]).T @ X1)))
    raw = np.append(free.coef / free.scale, free.intercept - np.sum(free.coef * free.mean / free.scale))
    assert np.all(np.abs(raw - np.append(truth, 0.3)) < 5 * se)
    # the shipped fit's small L2 penalty only ever pulls the weights towards zero
    model = fit_logistic(X, y)
    assert np.linalg.norm(model.coef) < np.linalg.norm(free.coef)
    # the reliability curve lies within a stated band: 0.05 where a bin holds at least 500 samples
    for b in reliability(model(X), y):
        if b["count"] >= 500:
            assert abs(b["predicted"] - b["observed"]) < 0.05
    again = Confidence(**{k: v for k, v in model.to_json().items() if k in ("coef", "intercept", "mean", "scale")})
    assert np.allclose(again(X[:50]), model(X[:50]))


def test_a_calibration_reads_features_outside_its_data_at_the_nearest_end(tmp_path):
    """A model is not extrapolated: a feature beyond the range it was fitted on (a real log's thousands of updates
    against the tuning drives' hundred) is read at the range's end, so a long right run is judged as the longest
    tuning runs were; the bounds go through the calibration file; a file without them is read as before."""
    rng = np.random.default_rng()
    X = rng.normal(0, 1, (5000, len(FEATURES)))
    k = FEATURES.index("log_updates")
    y = rng.random(len(X)) < 1 / (1 + np.exp(-(X[:, 0] - 1.2 * X[:, k])))  # more updates: less right, in the data
    model = fit_logistic(X, y)
    assert np.allclose(model.lo, X.min(0)) and np.allclose(model.hi, X.max(0))
    inside, beyond = X[:1].copy(), X[:1].copy()
    inside[0, k], beyond[0, k] = X[:, k].max(), X[:, k].max() + 4.0  # well past the data
    assert model(beyond)[0] == model(inside)[0]
    unbounded = Confidence(model.coef, model.intercept, model.mean, model.scale)
    assert unbounded(beyond)[0] < 0.5 * unbounded(inside)[0]  # what the shipped 100k model did on long logs
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(model.to_json()))
    assert Confidence.load(path)(beyond)[0] == model(beyond)[0]
    old = {key: v for key, v in model.to_json().items() if key not in ("lo", "hi")}
    path.write_text(json.dumps(old))
    assert Confidence.load(path).lo is None and Confidence.load(path)(beyond)[0] == unbounded(beyond)[0]


def test_right_means_within_half_a_metre_and_ten_degrees():
    gt = np.zeros((4, 3))
    est = np.array([[0.3, 0.3, 0.0], [0.4, 0.4, 0.0], [0.0, 0.0, np.radians(9.0)], [0.0, 0.0, np.radians(-11.0)]])
    assert right(est, gt).tolist() == [True, False, True, False]


# --- the filter's AMCL habits ------------------------------------------------------------------------------


def _filter(**mcl):
    occ, origin, res = _box_map()
    cfg = MCLConfig(num_particles=2000, num_beams=30, resample_threshold=0.0, **mcl)
    view = free_space_view(occ, origin, res)
    maps = WeightingMaps(occupancy=occ, origin_xy=origin, resolution_m=res)
    return build_filter(cfg, view, (0.1, 0, 0), np.linspace(-2.3, 2.3, 360), 20.0, DEVICE, maps)


def test_a_tempered_likelihood_scales_the_accumulated_weights():
    ranges = np.random.default_rng().uniform(1, 8, 360).astype(np.float32)
    logs = []
    for temper in (1.0, 0.25):
        pf = _filter(weighting="likelihood_field", temper=temper)
        pf.init_uniform()
        pf.step((0.0, 0.0, 0.0), ranges)
        logs.append(pf.log_w.numpy().copy())
    assert np.allclose(logs[1], 0.25 * logs[0], rtol=1e-5, atol=1e-4) and np.ptp(logs[0]) > 1


@pytest.mark.parametrize("weighting", ["likelihood_field", "beam_model"])
def test_the_grid_models_constants_are_settings_that_reach_the_kernel(weighting):
    ranges = np.random.default_rng().uniform(1, 8, 360).astype(np.float32)
    out = []
    for z_rand in (0.05, 0.5):
        pf = _filter(weighting=weighting, z_rand=z_rand)
        pf.set_particles(np.array([[4.0, 5.0, 0.1], [6.0, 3.0, 1.0]]))
        pf.step((0.0, 0.0, 0.0), ranges)
        out.append(pf.log_lik.numpy().copy())
    assert not np.allclose(out[0], out[1])
    assert np.all(out[1] > out[0])  # more of every beam's likelihood put on random readings: a likelihood never lower


def _standing_then_driving_log(n=30):
    odom = np.zeros((n, 3))
    odom[10:, 0] = np.arange(n - 10) * 0.05  # stands for 10 scans, then drives along x
    info = LaserInfo(360, -2.3, 4.6 / 359, 0.0, 20.0, 20.0)
    ranges = np.full((n, 360), 3.0, np.float32)
    return LaserLog(1000 + np.arange(n) * 0.2, ranges, odom, info, np.array([0.1, 0, 0]), None, "standing")


def test_the_first_update_waits_for_motion_when_asked():
    log = _standing_then_driving_log()
    m = MCLConfig(update_min_trans_m=0.22, first_update="motion")
    pf = _filter(weighting="likelihood_field", update_min_trans_m=0.22, first_update="motion")
    pf.init_uniform()
    est = follow(pf, log, np.arange(len(log.stamps)), m)
    first = int(np.argmax(np.all(np.isfinite(est), 1)))
    assert np.isnan(est[:first]).all() and first == 15 and pf.steps == 3  # scans 15, 20, 25
    m_scan = MCLConfig(update_min_trans_m=0.22, first_update="scan")
    pf = _filter(weighting="likelihood_field", update_min_trans_m=0.22)
    pf.init_uniform()
    assert np.isfinite(
        follow(pf, log, np.arange(len(log.stamps)), m_scan)
    ).all()  # IR-MCL's code: the first scan at once


def test_feature_tracker_gives_every_feature_and_resets():
    occ, origin, res = _box_map()
    tracker = FeatureTracker(ScanAgreement(occ, origin, res))
    rng = np.random.default_rng()
    particles = np.column_stack([rng.uniform(1, 14, 500), rng.uniform(1, 9, 500), rng.uniform(-3, 3, 500)])
    f, m = tracker(particles, np.zeros(500), np.full(360, 3.0), np.linspace(-2.3, 2.3, 360), (0.1, 0, 0))
    assert f.shape == (len(FEATURES),) and np.isfinite(f).all() and tracker.updates == 1
    assert f[0] == pytest.approx(m.weights[0]) and f[0] < 0.5  # a uniform cloud has no dominant mode
    tracker.reset()
    assert tracker.updates == 0 and not tracker.history


# --- the stage ----------------------------------------------------------------------------------------------


def _worlds_cfg(*extra):
    return compose_config(
        [
            "+exp=worlds",
            "worlds.split=hall-5",
            "worlds.runs=1",
            "worlds.run_s=12",
            "worlds.map_drive=random",  # a short map (the stage's tests; the floors' coverage drive has its own)
            "worlds.map_drive_m=60",
            "mcl.num_particles=3000",
            f"device={DEVICE}",
            *extra,
        ]
    )


def _fake_calibration(path, refine_rivals=True, search_every=5, mode_pose="densest"):
    """A calibration that trusts the scan's agreement alone (for the stage's bookkeeping, not a fitted one), as
    if fitted on runs tracking rivals and reading modes as +exp=worlds does."""
    coef = np.zeros(len(FEATURES))
    coef[FEATURES.index("agreement")] = 6.0
    path.write_text(
        json.dumps(
            {
                "tracker": {"refine_rivals": refine_rivals, "search_every": search_every, "mode_pose": mode_pose},
                "features": list(FEATURES),
                "coef": coef.tolist(),
                "intercept": 0.0,
                "mean": [0.0] * len(FEATURES),
                "scale": [1.0] * len(FEATURES),
            }
        )
    )
    return path


def test_the_worlds_stage_records_every_update_and_ends_with_a_verdict(tmp_path, monkeypatch, capsys):
    from irmcl_warp.mcl.worlds import run_worlds

    monkeypatch.chdir(tmp_path)
    cal = _fake_calibration(tmp_path / "cal.json")
    out = run_worlds(_worlds_cfg(f"worlds.calibration={cal}"))
    doc = json.loads((out / "metrics.json").read_text())
    z = np.load(out / "hall-5-run1.npz")
    assert z["features"].shape == (len(z["stamps"]), len(FEATURES))
    assert np.isfinite(z["features"][z["updated"]]).all() and np.isnan(z["features"][~z["updated"]]).all()
    lik = z["log_mean_likelihood"]  # what AMCL's w_slow / w_fast would average (eval.analyses.lost_rules)
    assert (
        np.isfinite(lik[z["updated"]]).all() and np.isnan(lik[~z["updated"]]).all() and (lik[z["updated"]] <= 0).all()
    )
    r = doc["runs"][0]
    assert r["localized_at_end"] == (r["confidence_at_end"] >= 0.8)
    assert set(z["particles"][z["updated"]]) == {3000} and not z["particles"][~z["updated"]].any()  # a fixed count
    assert r["particles_per_update"] == 3000 == doc["summary"]["particles_per_update"]
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert "ended NOT localized" in last and f"{doc['summary']['localized_at_end']} ended confident" in last
    assert doc["summary"]["calibrated"] and doc["summary"]["runs"] == 1
    # a second call with the same settings returns the finished run; another calibration is another run
    assert run_worlds(_worlds_cfg(f"worlds.calibration={cal}")) == out
    cal.write_text(cal.read_text().replace('"intercept": 0.0', '"intercept": -1.0'))
    assert run_worlds(_worlds_cfg(f"worlds.calibration={cal}")) != out


def test_a_drive_that_leaves_the_map_is_a_loud_warning(tmp_path, monkeypatch, capsys):
    """A map of a 5 m drive knows little of the floor: the drive localized in it leaves its known cells, which the
    run records per drive, counts in its summary and says as a warning and on its last line."""
    from irmcl_warp.mcl.worlds import run_worlds

    monkeypatch.chdir(tmp_path)
    with pytest.warns(UserWarning, match="hall-5 run 1: .* outside the map's known cells"):
        out = run_worlds(_worlds_cfg("worlds.map_drive_m=5", "worlds.run_s=6"))
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["runs"][0]["truth_unmapped_share"] > 0.01 and doc["summary"]["drives_leaving_map"] == 1
    assert "WARNING: 1 drives left the map's known cells" in capsys.readouterr().out.strip().splitlines()[-1]


def test_the_worlds_table_reads_the_stages_record(tmp_path, monkeypatch):
    from eval.report.tables import worlds_table
    from irmcl_warp import runs
    from irmcl_warp.mcl.worlds import run_worlds

    monkeypatch.chdir(tmp_path)
    cal = _fake_calibration(tmp_path / "cal.json")
    out = run_worlds(_worlds_cfg(f"worlds.calibration={cal}", "worlds.split=hall-1005+loop-1004"))
    doc = json.loads((out / "metrics.json").read_text())
    rec = runs.Record(
        doc,
        "worlds",
        "worlds",
        "x" * 64,
        json.loads(
            json.dumps(
                {
                    "worlds": {"split": "test", "kidnap_at_s": 0.0},
                    "mcl": {"weighting": "likelihood_field", "num_particles": 3000},
                }
            )
        ),
    )
    row = worlds_table([rec]).splitlines()[-1]
    s = doc["summary"]
    assert f"| {s['successes']}/2 | {s['right_at_end']}/2 | {s['localized_at_end']}/2 |" in row
    assert "hall-1005" in row and "loop-1004" in row and 0.0 <= s["auroc"] <= 1.0 if s["auroc"] is not None else True
    assert "KLD" not in row
    assert "map of a random 400 m drive" in row  # a record before worlds.map_drive: a random drive's map
    rec.config["worlds"]["map_drive"] = "cover"
    assert "random" not in worlds_table([rec]).splitlines()[-1]
    rec.config["mcl"].update(kld_sampling=True, kld_min_particles=500)  # an adaptive count says so, with its mean
    assert (
        f"KLD-sampling from 500, {s['particles_per_update'] / 1000:.1f}k per update on average"
        in (worlds_table([rec]).splitlines()[-1])
    )
    assert "confidence fitted on" not in worlds_table([rec]).splitlines()[-1]  # a calibration of one tuning run
    doc["summary"]["calibration"] = "eval.confidence fit on tuning-a, tuning-b, tuning-c"
    assert "confidence fitted on 3 tuning runs" in worlds_table([rec]).splitlines()[-1]
    rec.config["worlds"]["split"] = "tuning"
    assert len(worlds_table([rec]).splitlines()) == 2  # tuning runs are never reported


def test_the_stage_searches_for_rivals_when_asked(tmp_path, monkeypatch):
    from irmcl_warp.mcl.worlds import run_worlds

    monkeypatch.chdir(tmp_path)
    cal = _fake_calibration(tmp_path / "cal.json", search_every=2)
    out = run_worlds(
        _worlds_cfg(
            f"worlds.calibration={cal}",
            "worlds.split=twin-9",
            "worlds.search_rivals_every=2",
            "worlds.refine_rivals=true",
        )
    )
    z = np.load(out / "twin-9-run1.npz")
    margin = z["features"][z["updated"], FEATURES.index("rival_margin")]
    assert np.isfinite(margin).all() and (margin < 0.5).any()  # a half-turn floor: some place fits as well


def test_the_worlds_stage_refuses_a_nof_weighting_it_cannot_train(tmp_path, monkeypatch):
    from irmcl_warp.mcl.worlds import run_worlds

    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="NOF trained on each world"):
        run_worlds(_worlds_cfg("mcl.weighting=nog_raymarch"))


@pytest.mark.parametrize(
    "side,world,refused",
    [
        ("tuning", "office-1001", "test world"),  # fit: tuning only
        ("test", "office-3", "tuning world"),
    ],
)  # judge: test only
def test_calibration_is_fitted_on_tuning_worlds_and_judged_on_test_worlds_only(tmp_path, side, world, refused):
    from eval.confidence import samples

    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(
        json.dumps({"summary": {"weighting": "likelihood_field"}, "runs": [{"world": world, "run": 1}]})
    )
    with pytest.raises(ValueError, match=refused):
        samples([run], side)


def test_judging_against_a_second_calibration_compares_them_on_the_same_updates(tmp_path, rng, capsys):
    """eval.confidence judge --against: on test drives whose right updates agree with the map better than their wrong
    ones, a calibration that reads the agreement beats one that reads it backwards, the interval of the difference
    over drive resamples lies above 0, and the record names both calibrations."""
    from eval.confidence import main

    run = tmp_path / "test-run"
    run.mkdir()
    rows = []
    for k in range(1, 9):
        n = 40
        truth = np.zeros((n, 3))
        wrong = rng.random(n) < 0.4
        est = truth + np.where(wrong[:, None], [3.0, 0.0, 0.0], 0.0)
        feats = np.full((n, len(FEATURES)), 0.5)
        feats[:, FEATURES.index("agreement")] = np.where(wrong, 0.6, 0.9) + rng.normal(0.0, 0.1, n)
        np.savez(run / f"office-1001-run{k}.npz", features=feats, estimate=est, truth=truth, updated=np.ones(n, bool))
        rows.append({"world": "office-1001", "run": k})
    w = {"refine_rivals": True, "search_rivals_every": 5, "mode_pose": "densest", "map_drive": "cover"}
    doc = {"summary": {"weighting": "likelihood_field", "num_particles": 20000}, "settings": {"worlds": w}}
    (run / "metrics.json").write_text(json.dumps({**doc, "runs": rows}))
    good = _fake_calibration(tmp_path / "good.json")
    bad = json.loads(good.read_text())
    bad["coef"] = [-c for c in bad["coef"]]
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    main(
        ["judge", str(run), "--calibration", str(good), "--against", str(tmp_path / "bad.json"), "--out", str(tmp_path)]
    )
    rec = json.loads((tmp_path / "confidence-likelihood_field-20k.json").read_text())
    a = rec["against"]
    assert rec["auroc"] > 0.8 and a["auroc"] == pytest.approx(1.0 - rec["auroc"], abs=1e-9)
    assert a["difference"] == pytest.approx(rec["auroc"] - a["auroc"]) and a["ci95"][0] > 0.0 and a["drives"] == 8
    assert a["calibration"].endswith("bad.json") and "against" in capsys.readouterr().out
    assert a["max_calibration_gap"] > rec["max_calibration_gap"]  # the backward one is the further off its curve


def test_a_pose_without_estimate_has_no_tum_line(tmp_path):
    from irmcl_warp.io import read_tum, write_tum

    est = np.array([[np.nan] * 3, [1.0, 2.0, 0.5], [np.nan] * 3, [2.0, 2.0, 0.1]])
    write_tum(tmp_path / "a.tum", [1.0, 2.0, 3.0, 4.0], est)
    stamps, poses = read_tum(tmp_path / "a.tum")
    assert stamps.tolist() == [2.0, 4.0] and np.allclose(poses[:, :2], est[[1, 3], :2])


def test_a_drive_log_follows_its_waypoints():
    cfg = compose_config([])
    world = floors.build("hall-7")
    pts = floors.drive(world, np.random.default_rng(2), 20.0)
    log = drive_log(world, cfg.sim, pts, 2, device=DEVICE)
    assert np.allclose(log.ground_truth[0, :2], pts[0]) and np.isfinite(log.ranges_m).any(1).all()


@pytest.mark.parametrize("kind", floors.KINDS)
def test_unmapped_objects_stand_off_the_path_and_off_the_walls(kind):
    world = floors.build(f"{kind}-{np.random.randint(3, 900)}")
    path = floors.drive(world, np.random.default_rng(3), 30.0)
    assert floors.with_unmapped(world, path, np.random.default_rng(0), 0.0) is world  # off: the map's own world
    seen = floors.with_unmapped(world, path, np.random.default_rng(0), 0.3)
    extra = seen.segments[len(world.segments) :]
    assert np.array_equal(seen.segments[: len(world.segments)], world.segments) and seen.n_walls >= 0
    length = np.sum(np.hypot(*np.diff(path, axis=0).T))
    assert 0.5 * 0.3 * length <= len(extra) / 4 <= 0.3 * length + 1  # about 0.3 a metre (some draws are refused)
    legs = np.column_stack([path[:-1], path[1:]])
    points = np.concatenate([a + np.linspace(0, 1, 20)[:, None] * (b - a) for a, b in zip(extra[:, :2], extra[:, 2:])])
    assert floors.distance_to_segments(points, legs).min() >= 0.3 - 1e-9  # never on the way
    centres = extra.reshape(-1, 4, 4)[:, :, :2].mean(1)
    assert floors.distance_to_segments(centres, world.segments).min() >= 0.3 - 1e-9  # in free space
    assert getattr(seen, "solid", None) == getattr(world, "solid", None)


@pytest.mark.cpu_only  # it builds the map with device=cpu
def test_a_drive_among_unmapped_objects_is_the_same_drive_with_scans_the_map_explains_less():
    from irmcl_warp.mcl.worlds import query_log, world_map

    cfg = compose_config(["+exp=worlds", "worlds.run_s=12", "device=cpu"])
    world = floors.build("office-5")
    grid = world_map(world, cfg, "cpu")
    agree = ScanAgreement(
        np.where(grid.known, grid.probability, 0.0), grid.origin_xy, grid.resolution_m, cfg.mcl.field_occ_threshold
    )
    plain, _ = query_log(world, cfg, 1, "cpu")
    cfg.worlds.unmapped_per_m = 1.0
    among, _ = query_log(world, cfg, 1, "cpu")
    assert np.array_equal(plain.ground_truth, among.ground_truth) and np.array_equal(plain.odom, among.odom)
    assert not np.array_equal(np.nan_to_num(plain.ranges_m), np.nan_to_num(among.ranges_m))
    fit = [
        [agree(log.ground_truth[i], log.ranges_m[i], log.info.angles_rad, log.T_base_laser) for i in range(0, 60, 3)]
        for log in (plain, among)
    ]
    assert np.mean(fit[1]) < np.mean(fit[0]) - 0.03 and min(fit[0]) > 0.9


def test_between_updates_the_pose_follows_the_odometry():
    from irmcl_warp.geometry import compose, relative
    from irmcl_warp.mcl.track import between_updates

    rng = np.random.default_rng()
    pose, o0 = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3)  # (yaws within [-pi, pi], as the filter gives them)
    o1 = compose(o0[None], np.array([[0.15, 0.02, 0.4]]))[0]
    moved = between_updates(pose, o0, o1)
    assert np.allclose(relative(pose[None], moved[None])[0], [0.15, 0.02, 0.4])
    assert between_updates(pose, o0, o0) is pose and np.isnan(between_updates(None, o0, o1)).all()


def test_a_rival_place_is_remembered_until_the_scans_rule_it_out():
    """Two look-alike places: once the set drifted onto one, the other stays a rival while it explains the scans
    as well (rival margin near 0), and is dropped once it does not."""
    from irmcl_warp.mcl.confidence import FeatureTracker

    class Agreement:  # the scan agrees at A always, at B until told otherwise
        b_agrees = True

        def __call__(self, pose, *_):
            return 1.0 if pose[0] < 5 or self.b_agrees else 0.2

        def many(self, poses, *_):
            return np.array([self(p) for p in poses])

    agree = Agreement()
    tracker = FeatureTracker(agree, recent=3)
    rng = np.random.default_rng()
    a, b = np.array([2.0, 2.0, 0.0]), np.array([8.0, 2.0, np.pi])
    both = np.vstack([a + rng.normal(0, 0.05, (500, 3)), b + rng.normal(0, 0.05, (500, 3))])
    f, m = tracker(both, np.r_[np.full(500, 0.1), np.zeros(500)], None, None, None)  # A a little heavier
    assert m.poses[0][0] < 5 and f[FEATURES.index("rival_margin")] == pytest.approx(0.0) and len(tracker.rivals) == 1
    only_a = a + rng.normal(0, 0.05, (1000, 3))
    f, _ = tracker(only_a, np.zeros(1000), None, None, None, (0.5, 0.0, 0.0))
    assert f[FEATURES.index("rival_margin")] == pytest.approx(0.0)  # B is remembered: nothing ruled it out
    assert tracker.rivals[0, 0] == pytest.approx(8.0 - 0.5, abs=0.05)  # moved with the odometry (B faces -x)
    agree.b_agrees = False
    for _ in range(3):
        f, _ = tracker(only_a, np.zeros(1000), None, None, None)
    assert f[FEATURES.index("rival_margin")] == 1.0 and len(tracker.rivals) == 0


def test_a_bounded_map_forgets_a_wall_that_later_beams_graze_and_an_unbounded_one_keeps_it():
    """150 scans hit a wall cell head on, then 200 beams pass through it and end beyond (as beams grazing a wall
    do, their range a little long): with log-odds bounded at +-4 the cell ends free, unbounded it stays a wall."""
    from irmcl_warp.mapping import integrate_scans
    from irmcl_warp.mcl.worlds import logodds_bounds

    head_on = np.tile([0.025, 1.0, -np.pi / 2], (150, 1))  # from 1 m above the cell (0, 0), looking down
    grazing = np.tile([-3.0, 0.025, 0.0], (200, 1))  # along the cell row, ending 1 m past the cell
    poses = np.vstack([head_on, grazing])
    ranges = np.r_[np.full(150, 0.99), np.full(200, 4.0)][:, None].astype(np.float32)
    probs = {}
    for limit in (4.0, None):
        grid = integrate_scans(
            poses,
            ranges,
            np.zeros(1),
            resolution_m=0.05,
            far_m=20.0,
            bounds=(-4, -1, 4, 2),
            device=DEVICE,
            **logodds_bounds(limit),
        )
        i, j = grid.cell_of(np.array([[0.025, 0.0]]))[0]
        probs[limit] = float(grid.probability[j, i])
    assert probs[4.0] < 0.1 and probs[None] > 0.9, probs


def test_a_calibration_refuses_runs_that_track_rivals_otherwise(tmp_path, monkeypatch):
    from irmcl_warp.mcl.worlds import run_worlds

    monkeypatch.chdir(tmp_path)
    cal = _fake_calibration(tmp_path / "cal.json", refine_rivals=False, search_every=0)
    with pytest.raises(ValueError, match="tracked rivals as"):
        run_worlds(_worlds_cfg(f"worlds.calibration={cal}"))  # +exp=worlds: searched every 5, refined


def test_a_calibration_refuses_runs_that_read_modes_otherwise(tmp_path):
    """A calibration fitted before the densest poses (no mode_pose in its file: "block") is refused by a run that
    reads them, and accepted by one that reads block means, as those runs did."""
    from irmcl_warp.mcl.worlds import calibration_of

    cal = _fake_calibration(tmp_path / "cal.json")
    doc = json.loads(cal.read_text())
    del doc["tracker"]["mode_pose"]
    cal.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="worlds.mode_pose"):
        calibration_of(_worlds_cfg(f"worlds.calibration={cal}"))
    assert calibration_of(_worlds_cfg(f"worlds.calibration={cal}", "worlds.mode_pose=block")) is not None


def test_a_calibration_fitted_on_other_maps_is_a_loud_warning(tmp_path):
    from irmcl_warp.mcl.worlds import calibration_of

    cal = _fake_calibration(tmp_path / "cal.json")
    doc = json.loads(cal.read_text())
    doc["maps"] = {"map_drive": "random", "map_logodds_limit": None}  # as the stage's tests make theirs
    cal.write_text(json.dumps(doc))
    with warnings.catch_warnings(record=True) as seen:  # (only the stage's own warning: a library's may come)
        warnings.simplefilter("always")
        assert calibration_of(_worlds_cfg(f"worlds.calibration={cal}")) is not None
    assert not [w for w in seen if "was fitted on runs whose maps" in str(w.message)]
    doc["maps"] = {"map_drive": "cover", "map_logodds_limit": 4.0}
    cal.write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match=f"{cal.name} was fitted on runs whose maps"):
        calibration_of(_worlds_cfg(f"worlds.calibration={cal}"))


class _TwoPlaces:
    """The scan's agreement: ``a`` at places x < 5 (where the set is), ``b`` elsewhere (the rival)."""

    def __init__(self, a, b):
        self.a, self.b = a, b

    def __call__(self, pose, *_):
        return self.a if pose[0] < 5 else self.b

    def many(self, poses, *_):
        return np.array([self(p) for p in poses])


def _set_on_a_rival_at_b(tracker):
    """One update with most weight at A (x = 2) and a mode at B (x = 8): B becomes a rival. Returns A's cloud."""
    rng = np.random.default_rng()
    a, b = np.array([2.0, 2.0, 0.0]), np.array([8.0, 2.0, np.pi])
    both = np.vstack([a + rng.normal(0, 0.05, (500, 3)), b + rng.normal(0, 0.05, (500, 3))])
    tracker(both, np.r_[np.full(500, 0.5), np.zeros(500)], None, None, None)
    assert len(tracker.rivals) == 1
    return a + rng.normal(0, 0.05, (1000, 3))


def test_a_rival_that_explains_the_scans_better_gathers_evidence_against_the_estimate():
    """The set sits on A, B fits every scan 0.3 better: each update adds -0.3 to B's evidence, the feature reads
    it (bounded at -EVIDENCE_CAP), best_rival names B, and forget_evidence starts it again."""
    from irmcl_warp.mcl.confidence import EVIDENCE_CAP, FeatureTracker

    tracker = FeatureTracker(_TwoPlaces(0.6, 0.9), recent=3)
    only_a = _set_on_a_rival_at_b(tracker)
    ev = FEATURES.index("rival_evidence")
    for k in range(2, 6):
        f, _ = tracker(only_a, np.zeros(1000), None, None, None)
        assert f[ev] == pytest.approx(-0.3 * k)
    pose, evidence = tracker.best_rival()
    assert pose[0] == pytest.approx(8.0, abs=0.1) and evidence == pytest.approx(-1.5)
    for _ in range(10):
        f, _ = tracker(only_a, np.zeros(1000), None, None, None)
    assert f[ev] == -EVIDENCE_CAP and tracker.best_rival()[1] < -EVIDENCE_CAP  # the feature is bounded, not the sum
    tracker.forget_evidence()
    f, _ = tracker(only_a, np.zeros(1000), None, None, None)
    assert f[ev] == pytest.approx(-0.3)


def test_a_rival_slightly_worse_at_every_scan_is_ruled_out_once_its_evidence_adds_up():
    """B fits each scan 0.1 worse than A: within rule_out of the recent agreement, so only the evidence summed
    over updates rules it out, at EVIDENCE_CAP (3.0: the 30th update); without a rival the feature reads the cap."""
    from irmcl_warp.mcl.confidence import EVIDENCE_CAP, FeatureTracker

    tracker = FeatureTracker(_TwoPlaces(0.9, 0.8), recent=3)
    only_a = _set_on_a_rival_at_b(tracker)
    ev = FEATURES.index("rival_evidence")
    for _ in range(27):
        f, _ = tracker(only_a, np.zeros(1000), None, None, None)
    assert len(tracker.rivals) == 1 and f[ev] == pytest.approx(2.8)
    for _ in range(3):
        f, _ = tracker(only_a, np.zeros(1000), None, None, None)
    assert len(tracker.rivals) == 0 and f[ev] == EVIDENCE_CAP and tracker.best_rival() is None


def test_seeding_a_rival_gives_it_its_share_of_the_particles_with_equal_weights():
    from irmcl_warp.mcl.worlds import SEED_STD, seed_at

    pf = _filter(weighting="likelihood_field")
    pf.init_uniform()
    rival = np.array([12.0, 7.0, 1.0])
    log_w = np.full(pf.num_particles, -50.0)
    log_w[:10] = 0.0  # the set's weight lies on ten particles
    pf.log_w.assign(log_w.astype(np.float32))
    before = pf.particles.numpy()[:10].copy()
    seed_at(pf, rival, 0.25)
    p, w = pf.particles.numpy(), pf.log_w.numpy()
    assert len(p) == 2000 and not w.any()
    near = np.hypot(*(p[:, :2] - rival[:2]).T) < 5 * SEED_STD[0]
    assert near.sum() == 500 and np.abs(np.angle(np.exp(1j * (p[near, 2] - 1.0)))).max() < 5 * SEED_STD[2]
    kept = p[~near]
    assert all(np.any(np.all(np.isclose(before, q, atol=1e-6), 1)) for q in kept)  # drawn by weight: the ten


def test_the_stage_seeds_a_rival_once_its_evidence_passes_the_setting_and_says_when():
    """follow_with_confidence with a tracker whose rival gathers -0.5 a update: seeded at the third update
    (-1.5 <= -1.2), its evidence forgotten, again three updates later; the times are in the trace."""
    from types import SimpleNamespace

    from irmcl_warp.mcl.worlds import follow_with_confidence

    class Tracker:
        evidence = 0.0

        def __call__(self, particles, *_):
            self.evidence -= 0.5
            return np.zeros(len(FEATURES)), SimpleNamespace(poses=np.array([[2.0, 2.0, 0.0]]))

        def best_rival(self):
            return np.array([12.0, 7.0, 0.0]), self.evidence

        def forget_evidence(self):
            self.evidence = 0.0

    log = _standing_then_driving_log(n=50)
    m = MCLConfig(update_min_trans_m=0.04, first_update="motion")
    pf = _filter(weighting="likelihood_field", update_min_trans_m=0.04, first_update="motion")
    pf.init_uniform()
    w = SimpleNamespace(
        **dict(confident_above=0.8, lost_below=0.2, lost_after_s=1.0, lost_agreement_below=0.0),
        **dict(lost_agreement_updates=2, relocalize=False, rival_seed_below=1.2, rival_seed_share=0.5),
    )
    trace = follow_with_confidence(pf, log, m, w, Tracker(), None)
    t_updates = (log.stamps - log.stamps[0])[trace["updated"]]
    assert trace["rival_seeded_at_s"] == pytest.approx(t_updates[2::3][: len(trace["rival_seeded_at_s"])])
    assert len(trace["rival_seeded_at_s"]) == len(t_updates) // 3 >= 3
    near = np.hypot(*(pf.particles.numpy()[:, :2] - [12.0, 7.0]).T) < 1.0
    assert near.mean() >= 0.3  # the last seeding's half, moved by the updates since


def test_a_calibration_of_fewer_features_reads_its_own_columns(tmp_path):
    from irmcl_warp.mcl.confidence import Confidence

    older = [f for f in FEATURES if f != "rival_evidence"]
    path = tmp_path / "old.json"
    coef = [3.0 if f == "agreement" else 0.0 for f in older]
    path.write_text(
        json.dumps({"features": older, "coef": coef, "intercept": 0.0, "mean": [0.0] * 8, "scale": [1.0] * 8})
    )
    row = np.zeros(len(FEATURES))
    row[FEATURES.index("agreement")], row[FEATURES.index("rival_evidence")] = 0.5, -100.0
    assert Confidence.load(path)(row) == pytest.approx(1 / (1 + np.exp(-1.5)))
    path.write_text(path.read_text().replace('"top_weight"', '"no_such_feature"'))
    with pytest.raises(ValueError, match="no_such_feature"):
        Confidence.load(path)


def test_the_search_finds_a_twin_floors_look_alike_place():
    """On a floor whose walls repeat after a half turn, the place the scan fits as well as the truth is the truth
    turned about the floor's centre (the furniture aside); the search over the free space finds it."""
    from irmcl_warp.mcl.confidence import search_grid
    from irmcl_warp.mapping import integrate_scans
    from irmcl_warp.geometry import compose

    cfg = compose_config([])
    world = floors.build("twin-7")
    world.segments = world.segments[: world.n_walls]  # walls only: the twin is exact
    mapping = drive_log(world, cfg.sim, floors.drive(world, np.random.default_rng(0), 150.0), 0, device=DEVICE)
    grid = integrate_scans(
        compose(mapping.ground_truth, mapping.T_base_laser),
        mapping.ranges_m,
        mapping.info.angles_rad,
        resolution_m=0.05,
        far_m=20.0,
        device=DEVICE,
    )
    agree = ScanAgreement(np.where(grid.known, grid.probability, 0.0), grid.origin_xy, grid.resolution_m)
    log = drive_log(world, cfg.sim, floors.drive(world, np.random.default_rng(5), 15.0), 5, device=DEVICE)
    i = len(log.stamps) // 2
    truth = log.ground_truth[i]
    twin = np.array([world.width_m - truth[0], world.height_m - truth[1], np.angle(np.exp(1j * (truth[2] + np.pi)))])
    found = agree.search(search_grid(grid), log.ranges_m[i], log.info.angles_rad, log.T_base_laser, truth, 2.0)
    best, score = found[0]
    assert np.hypot(*(best[:2] - twin[:2])) < 0.3 and abs(np.angle(np.exp(1j * (best[2] - twin[2])))) < 0.1
    assert score > agree(truth, log.ranges_m[i], log.info.angles_rad, log.T_base_laser) - 0.1


def _lost_settings(**extra):
    from types import SimpleNamespace

    base = dict(
        confident_above=0.8, lost_below=0.2, lost_after_s=1.0, lost_agreement_below=0.0, lost_agreement_updates=2
    )
    return SimpleNamespace(**{**base, **extra})


def test_the_lost_rule_fires_on_a_low_confidence_held_or_a_low_agreement_in_a_row():
    """LostRule: the confidence trigger as the stage always had it (localized first; below lost_below for lost_after_s);
    the agreement trigger only once localized, after the given updates in a row; both start over after an event."""
    from irmcl_warp.mcl.worlds import LostRule

    rule = LostRule(_lost_settings())
    # never localized: nothing fires however low
    assert not any(rule(t, 0.05, 0.1) for t in np.arange(0, 3, 0.4))
    rule = LostRule(_lost_settings())
    assert not rule(0.0, 0.9, 1.0)  # localized
    assert [rule(t, 0.1, 0.1) for t in (0.5, 1.0, 1.5, 2.0)] == [False, False, True, False]  # 1.5 - 0.5 >= 1 s
    assert not rule(2.5, 0.1, 0.1)  # after an event the rule waits for the confidence to rise again
    rule = LostRule(_lost_settings(lost_agreement_below=0.4, lost_agreement_updates=2))
    assert not rule(0.0, 0.95, 1.0)
    assert [rule(t, 0.6, a) for t, a in ((0.4, 0.3), (0.8, 0.5), (1.2, 0.3), (1.6, 0.35))] == [
        False,
        False,
        False,
        True,
    ]
    one = LostRule(_lost_settings(lost_agreement_below=0.4, lost_agreement_updates=1))
    assert not one(0.0, 0.95, 1.0) and one(0.4, 0.95, 0.39)  # one low scan: lost, even with the confidence high
    assert not one(0.8, 0.5, 0.1)  # and not localized again until the confidence says so


def test_the_lost_rules_timeout_waits_while_the_estimate_explains_the_scans():
    """worlds.lost_timeout_agreement_below: a confidence held low while the scans keep agreeing with the map at the
    estimate (two modes, both fitting them) is ambiguity, not lost; once the agreement falls the timeout counts from
    there; without the setting the rule fires as before. The agreement trigger is not gated."""
    from irmcl_warp.mcl.worlds import LostRule

    ts = np.arange(0.4, 3.0, 0.4)
    gated = LostRule(_lost_settings(lost_timeout_agreement_below=0.94))
    assert not gated(0.0, 0.9, 1.0)
    assert not any(gated(t, 0.1, 0.97) for t in ts)  # ambiguous for 2.6 s: not lost
    assert [gated(t, 0.1, 0.6) for t in (3.2, 3.6, 4.0, 4.4)] == [False, False, False, True]  # counted from 3.2 s
    plain = LostRule(_lost_settings())
    assert not plain(0.0, 0.9, 1.0)
    assert any(plain(t, 0.1, 0.97) for t in ts)
    one = LostRule(
        _lost_settings(lost_timeout_agreement_below=0.94, lost_agreement_below=0.4, lost_agreement_updates=1)
    )
    assert not one(0.0, 0.95, 1.0) and one(0.4, 0.95, 0.1)


def test_the_lost_rule_reads_the_best_agreement_near_an_estimate_that_lags_its_scan(rng):
    """worlds.lost_agreement_near_m / _rad: an estimate a fast turn left behind its scan (off by about 0.15 or 0.3 rad
    and 0 or 0.15 m each way, near a point of the search's coarse grid, drawn) agrees below lost_agreement_below, and
    the rule reads the best agreement within the neighbourhood, which is high; a scan taken elsewhere in the box (a
    kidnapping) stays low; off (0), or above the threshold, the agreement at the estimate is read unchanged; a NaN
    estimate is not searched. (Lags between the coarse grid's points can be missed: of 60 lags drawn uniformly over
    0.1-0.25 rad and 0.15 m, 3-5 stayed below 0.6; LostRule.seen says so.)"""
    from irmcl_warp.mcl.worlds import LostRule

    occ, origin, res = _box_map()
    T, angles = np.array([0.1, 0.0, 0.0]), np.linspace(-2.3, 2.3, 180)
    agree = ScanAgreement(occ, origin, res, tolerance_m=0.1, beam_step=1)
    near = LostRule(_lost_settings(lost_agreement_below=0.4, lost_agreement_near_m=0.3, lost_agreement_near_rad=0.3))
    off = LostRule(_lost_settings(lost_agreement_below=0.4))
    for _ in range(5):
        truth = np.array([rng.uniform(3.5, 6.5), rng.uniform(3.5, 6.5), rng.uniform(-np.pi, np.pi)])
        r = _true_ranges(occ, res, truth, angles)
        shift = rng.choice([-0.15, 0.0, 0.15], 2).tolist() + [rng.choice([-0.3, -0.15, 0.15, 0.3])]
        lag = truth + np.asarray(shift) + rng.uniform(-0.02, 0.02, 3)
        at = agree(lag, r, angles, T)
        assert at < 0.4, f"seed {rng.seed}"  # the lagging estimate's own agreement: the rule would count it low
        assert near.seen(agree, lag, r, angles, T, at) >= 0.6, f"seed {rng.seed}"
        assert off.seen(agree, lag, r, angles, T, at) == at
        elsewhere = np.array([2.0, 2.0, truth[2] + np.pi / 2])  # the scan of a robot carried away
        kidnapped = _true_ranges(occ, res, elsewhere, angles)
        at = agree(truth, kidnapped, angles, T)
        assert near.seen(agree, truth, kidnapped, angles, T, at) < 0.4, f"seed {rng.seed}"
    assert near.seen(agree, truth, r, angles, T, 0.7) == 0.7  # above the threshold: not searched
    strict = LostRule(
        _lost_settings(
            lost_agreement_below=0.4,
            lost_agreement_near_m=0.3,
            lost_agreement_near_rad=0.3,
            lost_agreement_near_fit=1.01,
        )
    )
    assert strict.seen(agree, lag, r, angles, T, 0.1) == 0.1  # the best near it below the bar: the estimate's own
    assert near.seen(agree, np.full(3, np.nan), r, angles, T, 0.1) == 0.1


def test_replaying_a_recorded_run_gives_its_recorded_events_and_a_faster_trigger(tmp_path):
    """eval.analyses.lost_rules over a recorded kidnapped run (a synthetic trace: right until the jump at 10 s, then
    the agreement at once and the confidence slowly down): with the agreement trigger off the replay gives the events
    the run recorded; the agreement trigger detects the jump on its first scan; a rule that fires during right
    tracking counts a false alarm; the chooser keeps the faster rule without false alarms."""
    from eval.analyses.lost_rules import agreement_rule, amcl_rule, choose, replay, score_rule
    from irmcl_warp.mcl.confidence import FEATURES
    from irmcl_warp.mcl.worlds import AGREEMENT

    t = np.arange(0.0, 20.0, 0.2)
    truth = np.column_stack([t * 0.1, np.zeros_like(t), np.zeros_like(t)])
    est = truth.copy()
    est[t >= 10.0, 0] += 5.0  # carried 5 m at 10 s: the estimate stays where it was
    conf = np.where(t < 1.0, 0.5, 0.99)
    drop = t >= 10.0
    conf[drop] = np.maximum(0.99 - 0.25 * (np.arange(drop.sum()) + 1), 0.01)
    feats = np.full((len(t), len(FEATURES)), 0.5)
    feats[:, AGREEMENT] = np.where(drop, 0.15, 0.95)
    feats[25, AGREEMENT] = 0.3  # one poor scan while right (4.9-5.0 s)
    rule_settings = dict(
        confident_above=0.8, lost_below=0.2, lost_after_s=1.0, relocalize=False, kidnap_at_s=10.0, run_s=20.0
    )
    trace = dict(
        stamps=t + 100.0, truth=truth, estimate=est, features=feats, confidence=conf, updated=np.ones(len(t), bool)
    )
    recorded = replay({**trace, "lost_at_s": np.array([])}, rule_settings, agreement_rule(0.0, 1))
    assert recorded and 11.0 <= recorded[0] <= 12.5  # the confidence alone: > 1 s after the jump
    searched = {**rule_settings, "lost_agreement_near_m": 0.3, "lost_agreement_near_rad": 0.3}
    with pytest.warns(
        UserWarning, match="holds no scans|hold no scans"
    ):  # a run made with the search near the estimate
        again = replay({**trace, "lost_at_s": np.array([])}, searched, agreement_rule(0.4, 1))
    assert again == replay({**trace, "lost_at_s": np.array([])}, rule_settings, agreement_rule(0.4, 1))
    run = tmp_path / "run"
    run.mkdir()
    np.savez(run / "office-1-run1.npz", **trace, lost_at_s=np.array(recorded))
    w = {**rule_settings, "lost_agreement_below": 0.0, "lost_agreement_updates": 2}
    (run / "metrics.json").write_text(
        json.dumps({"settings": {"worlds": w}, "runs": [{"world": "office-1", "run": 1}]})
    )
    off = score_rule([run], agreement_rule(0.0, 1))
    assert off["kidnaps"] == 1 and off["detected_within_2s"] == (recorded[0] - 10.0 <= 2.0)
    fast = score_rule([run], agreement_rule(0.2, 1))
    assert fast["detected_within_2s"] == 1 and fast["median_detection_s"] == pytest.approx(0.0, abs=1e-9)
    assert fast["false_alarms"] == 0
    loose = score_rule([run], agreement_rule(0.4, 1))  # the poor scan at 5 s is taken for a kidnapping
    assert loose["false_alarms"] == 1 and loose["detected_within_2s"] == 1  # localized again at once after it
    assert choose([off, fast, loose]) is fast
    # AMCL's recovery as a detector: the mean likelihood falls from e^-1 to e^-5 at the jump; w_fast follows at 0.1 a
    # scan, so 1 - w_fast / w_slow passes 0.3 after 4 updates (0.8 s) and 0.9 only after 22 (4.4 s)
    trace["log_mean_likelihood"] = np.where(t >= 10.0, -5.0, -1.0)
    np.savez(run / "office-1-run1.npz", **trace, lost_at_s=np.array(recorded))
    amcl = {b: score_rule([run], amcl_rule(0.001, 0.1, b)) for b in (0.3, 0.9)}
    assert amcl[0.3]["detected_within_2s"] == 1 and amcl[0.3]["median_detection_s"] == pytest.approx(0.6, abs=0.01)
    assert amcl[0.9]["detected_within_2s"] == 0 and amcl[0.3]["false_alarms"] == amcl[0.9]["false_alarms"] == 0
    assert amcl[0.3]["above"] == 0.3 and "agreement_below" not in amcl[0.3]  # each rule's own settings beside it
    assert choose([amcl[0.3], amcl[0.9]]) is amcl[0.3]


def test_replaying_with_the_timeout_gated_or_not_tells_ambiguity_from_a_false_alarm(tmp_path):
    """eval.analyses.lost_rules --timeout-below: a right drive whose confidence sits at 0.1 for 3 s while its scans
    keep agreeing with the map (a second mode as likely) is a false alarm with the timeout always counting, none with
    it gated at 0.94, and the run's own gate (recorded with it) is what the default replays."""
    from eval.analyses.lost_rules import AS_RECORDED, agreement_rule, score_rule
    from irmcl_warp.mcl.confidence import FEATURES
    from irmcl_warp.mcl.worlds import AGREEMENT

    t = np.arange(0.0, 20.0, 0.2)
    truth = np.column_stack([t * 0.1, np.zeros_like(t), np.zeros_like(t)])
    conf = np.where((t >= 6.0) & (t < 9.0), 0.1, 0.99)
    feats = np.full((len(t), len(FEATURES)), 0.5)
    feats[:, AGREEMENT] = 0.97
    trace = dict(stamps=t, truth=truth, estimate=truth.copy(), features=feats, confidence=conf, updated=t >= 0)
    run = tmp_path / "run"
    run.mkdir()
    np.savez(run / "loop-1-run1.npz", **trace, lost_at_s=np.array([]))
    w = dict(
        confident_above=0.8,
        lost_below=0.2,
        lost_after_s=1.0,
        relocalize=True,
        kidnap_at_s=0.0,
        run_s=20.0,
        lost_agreement_below=0.4,
        lost_agreement_updates=1,
        lost_timeout_agreement_below=0.94,
    )
    (run / "metrics.json").write_text(json.dumps({"settings": {"worlds": w}, "runs": [{"world": "loop-1", "run": 1}]}))
    always = score_rule([run], agreement_rule(0.4, 1, None))
    gated = score_rule([run], agreement_rule(0.4, 1, 0.94))
    recorded = score_rule([run], agreement_rule(0.4, 1, AS_RECORDED))
    assert always["false_alarms"] == 1 and gated["false_alarms"] == 0 and recorded["false_alarms"] == 0
    assert always["timeout_below"] is None and gated["timeout_below"] == 0.94 and "timeout_below" not in recorded
    assert "timeout always" in always["rule"] and "timeout at agreement < 0.94" in gated["rule"]


def test_paired_worlds_counts_the_discordant_drives_and_refuses_unpaired_runs(tmp_path):
    """eval.analyses.paired_worlds: McNemar's exact test on the drives where only one run ended right (7 against 1:
    p = 0.0703, the binomial's two-sided tail), the counts of both, and an error naming the problem when the runs
    localized different drives."""
    import json

    from eval.analyses.paired_worlds import main, mcnemar_exact

    assert mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(7, 1) == pytest.approx(0.0703125)

    def run(right, particles=None):
        rows = [{"world": "w-1", "run": k, "right_at_end": r, "success": r, "localized_at_end": r} for k, r in right]
        return {"runs": rows, "summary": {"num_particles": 100, "particles_per_update": particles}}

    a = [(k, k < 9) for k in range(1, 11)]  # 8 right: 1-8
    b = [(k, k in (1, 9)) for k in range(1, 11)]  # 2 right: 1 (both), 9 (only B)
    for name, rows in (("a", a), ("b", b), ("c", a[:5])):
        (tmp_path / name).mkdir()
        (tmp_path / name / "metrics.json").write_text(json.dumps(run(rows, 50.0)))
    out = main([str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "p.json")])
    o = out["outcomes"]["right_at_end"]
    assert (o["a"], o["b"], len(o["only_a"]), o["only_b"]) == (8, 2, 7, ["w-1-run9"])
    assert o["p_mcnemar"] == pytest.approx(0.0703125) and json.loads((tmp_path / "p.json").read_text())["drives"] == 10
    assert "false_alarms" not in out  # (runs that did not score them)
    with pytest.raises(SystemExit, match="different drives"):
        main([str(tmp_path / "a"), str(tmp_path / "c")])
    for name, alarms, hours in (("a", 0, 1.0), ("b", 4, 1.0)):  # the false alarms over each run's right tracking
        doc = json.loads((tmp_path / name / "metrics.json").read_text())
        doc["summary"].update(false_alarms=alarms, tracking_right_h=hours)
        (tmp_path / name / "metrics.json").write_text(json.dumps(doc))
    fa = main([str(tmp_path / "a"), str(tmp_path / "b")])["false_alarms"]
    assert (fa["a"], fa["b"], fa["hours_b"]) == (0, 4, 1.0) and fa["p_rates"] == pytest.approx(2 / 16)
    # kidnapped runs: detection (<= 2 s) and re-convergence (<= 5 s) over the drives right before it in both
    for name, detected, back in (
        ("a", [1.0, 0.4, None, 2.0], [3.0, 6.0, None, 5.0]),
        ("b", [1.0, 2.2, 0.2, 0.2], [9.0] * 4),
    ):
        doc = json.loads((tmp_path / name / "metrics.json").read_text())
        for k, row in enumerate(doc["runs"]):
            row.update(kidnap_at_s=30.0, right_before_kidnap=k < 4 or (name == "a" and k == 9))
            row.update(detected_after_s=detected[k % 4], reconverged_after_s=back[k % 4])
        (tmp_path / name / "metrics.json").write_text(json.dumps(doc))
    out = main([str(tmp_path / "a"), str(tmp_path / "b")])
    det, rec = out["outcomes"]["detected_within_2s"], out["outcomes"]["reconverged_within_5s"]
    assert out["kidnapped_drives"] == 4 and det["of"] == 4  # run 10 was right before it in A only
    assert (det["a"], det["b"], det["only_a"], det["only_b"]) == (3, 3, ["w-1-run2"], ["w-1-run3"])
    assert (rec["a"], rec["b"], len(rec["only_a"]), rec["p_mcnemar"]) == (2, 0, 2, pytest.approx(0.5))


def test_the_twins_analysis_turns_walls_onto_walls_and_sums_over_the_updates_only():
    """eval.analyses.twins: a twin floor's wall end points turned about its centre are wall end points again; the
    evidence is summed over the run's updates only: over a mask and over its complement it adds up to the sum over
    every scan."""
    from eval.analyses.twins import drive_evidence, turned
    from irmcl_warp.mcl.worlds import world_map

    world = floors.build("twin-9")
    walls = world.segments[: world.n_walls]
    ends = np.vstack([walls[:, :2], walls[:, 2:]])
    moved = turned(world, np.column_stack([ends, np.zeros(len(ends))]))[:, :2]
    assert np.min(np.hypot(*(moved[:, None] - ends[None]).transpose(2, 0, 1)), 1).max() < 1e-9
    assert np.allclose(turned(world, turned(world, np.array([[3.0, 4.0, 0.5]]))), [[3.0, 4.0, 0.5]])
    cfg = _worlds_cfg("worlds.split=twin-9", "worlds.run_s=6")
    grid = world_map(world, cfg, DEVICE)
    every = np.ones(400, bool)
    odd = np.arange(400) % 2 == 1
    parts = [drive_evidence(world, cfg, 1, m, grid, DEVICE) for m in (every, odd, ~odd)]
    assert parts[1]["updates"] + parts[2]["updates"] == parts[0]["updates"] > 0
    assert parts[1]["evidence"] + parts[2]["evidence"] == pytest.approx(parts[0]["evidence"], rel=1e-9, abs=1e-9)
    assert parts[0]["evidence"] != 0.0


def test_the_auroc_difference_resamples_drives_and_brackets_a_real_gain():
    """A's confidence orders every drive's updates right, B's is noise: the interval lies above 0; A against itself
    gives 0 in every resample."""
    from eval.analyses.paired_worlds import auroc_difference

    rng = np.random.default_rng()
    a, b = {}, {}
    for k in range(20):
        y = rng.random(30) < 0.6
        a[("w", k)] = (np.where(y, 0.7, 0.3) + rng.normal(0, 0.05, 30), y)
        b[("w", k)] = (rng.random(30), y)
    d = auroc_difference(a, b, draws=200)
    assert d["a"] > 0.95 and abs(d["b"] - 0.5) < 0.1 and d["ci95"][0] > 0.2 and d["ci95"][0] <= d["difference"]
    same = auroc_difference(a, a, draws=50)
    assert same["difference"] == 0 and same["ci95"] == [0.0, 0.0]


def test_the_unmapped_analysis_names_the_drives_that_leave_a_random_drives_map():
    """eval.analyses.unmapped on twin-1002's first three drives: drive 2 enters a room the random 400 m drive never
    mapped (its scans then fit the mapped twin room), and no drive leaves the coverage drive's map."""
    from eval.analyses.unmapped import unmapped

    res = unmapped("twin-1002", 3, DEVICE)
    assert set(res["shares"]) == {"random", "cover"}
    random_shares, cover_shares = res["shares"]["random"]["twin-1002"], res["shares"]["cover"]["twin-1002"]
    assert len(random_shares) == len(cover_shares) == 3 and all(0.0 <= s <= 1.0 for s in random_shares)
    assert "twin-1002-run2" in res["leaving"]["random"] and random_shares[1] > 0.1
    assert res["leaving"]["cover"] == [] and max(cover_shares) == 0.0


def test_the_kidnaps_analysis_tells_the_misses_apart(tmp_path):
    """eval.analyses.kidnaps on four synthetic kidnapped drives (kidnapped at 3 s, scans every 0.2 s, an update every
    other scan): one met, one right again after 0.4 s but 15 deg off between two updates later, one right again but
    taken over at an update later, one never detected and confidently wrong for 1 s; a drive wrong before the
    kidnapping is left out."""
    import json

    from eval.analyses.kidnaps import kidnaps

    t = np.arange(0.0, 10.0, 0.2)
    updated = np.arange(len(t)) % 2 == 0
    rows, cases = (
        [],
        {
            1: (0.2, 0.4, None),  # met
            2: (0.2, 6.0, ("yaw", 7.0)),  # back at 3.6 s, 15 deg off at the scan after 7 s (between updates)
            3: (0.2, 6.0, ("place", 7.0)),  # back, then 5 m off from the update at 7 s on
            4: (None, None, None),  # not detected
        },
    )
    for run, (detected, back, later) in cases.items():
        truth = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
        est = truth.copy()
        conf = np.full(len(t), 0.95)
        gone = (t >= 3.0) & (t < 3.0 + (detected or 0.0) + 0.4)  # wrong from the kidnapping until right again
        if detected is None:
            gone = (t >= 3.0) & (t < 4.0)
        est[gone, 1] += 8.0
        conf[gone & (detected is not None)] = 0.1
        if later and later[0] == "yaw":
            k = int(np.flatnonzero((t > later[1]) & ~updated)[0])
            est[k, 2] = np.radians(15.0)
        if later and later[0] == "place":
            est[t >= later[1], 1] += 5.0
        np.savez(tmp_path / f"w-1-run{run}.npz", stamps=t, estimate=est, truth=truth, updated=updated, confidence=conf)
        rows.append(
            dict(
                world="w-1",
                run=run,
                kidnap_at_s=3.0,
                right_before_kidnap=True,
                detected_after_s=detected,
                reconverged_after_s=back,
            )  # fmt: skip
        )
    rows.append(dict(world="w-1", run=5, kidnap_at_s=3.0, right_before_kidnap=False))
    (tmp_path / "metrics.json").write_text(json.dumps({"runs": rows, "settings": {"worlds": {"confident_above": 0.8}}}))
    res = kidnaps(tmp_path)
    by = {d["drive"]: d for d in res["drives"]}
    assert res["kidnaps"] == 4 and by["w-1-run1"]["class"] == "met"
    assert by["w-1-run2"]["class"] == "back, off between updates only"
    assert by["w-1-run2"]["excursion_max_heading_deg"] == pytest.approx(15.0) and by["w-1-run2"][
        "first_right_after_s"
    ] == pytest.approx(0.2, abs=0.21)
    assert by["w-1-run3"]["class"] == "back, then wrong again at updates"
    assert by["w-1-run4"]["class"] == "not detected" and by["w-1-run4"]["confidently_wrong_s"] == pytest.approx(1.0)
    assert by["w-1-run1"]["confidently_wrong_s"] == 0.0


def test_the_kidnaps_evidence_tells_a_look_alike_window_from_one_whose_scans_told(rng):
    """eval.analyses.kidnaps --evidence on a corridor with a wall 5 m ahead of the true pose: where the wrong place
    the filter held (10 m further) has a wall 5 m ahead as well, the window's scans fit both and the miss counts as
    one no localizer could have resolved; without that wall the true pose fits better and the scans told. A drive
    made again that is not the recorded one is refused."""
    from types import SimpleNamespace

    from eval.analyses.kidnaps import window_evidence

    res, t = 0.1, np.arange(0.0, 8.0, 0.2)
    angles = np.linspace(-0.4, 0.4, 60)
    shift = rng.uniform(0.0, 0.3)  # the robot creeps towards the wall
    truth = np.column_stack([shift * t / t[-1], np.full_like(t, 2.0), np.zeros_like(t)])
    ranges = (5.0 - truth[:, :1]) / np.cos(angles)[None, :]
    log = SimpleNamespace(
        ground_truth=truth, odom=truth.copy(), ranges_m=ranges, info=SimpleNamespace(angles_rad=angles),
        T_base_laser=(0.0, 0.0, 0.0),
    )  # fmt: skip
    est = truth.copy()
    est[t >= 3.0, 0] += 10.0  # kidnapped at 3 s, never detected: the filter holds a place 10 m along
    trace = dict(stamps=t, estimate=est, truth=truth)
    row = dict(world="w-1", run=1, kidnap_at_s=3.0, detected_after_s=None)
    verdicts = {}
    for walls in ((50,), (50, 150)):  # cells of x = 5 m, and x = 15 m
        occ = np.zeros((40, 200))
        occ[:, list(walls)] = 1.0
        ev = window_evidence(trace, row, log, ScanAgreement(occ, (0.0, 0.0), res))
        assert ev["window_s"] == [3.0, 10.0] and ev["wrong_place"][0] == pytest.approx(10.0 + shift)
        verdicts[walls] = ev
    alike, told = verdicts[(50, 150)], verdicts[(50,)]
    assert alike["scans_tell"] is False and abs(alike["margin"]) < 0.02, alike
    assert told["scans_tell"] is True and told["margin"] > 0.9 and told["agreement_at_wrong_place"] < 0.05, told
    lost = dict(trace, estimate=np.where((t >= 3.0)[:, None], np.nan, est))  # a re-seed: no estimate to judge
    assert "scans_tell" not in window_evidence(lost, row, log, ScanAgreement(occ, (0.0, 0.0), res))
    other = SimpleNamespace(**{**vars(log), "ground_truth": truth + [0.5, 0.0, 0.0]})
    with pytest.raises(SystemExit, match="not the one the run recorded"):
        window_evidence(trace, row, other, ScanAgreement(occ, (0.0, 0.0), res))


def test_a_search_grid_over_the_budget_is_covered_in_turns(monkeypatch):
    """confidence.SEARCH_BUDGET: a grid of at most the budget is searched whole every time; a larger one in slices of
    the budget that together hold every pose once per turn, and the turns go on."""
    import irmcl_warp.mcl.confidence as confidence

    occ, origin, res = _box_map()
    rng = np.random.default_rng()
    grid = np.column_stack([rng.uniform(1, 14, 1000), rng.uniform(1, 9, 1000), rng.uniform(-3, 3, 1000)])
    monkeypatch.setattr(confidence, "SEARCH_BUDGET", 1000)
    whole = FeatureTracker(ScanAgreement(occ, origin, res), search_poses=grid, search_every=1)
    assert whole._search_slice() is grid and whole._search_slice() is grid
    monkeypatch.setattr(confidence, "SEARCH_BUDGET", 300)
    turns = FeatureTracker(ScanAgreement(occ, origin, res), search_poses=grid, search_every=1)
    slices = [turns._search_slice() for _ in range(4)]  # 300 + 300 + 300 + 100 of one turn, 200 of the next
    assert all(len(s) == 300 for s in slices)
    first_turn = np.vstack(slices)[:1000]
    assert len(np.unique(first_turn, axis=0)) == 1000 and np.array_equal(
        np.unique(first_turn, axis=0), np.unique(grid, axis=0)
    )
    assert np.array_equal(np.vstack(slices)[1000:], turns.search_poses[:200])


# --- a relocalization's places (worlds.relocalize_places) ---


def _box_scan(pose):
    occ, origin, res = _box_map()
    angles = np.linspace(-2.3, 2.3, 360)
    return occ, origin, res, angles, _true_ranges(occ, res, pose, angles)


def test_a_global_starts_first_draw_weighs_the_places_it_is_given():
    """add_candidates: poses about the truth join the uniform candidates of a global start's first update, and the
    scan keeps them (most of the set lands within 0.3 m of the truth, far more than from the uniform candidates alone);
    without a global start with candidates it is an error; poses off the map are dropped."""
    truth = np.array([3.0, 2.5, 0.4])
    _, _, _, _, scan = _box_scan(truth)
    near = {}
    for extra in (False, True):
        pf = _filter(weighting="likelihood_field", global_candidates=2)
        pf.rng = np.random.default_rng(1)
        pf.init_uniform()
        if extra:
            about = truth + pf.rng.normal(0.0, 1.0, (200, 3)) * [0.1, 0.1, 0.03]
            pf.add_candidates(np.vstack([about, [[-50.0, 3.0, 0.0]]]))
            assert len(pf.extra_candidates) == 200  # the pose off the map dropped
            pf.add_candidates(pf.uniform_poses(2100))  # more than one batch of N = 2000: weighed in two
            assert len(pf.extra_candidates) == 2300
        pf.step((0.0, 0.0, 0.0), scan)
        p = pf.particles.numpy()
        near[extra] = float(np.mean(np.hypot(*(p[:, :2] - truth[:2]).T) < 0.3))
    assert near[True] > 0.5 and near[True] > near[False] + 0.3
    assert len(pf.extra_candidates) == 0  # weighed once
    with pytest.raises(ValueError, match="global start"):
        pf.add_candidates(truth[None])
    plain = _filter(weighting="likelihood_field")
    plain.init_uniform()
    with pytest.raises(ValueError, match="global_candidates > 1"):
        plain.add_candidates(truth[None])


def test_a_relocalization_is_given_the_places_its_scan_fits_best():
    """RelocalizePlaces.seed: a search of the whole map finds the truth (or the box's half-turn twin) among its places,
    PLACE_SHARE of the particles about each; relocalize_places needs the search poses and a global start with
    candidates (errors naming the settings)."""
    from types import SimpleNamespace

    from irmcl_warp.mcl.confidence import search_grid
    from irmcl_warp.mcl.worlds import PLACE_SHARE, RelocalizePlaces

    truth = np.array([4.0, 3.0, 0.7])
    occ, origin, res, angles, scan = _box_scan(truth)
    grid = SimpleNamespace(known=np.ones(occ.shape, bool), probability=occ, origin_xy=origin, resolution_m=res)
    agree = ScanAgreement(occ, origin, res)
    w = SimpleNamespace(relocalize_places=2)
    got = []
    pf = SimpleNamespace(num_particles=2000, rng=np.random.default_rng(0), add_candidates=got.append)
    places = RelocalizePlaces(w, agree, search_grid(grid), global_candidates=10)
    assert places.seed(pf, scan, angles, np.array([0.1, 0.0, 0.0])) == 2
    poses = got[0]
    assert len(poses) == 2 * round(PLACE_SHARE * 2000)
    twin = np.array([15.0 - truth[0], 10.0 - truth[1], truth[2] - np.pi])
    centres = [poses[: len(poses) // 2].mean(0), poses[len(poses) // 2 :].mean(0)]
    hits = [
        min(np.hypot(*(c[:2] - q[:2])) for q in (truth, twin)) < 0.3
        and min(abs(np.angle(np.exp(1j * (c[2] - q[2])))) for q in (truth, twin)) < 0.15
        for c in centres
    ]
    assert any(hits)
    with pytest.raises(ValueError, match="search poses"):
        RelocalizePlaces(w, agree, None, global_candidates=10)
    with pytest.raises(ValueError, match="mcl.global_candidates > 1"):
        RelocalizePlaces(w, agree, search_grid(grid), global_candidates=1)  # (the message names both settings)


def test_the_lost_rule_chooser_breaks_a_tie_by_the_rule_that_asks_the_most_of_the_scans():
    """choose: the most kidnappings within 2 s without false alarms first; among equals the lowest agreement threshold,
    then the most updates in a row (not the earliest detection); the confidence alone loses a tie; a rule over 1 false
    alarm an hour is out however fast."""
    from eval.analyses.lost_rules import choose

    def row(below, updates, detected, per_h, median):
        return dict(
            agreement_below=below,
            updates=updates,
            detected_within_2s=detected,
            kidnaps=23,
            false_alarms_per_h=per_h,
            median_detection_s=median,
        )

    one, two, three = row(0.4, 1, 22, 0.0, 0.4), row(0.4, 2, 22, 0.0, 0.8), row(0.5, 3, 22, 0.0, 1.2)
    fast_loose, alone = row(0.5, 1, 23, 17.5, 0.4), row(0.0, 1, 22, 0.0, 0.2)
    assert choose([one, two, three, fast_loose, alone]) is two
    assert choose([one, three, alone]) is one
    assert choose([alone, row(0.3, 1, 21, 0.0, 0.4)]) is alone  # more detections first


def test_a_relocalization_can_weigh_the_particles_it_had_moved_by_the_odometry():
    """relocalize_keeps_particles: the particles at the lost event, remembered with the odometry's pose then, are
    given to the first update moved by the odometry since (the robot 1 m ahead: each particle 1 m ahead along its own
    heading, the yaw kept), once; without the setting nothing is remembered."""
    from types import SimpleNamespace

    from irmcl_warp.mcl.worlds import RelocalizePlaces

    occ, origin, res = _box_map()
    agree = ScanAgreement(occ, origin, res)
    had = np.array([[3.0, 2.0, 0.5], [6.0, 4.0, -1.0]])
    got = []
    pf = SimpleNamespace(
        particles=SimpleNamespace(numpy=lambda: had.astype(np.float32)), num_particles=2, add_candidates=got.append
    )
    keep = RelocalizePlaces(SimpleNamespace(relocalize_places=0, relocalize_keeps_particles=True), agree, None, 10)
    keep.remember(pf, [10.0, 10.0, np.pi / 2])
    assert keep.seed(pf, None, None, None, [10.0, 11.0, np.pi / 2]) == 0  # (no places searched)
    moved = got[0]
    forward = np.column_stack([np.cos(had[:, 2]), np.sin(had[:, 2])])  # 1 m ahead in each particle's own heading
    assert np.allclose(moved[:, :2], had[:, :2] + forward)
    assert np.allclose(moved[:, 2], had[:, 2])
    keep.seed(pf, None, None, None, [10.0, 12.0, np.pi / 2])
    assert len(got) == 1  # given once
    plain = RelocalizePlaces(SimpleNamespace(relocalize_places=0), agree, None, 1)
    plain.remember(pf, [0.0, 0.0, 0.0])
    assert plain.kept is None
    assert keep.describe() == "the particles it had" and plain.describe() == ""  # (an own-map run's lost line)
    with pytest.raises(ValueError, match="mcl.global_candidates > 1"):
        RelocalizePlaces(SimpleNamespace(relocalize_keeps_particles=True), agree, None, 1)


def test_the_lost_rule_is_chosen_again_from_a_record_without_replaying(tmp_path):
    """python -m eval.analyses.lost_rules --from-record: the rules of an earlier --out (rows written before the rules'
    names were kept) are chosen among again and the choice written; run folders and a record together are an error."""
    from eval.analyses.lost_rules import main

    rows = [
        dict(agreement_below=b, updates=n, detected_within_2s=d, kidnaps=23, false_alarms=0)
        | dict(false_alarms_per_h=0.0, median_detection_s=m, tracking_right_h=1.0)
        for b, n, d, m in ((0.0, 1, 16, 1.8), (0.4, 1, 22, 0.4), (0.4, 2, 22, 0.8), (0.4, 3, 21, 1.2))
    ]
    record = tmp_path / "tuning.json"
    record.write_text(json.dumps({"runs": ["outputs/worlds/worlds/tuning-x"], "rules": rows}))
    chosen = tmp_path / "lost_rule.txt"
    out = main(["--from-record", str(record), "--choose", str(chosen)])
    assert out["chosen"] == {"agreement_below": 0.4, "updates": 2}
    assert chosen.read_text().startswith("lost_agreement_below=0.4 lost_agreement_updates=2: detected within 2 s 22/23")
    with pytest.raises(ValueError, match="not both"):
        main([str(tmp_path), "--from-record", str(record)])


def test_a_worlds_run_naming_no_calibration_reads_the_one_for_its_particle_count(tmp_path, monkeypatch):
    """A 100k run that names no calibration judges itself with the 100k file (it took the 20k one until the
    2026-12-02 session, silently); with no file for its count it takes the 20k one with a warning naming both counts,
    and the file it reads is the one its identity holds."""
    import irmcl_warp.config as config
    from irmcl_warp import runs
    from irmcl_warp.mcl.worlds import calibration_of

    monkeypatch.setattr(config, "CALIBRATION_DIR", tmp_path)
    for name, n in (("likelihood_field.json", 20000), ("likelihood_field-100k.json", 100000)):
        doc = json.loads(_fake_calibration(tmp_path / name).read_text())
        (tmp_path / name).write_text(json.dumps({**doc, "num_particles": n}))
    cfg = _worlds_cfg("mcl.num_particles=100000")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        assert calibration_of(cfg).meta["num_particles"] == 100000
    assert [f["path"] for f in runs.identify(cfg, "worlds").inputs["worlds.calibration"]] == [
        str(tmp_path / "likelihood_field-100k.json")
    ]
    (tmp_path / "likelihood_field-100k.json").unlink()
    with pytest.warns(UserWarning, match="fitted on a filter of 20,000 particles, this run has 100,000"):
        assert calibration_of(cfg).meta["num_particles"] == 20000
    assert [f["path"] for f in runs.identify(cfg, "worlds").inputs["worlds.calibration"]] == [
        str(tmp_path / "likelihood_field.json")
    ]
