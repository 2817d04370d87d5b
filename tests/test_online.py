"""The online localizer (mcl/online.py, track.Localizer): fed one scan and one odometry reading at a time it gives
the offline run's poses bit for bit, with a covariance and the updates AMCL's gates allow."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import SimConfig, register
from irmcl_warp.io import write_bag, write_tum
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.mcl.online import open_localizer
from irmcl_warp.mcl.stage import run_localize
from irmcl_warp.mcl.track import particle_covariance, window
from irmcl_warp.services.data import far_bound_m, load_stream
from irmcl_warp.sim import simulate
from tests.devices import DEVICE

CONF = Path(__file__).resolve().parents[1] / "conf"


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    d = tmp_path_factory.mktemp("online")
    log, _ = simulate(OmegaConf.structured(SimConfig(width_m=14.0, height_m=10.0, duration_s=30.0)), DEVICE)
    files = save_map(build_map(log, log.ground_truth, resolution_m=0.05, far_m=20.0, device=DEVICE), d / "office")
    return files["yaml"], write_bag(log, d / "drive.bag"), log.ground_truth


def _cfg(bag, map_yaml, *overrides, gates=("mcl.update_min_trans_m=0.2", "mcl.update_min_rot_rad=0.5")):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(
            "config",
            overrides=[
                "data=bag",
                f"data.path={bag}",
                f"localize.map_path={map_yaml}",
                f"device={DEVICE}",
                "mcl.weighting=likelihood_field",
                "localize.run_s=20",
                "localize.start_s=2",
                *gates,
                *overrides,
            ],
        )


@pytest.mark.parametrize("start", ["pose", "global"])
def test_one_scan_at_a_time_gives_the_offline_run_bit_for_bit(world, tmp_path, monkeypatch, start):
    map_yaml, bag, truth = world
    monkeypatch.chdir(tmp_path)
    pose = [float(truth[0, 0]) + 0.2, float(truth[0, 1]) - 0.1, float(truth[0, 2]) + 0.05]
    extra = (
        ["mcl.num_particles=600", f"localize.initial_pose=[{pose[0]},{pose[1]},{pose[2]}]"]
        if start == "pose"
        else ["mcl.num_particles=3000", "mcl.first_update=motion"]
    )
    cfg = _cfg(bag, map_yaml, *extra)
    out = run_localize(cfg)  # the offline stage

    log = load_stream(cfg)  # the log as the stage read it
    idx = window(log, cfg.localize.start_s, cfg.localize.run_s, "localize")
    loc = open_localizer(
        map_yaml,
        cfg.mcl,
        log.T_base_laser,
        log.info.angles_rad,
        far_bound_m(cfg, log.info.range_max_m),
        device=DEVICE,
        initial_pose=cfg.localize.initial_pose,
        initial_std=list(cfg.localize.tracking_std),
        reduce_after_s=cfg.localize.reduce_after_s if start == "global" else None,
    )
    est, updated, covs = [], [], []
    for i in idx:  # as a robot's driver would hand them over
        e = loc.update(float(log.stamps[i]), log.ranges_m[i].copy(), log.odom[i].copy())
        est.append(e.pose)
        updated.append(e.updated)
        covs.append(e.covariance)
    write_tum(tmp_path / "online.tum", log.stamps[idx], np.array(est))
    assert (tmp_path / "online.tum").read_bytes() == (out / "trajectory.tum").read_bytes()

    updated = np.array(updated)
    assert 0 < updated.sum() < len(idx)  # AMCL's gates: not every scan weighs
    if start == "global":
        assert not updated[0] and np.isnan(est[0]).all()  # first_update=motion: no pose before the robot moves
    else:
        assert updated[0]
    cov = covs[int(np.flatnonzero(updated)[-1])]
    assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) >= -1e-12)
    # the resampled set's x-y variance against the filter's own spread of the weighted set before resampling
    assert 0.5 < (cov[0, 0] + cov[1, 1]) / loc.pf.spread**2 < 2.0
    assert np.isnan(covs[int(np.flatnonzero(~updated)[-1])]).all()  # between updates: no fresh covariance


def test_the_covariance_wraps_the_heading_and_weighs_the_particles():
    rng = np.random.default_rng()
    pose = np.array([1.0, 2.0, np.pi - 0.01])
    particles = pose + rng.normal(0, [0.2, 0.1, 0.05], (4000, 3))
    particles[:, 2] = (particles[:, 2] + np.pi) % (2 * np.pi) - np.pi  # across the +-pi seam
    cov = particle_covariance(particles, np.zeros(len(particles)), pose)
    assert np.allclose(np.sqrt(np.diag(cov)), [0.2, 0.1, 0.05], rtol=0.1)
    heavy = np.zeros(len(particles))
    heavy[0] = 50.0  # one particle holds (almost) all the weight: the covariance is its offset squared
    d = particles[0] - pose
    d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
    assert np.allclose(particle_covariance(particles, heavy, pose), np.outer(d, d), atol=1e-6)


def test_the_ros2_example_calls_the_localizer_as_it_is():
    """examples/ros2_localizer.py runs only where rclpy exists; here: what it imports from the package exists and
    its call of open_localizer binds to the function's signature (so the example cannot rot unseen)."""
    import ast
    import importlib
    import inspect

    from irmcl_warp.mcl import online

    tree = ast.parse((Path(__file__).resolve().parents[1] / "examples" / "ros2_localizer.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module.startswith("irmcl_warp"):
            module = importlib.import_module(node.module)
            assert all(hasattr(module, a.name) for a in node.names), node.module
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", None) == "open_localizer"]
    assert len(calls) == 1
    inspect.signature(online.open_localizer).bind(*calls[0].args, **{k.arg: None for k in calls[0].keywords})


@pytest.mark.cpu_only  # the example converts on the CPU (it names no device)
def test_the_converter_template_turns_arrays_into_a_bag_we_read_back(tmp_path):
    """examples/convert_to_bag.py, the documented way to bring another format in, run as a user would."""
    import subprocess
    import sys

    from irmcl_warp.config import SimConfig
    from irmcl_warp.io import read_bag

    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=4.0, num_beams=30, width_m=12, height_m=8)), "cpu")
    i = log.info
    np.savez(
        tmp_path / "mine.npz",
        stamps=log.stamps,
        ranges=np.nan_to_num(log.ranges_m, nan=np.inf),
        odom=log.odom,
        angle_min=i.angle_min_rad,
        angle_increment=i.angle_increment_rad,
        range_min=i.range_min_m,
        range_max=i.range_max_m,
        T_base_laser=log.T_base_laser,
    )
    script = Path(__file__).resolve().parents[1] / "examples" / "convert_to_bag.py"
    run = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "mine.npz"), str(tmp_path / "mine.bag")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    back = read_bag(tmp_path / "mine.bag")
    assert np.array_equal(np.isnan(back.ranges_m), np.isnan(log.ranges_m))
    assert np.allclose(np.nan_to_num(back.ranges_m), np.nan_to_num(log.ranges_m)) and np.allclose(back.odom, log.odom)
    assert np.allclose(back.info.angles_rad, log.info.angles_rad) and np.allclose(back.T_base_laser, log.T_base_laser)


