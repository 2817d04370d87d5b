"""Shared handling of range arrays: beam-count mismatches and "no return" masking."""

from __future__ import annotations

from collections import Counter
from typing import Literal

import numpy as np

from irmcl_warp.io.errors import LogFormatError
from irmcl_warp.types import DefectReport

BeamPolicy = Literal["error", "reject", "resample"]


def harmonise_beams(path, scans, locations, policy: BeamPolicy, report: DefectReport):
    """Stack scans of possibly different beam counts into [N, B] (B = the most common count).

    ``policy``: "error" raises naming the first odd scan; "reject" drops odd scans (counted);
    "resample" linearly resamples them onto B beams over the same field of view (counted).
    Returns (ranges[N, B], indices of the kept scans).
    """
    counts = Counter(len(s) for s in scans)
    B = counts.most_common(1)[0][0]
    odd = [i for i, s in enumerate(scans) if len(s) != B]
    if odd and policy == "error":
        i = odd[0]
        raise LogFormatError(path, locations[i], f"scan has {len(scans[i])} beams, the log's scans have {B} "
                             f"({len(odd)} such scans; set data.beam_policy=reject or resample to accept them)")
    if policy == "reject":
        report.add("scans_rejected_beam_count", len(odd), f"scans whose beam count differs from {B}, dropped")
        keep = [i for i in range(len(scans)) if len(scans[i]) == B]
        return np.array([scans[i] for i in keep], dtype=np.float64).reshape(len(keep), B), keep
    report.add("scans_resampled_beam_count", len(odd), f"scans resampled onto {B} beams")
    out = np.empty((len(scans), B))
    for i, s in enumerate(scans):
        out[i] = s if len(s) == B else np.interp(np.linspace(0, 1, B), np.linspace(0, 1, len(s)), s)
    return out, list(range(len(scans)))


def detect_no_return(ranges: np.ndarray, min_share: float = 1e-4) -> float:
    """The driver's "no echo" value: the largest range, if at least ``min_share`` of all beams carry it."""
    top = float(np.nanmax(ranges))
    share = float(np.mean(ranges >= top - 1e-3))
    return top if share >= min_share else float("inf")


MAX_PLAUSIBLE_RANGE_M = 1.0e4  # larger values are corrupt data (and overflow float32 beyond 3.4e38)


def mask_ranges(path, ranges, no_return_m, report: DefectReport, tol_m: float = 5e-3):
    """NaN-mask no-return beams (>= no_return_m - tol) and zero ranges; negative ranges are an error."""
    ranges = np.asarray(ranges, dtype=np.float64)
    if ranges.size and ranges.min() < 0:
        row = int(np.argwhere(ranges < 0)[0, 0])
        raise LogFormatError(path, f"scan {row}", f"negative range {ranges.min():g} m (ranges must be >= 0)")
    if ranges.size and ranges.max() > MAX_PLAUSIBLE_RANGE_M:
        row = int(np.argwhere(ranges > MAX_PLAUSIBLE_RANGE_M)[0, 0])
        raise LogFormatError(path, f"scan {row}", f"range {ranges.max():g} m is beyond any lidar "
                             f"(> {MAX_PLAUSIBLE_RANGE_M:g} m)")
    no_return = detect_no_return(ranges) if no_return_m is None else float(no_return_m)
    masked = ranges.astype(np.float32)
    masked[ranges >= no_return - tol_m] = np.nan
    zero = ranges <= 0.0
    report.add("zero_ranges", int(zero.sum()), "beams reading 0 m, masked as no return")
    masked[zero] = np.nan
    if not np.isfinite(no_return):
        no_return = float(np.nanmax(masked)) if np.isfinite(masked).any() else 0.0
    return masked, no_return
