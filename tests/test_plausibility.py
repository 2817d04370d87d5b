"""Inputs that read without an error and are still wrong are said loudly, naming the file: an inverted map, beams
in the other order, a second no-return code, zero ranges, odometry that jumps off the map, settings that make a
run meaningless."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from omegaconf import OmegaConf

from irmcl_warp.config import SimConfig, compose_config, settings_warnings
from irmcl_warp.io import LogDefectWarning, read_bag, read_log, write_bag
from irmcl_warp.io.beams import mask_ranges
from irmcl_warp.io.plausibility import beam_order_votes, check_beam_order, check_odometry
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.mapping.mapio import load_map
from irmcl_warp.sim import simulate
from irmcl_warp.types import DefectReport


@pytest.fixture(scope="module")
def drive():
    log, _ = simulate(OmegaConf.structured(SimConfig(width_m=14.0, height_m=10.0, duration_s=40.0)), "cpu")
    return log


def _warned(fn, *args) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn(*args)
    return [str(w.message) for w in caught if issubclass(w.category, LogDefectWarning)]


def test_an_inverted_map_is_said_to_be_one(drive, tmp_path):
    grid = build_map(drive, drive.ground_truth, resolution_m=0.05, far_m=20.0, device="cpu")
    files = save_map(grid, tmp_path / "office")
    assert _warned(load_map, files["yaml"]) == []
    inverted = tmp_path / "inverted.yaml"
    inverted.write_text(files["yaml"].read_text().replace("negate: 0", "negate: 1"))
    said = _warned(load_map, inverted)
    assert len(said) == 1 and "inverted.yaml" in said[0] and "occupied" in said[0] and "negate" in said[0]


def test_a_map_whose_free_space_is_mostly_beside_walls_is_said_to_be(drive):
    from irmcl_warp.io.plausibility import check_map, free_on_walls_share

    grid = build_map(drive, drive.ground_truth, resolution_m=0.05, far_m=20.0, device="cpu")
    assert (
        free_on_walls_share(grid.probability, grid.known) < 0.25
        and _warned(check_map, "office.yaml", grid.probability, grid.known) == []
    )
    # free space only in thin lines beside the walls (a third of the known cells occupied: the share check is quiet)
    p, known = np.full((200, 200), 0.5, np.float32), np.zeros((200, 200), bool)
    for row in range(10, 190, 20):
        p[row], p[row - 1], p[row + 1] = 0.9, 0.1, 0.1
        known[row - 1 : row + 2] = True
    said = _warned(check_map, "thin.yaml", p, known)
    assert free_on_walls_share(p, known) == 1.0
    assert len(said) == 1 and "thin.yaml" in said[0] and "touch an occupied cell" in said[0]
    known[:] = True  # the same walls with the rooms between them free: quiet
    p[p == 0.5] = 0.1
    assert _warned(check_map, "rooms.yaml", p, known) == []


def test_beams_in_the_other_order_are_said_to_be(drive, tmp_path):
    """Turning on the spot, consecutive scans line up with the odometry's rotation as the log orders its beams;
    mirrored, they line up only the other way round."""
    inc = drive.info.angle_increment_rad
    fwd, rev = beam_order_votes(drive.ranges_m, drive.odom, inc)
    assert fwd > 8 and rev <= fwd // 10
    assert not check_beam_order("office.bag", drive.ranges_m, drive.odom, inc)
    said = _warned(check_beam_order, "mirrored.bag", drive.ranges_m[:, ::-1], drive.odom, inc)
    assert len(said) == 1 and "mirrored.bag" in said[0] and "other way round" in said[0]
    # end to end: a bag whose scans were written in the other order warns when it is read
    bag = write_bag(dataclasses.replace(drive, ranges_m=drive.ranges_m[:, ::-1].copy()), tmp_path / "mirrored.bag")
    said = _warned(read_log, compose_config(["data=bag", f"data.path={bag}", "device=cpu"]))
    assert any("mirrored.bag" in s and "other way round" in s for s in said)


def test_a_second_no_return_code_is_counted_and_named(rng):
    ranges = rng.uniform(0.5, 20.0, (200, 90))
    ranges[rng.random(ranges.shape) < 0.1] = 81.91  # the log's no-return value
    ranges[rng.random(ranges.shape) < 0.05] = 81.80  # and a second code a few cm under it
    report = DefectReport()
    masked, no_return = mask_ranges("odd.clf", ranges, None, report)
    assert no_return == pytest.approx(81.91), rng.seed
    assert report.counts.get("near_no_return_code", 0) == int(np.sum(ranges == 81.80)), rng.seed
    assert "81.8 m" in report.notes["near_no_return_code"] and np.isfinite(masked[ranges == 81.80]).all()
    clean = DefectReport()
    mask_ranges("clean.clf", np.where(ranges == 81.80, 5.0, ranges), None, clean)
    assert "near_no_return_code" not in clean.counts


def test_zero_ranges_in_a_bag_are_no_return_even_where_range_min_is_zero(drive, tmp_path):
    ranges = drive.ranges_m.copy()
    ranges[::7, ::5] = 0.0  # a driver's "no echo"; the simulator's range_min is 0
    log = read_bag(write_bag(dataclasses.replace(drive, ranges_m=ranges), tmp_path / "zeros.bag"))
    assert drive.info.range_min_m == 0.0 and np.isnan(log.ranges_m[::7, ::5]).all()
    assert log.defects.counts.get("zero_ranges", 0) == ranges[::7, ::5].size


def test_odometry_that_jumps_off_the_map_is_an_error_naming_the_log():
    odom = np.column_stack([np.linspace(0, 5, 50), np.zeros(50), np.zeros(50)])
    check_odometry("fine.bag", odom)
    odom[30:, 0] += 1e6
    with pytest.raises(ValueError, match=r"broken.bag: the odometry jumps 1e\+06 m between scans 29 and 30"):
        check_odometry("broken.bag", odom)


def test_settings_that_make_a_run_meaningless_are_warned_about():
    assert settings_warnings(compose_config(["device=cpu"])) == []
    said = settings_warnings(compose_config(["mcl.num_particles=2", "data.far_m=0.1"]))
    assert len(said) == 2 and said[0].startswith("mcl.num_particles=2") and said[1].startswith("data.far_m=0.1")
