"""Shared handling of range arrays: per-scan beam geometry, beam-count mismatches and "no return" masking.

Each scan carries its own geometry (beam count, first angle, increment) where the format records it (bags:
every LaserScan message; CARMEN's ROBOTLASER1 lines); a log is read onto one common set of beam angles, the
geometry most of its scans share. A scan whose beams point elsewhere (another count, another first angle or
increment) is an error by default, naming the scan; ``data.beam_policy`` can drop such scans or resample them
onto the common angles, each beam taking the scan's beam nearest in angle (never blending two beams: across a
depth edge a blend is a point on no surface).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from irmcl_warp.io.plausibility import near_no_return
from irmcl_warp.io.errors import LogFormatError
from irmcl_warp.types import DefectReport

BeamPolicy = Literal["error", "reject", "resample"]
ANGLE_TOL_RAD = 1e-4  # beams of two scans closer than this point the same way (0.006 deg)


@dataclass(frozen=True)
class ScanGeometry:
    """Where the beams of one scan point, in the laser frame: beam b at ``angle_min + b * increment``."""

    num_beams: int
    angle_min_rad: float
    angle_increment_rad: float

    def angles(self) -> np.ndarray:
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.num_beams)

    def key(self) -> tuple:
        """Equal for geometries within the tolerance (bar the rounding edge): the count, the first beam's angle
        and the last beam's, each on a grid of ANGLE_TOL_RAD. (The increment itself rounded to 1e-9 split the
        scans of a driver whose float32 increment jitters into many keys, and a steady minority won the vote.)"""
        last = self.angle_min_rad + self.angle_increment_rad * (self.num_beams - 1)
        return (self.num_beams, round(self.angle_min_rad / ANGLE_TOL_RAD), round(last / ANGLE_TOL_RAD))

    def same_as(self, other: "ScanGeometry") -> bool:
        if self.num_beams != other.num_beams:
            return False
        return bool(np.max(np.abs(self.angles() - other.angles())) <= ANGLE_TOL_RAD)


def check_geometry(path, where, num_beams, angle_min, increment, range_min=0.0, range_max=1.0) -> ScanGeometry:
    """A scan's geometry as a :class:`ScanGeometry` with a positive increment, or a LogFormatError naming the
    scan when it is degenerate (no beams, an increment of 0, NaN or inf, limits that are not 0 <= min < max)."""
    values = {"angle_min": angle_min, "angle_increment": increment, "range_min": range_min, "range_max": range_max}
    bad = [k for k, v in values.items() if not np.isfinite(v)]
    if bad:
        raise LogFormatError(path, where, f"{', '.join(bad)} is {values[bad[0]]}: expected a finite number")
    if num_beams < 2:
        raise LogFormatError(path, where, f"scan has {num_beams} beams: expected at least 2")
    if increment == 0 or abs(increment) * (num_beams - 1) > 2 * np.pi + 1e-6:
        raise LogFormatError(
            path,
            where,
            f"angle_increment {increment:g} rad over {num_beams} beams: expected a "
            f"non-zero increment spanning at most 2 pi",
        )
    if not 0.0 <= range_min < range_max:
        raise LogFormatError(
            path, where, f"range_min {range_min:g} m, range_max {range_max:g} m: expected 0 <= range_min < range_max"
        )
    return ScanGeometry(int(num_beams), float(angle_min), float(increment))


def harmonise_beams(path, scans, locations, policy: BeamPolicy, report: DefectReport, geometries=None):
    """Stack scans into [N, B] on the common geometry (the one most scans share).

    ``geometries``: one :class:`ScanGeometry` per scan, or None where the format records none (FLASER: every
    scan then spans the same field of view whatever its count). ``policy``: "error" raises naming the first
    odd scan; "reject" drops odd scans (counted); "resample" puts each odd scan onto the common angles
    (counted), each common beam taking the scan's nearest beam within half an increment, NaN where none.
    A scan with a negative increment is read reversed. Returns (ranges[N, B], kept indices, common geometry).
    """
    if policy not in get_args(BeamPolicy):
        raise ValueError(f"beam_policy={policy!r}: expected one of {', '.join(get_args(BeamPolicy))}")
    if geometries is None:  # same field of view, any count: place the beams evenly over it
        geometries = [ScanGeometry(len(s), -1.0, 2.0 / max(len(s) - 1, 1)) for s in scans]
    scans, geometries = list(scans), list(geometries)  # reversed scanners are flipped here, not in the caller's lists
    for i, g in enumerate(geometries):
        if g.angle_increment_rad < 0:  # reversed scanner: the same beams, in increasing angle
            scans[i] = np.asarray(scans[i])[::-1]
            geometries[i] = ScanGeometry(
                g.num_beams, g.angle_min_rad + g.angle_increment_rad * (g.num_beams - 1), -g.angle_increment_rad
            )
    for i, (s, g) in enumerate(zip(scans, geometries)):
        if len(s) != g.num_beams:
            raise LogFormatError(path, locations[i], f"scan holds {len(s)} ranges, its geometry says {g.num_beams}")
    common_key = Counter(g.key() for g in geometries).most_common(1)[0][0]
    common = next(g for g in geometries if g.key() == common_key)
    B = common.num_beams
    odd = [i for i, g in enumerate(geometries) if not g.same_as(common)]
    if odd and policy == "error":
        i, g = odd[0], geometries[odd[0]]
        what = (
            f"scan has {g.num_beams} beams, the log's scans have {B}"
            if g.num_beams != B
            else f"scan's beams start at {np.degrees(g.angle_min_rad):.4f} deg every "
            f"{np.degrees(g.angle_increment_rad):.4f} deg, the log's at {np.degrees(common.angle_min_rad):.4f} "
            f"every {np.degrees(common.angle_increment_rad):.4f} deg"
        )
        raise LogFormatError(
            path,
            locations[i],
            f"{what} ({len(odd)} such scans; set data.beam_policy=reject or resample to accept them)",
        )
    if policy == "reject":
        report.add("scans_rejected_beam_geometry", len(odd), f"scans whose beams differ from the log's {B}, dropped")
        keep = [i for i in range(len(scans)) if geometries[i].same_as(common)]
        return np.array([scans[i] for i in keep], dtype=np.float64).reshape(len(keep), B), keep, common
    report.add("scans_resampled_beam_geometry", len(odd), f"scans resampled onto the log's {B} beam angles")
    out = np.empty((len(scans), B))
    target = common.angles()
    for i, (s, g) in enumerate(zip(scans, geometries)):
        out[i] = s if g.same_as(common) else resample_nearest(np.asarray(s, np.float64), g, target)
    return out, list(range(len(scans))), common


def resample_nearest(ranges, geometry: ScanGeometry, target_angles) -> np.ndarray:
    """``ranges`` of a scan with ``geometry`` read at ``target_angles``: the nearest beam within half an
    increment, NaN outside the scan's field of view."""
    k = np.rint((np.asarray(target_angles) - geometry.angle_min_rad) / geometry.angle_increment_rad).astype(np.int64)
    inside = (k >= 0) & (k < geometry.num_beams)
    out = np.full(len(k), np.nan)
    out[inside] = ranges[k[inside]]
    return out


