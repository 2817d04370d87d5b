"""The CARMEN reader on small hand-written logs, on corrupted ones, and fuzzed."""

import gzip
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from irmcl_warp.io import LogDefectWarning, LogFormatError, read_carmen


def flaser(ranges, pose, stamp):
    r = " ".join(f"{v:.2f}" for v in ranges)
    p = " ".join(f"{v:.4f}" for v in pose)
    return f"FLASER {len(ranges)} {r} {p} {p} {stamp:.6f} host {stamp:.6f}\n"


def small_log(n=5, beams=6, stamps=None):
    stamps = stamps if stamps is not None else [100.0 + 0.2 * k for k in range(n)]
    lines = ["# a comment\n", "PARAM robot_width 0.4\n"]
    for k, t in enumerate(stamps):
        ranges = [1.0 + 0.1 * b for b in range(beams)]
        ranges[-1] = 81.91  # no return
        lines.append(flaser(ranges, (0.1 * k, 0.0, 0.0), t))
        lines.append(f"ODOM {0.1 * k} 0 0 0.5 0 0 {t + 0.1:.6f} host 0\n")
    return "".join(lines)


def test_reads_scans_odometry_and_masks_no_return(tmp_path):
    p = tmp_path / "a.clf"
    p.write_text(small_log())
    log = read_carmen(p)
    assert len(log) == 5 and log.info.num_beams == 6
    assert np.isnan(log.ranges_m[:, -1]).all() and log.ranges_m[0, 0] == pytest.approx(1.0)
    assert log.info.no_return_m == pytest.approx(81.91)
    np.testing.assert_allclose(log.odom[:, 0], 0.1 * np.arange(5))
    np.testing.assert_allclose(log.info.angles_rad[[0, -1]], [-np.pi / 2, np.pi / 2], atol=1e-6)


def test_gzip_is_detected_by_content(tmp_path):
    p = tmp_path / "a.log"  # no .gz suffix on purpose
    p.write_bytes(gzip.compress(small_log().encode()))
    assert len(read_carmen(p)) == 5


def test_robotlaser1(tmp_path):
    ranges = " ".join(["2.0"] * 4)
    line = f"ROBOTLASER1 0 -1.0 2.0 0.5 50.0 0.1 0 4 {ranges} 0 1.1 0 0 1.0 0 0 0 0 0 0 0 7.5 host 7.5\n"
    log = read_carmen(_write(tmp_path, line + line.replace("7.5", "7.7")), no_return_m=50.0)
    assert log.info.angle_min_rad == -1.0 and log.info.fov_rad == pytest.approx(2.0)
    np.testing.assert_allclose(log.T_base_laser, [0.1, 0, 0], atol=1e-9)