def test_a_calibrated_confidence_judges_the_run_and_changes_no_pose(world, tmp_path, monkeypatch, capsys):
    """With the calibrated filter (mcl=amcl) an own-map run writes its confidence per scan and ends saying
    whether it is localized (never "localized" below the threshold); with another filter the run says it has no
    calibrated confidence."""
    import json

    from irmcl_warp.mcl.own_map import CONFIDENT_ABOVE

    map_yaml, bag, truth = world
    monkeypatch.chdir(tmp_path)
    out = run_localize(_cfg(bag, map_yaml, "mcl=amcl", "localize.run_s=25", gates=()))
    last = capsys.readouterr().out.strip().splitlines()[-1]
    m = json.loads((out / "metrics.json").read_text())
    c = m["confidence_at_end"]
    assert 0 <= c <= 1 and m["localized_at_end"] == (c >= CONFIDENT_ABOVE)
    assert (f"localized, confidence {c:.2f}" in last) if c >= CONFIDENT_ABOVE else ("NOT localized" in last)
    spread = np.genfromtxt(out / "spread.csv", delimiter=",", names=True)
    assert np.isfinite(spread["confidence"][-1]) and np.isnan(spread["confidence"][0])  # none before the first update
    plain = run_localize(
        _cfg(bag, map_yaml, "mcl=amcl", "localize.run_s=25", "mcl.temper=0.031", gates=())
    )  # another filter: no calibration holds
    assert "no confidence: the filter differs from the calibrated one (mcl=amcl) in temper" in capsys.readouterr().out
    assert json.loads((plain / "metrics.json").read_text())["confidence_at_end"] is None


