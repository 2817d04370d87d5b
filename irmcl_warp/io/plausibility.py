"""Inputs that read without an error and are still wrong: each check says so loudly, naming the file.

* ``check_map``: a map whose known cells are mostly occupied, or whose known free space is mostly cells beside
  walls (an inverted image: white read as occupied, the walls' thin lines as free space);
* ``check_beam_order``: a scan whose beams run clockwise while the log says counter-clockwise (or the
  reverse): turning on the spot, consecutive scans then line up with the odometry's rotation only mirrored;
* ``check_odometry``: odometry that jumps farther between two scans than any robot drives (a corrupt
  message): an error for localization, which would otherwise follow it out of the map;
* ``near_no_return``: readings a few centimetres under the log's no-return value, many of them at one value
  (a second no-return code the reader would take for returns).
"""

from __future__ import annotations

import warnings

import numpy as np

from irmcl_warp.io.errors import LogDefectWarning

MAX_OCCUPIED_SHARE = 0.5  # of a map's known cells; buildings are mostly free space (our logs' maps: 10-30 %)
MAX_FREE_ON_WALLS = 0.5  # of a map's known free cells touching a wall (our logs' 5 cm maps: well under a quarter)
ABSURD_STEP_M = 100.0  # an odometry step between two scans this long is corrupt, not a motion


def occupied_share(occupancy_p: np.ndarray, known: np.ndarray) -> float:
    k = np.asarray(known, bool)
    return float((np.asarray(occupancy_p)[k] > 0.5).mean()) if k.any() else 0.0


def free_on_walls_share(occupancy_p: np.ndarray, known: np.ndarray) -> float:
    """Share of the known free cells (p_occ < 0.5) that touch an occupied cell (8-neighbourhood): low in a
    building's map (rooms and corridors are many cells wide), high where the "free space" is thin lines."""
    from scipy.ndimage import binary_dilation

    p, k = np.asarray(occupancy_p), np.asarray(known, bool)
    free, occ = k & (p < 0.5), k & (p > 0.5)
    if not free.any():
        return 0.0
    return float((binary_dilation(occ, np.ones((3, 3), bool)) & free).sum() / free.sum())


def check_map(path, occupancy_p: np.ndarray, known: np.ndarray) -> float | None:
    """Warn when most of the map's known cells are occupied, or when its known free space is mostly the cells
    beside walls (thin lines: walls read as free); returns the share it warned about."""
    edge = free_on_walls_share(occupancy_p, known)
    if edge > MAX_FREE_ON_WALLS:
        warnings.warn(
            f"{path}: {100 * edge:.0f} % of its known free cells touch an occupied cell, where a building's "
            f"free space is rooms and corridors many cells wide: are walls read as free space (an inverted "
            f"image, map_server's 'negate')?",
            LogDefectWarning,
            stacklevel=2,
        )
        return edge
    share = occupied_share(occupancy_p, known)
    if share > MAX_OCCUPIED_SHARE:
        warnings.warn(
            f"{path}: {100 * share:.0f} % of its known cells are occupied, where a building's map is mostly "
            f"free space: is the image inverted (white read as occupied)? map_server's 'negate: 1' flips it",
            LogDefectWarning,
            stacklevel=2,
        )
        return share
    return None


def beam_order_votes(
    ranges_m: np.ndarray,
    odom: np.ndarray,
    increment_rad: float,
    max_trans_m: float = 0.05,
    min_shift: int = 2,
    max_shift_share: float = 0.1,
) -> tuple[int, int]:
    """(turns where the scans line up as the log orders its beams, turns where they line up mirrored), over
    consecutive scans that turn on the spot by at least ``min_shift`` beams: a counter-clockwise turn by dtheta
    moves a wall from beam i + s to beam i in the next scan (s = dtheta / increment)."""
    r = np.asarray(ranges_m, np.float64)
    step = np.diff(np.asarray(odom, np.float64), axis=0)
    shift = np.round(np.angle(np.exp(1j * step[:, 2])) / increment_rad).astype(int)
    B = r.shape[1]
    turns = np.flatnonzero(
        (np.hypot(step[:, 0], step[:, 1]) <= max_trans_m)
        & (np.abs(shift) >= min_shift)
        & (np.abs(shift) <= max_shift_share * B)
    )
    ok_fwd = ok_rev = 0
    for k in turns:
        fwd, rev = (_mismatch(r[k], r[k + 1], s) for s in (shift[k], -shift[k]))
        if np.isfinite(fwd) and np.isfinite(rev) and abs(fwd - rev) > 0.02:
            ok_fwd += fwd < rev
            ok_rev += rev < fwd
    return ok_fwd, ok_rev


def _mismatch(a: np.ndarray, b: np.ndarray, shift: int) -> float:
    """Median |b[i] - a[i + shift]| over the beams both scans return (NaN where under a quarter of them)."""
    B = len(a)
    i = np.arange(B)
    j = i + shift
    inside = (j >= 0) & (j < B)
    d = np.abs(b[i[inside]] - a[j[inside]])
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) > B // 4 else np.nan


def check_beam_order(path, ranges_m, odom, increment_rad: float, min_turns: int = 8) -> bool:
    """Warn when the scans line up with the odometry's turns only with their beams mirrored; True if it warned."""
    fwd, rev = beam_order_votes(ranges_m, odom, increment_rad)
    if fwd + rev >= min_turns and rev > 3 * fwd:
        warnings.warn(
            f"{path}: its beams appear to run the other way round: in {rev} of {fwd + rev} turns on the spot "
            f"consecutive scans line up with the odometry's rotation only when mirrored. Check the driver's "
            f"angle_increment sign (or data.angle_min_rad / data.fov_rad for a CARMEN log): mapped as they "
            f"are, the scans smear into a disc",
            LogDefectWarning,
            stacklevel=2,
        )
        return True
    return False


def check_odometry(path, odom: np.ndarray, max_step_m: float = ABSURD_STEP_M) -> None:
    """An error naming the scans where the odometry jumps farther than any robot drives between two scans."""
    step = np.hypot(*np.diff(np.asarray(odom, np.float64)[:, :2], axis=0).T)
    bad = np.flatnonzero(~np.isfinite(step) | (step > max_step_m))
    if len(bad):
        k = int(bad[0])
        raise ValueError(
            f"{path}: the odometry jumps {step[k]:.4g} m between scans {k} and {k + 1} "
            f"({len(bad)} such step{'s' if len(bad) > 1 else ''}): corrupt odometry, which localization "
            f"would follow off the map; repair the log or cut it (localize.start_s / run_s)"
        )


def near_no_return(ranges: np.ndarray, no_return_m: float, tol_m: float, below_m: float = 0.2) -> tuple[int, float]:
    """(how many finite readings lie within ``below_m`` under the no-return value at the single most common
    value there, that value): a second no-return code shows as one value repeated many times."""
    r = np.asarray(ranges, np.float64)
    near = r[(r >= no_return_m - below_m) & (r < no_return_m - tol_m)]
    if len(near) == 0:
        return 0, float("nan")
    values, counts = np.unique(np.round(near, 3), return_counts=True)
    i = int(np.argmax(counts))
    return int(counts[i]), float(values[i])
