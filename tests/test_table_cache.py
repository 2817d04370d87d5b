"""nog_table's range tables on disk (irmcl_warp/services/table_cache.py): built once per map and settings, read back
bit for bit by the next filter, never read stale, and a damaged file is said and replaced."""

from __future__ import annotations

import numpy as np
import pytest

from irmcl_warp.config import compose_config
from irmcl_warp.kernels.weighting import NogTable
from irmcl_warp.nog import NOG
from irmcl_warp.services import table_cache
from irmcl_warp.services.filters import WeightingMaps, make_weighting
from tests.devices import DEVICE


def _nog(rng) -> NOG:
    occ = (rng.random((24, 31)) < 0.08).astype(np.float32)
    occ[[0, -1], :] = occ[:, [0, -1]] = 1.0
    return NOG(occ, (rng.uniform(-1, 1), rng.uniform(-1, 1)), 0.1)


def _mcl(*overrides):
    return compose_config(["mcl.weighting=nog_table", "mcl.table_angles=24", "mcl.num_samples=64", *overrides]).mcl


@pytest.fixture
def builds(monkeypatch, tmp_path):
    """Counts the marches that build a table; the cache in a folder of this test's own."""
    monkeypatch.setenv(table_cache.CACHE_ENV, str(tmp_path / "cache"))
    made = []
    build = NogTable.build

    def counted(*args, **kwargs):
        made.append(1)
        return build(*args, **kwargs)

    monkeypatch.setattr(NogTable, "build", staticmethod(counted))
    return made


def _table(mcl, nog, far_m=6.0):
    return make_weighting(mcl, far_m, DEVICE, WeightingMaps(nog=nog), 50, 8).table.numpy()


def test_a_table_is_built_once_and_read_back_bit_for_bit(rng, builds, tmp_path):
    nog = _nog(rng)
    first = _table(_mcl(), nog)
    files = list((tmp_path / "cache" / "tables").glob("nog_table-*.npy"))
    assert len(builds) == 1 and len(files) == 1
    again = _table(_mcl(), nog)  # a new run: new maps, the same NOG and settings
    assert len(builds) == 1 and np.array_equal(first, again)
    assert not list((tmp_path / "cache" / "tables").glob(".*partial"))  # nothing half written left behind


def test_another_map_or_setting_never_reads_a_stale_table(rng, builds, tmp_path):
    nog = _nog(rng)
    _table(_mcl(), nog)
    changed = NOG(nog.occupancy.copy(), nog.origin_xy, nog.resolution_m)
    changed.occupancy[5, 7] = 1.0 - changed.occupancy[5, 7]  # one node
    _table(_mcl(), changed)
    _table(_mcl("mcl.num_samples=32"), nog)
    _table(_mcl(), nog, far_m=5.0)
    _table(_mcl(), NOG(nog.occupancy, (nog.origin_xy[0] + 0.05, nog.origin_xy[1]), nog.resolution_m))
    assert len(builds) == 5 and len(list((tmp_path / "cache" / "tables").glob("*.npy"))) == 5
    _table(_mcl("mcl.num_samples=32"), nog)
    assert len(builds) == 5


def test_a_damaged_table_is_named_and_built_again(rng, builds, tmp_path):
    nog = _nog(rng)
    want = _table(_mcl(), nog)
    (path,) = (tmp_path / "cache" / "tables").glob("*.npy")
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])  # a copy cut short
    with pytest.warns(
        UserWarning, match=rf"{path.name}: this cached nog_table cannot be read .*building the table again"
    ):
        got = _table(_mcl(), nog)
    assert np.array_equal(got, want) and len(builds) == 2
    np.save(path, np.zeros((3, 3), np.uint16))  # the right name, the wrong contents
    with pytest.warns(UserWarning, match=r"holds a uint16 array of \(3, 3\), not uint16 of \(744, 24\)"):
        assert np.array_equal(_table(_mcl(), nog), want)
    assert np.load(path).shape == (744, 24)  # replaced by the good one


def test_an_empty_cache_setting_keeps_nothing(rng, builds, tmp_path, monkeypatch):
    monkeypatch.setenv(table_cache.CACHE_ENV, "")
    nog = _nog(rng)
    _table(_mcl(), nog)
    _table(_mcl(), nog)
    assert len(builds) == 2 and not (tmp_path / "cache").exists()
    assert table_cache.cache_dir() is None


def test_a_cache_that_cannot_be_written_warns_and_the_run_goes_on(rng, builds, tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(table_cache.CACHE_ENV, str(blocker))
    with pytest.warns(UserWarning, match="could not keep the nog_table"):
        table = _table(_mcl(), _nog(rng))
    assert table.shape == (744, 24) and table.dtype == np.uint16
