"""Training and test beams for the NOF: scans with known poses, cut into the benchmark splits.

A :class:`BeamSet` holds, per scan, the laser pose in the map frame and the ranges; ``valid`` marks the
beams that train and score: a return (not NaN) within (near, far) of the renderer. The splits are the
fixed ids of ``splits/<name>.json`` (scan stamps), so results compare with other implementations; the
simulator, which has no split file, uses the same rule (``interleaved_splits``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irmcl_warp.geometry import compose
from irmcl_warp.types import LaserLog, match_stamps

SPLITS = {"interleaved": ("train", "val", "test"), "block": ("train_block", "val_block", "test_block")}


@dataclass
class BeamSet:
    stamps: np.ndarray  # [S]
    T_map_laser: np.ndarray  # [S, 3]
    ranges_m: np.ndarray  # [S, B] float32, NaN = no return
    angles_rad: np.ndarray  # [B]
    valid: np.ndarray  # [S, B] bool
    name: str = "beams"

    def __post_init__(self):
        S, B = self.ranges_m.shape if self.ranges_m.ndim == 2 else (None, None)
        if S is None:
            raise ValueError(f"{self.name}: ranges must be [scans, beams], got shape {self.ranges_m.shape}")
        if len(self.T_map_laser) != S or len(self.stamps) != S:
            raise ValueError(
                f"{self.name}: {len(self.T_map_laser)} poses and {len(self.stamps)} stamps "
                f"for {S} scans: one pose and one stamp per scan expected"
            )
        if len(self.angles_rad) != B or self.valid.shape != (S, B):
            raise ValueError(
                f"{self.name}: {len(self.angles_rad)} beam angles / valid mask {self.valid.shape} "
                f"do not match ranges {self.ranges_m.shape}"
            )
        if S == 0:
            raise ValueError(f"{self.name}: no scans")
        bad_pose = ~np.all(np.isfinite(self.T_map_laser), axis=1)
        if bad_pose.any():
            s = int(np.argmax(bad_pose))
            raise ValueError(f"{self.name}: scan {s} (stamp {self.stamps[s]:.6f}) has a non-finite pose")
        bad = self.valid & ~(np.isfinite(self.ranges_m) & (self.ranges_m > 0))
        if bad.any():
            s, b = map(int, np.argwhere(bad)[0])
            raise ValueError(
                f"{self.name}: scan {s} (stamp {self.stamps[s]:.6f}), beam {b}: range "
                f"{self.ranges_m[s, b]} is marked valid; expected a positive finite range"
            )
        if not self.valid.any():
            raise ValueError(f"{self.name}: none of its {S} scans has a valid beam")

    def __len__(self) -> int:
        return len(self.stamps)

    @property
    def num_rays(self) -> int:
        return int(self.valid.sum())

    def rays(self, valid_only: bool = True):
        """(origins [M, 2], directions [M, 2], ranges [M], scan index [M]) as float32 numpy arrays."""
        S, B = self.ranges_m.shape
        scan = np.repeat(np.arange(S), B)
        yaw = (self.T_map_laser[:, 2:3] + self.angles_rad[None, :]).reshape(-1)
        origins = np.repeat(self.T_map_laser[:, :2], B, axis=0)
        dirs = np.stack([np.cos(yaw), np.sin(yaw)], -1)
        ranges = self.ranges_m.reshape(-1)
        keep = self.valid.reshape(-1) if valid_only else slice(None)
        return (
            origins[keep].astype(np.float32),
            dirs[keep].astype(np.float32),
            ranges[keep].astype(np.float32),
            scan[keep],
        )

    def subset(self, index, name: str | None = None) -> "BeamSet":
        return BeamSet(
            self.stamps[index],
            self.T_map_laser[index],
            self.ranges_m[index],
            self.angles_rad,
            self.valid[index],
            name or self.name,
        )


def interleaved_splits(stamps: np.ndarray, block_share: float = 0.2) -> dict[str, np.ndarray]:
    """The rule of ../shared/data/splits: row k -> test if k % 10 == 0, val if k % 10 == 5, else train;
    test_block = the last 20 % in time, the rest split into train_block / val_block (k % 10 == 5)."""
    stamps = np.sort(np.asarray(stamps))
    k = np.arange(len(stamps))
    cut = int(round(len(stamps) * (1.0 - block_share)))
    early = k < cut
    return {
        "train": stamps[(k % 10 != 0) & (k % 10 != 5)],
        "val": stamps[k % 10 == 5],
        "test": stamps[k % 10 == 0],
        "train_block": stamps[early & (k % 10 != 5)],
        "val_block": stamps[early & (k % 10 == 5)],
        "test_block": stamps[~early],
    }


def beams_from_log(log: LaserLog, near_m: float, far_m: float, name: str = "beams") -> BeamSet:
    """All scans of ``log`` that have a ground-truth pose; valid = near < range < far."""
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: no ground-truth poses to train a NOF from")
    known = np.all(np.isfinite(log.ground_truth), axis=1)
    if not known.any():
        raise ValueError(f"{log.source}: none of its {len(log)} scans has a ground-truth pose")
    log = log.subset(known)
    r = log.ranges_m
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r > near_m) & (r < far_m)
    return BeamSet(
        log.stamps.copy(),
        compose(log.ground_truth, log.T_base_laser),
        r.astype(np.float32),
        log.info.angles_rad.astype(np.float64),
        valid,
        name,
    )


def split_beams(beams: BeamSet, splits: dict[str, np.ndarray], names, source: str = "splits") -> dict[str, BeamSet]:
    """Cut ``beams`` by the split ids (stamps); every id must name a scan with a pose."""
    out = {}
    for name in names:
        ids = np.asarray(splits.get(name, []), dtype=np.float64)
        if len(ids) == 0:
            raise ValueError(f"{source}: split {name!r} is empty or missing (found {sorted(splits)})")
        idx = match_stamps(beams.stamps, ids)
        if (idx < 0).any():
            raise ValueError(
                f"{source}: {int((idx < 0).sum())} of the {len(ids)} ids of split {name!r} match no "
                f"scan with a ground-truth pose (first: {ids[idx < 0][0]:.6f})"
            )
        out[name] = beams.subset(np.sort(idx), name)
    return out
