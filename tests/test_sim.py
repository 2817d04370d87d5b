import numpy as np
import pytest
from omegaconf import OmegaConf

from irmcl_warp.config import SimConfig
from irmcl_warp.geometry import relative
from irmcl_warp.io import read_bag, write_bag
from irmcl_warp.reference.sim import lidar_ranges, rasterize
from irmcl_warp.sim import simulate
from irmcl_warp.sim.trajectory import noisy_odometry
from irmcl_warp.sim.world import office
from irmcl_warp.kernels import SIM
from tests.devices import DEVICE


def small_sim(**over):
    base = dict(duration_s=12.0, num_beams=90, width_m=16.0, height_m=10.0)
    return OmegaConf.structured(SimConfig(**{**base, **over}))


def test_lidar_kernel_matches_twin_without_noise(rng):
    world = office(int(rng.integers(1000)), 16.0, 10.0)
    poses = np.c_[rng.uniform(1, 15, 10), rng.uniform(4.5, 5.5, 10), rng.uniform(-np.pi, np.pi, 10)]
    angles = np.linspace(-2.0, 2.0, 31)
    lidar = SIM.build("segment_lidar", segments=world.segments, angles_rad=angles, range_max_m=12.0, device=DEVICE)
    got, want = lidar.scan(poses, seed=0), lidar_ranges(world.segments, poses, angles, 12.0)
    assert np.array_equal(np.isnan(got), np.isnan(want)), f"seed {rng.seed}"
    np.testing.assert_allclose(got[~np.isnan(got)], want[~np.isnan(want)], atol=1e-4)


def test_lidar_noise_and_dropout_statistics():
    seg = np.array([[5.0, -50, 5.0, 50]])  # a wall 5 m ahead
    lidar = SIM.build(
        "segment_lidar",
        segments=seg,
        angles_rad=np.zeros(2000),
        range_max_m=20.0,
        noise_std_m=0.05,
        dropout_prob=0.1,
        device=DEVICE,
    )
    r = lidar.scan(np.zeros((1, 3)), seed=3)[0]
    valid = r[np.isfinite(r)]
    assert 0.08 < np.isnan(r).mean() < 0.12
    assert abs(valid.mean() - 5.0) < 0.01 and 0.045 < valid.std() < 0.055
    assert np.array_equal(r, lidar.scan(np.zeros((1, 3)), seed=3)[0], equal_nan=True)  # seeded: reproducible
    assert not np.array_equal(r, lidar.scan(np.zeros((1, 3)), seed=4)[0], equal_nan=True)


@pytest.mark.parametrize("on_lattice", [False, True])
def test_rasterize_matches_twin(rng, on_lattice):
    world = office(int(rng.integers(1000)), 12.0, 8.0)
    origin = (-0.5, -0.5) if on_lattice else (-0.5 + 0.013, -0.5 + 0.027)
    got = SIM.build("rasterize", device=DEVICE)(world.segments, origin, 0.1, (90, 130))
    want = rasterize(world.segments, origin, 0.1, (90, 130))
    assert np.mean(got == want) > 0.999
    # every wall is drawn, the outer ones included (on the lattice they lie on cell borders)
    for x0, y0, x1, y1 in world.segments:
        mid = ((x0 + x1) / 2 - origin[0]) / 0.1, ((y0 + y1) / 2 - origin[1]) / 0.1
        ix, iy = int(np.clip(mid[0], 0, 129)), int(np.clip(mid[1], 0, 89))
        assert got[max(iy - 1, 0) : iy + 2, max(ix - 1, 0) : ix + 2].any(), (x0, y0, x1, y1)


def test_simulation_is_deterministic_and_odometry_noise_follows_alphas():
    a, _ = simulate(small_sim(seed=5), device=DEVICE)
    b, _ = simulate(small_sim(seed=5), device=DEVICE)
    np.testing.assert_array_equal(a.ranges_m, b.ranges_m)
    np.testing.assert_array_equal(a.odom, b.odom)
    c, _ = simulate(small_sim(seed=6), device=DEVICE)
    assert not np.array_equal(a.ground_truth[:5], c.ground_truth[:5]) or not np.array_equal(a.ranges_m, c.ranges_m)
    exact = noisy_odometry(a.ground_truth, [0, 0, 0, 0], np.random.default_rng(0))
    np.testing.assert_allclose(
        relative(exact[:-1], exact[1:]), relative(a.ground_truth[:-1], a.ground_truth[1:]), atol=1e-9
    )
    drift = np.hypot(*(a.odom[-1, :2] - relative(a.ground_truth[:1], a.ground_truth[-1:])[0, :2]))
    assert drift > 1e-3  # the default alphas do perturb the odometry


@pytest.mark.parametrize("version", [1, 2])
def test_simulated_log_roundtrips_through_a_bag(tmp_path, version):
    log, _ = simulate(small_sim(seed=2, duration_s=6.0), device=DEVICE)
    path = write_bag(log, tmp_path / ("sim.bag" if version == 1 else "sim_ros2"), version=version)
    back = read_bag(path)
    np.testing.assert_allclose(back.stamps, log.stamps, atol=1e-9)
    np.testing.assert_array_equal(np.isnan(back.ranges_m), np.isnan(log.ranges_m))
    np.testing.assert_array_equal(back.ranges_m[back.valid], log.ranges_m[log.valid])
    np.testing.assert_allclose(back.odom, log.odom, atol=1e-6)
    np.testing.assert_allclose(back.T_base_laser, log.T_base_laser, atol=1e-7)
    np.testing.assert_allclose(back.info.angles_rad, log.info.angles_rad, atol=1e-6)
    assert not back.defects