def detect_no_return(ranges: np.ndarray, min_share: float = 1e-4, min_count: int = 3) -> float:
    """The driver's "no echo" value: the largest range that at least ``min_count`` beams and ``min_share`` of
    all beams carry (to the millimetre); inf when no value repeats so. A driver writes one constant for every
    missing echo, so a single absurd reading above it never wins (it is then beyond the no-return value)."""
    r = np.asarray(ranges, np.float64)
    r = np.round(r[np.isfinite(r)], 3)
    if not r.size:
        return float("inf")
    values, counts = np.unique(r, return_counts=True)
    need = max(min_count, int(np.ceil(min_share * r.size)))
    carried = values[counts >= need]
    return float(carried[-1]) if carried.size else float("inf")


MAX_PLAUSIBLE_RANGE_M = 1.0e4  # larger values are corrupt data (and overflow float32 beyond 3.4e38)


def mask_ranges(path, ranges, no_return_m, report: DefectReport, tol_m: float = 5e-3):
    """NaN-mask no-return beams (>= no_return_m - tol) and zero ranges; negative ranges are an error. Beams
    above the no-return value (corrupt readings) are masked and counted."""
    ranges = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        if (ranges < 0).any():
            row = int(np.argwhere(ranges < 0)[0, 0])
            raise LogFormatError(path, f"scan {row}", f"negative range {np.nanmin(ranges):g} m (ranges must be >= 0)")
        if (ranges > MAX_PLAUSIBLE_RANGE_M).any():
            row = int(np.argwhere(ranges > MAX_PLAUSIBLE_RANGE_M)[0, 0])
            raise LogFormatError(
                path,
                f"scan {row}",
                f"range {np.nanmax(ranges):g} m is beyond any lidar (> {MAX_PLAUSIBLE_RANGE_M:g} m)",
            )
        no_return = detect_no_return(ranges) if no_return_m is None else float(no_return_m)
        beyond = ranges > no_return + tol_m
        report.add(
            "ranges_beyond_no_return",
            int(beyond.sum()),
            f"beams reading more than the log's no-return value {no_return:g} m, masked",
        )
        count, value = near_no_return(ranges, no_return, tol_m)
        finite = int(np.isfinite(ranges).sum())
        if np.isfinite(no_return) and count >= max(20, 1e-3 * finite):
            report.add(
                "near_no_return_code",
                count,
                f"beams reading {value:g} m, just under the no-return value "
                f"{no_return:g} m: a second no-return code? Kept as returns (data.no_return_m={value:g} masks them)",
            )
        masked = ranges.astype(np.float32)
        masked[ranges >= no_return - tol_m] = np.nan
    zero = ranges <= 0.0
    report.add("zero_ranges", int(zero.sum()), "beams reading 0 m, masked as no return")
    masked[zero] = np.nan
    if not np.isfinite(no_return):
        no_return = float(np.nanmax(masked)) if np.isfinite(masked).any() else 0.0
    return masked, no_return
