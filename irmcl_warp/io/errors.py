"""Errors and warnings of the readers: always name the file, the line or message, and what was expected."""

from __future__ import annotations

import warnings

import numpy as np

MAX_PROBLEM_CHARS = 1500  # a message quoting a token of a binary file stays readable


class LogFormatError(ValueError):
    """A log that cannot be read as it claims to be. ``where`` is 'line 12' or 'message 40 on /scan'."""

    def __init__(self, path, where: str | None, problem: str):
        if len(problem) > MAX_PROBLEM_CHARS:
            problem = problem[:MAX_PROBLEM_CHARS] + f"... ({len(problem)} characters)"
        self.path, self.where, self.problem = str(path), where, problem
        loc = f"{self.path}, {where}" if where else self.path
        super().__init__(f"{loc}: {problem}")


class LogDefectWarning(UserWarning):
    """A recoverable oddity in a log (stamps going backwards, odometry jumps), reported with counts."""


def warn_defects(path, report) -> None:
    if report:
        warnings.warn(f"{path}: " + "; ".join(report.lines()), LogDefectWarning, stacklevel=3)


def check_pose_stamps(path, stamps, poses, lines):
    """Poses of a trajectory file in stamp order. A stamp given twice with two different poses is an error
    naming both lines; a line repeated exactly is dropped; stamps going backwards are sorted. Both are
    warned about, with counts."""
    stamps, poses, lines = np.asarray(stamps, np.float64), np.asarray(poses, np.float64), np.asarray(lines)
    notes = []
    backwards = int(np.sum(np.diff(stamps) < 0))
    order = np.argsort(stamps, kind="stable")
    stamps, poses, lines = stamps[order], poses[order], lines[order]
    same = np.flatnonzero(np.diff(stamps) == 0)
    differ = [k for k in same if not np.array_equal(poses[k], poses[k + 1])]
    if differ:
        k = differ[0]
        raise LogFormatError(
            path,
            f"line {lines[k + 1]}",
            f"stamp {stamps[k]:.6f} was given at line {lines[k]} "
            f"with another pose ({len(differ)} such stamps): expected one pose per stamp",
        )
    if backwards:
        notes.append(f"{backwards} poses stamped earlier than the line before them (sorted by stamp)")
    if same.size:
        notes.append(f"{same.size} lines repeating the line before them (dropped)")
        keep = np.ones(len(stamps), bool)
        keep[same + 1] = False
        stamps, poses = stamps[keep], poses[keep]
    if notes:
        warnings.warn(f"{path}: " + "; ".join(notes), LogDefectWarning, stacklevel=3)
    return stamps, poses
