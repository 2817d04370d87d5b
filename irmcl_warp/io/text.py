"""Text files as every reader sees them: plain or gzip, read whole, each failure a LogFormatError naming the
file; a last line without its newline (a file cut off while written) set apart; numbers parsed strictly."""

from __future__ import annotations

import gzip
import zlib
from pathlib import Path

import numpy as np

from irmcl_warp.io.errors import LogFormatError


def open_text(path: Path):
    """Open plain or gzip text; gzip is recognised by its magic bytes, not the file name. Undecodable bytes
    become U+FFFD, so they surface as a bad token on a numbered line."""
    with open(path, "rb") as f:
        magic = f.read(2)
    if magic == b"\x1f\x8b":
        return gzip.open(path, "rt", encoding="utf-8", errors="replace")
    return open(path, "rt", encoding="utf-8", errors="replace")


def decode_lines(path, data: bytes) -> tuple[list[tuple[int, str]], bool]:
    """(numbered lines, last line unfinished) of bytes already read (a zip member)."""
    text = data.decode("utf-8", "replace")
    lines = text.splitlines(keepends=True)
    return _numbered(lines)


def read_lines(path) -> tuple[list[tuple[int, str]], bool]:
    """([(line number, text)], whether the last line lacks its newline: cut off, to be dropped loudly)."""
    try:
        with open_text(Path(path)) as f:
            lines = f.readlines()
    except (EOFError, OSError, zlib.error) as e:
        raise LogFormatError(path, None, f"cannot read (truncated or corrupt gzip?): {e}") from e
    return _numbered(lines)


def _numbered(lines):
    cut = bool(lines) and not lines[-1].endswith(("\n", "\r")) and bool(lines[-1].strip())
    return list(enumerate(lines, start=1)), cut


def parse_floats(path, line_no, tokens, what):
    """Tokens as float64, or a LogFormatError naming the line and the first bad token; NaN and inf refused."""
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise LogFormatError(
            path,
            f"line {line_no}",
            f"{what}: expected a number, found {bad[:40]!r}" + (f" ({len(bad)} characters)" if len(bad) > 40 else ""),
        ) from None
    if not np.all(np.isfinite(values)):
        raise LogFormatError(path, f"line {line_no}", f"{what}: NaN or infinite value")
    return values


COMMENT_NUMBERS = 6  # a comment holding this many numbers swallowed a record


def check_comment(path, n_line, line):
    """A comment that holds a record's worth of numbers swallowed the next line when a line break was lost."""
    numbers = sum(_is_float(t) for t in line.replace(",", " ").split())
    if numbers >= COMMENT_NUMBERS:
        raise LogFormatError(
            path, f"line {n_line}", f"a comment holds {numbers} numbers: a record joined to it (a lost line break)?"
        )


def _is_float(t):
    try:
        float(t)
        return True
    except ValueError:
        return False
