"""Atomic writes: every file the project writes goes through here, so an interrupted run never leaves half a
file behind (a temporary file in the same folder, then one rename). A full disk is one error naming the
file (``DiskFullError``), not a traceback."""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path


class DiskFullError(OSError):
    """No space (or quota) left where a file was being written; nothing half-written is left behind."""


def raise_disk_full(e: BaseException, path: Path) -> None:
    """Re-raise ``e`` as a DiskFullError naming ``path`` when it says the disk is full; else return."""
    if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
        raise DiskFullError(
            e.errno,
            f"no space left on the device writing {path} (nothing half-written was kept): "
            f"free space under {Path(path).parent} and run the command again",
        ) from e


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder and a rename."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    except OSError as e:
        raise_disk_full(e, path)
        raise
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as e:
        Path(tmp).unlink(missing_ok=True)
        raise_disk_full(e, path)
        raise


def atomic_write_json(path: Path, obj) -> Path:
    """``obj`` as indented JSON with sorted keys (numpy scalars as floats), written atomically."""
    import json

    atomic_write_bytes(Path(path), (json.dumps(obj, indent=2, sort_keys=True, default=float) + "\n").encode())
    return Path(path)
