"""Per-scan beam geometry through the readers: every scan's beams read at their own angles, degenerate
geometry and quaternions rejected naming the message, typos in the beam policy rejected."""

import warnings

import numpy as np
import pytest

from bagmaker import scan, write_scans
from irmcl_warp.io import LogDefectWarning, LogFormatError, read_bag, read_carmen
from irmcl_warp.io.beams import ScanGeometry, resample_nearest

B = 19
STEP = np.pi / (B - 1)


def wall(angles):
    """Ranges of a room seen from its centre: a different value at every angle, so a beam read at the wrong
    angle shows."""
    return 2.0 + np.cos(3 * np.asarray(angles)) + 0.1 * np.asarray(angles)


def common_scan(k):
    a = -np.pi / 2 + STEP * np.arange(B)
    return scan(0.1 * k + 1.0, wall(a))


def shifted_scan(k, shift):
    """A scan whose beams start ``shift`` rad later: its ranges are what lies at its own angles."""
    a = -np.pi / 2 + shift + STEP * np.arange(B)
    return scan(0.1 * k + 1.0, wall(a), angle_min=-np.pi / 2 + shift)


def test_a_scan_starting_at_another_angle_is_an_error_naming_it(tmp_path):
    p = tmp_path / "shifted.bag"
    write_scans(p, [common_scan(0), common_scan(1), shifted_scan(2, np.radians(0.7)), common_scan(3)])
    with pytest.raises(LogFormatError, match=r"shifted.bag, message 2 on /scan: scan's beams start at -89.3000 deg"):
        read_bag(p)


def test_resample_reads_every_scan_at_its_own_angles(tmp_path):
    # a scan shifted by a whole beam and one with twice the beams over the same field of view
    a2 = -np.pi / 2 + STEP / 2 * np.arange(2 * B - 1)
    fine = scan(1.3, wall(a2), increment=STEP / 2)
    p = tmp_path / "mixed.bag"
    write_scans(p, [common_scan(0), common_scan(1), shifted_scan(2, STEP), fine, common_scan(4)])
    with pytest.warns(LogDefectWarning, match="scans_resampled_beam_geometry: 2"):
        log = read_bag(p, beam_policy="resample")
    angles = log.info.angles_rad.astype(np.float64)
    np.testing.assert_allclose(angles[[0, -1]], [-np.pi / 2, np.pi / 2], atol=1e-6)  # the common field of view
    truth = wall(angles)
    np.testing.assert_allclose(log.ranges_m[3], truth, atol=1e-5)  # the fine scan: its every other beam
    shifted = log.ranges_m[2]
    assert np.isnan(shifted[0])  # before the shifted scan's field of view: no beam there
    np.testing.assert_allclose(shifted[1:], truth[1:], atol=1e-5)  # each beam at its true angle
    # reading the shifted scan as if it had the common geometry (the old behaviour) would be wrong by a beam
    assert np.max(np.abs(wall(angles[1:] + STEP) - truth[1:])) > 0.1


def test_reject_drops_only_the_odd_scans(tmp_path):
    p = tmp_path / "odd.bag"
    write_scans(p, [common_scan(0), shifted_scan(1, 0.01), common_scan(2)])
    with pytest.warns(LogDefectWarning, match="scans_rejected_beam_geometry: 1"):
        log = read_bag(p, beam_policy="reject")
    np.testing.assert_allclose(log.stamps, [1.0, 1.2])


def test_reversed_scanner_is_read_in_increasing_angle(tmp_path):
    a = -np.pi / 2 + STEP * np.arange(B)
    forward, backward = tmp_path / "f.bag", tmp_path / "b.bag"
    write_scans(forward, [scan(1.0 + 0.1 * k, wall(a)) for k in range(3)])
    write_scans(backward, [scan(1.0 + 0.1 * k, wall(a)[::-1], angle_min=np.pi / 2, increment=-STEP) for k in range(3)])
    f, b = read_bag(forward), read_bag(backward)
    np.testing.assert_allclose(b.info.angles_rad, f.info.angles_rad, atol=1e-6)
    np.testing.assert_array_equal(b.ranges_m, f.ranges_m)


@pytest.mark.parametrize(
    "field, value, expected",
    [
        ("increment", 0.0, "non-zero increment"),
        ("increment", float("nan"), "angle_increment is nan"),
        ("range_max", 0.0, "0 <= range_min < range_max"),
        ("range_min", -1.0, "0 <= range_min < range_max"),
        ("angle_min", float("inf"), "angle_min is inf"),
        ("increment", 1.0, "spanning at most 2 pi"),
    ],
)
def test_degenerate_geometry_is_an_error_naming_the_message(tmp_path, field, value, expected):
    bad = common_scan(1)
    bad[field] = value
    p = tmp_path / "bad.bag"
    write_scans(p, [common_scan(0), bad, common_scan(2)])
    with pytest.raises(LogFormatError, match=rf"bad.bag, message 1 on /scan: .*{expected}"):
        read_bag(p)


def test_zero_quaternion_is_an_error_and_an_unnormalised_one_is_normalised_and_counted(tmp_path):
    zero = common_scan(1)
    zero["quat"] = (0, 0, 0, 0)
    p = tmp_path / "q0.bag"
    write_scans(p, [common_scan(0), zero])
    with pytest.raises(
        LogFormatError, match=r"q0.bag, message 1 on /odom: quaternion \(0.0, 0.0, 0.0, 0.0\) is no rotation"
    ):
        read_bag(p)
    yaw = 0.8
    scaled = [common_scan(k) for k in range(3)]
    for s in scaled:
        s["quat"] = (0, 0, 2 * np.sin(yaw / 2), 2 * np.cos(yaw / 2))  # the same rotation, length 2
    p2 = tmp_path / "q2.bag"
    write_scans(p2, scaled)
    with pytest.warns(LogDefectWarning, match="quaternions_not_unit: 3"):
        log = read_bag(p2)
    np.testing.assert_allclose(log.odom[:, 2], yaw, atol=1e-9)


