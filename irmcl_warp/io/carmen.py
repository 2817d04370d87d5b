"""CARMEN logs (``.log``, ``.clf``, optionally ``.gz``): FLASER, ROBOTLASER1 and ODOM lines.

Line formats (CARMEN's logger):
  FLASER n r_1..r_n x y theta odom_x odom_y odom_theta timestamp [host logger_timestamp]
  ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode n r_1..r_n
              m rem_1..rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta
              tv rv forward_safety side_safety turn_axis timestamp [host logger_timestamp]
  ODOM x y theta tv rv accel timestamp [host logger_timestamp]
Other message types (PARAM, SYNC, NEFF, RAWLASER*, ...) are counted and skipped.

Scans keep the file's (recording) order; the odometry of a scan is the pose its own line carries.
FLASER scans span 180 deg with angle_increment = pi / (n - 1), as the bags of the same logs declare.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from irmcl_warp.geometry import compose, interpolate_poses, inverse
from irmcl_warp.io.beams import BeamPolicy, check_geometry, harmonise_beams, mask_ranges
from irmcl_warp.io.defects import count_stamps_backwards, count_velocity_contradictions, scan_defects
from irmcl_warp.io.errors import LogFormatError, check_pose_stamps, warn_defects
from irmcl_warp.io.text import check_comment, parse_floats, read_lines
from irmcl_warp.types import DefectReport, LaserInfo, LaserLog


@dataclass
class _Scan:
    line: int
    stamp: float
    ranges: np.ndarray
    odom: tuple
    laser_pose: tuple
    start_angle: float | None = None
    fov: float | None = None
    range_max: float | None = None


@dataclass
class CarmenContents:
    scans: list = field(default_factory=list)
    odom_lines: list = field(default_factory=list)  # (stamp, x, y, theta, tv)
    skipped: Counter = field(default_factory=Counter)
    truncated_last_line: bool = False
    records_seen: int = 0  # lines read as a record (any name), to tell "not a CARMEN log" from a broken line


def _need(path, line_no, tokens, count, what):
    if len(tokens) < count:
        raise LogFormatError(path, f"line {line_no}", f"{what}: expected at least {count} fields, found {len(tokens)}")


def _count(path, n_line, token, what) -> int:
    """A count field: a non-negative integer (``3.5`` or ``-5`` is an error, not 3 or an index)."""
    v = parse_floats(path, n_line, [token], what)[0]
    if v < 0 or v != int(v) or v > 1e6:
        raise LogFormatError(path, f"line {n_line}", f"{what}: expected a whole number from 0 to 1e6, found {token!r}")
    return int(v)


def _exact(path, n_line, tok, count, what):
    """A record ends with its timestamp, optionally followed by ``host logger_timestamp``: any other count
    means a line merged with the next or split from its end."""
    if len(tok) not in (count, count + 2):
        raise LogFormatError(
            path,
            f"line {n_line}",
            f"{what}: expected {count} fields (or {count + 2} with host and logger timestamp), found {len(tok)}",
        )
    if len(tok) == count + 2:
        parse_floats(path, n_line, tok[-1:], f"{what} logger timestamp")


def _parse_flaser(path, n_line, tok):
    _need(path, n_line, tok, 2, "FLASER")
    n = _count(path, n_line, tok[1], "FLASER beam count")
    _exact(path, n_line, tok, 2 + n + 7, f"FLASER with {n} beams (n ranges, 6 pose values, timestamp)")
    ranges = parse_floats(path, n_line, tok[2 : 2 + n], "FLASER ranges")
    tail = parse_floats(path, n_line, tok[2 + n : 2 + n + 7], "FLASER poses/timestamp")
    return _Scan(n_line, tail[6], ranges, tuple(tail[3:6]), tuple(tail[0:3]))


def _parse_robotlaser(path, n_line, tok):
    _need(path, n_line, tok, 9, "ROBOTLASER1 header")
    head = parse_floats(path, n_line, tok[1:9], "ROBOTLASER1 header")
    n = _count(path, n_line, tok[8], "ROBOTLASER1 beam count")
    _need(path, n_line, tok, 10 + n, f"ROBOTLASER1 with {n} ranges")
    ranges = parse_floats(path, n_line, tok[9 : 9 + n], "ROBOTLASER1 ranges")
    m = _count(path, n_line, tok[9 + n], "ROBOTLASER1 remission count")
    i = 10 + n + m
    _exact(path, n_line, tok, i + 12, f"ROBOTLASER1 with {n} ranges and {m} remissions")
    tail = parse_floats(path, n_line, tok[i : i + 12], "ROBOTLASER1 poses/timestamp")
    return _Scan(
        n_line,
        tail[11],
        ranges,
        tuple(tail[3:6]),
        tuple(tail[0:3]),
        start_angle=head[1],
        fov=head[2],
        range_max=head[4],
    )


READ_RECORDS = ("FLASER", "ROBOTLASER1", "ODOM")
RECORD_NAME = re.compile(r"[A-Z][A-Z0-9_\-]{1,39}")
# the records CARMEN's logger and GMapping write besides the ones read here: skipped without a word
KNOWN_RECORDS = {
    "PARAM",
    "SYNC",
    "TRUEPOS",
    "NEFF",
    "RLASER",
    "LASER3",
    "LASER4",
    "RAWLASER1",
    "RAWLASER2",
    "RAWLASER3",
    "RAWLASER4",
    "ROBOTLASER2",
    "GPSNMEAGGA",
    "GPSNMEARMC",
    "SONAR",
    "BUMPER",
    "SCANMARK",
    "POSITIONLASER",
    "IMU",
    "VECTORMOVE",
    "ROBOTVELOCITY",
    "FOLLOW-TRAJECTORY",
    "BASEVELOCITY",
}


def parse_carmen(path) -> CarmenContents:
    """Parse a CARMEN log into raw records; raises :class:`LogFormatError` naming the line."""
    path = Path(path)
    out = CarmenContents()
    lines, cut = read_lines(path)
    if cut:  # a log cut off while it was written: its unfinished last line may hold a cut number; dropped, loudly
        lines = lines[:-1]
        out.truncated_last_line = True
    for n_line, line in lines:
        tok = line.split()
        if not tok:
            continue
        if tok[0].startswith("#"):
            check_comment(path, n_line, line)
            continue
        kind = tok[0]
        if kind == "FLASER":
            out.scans.append(_parse_flaser(path, n_line, tok))
        elif kind == "ROBOTLASER1":
            out.scans.append(_parse_robotlaser(path, n_line, tok))
        elif kind == "ODOM":
            _exact(path, n_line, tok, 8, "ODOM")
            v = parse_floats(path, n_line, tok[1:8], "ODOM")
            out.odom_lines.append((v[6], v[0], v[1], v[2], v[3]))
        elif not RECORD_NAME.fullmatch(kind):
            first = not out.scans and not out.odom_lines and not out.records_seen
            raise LogFormatError(
                path,
                f"line {n_line}",
                f"expected a record name (FLASER, ODOM, ...), found "
                f"{kind[:40]!r}: "
                + (
                    "not a CARMEN log? (the CARMEN subset this reads and how to "
                    "bring another format in: README, 'Your own log')"
                    if first
                    else "a line broken in two?"
                ),
            )
        else:
            merged = next((t for t in tok[1:] if any(name in t for name in READ_RECORDS)), None)
            if merged is not None:
                raise LogFormatError(
                    path,
                    f"line {n_line}",
                    f"{kind} line holds {merged[:40]!r}: two records on one line (a lost line break)?",
                )
            out.skipped[kind] += 1
        out.records_seen += 1
    return out


def _parse_report(c: CarmenContents) -> DefectReport:
    """What parsing found odd (a cut last line, lines of unknown kinds), for either reader to warn about."""
    report = DefectReport()
    report.add("truncated_last_line", int(c.truncated_last_line), "unfinished last line dropped")
    unknown = Counter({k: n for k, n in c.skipped.items() if k not in KNOWN_RECORDS})
    report.add("unknown_records", sum(unknown.values()), f"lines of unknown kinds skipped ({_kinds(unknown)})")
    return report


def _kinds(skipped: Counter, most: int = 5) -> str:
    """The commonest first words of the skipped lines, capped: a binary file is not listed line by line."""
    if not skipped:
        return "none"
    top = ", ".join(f"{k!r} x{n}" for k, n in skipped.most_common(most))
    return top + (f" and {len(skipped) - most} other kinds" if len(skipped) > most else "")


def read_carmen(
    path,
    *,
    no_return_m: float | None = None,
    fov_rad: float | None = None,
    beam_policy: BeamPolicy = "error",
    max_speed_mps: float = 3.0,
    max_step_m: float = 2.0,
    scan_time_offset_s: float = 0.0,
) -> LaserLog:
    """Read a CARMEN log into a :class:`LaserLog` (scans in file order, odometry from each scan line; with
    ``scan_time_offset_s``, each scan's odometry read at its stamp plus that, between the scan lines' own poses)."""
    path = Path(path)
    c = parse_carmen(path)
    if not c.scans:
        raise LogFormatError(path, None, f"no FLASER or ROBOTLASER1 lines (other lines: {_kinds(c.skipped)})")
    report = _parse_report(c)
    geometries = [_geometry(path, s, fov_rad) for s in c.scans]
    ranges, kept, common = harmonise_beams(
        path, [s.ranges for s in c.scans], [f"line {s.line}" for s in c.scans], beam_policy, report, geometries
    )
    scans = [c.scans[i] for i in kept]
    first = scans[0]
    ranges, no_return = mask_ranges(path, ranges, no_return_m if no_return_m is not None else first.range_max, report)
    info = LaserInfo(
        common.num_beams, common.angle_min_rad, common.angle_increment_rad, 0.0, float(no_return), float(no_return)
    )
    stamps = np.array([s.stamp for s in scans])
    odom = np.array([s.odom for s in scans])
    if scan_time_offset_s:
        odom = _odometry_shifted(path, stamps, odom, float(scan_time_offset_s), report)
    # the extrinsic is what separates the laser pose from the robot pose on the same line
    T_base_laser = compose(inverse(np.array(first.odom)), np.array(first.laser_pose))
    if np.hypot(*T_base_laser[:2]) > 2.0:  # fields hold different frames (corrected vs raw), not an extrinsic
        T_base_laser = np.zeros(3)
    T_base_laser = np.round(T_base_laser, 9) + 0.0
    scan_defects(report, stamps, odom, max_speed_mps=max_speed_mps, max_step_m=max_step_m)
    if c.odom_lines:
        od = np.array(c.odom_lines)
        stamped = od[:, 0] != 0.0  # GMapping's corrected logs interleave path points stamped 0
        report.add(
            "odom_stamps_backwards",
            count_stamps_backwards(od[stamped, 0]),
            "ODOM lines stamped earlier than the one before",
        )
        report.add(
            "odometry_contradicts_velocity",
            count_velocity_contradictions(od[:, 1:4], od[:, 4]),
            "ODOM steps moving against their own forward velocity",
        )
    warn_defects(path, report)
    return LaserLog(stamps, ranges, odom, info, T_base_laser, None, str(path), report)


def _geometry(path, scan: _Scan, fov_rad):
    """A scan line's beam geometry: ROBOTLASER1 records its start angle and field of view (``fov_rad``
    overrides the latter); FLASER records neither and spans ``fov_rad`` (default pi) centred ahead."""
    n = len(scan.ranges)
    where = f"line {scan.line}"
    if scan.start_angle is None or fov_rad is not None:
        fov = np.pi if fov_rad is None else float(fov_rad)
        start = -fov / 2 if scan.start_angle is None else scan.start_angle
        return check_geometry(path, where, n, start, fov / max(n - 1, 1))
    range_max = 1.0 if scan.range_max == 0 else scan.range_max  # 0: "not recorded" in some converters
    return check_geometry(path, where, n, scan.start_angle, scan.fov / max(n - 1, 1), 0.0, range_max)


def _odometry_shifted(path, stamps, odom, offset_s: float, report: DefectReport) -> np.ndarray:
    """The scans' odometry read ``offset_s`` after their stamps: interpolated between the scan lines' own poses
    (which sample the odometry at every scan), the first and last clamped (counted). Needs the scans in stamp order."""
    backwards = int(np.sum(np.diff(stamps) < 0))
    if backwards:
        raise LogFormatError(
            path,
            None,
            f"data.scan_time_offset_s={offset_s:g} reads each scan's odometry at another moment, between the scan "
            f"lines' poses, which needs them in stamp order; {backwards} scans are stamped before the one before",
        )
    shifted = stamps + offset_s
    report.add(
        "scans_shifted_outside_odometry",
        int(np.sum((shifted < stamps[0]) | (shifted > stamps[-1]))),
        f"scans whose odometry, read {offset_s:+g} s from their stamps, falls outside the log; clamped",
    )
    return interpolate_poses(stamps, odom, shifted)


def read_carmen_poses(path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, poses[N,3]) of the scans of a CARMEN log, from the pose fields of each scan line:
    for the GMapping-corrected logs these are the corrected poses."""
    c = parse_carmen(path)
    if not c.scans:
        raise LogFormatError(path, None, f"no FLASER or ROBOTLASER1 lines (other lines: {_kinds(c.skipped)})")
    warn_defects(path, _parse_report(c))
    return check_pose_stamps(
        path, np.array([s.stamp for s in c.scans]), np.array([s.odom for s in c.scans]), [s.line for s in c.scans]
    )


