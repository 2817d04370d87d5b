import numpy as np
import pytest
import warp as wp

from irmcl_warp.mapping import OccupancyGrid, load_map, save_map
from irmcl_warp.reference.mapping import integrate
from irmcl_warp.kernels import MAPPING
from tests.devices import DEVICE

SETTINGS = dict(l_occ=0.85, l_free=-0.4, l_min=-4.0, l_max=4.0, far_m=3.0)


def test_logodds_kernel_matches_numpy_twin(rng):
    H, W, res, origin = 40, 50, 0.1, (-1.0, -2.0)
    poses = np.c_[rng.uniform(-0.5, 3.5, 6), rng.uniform(-1.5, 1.5, 6), rng.uniform(-np.pi, np.pi, 6)].astype(
        np.float32
    )
    angles = np.linspace(-2, 2, 21).astype(np.float32)
    ranges = rng.uniform(0.05, 4.0, (6, 21)).astype(np.float32)
    ranges[rng.random((6, 21)) < 0.1] = np.nan
    got = wp.zeros((H, W), dtype=wp.float32, device=DEVICE)
    MAPPING.build("logodds", **SETTINGS).integrate(
        got,
        origin,
        res,
        wp.array(poses, dtype=wp.vec3, device=DEVICE),
        wp.array(ranges, device=DEVICE),
        wp.array(angles, device=DEVICE),
    )
    want = integrate(np.zeros((H, W), np.float32), origin, res, poses, ranges, angles, **SETTINGS)
    assert np.mean(np.abs(got.numpy() - want) < 1e-5) > 0.995, f"seed {rng.seed}"
    # the same scans in another order give the same grid bit for bit (the per-cell counts are whole numbers)
    order = rng.permutation(len(poses))
    again = wp.zeros((H, W), dtype=wp.float32, device=DEVICE)
    MAPPING.build("logodds", **SETTINGS).integrate(
        again,
        origin,
        res,
        wp.array(poses[order], dtype=wp.vec3, device=DEVICE),
        wp.array(ranges[order], device=DEVICE),
        wp.array(angles, device=DEVICE),
    )
    assert np.array_equal(again.numpy(), got.numpy()), f"seed {rng.seed}"


def test_map_files_roundtrip(tmp_path, rng):
    logodds = np.zeros((20, 30), np.float32)
    logodds[rng.random((20, 30)) < 0.2] = 3.0
    logodds[rng.random((20, 30)) < 0.3] = -3.0
    grid = OccupancyGrid(logodds, (-1.5, 2.0), 0.05)
    paths = save_map(grid, tmp_path / "m")
    exact = load_map(paths["npz"])
    np.testing.assert_array_equal(exact.logodds, logodds)
    ros = load_map(paths["yaml"])
    assert ros.origin_xy == (-1.5, 2.0) and ros.resolution_m == 0.05
    np.testing.assert_array_equal(np.sign(ros.logodds), np.sign(logodds))  # trinary keeps occupied/free/unknown
    assert "mode: trinary" in paths["yaml"].read_text()


def test_corrupt_pgm_is_a_clear_error(tmp_path):
    grid = OccupancyGrid(np.zeros((4, 4), np.float32), (0, 0), 0.1)
    paths = save_map(grid, tmp_path / "m")
    paths["pgm"].write_bytes(paths["pgm"].read_bytes()[:-5])
    with pytest.raises(ValueError, match="expected 4x4"):
        load_map(paths["yaml"])