def test_the_judge_changes_no_pose(world):
    """follow's default (report_pose="filter"): the judge reads the filter and changes none of its poses."""
    from irmcl_warp.config import compose_config
    from irmcl_warp.mcl.confidence import FEATURES, Confidence, FeatureTracker, Judge, ScanAgreement
    from irmcl_warp.mcl.online import filter_in_map
    from irmcl_warp.mcl.track import follow
    from irmcl_warp.io import read_bag

    map_yaml, bag, truth = world
    log = read_bag(bag)
    m = compose_config(["mcl=amcl", "mcl.num_particles=3000"]).mcl
    runs_ = []
    for judged in (False, True):
        pf, grid = filter_in_map(map_yaml, m, log.T_base_laser, log.info.angles_rad, 20.0, DEVICE)
        pf.init_uniform()
        judge = Judge(
            FeatureTracker(
                ScanAgreement(np.where(grid.known, grid.probability, 0.0), grid.origin_xy, grid.resolution_m)
            ),
            Confidence(np.zeros(len(FEATURES)), 0.0, np.zeros(len(FEATURES)), np.ones(len(FEATURES))),
            log.info.angles_rad,
            log.T_base_laser,
        )
        conf = []
        runs_.append(follow(pf, log, np.arange(60), m, judge=judge if judged else None, confidences=conf))
    assert np.array_equal(runs_[0], runs_[1], equal_nan=True)


@pytest.mark.parametrize("weighting", ["nog_raymarch", "nof_direct"])
def test_a_nof_trained_for_another_far_bound_is_refused_naming_both(world, tmp_path, monkeypatch, weighting):
    """A NOF answers for the ranges it was trained on: localizing with another far bound is an error that names
    the two bounds (and the setting that picks the run's), before any scan is weighed; the trained bound goes."""
    from irmcl_warp.config import ModelConfig
    from irmcl_warp.nof.checkpoint import atomic_torch_save
    from irmcl_warp.nof.model import NOF

    map_yaml, bag, _ = world
    monkeypatch.chdir(tmp_path)
    cfg = _cfg(bag, map_yaml)
    far_m = far_bound_m(cfg, load_stream(cfg).info.range_max_m)
    model = NOF(ModelConfig(width=16, depth=2, skip_after=1, num_freqs=2)).eval()
    ckpt = tmp_path / "nof.pt"
    trained = far_m + 10.0
    atomic_torch_save({"model": model.state_dict(), "model_config": model.config_dict(), "far_m": trained}, ckpt)
    common = (f"mcl.weighting={weighting}", f"localize.nof_path={ckpt}", "mcl.num_particles=200", "localize.run_s=3")
    with pytest.raises(
        ValueError,
        match=rf"nof.pt: this NOF was trained with the far bound {trained:g} m, and this "
        rf"run localizes with {far_m:g} m .*data.far_m={trained:g}",
    ):
        run_localize(_cfg(bag, map_yaml, *common))
    assert not list(Path("outputs").rglob("trajectory.tum"))
    out = run_localize(_cfg(bag, map_yaml, *common, f"data.far_m={trained}"))  # the bound it was trained with
    assert (out / "trajectory.tum").is_file()