GFS_RESOLUTION_DEG = {
    180: 1.0,
    181: 1.0,
    360: 0.5,
    361: 0.5,
    540: 0.5,
    541: 0.5,
    682: 360 / 1024,
    683: 360 / 1024,
    769: 360 / 1024,
}  # the released GMapping's CARMEN reader (log/carmenconfiguration.cpp)


def gfs_flaser_angles(num_beams: int) -> np.ndarray:
    """The beam angles (rad) that the released GMapping's own CARMEN reader (gfs_nogui's) gives an n-beam FLASER
    laser without PARAM lines: a resolution chosen by the beam count (1 deg for 180/181 beams, 0.5 deg for
    360/361 and 540/541), the beams symmetric about the heading; an odd count has a beam at 0, an even one
    none (360 beams: -90, ..., -0.5, +0.5, ..., +90 deg, where the log's uniform 180-deg span puts them
    0.501 deg apart). Used by ``slam.beam_angles=gfs`` to feed our filter the released tool's input."""
    if num_beams not in GFS_RESOLUTION_DEG:
        raise ValueError(
            f"slam.beam_angles=gfs: the released CARMEN reader sets no resolution for {num_beams} beams "
            f"(it knows {sorted(GFS_RESOLUTION_DEG)}; others need a PARAM line)"
        )
    step, j = np.deg2rad(GFS_RESOLUTION_DEG[num_beams]), np.arange(num_beams)
    if num_beams % 2:
        return (j - num_beams // 2) * step
    half = num_beams // 2
    return np.where(j < half, j - half, j - half + 1) * step