def _write(tmp_path, text, name="x.clf"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_stamps_going_backwards_are_counted_not_fatal(tmp_path):
    p = _write(tmp_path, small_log(stamps=[1.0, 2.0, 1.5, 3.0, 2.9]))
    with pytest.warns(LogDefectWarning, match="scans_stamps_backwards: 2"):
        log = read_carmen(p)
    assert log.defects.counts["scans_stamps_backwards"] == 2
    np.testing.assert_array_equal(log.stamps, [1.0, 2.0, 1.5, 3.0, 2.9])  # recording order kept


def test_odometry_against_its_velocity_is_reported(tmp_path):
    text = small_log().replace("0.5 0 0", "-0.5 0 0")  # moves forward while reporting reverse
    with pytest.warns(LogDefectWarning, match="odometry_contradicts_velocity: 4"):
        read_carmen(_write(tmp_path, text))


@pytest.mark.parametrize(
    "bad, match",
    [
        ("FLASER 6 1 2 x 4 5 6 0 0 0 0 0 0 9.0 h 9.0\n", r"line 2: FLASER ranges: expected a number, found 'x'"),
        ("FLASER 6 1 2 nan 4 5 6 0 0 0 0 0 0 9.0 h 9.0\n", "line 2: FLASER ranges: NaN or infinite"),
        ("FLASER 6 1 2 3\n", "line 2: FLASER with 6 beams"),
        ("ODOM 1 2\n", "line 2: ODOM: expected 8 fields"),
    ],
)
def test_garbage_lines_name_the_line(tmp_path, bad, match):
    text = small_log(1).split("\n")
    text.insert(1, bad.strip())
    with pytest.raises(LogFormatError, match=match):
        read_carmen(_write(tmp_path, "\n".join(text)))


def test_negative_range_is_an_error(tmp_path):
    with pytest.raises(LogFormatError, match="negative range"):
        read_carmen(_write(tmp_path, small_log(2).replace("FLASER 6 1.00", "FLASER 6 -1.00", 1)))


def test_absurd_range_is_an_error_not_an_overflow(tmp_path):
    with pytest.raises(LogFormatError, match=r"scan 1: range 1e\+39 m is beyond any lidar"):
        read_carmen(
            _write(
                tmp_path,
                small_log(2).replace("FLASER 6 1.00", "FLASER 6 1e39", 2).replace("FLASER 6 1e39", "FLASER 6 1.00", 1),
            )
        )


def test_empty_log_is_an_error_not_an_empty_result(tmp_path):
    with pytest.raises(LogFormatError, match="no FLASER or ROBOTLASER1"):
        read_carmen(_write(tmp_path, "# nothing\nPARAM a b\n"))


def test_beam_count_mismatch_policies(tmp_path):
    text = small_log(4) + flaser([1.0, 1.0, 1.0], (0, 0, 0), 200.0)
    p = _write(tmp_path, text)
    with pytest.raises(LogFormatError, match=r"line 11: scan has 3 beams, the log's scans have 6"):
        read_carmen(p)
    with pytest.warns(LogDefectWarning, match="scans_rejected_beam_geometry: 1"):
        assert len(read_carmen(p, beam_policy="reject")) == 4
    with pytest.warns(LogDefectWarning, match="scans_resampled_beam_geometry: 1"):
        log = read_carmen(p, beam_policy="resample")
    assert len(log) == 5 and log.ranges_m.shape == (5, 6)


def test_truncated_gzip_and_truncated_last_line(tmp_path):
    blob = gzip.compress(small_log(50).encode())
    p = tmp_path / "cut.clf.gz"
    p.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(LogFormatError, match="truncated or corrupt gzip"):
        read_carmen(p)
    text = small_log(3)
    with pytest.warns(LogDefectWarning, match="truncated_last_line"):
        log = read_carmen(_write(tmp_path, text + "FLASER 6 1.0 2.0"))
    assert len(log) == 3


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_fuzzed_logs_read_or_fail_clearly(tmp_path, data):
    text = small_log(4)
    pos = data.draw(st.integers(0, len(text) - 1))
    junk = data.draw(st.text(alphabet="0123456789 .-naxFLSERODM\n", max_size=12))
    cut = data.draw(st.booleans())
    mutated = text[:pos] + junk + ("" if cut else text[pos + len(junk) :])
    p = _write(tmp_path, mutated, "fuzz.clf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogDefectWarning)
        try:
            log = read_carmen(p)
        except LogFormatError as e:
            assert str(p) in str(e)
            return
    assert len(log) >= 1 and log.ranges_m.shape[1] == log.info.num_beams
    assert not np.any(log.ranges_m[np.isfinite(log.ranges_m)] < 0)


def test_gfs_beam_angles_follow_the_released_reader():
    """The released GMapping's CARMEN reader: 360 beams 0.5 deg apart with no beam at 0, 181 beams 1 deg apart
    with one at 0; a count it has no resolution for is an error naming the count."""
    from irmcl_warp.io.carmen import gfs_flaser_angles

    a = np.rad2deg(gfs_flaser_angles(360))
    assert len(a) == 360 and np.allclose(np.diff(a)[np.arange(359) != 179], 0.5) and np.isclose(a[180] - a[179], 1.0)
    assert np.isclose(a[0], -90) and np.isclose(a[-1], 90) and np.allclose(a, -a[::-1]) and not np.any(np.isclose(a, 0))
    b = np.rad2deg(gfs_flaser_angles(181))
    assert np.allclose(np.diff(b), 1.0) and b[90] == 0 and np.isclose(b[0], -90)
    with pytest.raises(ValueError, match="361|200 beams"):
        gfs_flaser_angles(200)


def test_a_file_of_another_format_is_called_not_a_carmen_log(tmp_path):
    other = tmp_path / "other.txt"
    other.write_text("L 0.1 0.2 0.3 5.0 5.1\nO 0.0 0.0 0.0\n")
    with pytest.raises(LogFormatError, match=r"other.txt, line 1: .*found 'L': not a CARMEN log\?"):
        read_carmen(other)
    broken = tmp_path / "broken.log"
    broken.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\n0.5 0.6\n")
    with pytest.raises(LogFormatError, match=r"broken.log, line 2: .*a line broken in two\?"):
        read_carmen(broken)


def test_a_scan_s_odometry_is_read_at_its_stamp_plus_the_offset(tmp_path, rng):
    """data.scan_time_offset_s: between the scan lines' own poses (x = 0.5 m/s times t here), the ends clamped and
    counted; a log whose scans go back in time is refused for it, naming the setting."""
    offset = float(rng.uniform(-0.19, -0.01))
    p = _write(tmp_path, small_log(6))
    with pytest.warns(LogDefectWarning, match="falls outside the log; clamped"):
        log = read_carmen(p, scan_time_offset_s=offset)
    want = np.maximum(0.0, 0.5 * (0.2 * np.arange(6) + offset))
    np.testing.assert_allclose(log.odom[:, 0], want, atol=1e-9)
    np.testing.assert_allclose(read_carmen(p).odom[:, 0], 0.1 * np.arange(6), atol=1e-12)  # no offset: the lines
    backwards = _write(tmp_path, small_log(4, stamps=[100.0, 100.2, 100.1, 100.4]), "back.clf")
    with pytest.raises(LogFormatError, match=r"data\.scan_time_offset_s=.* 1 scans are stamped before"):
        read_carmen(backwards, scan_time_offset_s=offset)
