"""The one data type every reader produces: :class:`LaserLog`.

Conventions
-----------
* ``ranges_m[N, B]`` float32; a beam with no return (at or above the log's "no return" value, or
  beyond ``range_max_m``) is NaN. ``valid`` is the mask of usable beams.
* ``odom[N, 3]`` is ``T_odom_base`` (x, y, yaw) at each scan stamp; ``ground_truth[N, 3]`` is
  ``T_map_base`` where known and NaN elsewhere.
* ``T_base_laser`` (x, y, yaw) is the laser extrinsic; beam ``b`` points at ``angles_rad[b]`` in the
  laser frame.
* Scans are kept in the order the reader documents (recording order for CARMEN logs, header-stamp order
  for bags, as ROS tools replay them); ``defects`` records what looked wrong, with counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class LaserInfo:
    """Geometry of a planar scanner; angles in the laser frame."""

    num_beams: int
    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    no_return_m: float  # the value the driver writes for "no echo"; masked on reading

    @property
    def angles_rad(self) -> np.ndarray:
        return (self.angle_min_rad + self.angle_increment_rad * np.arange(self.num_beams)).astype(np.float32)

    @property
    def fov_rad(self) -> float:
        return self.angle_increment_rad * (self.num_beams - 1)


@dataclass
class DefectReport:
    """Recoverable oddities found while reading, as counts with a human explanation each."""

    counts: dict[str, int] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)

    def add(self, key: str, count: int, note: str) -> None:
        if count:
            self.counts[key] = self.counts.get(key, 0) + int(count)
            self.notes[key] = note

    def __bool__(self) -> bool:
        return bool(self.counts)

    def lines(self) -> list[str]:
        return [f"{k}: {v} ({self.notes[k]})" for k, v in self.counts.items()]


@dataclass
class LaserLog:
    stamps: np.ndarray  # [N] float64 seconds
    ranges_m: np.ndarray  # [N, B] float32, NaN = no return
    odom: np.ndarray  # [N, 3] float64 T_odom_base at scan stamps
    info: LaserInfo
    T_base_laser: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ground_truth: np.ndarray | None = None  # [N, 3] T_map_base, NaN where unknown
    source: str = ""
    defects: DefectReport = field(default_factory=DefectReport)

    def __post_init__(self):
        self.stamps = np.asarray(self.stamps, dtype=np.float64)
        self.ranges_m = np.asarray(self.ranges_m, dtype=np.float32)
        self.odom = np.asarray(self.odom, dtype=np.float64)
        self.T_base_laser = np.asarray(self.T_base_laser, dtype=np.float64)
        n = len(self.stamps)
        where = self.source or "<log>"
        if n == 0:
            raise ValueError(f"{where}: the log holds no scans")
        if self.ranges_m.shape != (n, self.info.num_beams):
            raise ValueError(f"{where}: ranges shape {self.ranges_m.shape}, expected ({n}, {self.info.num_beams})")
        if self.odom.shape != (n, 3):
            raise ValueError(f"{where}: odometry shape {self.odom.shape}, expected ({n}, 3)")
        if not np.all(np.isfinite(self.stamps)) or not np.all(np.isfinite(self.odom)):
            raise ValueError(f"{where}: non-finite stamps or odometry")
        finite = self.ranges_m[np.isfinite(self.ranges_m)]
        if finite.size and finite.min() < 0:
            raise ValueError(f"{where}: negative range {finite.min()}")
        if self.ground_truth is not None:
            self.ground_truth = np.asarray(self.ground_truth, dtype=np.float64)
            if self.ground_truth.shape != (n, 3):
                raise ValueError(f"{where}: ground truth shape {self.ground_truth.shape}, expected ({n}, 3)")

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.ranges_m)

    @property
    def num_ground_truth(self) -> int:
        return 0 if self.ground_truth is None else int(np.isfinite(self.ground_truth[:, 0]).sum())

    def subset(self, index) -> "LaserLog":
        """The scans at ``index`` (mask or indices), keeping info, extrinsic and defects."""
        gt = None if self.ground_truth is None else self.ground_truth[index]
        return LaserLog(
            self.stamps[index],
            self.ranges_m[index],
            self.odom[index],
            self.info,
            self.T_base_laser,
            gt,
            self.source,
            self.defects,
        )


def match_stamps(stamps, query, tol_s: float = 1e-4) -> np.ndarray:
    """Index into ``stamps`` of each query stamp (nearest within ``tol_s``), -1 where none.

    Files are matched by stamp, never by position. The default tolerance covers files that print stamps
    to 5 decimals (mit-csail's relations) while staying far below the >= 25 ms between two scans."""
    stamps = np.asarray(stamps, dtype=np.float64)
    order = np.argsort(stamps, kind="stable")
    s = stamps[order]
    q = np.asarray(query, dtype=np.float64)
    hi = np.clip(np.searchsorted(s, q), 0, len(s) - 1)
    lo = np.clip(hi - 1, 0, len(s) - 1)
    best = np.where(np.abs(s[lo] - q) <= np.abs(s[hi] - q), lo, hi)
    return np.where(np.abs(s[best] - q) <= tol_s, order[best], -1)
