"""Shared fixtures. Tests marked ``data`` read the real logs under IRMCL_DATA; when the data is missing
they fail if IRMCL_REQUIRE_DATA=1 (CI) and are reported as not run otherwise (a laptop without data)."""

from __future__ import annotations

import os
import secrets
import tempfile
from pathlib import Path

import numpy as np
import pytest

from irmcl_warp.io import data_root

# tests change directory (tmp_path): pin a relative IRMCL_DATA to where the session started
if os.environ.get("IRMCL_DATA"):
    os.environ["IRMCL_DATA"] = str(Path(os.environ["IRMCL_DATA"]).resolve())
HAVE_DATA = (data_root() / "README.md").is_file()
# nog_table's tables are cached on disk (irmcl_warp/services/table_cache.py): tests keep theirs apart from a user's
os.environ["IRMCL_CACHE_DIR"] = tempfile.mkdtemp(prefix="irmcl-test-cache-")


def _cuda() -> bool:
    import warp as wp

    wp.config.quiet = True
    return wp.is_cuda_available()


def pytest_collection_modifyitems(config, items):
    gpu = [item for item in items if "gpu" in item.keywords]
    if gpu and not _cuda():  # marker gpu: CUDA-only checks, run on a lent GPU (eval/gpu/tests.sh), never in CI
        for item in gpu:
            item.add_marker(pytest.mark.skip(reason="needs a CUDA device (eval/gpu/tests.sh runs these on a GPU)"))
    if HAVE_DATA:
        return
    if os.environ.get("IRMCL_REQUIRE_DATA") == "1":
        return  # the data_dir fixture fails each data test
    for item in items:
        if "data" in item.keywords:
            item.add_marker(pytest.mark.skip(reason=f"real data not found at {data_root()} (set IRMCL_DATA)"))


@pytest.fixture
def data_dir() -> Path:
    if not HAVE_DATA:
        pytest.fail(f"IRMCL_REQUIRE_DATA=1 but the shared data is missing at {data_root()}")
    return data_root()


class SeededRng:
    """numpy's Generator plus the seed it was made from, so a failing test can name it."""

    def __init__(self, seed: int):
        self.seed, self._g = seed, np.random.default_rng(seed)

    def __getattr__(self, name):
        return getattr(self._g, name)


@pytest.fixture
def rng():
    """A fresh random generator per test (fresh inputs every run); assertions print ``rng.seed``."""
    return SeededRng(secrets.randbits(32))
