"""Errors and warnings of the readers: always name the file, the line or message, and what was expected."""

from __future__ import annotations

import warnings


class LogFormatError(ValueError):
    """A log that cannot be read as it claims to be. ``where`` is 'line 12' or 'message 40 on /scan'."""

    def __init__(self, path, where: str | None, problem: str):
        self.path, self.where, self.problem = str(path), where, problem
        loc = f"{self.path}, {where}" if where else self.path
        super().__init__(f"{loc}: {problem}")


class LogDefectWarning(UserWarning):
    """A recoverable oddity in a log (stamps going backwards, odometry jumps), reported with counts."""


def warn_defects(path, report) -> None:
    if report:
        warnings.warn(f"{path}: " + "; ".join(report.lines()), LogDefectWarning, stacklevel=3)
