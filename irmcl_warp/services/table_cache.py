"""``nog_table``'s range tables kept on disk, so a map's table is built once per machine and not per run.

Building a table marches every NOG node at every heading: fr079's at 720 headings takes about 80 s on the 2-core
CPU (0.05 s on an H100); reading it back from disk takes well under a second. A table is named by what it is made
of: the NOG's values, origin and resolution, the march's settings and the kind of device that marched it (a CUDA
march and a CPU march may round differently, and a run must be bit for bit the same on its device whether its
table came from the disk or not). So a changed NOG or setting makes a new file and never reads a stale one.

Where: ``$IRMCL_CACHE_DIR/tables/`` if that is set (set it empty to keep nothing), else
``$XDG_CACHE_HOME/irmcl_warp/tables/`` (``~/.cache/irmcl_warp/tables/``). A table is written to a temporary
file and renamed, so an interrupted run leaves no half table under the final name; a file that cannot be read
back as the table expected is reported (naming it) and built again.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import Callable

import numpy as np
import warp as wp

CACHE_ENV = "IRMCL_CACHE_DIR"
TABLE_FORMAT = 1  # raise when the table's layout or quantisation changes: old files are then never read


def cache_dir() -> Path | None:
    """The folder for cached tables, or None when ``IRMCL_CACHE_DIR`` is set empty (no cache)."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return Path(chosen).expanduser() / "tables" if chosen.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "irmcl_warp" / "tables"


def table_name(nog, settings: dict, device: str) -> str:
    """The file name of the table of ``nog`` built with ``settings`` on ``device``'s kind (cpu or cuda)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(nog.occupancy, dtype=np.float32).tobytes())
    made_of = dict(
        format=TABLE_FORMAT,
        shape=list(nog.occupancy.shape),
        origin=[float(v) for v in nog.origin_xy],
        resolution=float(nog.resolution_m),
        device=str(device).split(":")[0],
        **settings,
    )
    h.update(json.dumps(made_of, sort_keys=True).encode())
    return f"nog_table-{h.hexdigest()[:24]}.npy"


def table_path(nog, settings: dict, device: str) -> Path | None:
    """Where the table of ``nog`` built with ``settings`` on ``device`` is kept; None when nothing is kept."""
    folder = cache_dir()
    return None if folder is None else folder / table_name(nog, settings, device)


def cached_table(nog, settings: dict, device: str, build: Callable[[], wp.array]) -> wp.array:
    """The table from the cache when it holds one made of the same inputs, else ``build()``, kept for next time."""
    path = table_path(nog, settings, device)
    if path is None:
        return build()
    folder = path.parent
    expected = (int(np.prod(nog.occupancy.shape)), int(settings["num_angles"]))
    if path.is_file():
        try:
            table = np.load(path, allow_pickle=False)
            if table.dtype == np.uint16 and table.shape == expected:
                return wp.array(table, dtype=wp.uint16, device=device)
            problem = f"holds a {table.dtype} array of {table.shape}, not uint16 of {expected}"
        except (OSError, ValueError, EOFError) as e:
            problem = f"cannot be read ({e})"
        warnings.warn(f"{path}: this cached nog_table {problem}; building the table again", stacklevel=2)
    table = build()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f".{path.stem}.{os.getpid()}.partial")
        with open(partial, "wb") as f:
            np.save(f, table.numpy())
        os.replace(partial, path)
    except OSError as e:  # a full or read-only disk: the run goes on without keeping the table
        warnings.warn(f"{path}: could not keep the nog_table ({e}); the next run builds it again", stacklevel=2)
    return table