def test_a_run_whose_particle_count_moves_borrows_no_calibration():
    """mcl.kld_sampling changes the filter the calibration was fitted on (a fixed count, kld_sampling false in
    conf/mcl/amcl.yaml), so an own-map run with it says it has no confidence, naming the setting, as for any other
    difference from mcl=amcl."""
    from irmcl_warp.config import compose_config
    from irmcl_warp.mcl.own_map import calibrated_judge

    judge, why = calibrated_judge(compose_config(["mcl=amcl", "mcl.kld_sampling=true"]), None, None)
    assert judge is None and why.endswith("in kld_sampling"), why
    judge, why = calibrated_judge(compose_config(["mcl=amcl", "mcl.kld_sampling=true", "mcl.temper=0.1"]), None, None)
    assert judge is None and why.endswith("in kld_sampling, temper"), why


class _TwoClusters:
    """A stand-in filter whose set holds two clusters, 70 % at (2, 2, 0) and 30 % at (6, 2, 0): its estimate, the
    mean, lies between them at (3.2, 2, 0), where no particle is."""

    num_particles = 1000

    def __init__(self, rng):
        n = self.num_particles
        xy = np.where(np.arange(n)[:, None] < 700, [2.0, 2.0], [6.0, 2.0]) + rng.normal(0, 0.05, (n, 2))
        self.p = np.column_stack([xy, rng.normal(0, 0.02, n)])
        self.particles = type("A", (), {"numpy": lambda _: self.p})()
        self.log_w = type("A", (), {"numpy": lambda _: np.zeros(n)})()

    def step(self, u, ranges_m):
        return (np.array([3.2, 2.0, 0.0]),)


@pytest.mark.parametrize("report_pose", ["mode", "filter"])
def test_a_judged_run_reports_the_pose_its_confidence_is_about(report_pose, rng):
    """With a judge, report_pose="mode" gives the heaviest mode's pose (what the confidence judged, as the worlds
    stage reports), not the filter's mean between two clusters; "filter" keeps the filter's estimate; between
    updates either pose follows the odometry."""
    from omegaconf import OmegaConf

    from irmcl_warp.mcl.confidence import FEATURES, Confidence, FeatureTracker, Judge, ScanAgreement
    from irmcl_warp.mcl.track import Localizer

    grid = np.zeros((100, 100))
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 1.0  # a 10 m box
    judge = Judge(
        FeatureTracker(ScanAgreement(grid, (0.0, 0.0), 0.1)),
        Confidence(np.zeros(len(FEATURES)), 0.0, np.zeros(len(FEATURES)), np.ones(len(FEATURES))),
        np.linspace(-1.5, 1.5, 30),
        (0.0, 0.0, 0.0),
    )
    m = OmegaConf.create(
        {"update_min_trans_m": 0.2, "update_min_rot_rad": 0.5, "first_update": "motion", "reduce_to": 0}
    )
    loc = Localizer(_TwoClusters(rng), m, judge=judge, report_pose=report_pose)
    ranges = np.full(30, 3.0)
    assert np.isnan(loc.update(0.0, ranges, [0.0, 0.0, 0.0]).pose).all()  # no update before the robot moved
    e = loc.update(0.1, ranges, [0.3, 0.0, 0.0])
    assert e.updated
    want = judge.pose if report_pose == "mode" else np.array([3.2, 2.0, 0.0])
    assert np.allclose(e.pose, want)
    assert (np.hypot(*(e.pose[:2] - [2.0, 2.0])) < 0.1) == (report_pose == "mode")
    moved = loc.update(0.2, ranges, [0.4, 0.0, 0.0])  # 0.1 m more: no update, the pose follows the odometry
    assert not moved.updated and np.allclose(moved.pose, want + [0.1, 0.0, 0.0], atol=1e-3)
    with pytest.raises(ValueError, match="report_pose 'mean' is not one of"):
        Localizer(_TwoClusters(rng), m, judge=judge, report_pose="mean")