def test_per_scan_range_limits_mask_each_scans_own_beams(tmp_path):
    a = -np.pi / 2 + STEP * np.arange(B)
    short = scan(1.1, np.full(B, 3.0), range_max=2.5)  # every beam at or beyond this scan's own range_max
    p = tmp_path / "lim.bag"
    write_scans(p, [scan(1.0, wall(a)), short, scan(1.2, wall(a))])
    with pytest.warns(LogDefectWarning, match="scans_with_other_range_limits: 1"):
        log = read_bag(p)
    assert np.isnan(log.ranges_m[1]).all() and np.isfinite(log.ranges_m[0]).all()


def test_a_typo_in_the_beam_policy_is_an_error(tmp_path):
    p = tmp_path / "ok.bag"
    write_scans(p, [common_scan(0), common_scan(1)])
    with pytest.raises(ValueError, match="beam_policy='resampel': expected one of error, reject, resample"):
        read_bag(p, beam_policy="resampel")


def robotlaser(start, fov, ranges, stamp):
    r = " ".join(f"{v:.3f}" for v in ranges)
    pose = "0 0 0 0 0 0"
    return (
        f"ROBOTLASER1 0 {start:.6f} {fov:.6f} {fov / (len(ranges) - 1):.6f} 30 0.01 0 {len(ranges)} {r} 0 "
        f"{pose} 0 0 0 0 0 {stamp:.6f} host {stamp:.6f}\n"
    )


def test_carmen_robotlaser_lines_carry_their_own_geometry(tmp_path):
    a = -np.pi / 2 + STEP * np.arange(B)
    shift = 2 * STEP
    lines = [
        robotlaser(-np.pi / 2, np.pi, wall(a), 1.0),
        robotlaser(-np.pi / 2, np.pi, wall(a), 1.1),
        robotlaser(-np.pi / 2 + shift, np.pi, wall(a + shift), 1.2),
    ]
    p = tmp_path / "rl.clf"
    p.write_text("".join(lines))
    with pytest.raises(LogFormatError, match=r"rl.clf, line 3: scan's beams start at"):
        read_carmen(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogDefectWarning)
        log = read_carmen(p, beam_policy="resample")
    truth = wall(log.info.angles_rad.astype(np.float64))
    np.testing.assert_allclose(log.ranges_m[2, 2:], truth[2:], atol=2e-3)
    assert np.isnan(log.ranges_m[2, :2]).all()


@pytest.mark.parametrize(
    "line, expected",
    [
        ("FLASER -5 1 2 3", "FLASER beam count: expected a whole number"),
        ("FLASER 2.5 1 2 3 4 5 6 7 8 9", "FLASER beam count: expected a whole number"),
        ("FLASER 1 1.0 0 0 0 0 0 0 5.0", "scan has 1 beams: expected at least 2"),
    ],
)
def test_carmen_bad_beam_counts_are_clear_errors(tmp_path, line, expected):
    p = tmp_path / "c.clf"
    p.write_text(line + "\n")
    with pytest.raises(LogFormatError, match=rf"c.clf, line 1: {expected}"):
        read_carmen(p)


def test_resample_nearest_twin(rng):
    """The resampler against the definition: each target angle takes the beam at the least angular distance."""
    g = ScanGeometry(int(rng.integers(5, 40)), float(rng.uniform(-2, -1)), float(rng.uniform(0.01, 0.1)))
    ranges = rng.uniform(0.5, 9, g.num_beams)
    target = rng.uniform(g.angle_min_rad, g.angle_min_rad + g.angle_increment_rad * (g.num_beams - 1), 50)
    got = resample_nearest(ranges, g, target)
    want = ranges[np.argmin(np.abs(target[:, None] - g.angles()[None, :]), axis=1)]
    np.testing.assert_array_equal(got, want)


def test_one_absurd_range_does_not_win_the_no_return_detection(tmp_path):
    from test_carmen import small_log

    text = small_log(5).replace("FLASER 6 1.00", "FLASER 6 5000.00", 1)  # one corrupt reading, below 1e4 m
    p = tmp_path / "absurd.clf"
    p.write_text(text)
    with pytest.warns(LogDefectWarning, match="ranges_beyond_no_return: 1"):
        log = read_carmen(p)
    assert log.info.no_return_m == pytest.approx(81.91)  # the driver's value, carried by every scan
    assert np.isnan(log.ranges_m[:, -1]).all() and np.isnan(log.ranges_m[0, 0])


def test_the_log_s_geometry_is_the_majority_s_even_when_its_increment_jitters(rng):
    """Three in four scans of 180 beams whose float32 increment jitters by a few 1e-9 rad, one in four of 181:
    the 180-beam geometry is the log's, and rejecting keeps three in four (it kept the 181 minority's quarter)."""
    from irmcl_warp.io.beams import harmonise_beams
    from irmcl_warp.types import DefectReport

    n = 400
    minority = rng.random(n) < 0.25
    geometries = [
        ScanGeometry(181, -1.5708, 0.0174533)
        if m
        else ScanGeometry(180, -1.5708, float(np.float32(0.0175504 + rng.normal(0, 3e-9))))
        for m in minority
    ]
    scans = [rng.uniform(1, 5, g.num_beams) for g in geometries]
    ranges, kept, common = harmonise_beams(
        "log", scans, [f"scan {i}" for i in range(n)], "reject", DefectReport(), geometries
    )
    assert common.num_beams == 180 and len(kept) == int((~minority).sum()) and ranges.shape == (len(kept), 180)