class _Scripted:
    """A stand-in judge: the confidences it is given, one per update, with the scan's agreement at 0.5 (above the
    lost rule's one-scan trigger, below its timeout gate)."""

    def __init__(self, confidences):
        from irmcl_warp.mcl.confidence import FEATURES

        self.left, self.resets = list(confidences), 0
        self.features = np.zeros(len(FEATURES))
        self.features[FEATURES.index("agreement")] = 0.5
        self.pose = np.array([2.0, 2.0, 0.0])
        self.angles, self.T = np.zeros(30), (0.0, 0.0, 0.0)

    def __call__(self, particles, log_w, ranges_m, odom_delta):
        return self.left.pop(0)

    def reset(self):
        self.resets += 1


class _Counting(_TwoClusters):
    def __init__(self, rng):
        super().__init__(rng)
        self.uniform_starts = 0

    def init_uniform(self):
        self.uniform_starts += 1


@pytest.mark.parametrize("relocalize", [True, False])
def test_a_robot_the_worlds_rule_declares_lost_starts_again_and_says_when(relocalize, rng):
    """An own-map localizer with a judge runs the worlds stage's lost-robot rule (its settings from
    conf/exp/worlds.yaml): localized (0.9), then a confidence below lost_below for lost_after_s is one lost event,
    at that update's time; with relocalize the filter starts again from a uniform spread (the judge reset, no pose
    until the next update after motion), without it only the event is kept."""
    from omegaconf import OmegaConf

    from irmcl_warp.config import own_map_lost_rule_settings
    from irmcl_warp.mcl.track import Localizer
    from irmcl_warp.mcl.worlds import LostRule

    w = own_map_lost_rule_settings()
    assert w.lost_after_s == 1.0 and w.lost_below == 0.2  # the +exp=worlds values the rule was chosen with
    m = OmegaConf.create(
        {"update_min_trans_m": 0.2, "update_min_rot_rad": 0.5, "first_update": "motion", "reduce_to": 0}
    )
    pf, judge = _Counting(rng), _Scripted([0.9, 0.1, 0.1, 0.1, 0.1, 0.9])
    loc = Localizer(pf, m, judge=judge, report_pose="mode", lost_rule=LostRule(w), relocalize=relocalize)
    ranges = np.full(30, 3.0)
    loc.update(0.0, ranges, [0.0, 0.0, 0.0])
    out = [loc.update(0.5 * k, ranges, [0.3 * k, 0.0, 0.0]) for k in range(1, 5)]  # updates at 0.5 .. 2.0 s
    assert [e.updated for e in out] == [True] * 4
    assert loc.lost_at_s == [2.0]  # low since 1.0 s: lost at 2.0 s
    assert out[-1].confidence == 0.1
    if relocalize:
        assert pf.uniform_starts == 1 and judge.resets == 1 and np.isnan(out[-1].pose).all()
        still = loc.update(2.1, ranges, [1.2, 0.0, 0.0])  # the spread waits for the robot to move
        assert not still.updated and np.isnan(still.pose).all()
        again = loc.update(2.5, ranges, [1.5, 0.0, 0.0])
        assert again.updated and np.allclose(again.pose, judge.pose)
    else:
        assert pf.uniform_starts == 0 and judge.resets == 0 and np.isfinite(out[-1].pose).all()


class _Near:
    """A stand-in ScanAgreement for the lost rule's search near a low estimate: ``refine`` gives ``best``."""

    def __init__(self, best):
        self.best, self.asked = best, 0

    def refine(self, pose, ranges_m, angles_rad, T_base_laser, step_m=0.1, step_rad=0.05):
        self.asked += 1
        return np.asarray(pose, float), self.best


@pytest.mark.parametrize("best", [0.9, 0.2])
def test_a_localizer_asks_near_a_low_estimate_before_it_counts_the_scan(best, rng):
    """Localizer with conf/exp/worlds.yaml's rule (the search near a low estimate on): scans that agree 0.1 at the
    estimate, the confidence high. Where a pose near it fits them (0.9, at or above lost_agreement_near_fit) the robot
    is not lost; where none does (0.2) it is lost at the second low update, as lost_agreement_updates says. The search
    is asked only at low updates."""
    from types import SimpleNamespace

    from omegaconf import OmegaConf

    from irmcl_warp.config import own_map_lost_rule_settings
    from irmcl_warp.mcl.confidence import FEATURES
    from irmcl_warp.mcl.track import Localizer
    from irmcl_warp.mcl.worlds import LostRule

    w = own_map_lost_rule_settings()
    assert w.lost_agreement_near_m > 0 and w.lost_agreement_updates == 2 and w.lost_agreement_near_fit == 0.8
    m = OmegaConf.create(
        {"update_min_trans_m": 0.2, "update_min_rot_rad": 0.5, "first_update": "motion", "reduce_to": 0}
    )
    pf, judge = _Counting(rng), _Scripted([0.95] * 6)
    near = _Near(best)
    judge.tracker = SimpleNamespace(agreement=near)
    loc = Localizer(pf, m, judge=judge, report_pose="mode", lost_rule=LostRule(w), relocalize=False)
    ranges = np.full(30, 3.0)
    loc.update(0.0, ranges, [0.0, 0.0, 0.0])  # agreement 0.5: localized, nothing searched
    assert near.asked == 0
    judge.features[FEATURES.index("agreement")] = 0.1
    for k in range(1, 4):
        loc.update(0.5 * k, ranges, [0.3 * k, 0.0, 0.0])
    assert near.asked >= 2
    assert loc.lost_at_s == ([] if best >= w.lost_agreement_near_fit else [1.0])


class _Places:
    """A stand-in RelocalizePlaces: how often a relocalization asked it for places."""

    def __init__(self):
        self.seeded, self.remembered = 0, []

    def remember(self, pf, odom):
        self.remembered.append(list(odom))

    def seed(self, pf, ranges_m, angles_rad, T_base_laser, odom=None):
        self.seeded += 1
        return 1


def test_a_relocalizations_first_update_is_given_the_places_its_scan_fits(rng):
    """Localizer with places: lost at 2.0 s (the worlds rule), a uniform start; the first update after the robot moved
    again asks for the places once, before the filter weighs; later updates do not."""
    from omegaconf import OmegaConf

    from irmcl_warp.config import own_map_lost_rule_settings
    from irmcl_warp.mcl.track import Localizer
    from irmcl_warp.mcl.worlds import LostRule

    m = OmegaConf.create(
        {"update_min_trans_m": 0.2, "update_min_rot_rad": 0.5, "first_update": "motion", "reduce_to": 0}
    )
    pf, places = _Counting(rng), _Places()
    judge = _Scripted([0.9, 0.1, 0.1, 0.1, 0.9, 0.9])
    w = own_map_lost_rule_settings()
    loc = Localizer(pf, m, judge=judge, report_pose="mode", lost_rule=LostRule(w), relocalize=True, places=places)
    ranges = np.full(30, 3.0)
    loc.update(0.0, ranges, [0.0, 0.0, 0.0])
    out = [loc.update(0.5 * k, ranges, [0.3 * k, 0.0, 0.0]) for k in range(1, 5)]
    assert loc.lost_at_s == [2.0] and pf.uniform_starts == 1 and np.isnan(out[-1].pose).all()
    assert places.seeded == 0 and places.remembered == [[1.2, 0.0, 0.0]]  # the odometry when declared lost
    assert not loc.update(2.5, ranges, [1.5, 0.0, 0.0]).updated and places.seeded == 0  # waits for motion
    again = loc.update(3.0, ranges, [1.8, 0.0, 0.0])
    assert again.updated and places.seeded == 1
    loc.update(3.5, ranges, [2.1, 0.0, 0.0])
    assert places.seeded == 1  # only a relocalization's first update
