"""End to end: the inspect stage on the simulator (default config) and on fr079 (real data)."""

import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from irmcl_warp.config import register
from irmcl_warp.inspect import run_inspect
from irmcl_warp.mapping import load_map
from irmcl_warp.sim import simulate
from irmcl_warp.kernels import SIM

CONF = Path(__file__).resolve().parents[1] / "conf"


def _cfg(overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("config", overrides=overrides)


def test_inspect_on_the_simulator_maps_its_walls(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = _cfg(["sim.duration_s=60", "device=cpu", "mapping.resolution_m=0.1"])
    out = run_inspect(cfg)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scans"] == 300 and summary["ground_truth_poses"] == 300
    for f in ("map.pgm", "map.yaml", "map.png", "config.yaml", "manifest.json", "sim.bag"):
        assert (out / f).is_file(), f
    grid = load_map(out / "map.npz")
    occupied = grid.probability > 0.65
    assert occupied.sum() > 100
    _, world = simulate(cfg.sim, "cpu")
    walls = SIM.build("rasterize", device="cpu")(world.segments, grid.origin_xy, grid.resolution_m, grid.shape)
    from scipy.ndimage import binary_dilation

    near_wall = binary_dilation(walls > 0, iterations=1)
    assert near_wall[occupied].mean() > 0.95  # mapped obstacles sit on the true walls


@pytest.mark.data
def test_inspect_fr079(data_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = run_inspect(_cfg(["+exp=fr079", "device=cpu"]))
    s = json.loads((out / "summary.json").read_text())
    assert (s["scans"], s["beams"], s["ground_truth_poses"]) == (4934, 360, 4791)
    assert s["T_base_laser"][0] == pytest.approx(0.04)
    grid = load_map(out / "map.npz")
    occ = grid.probability > 0.65
    # crisp walls: a 3x3 erosion removes every wall at most 2 cells thick; what survives is the inside
    # of thicker blobs (pillars, furniture). Blurred poses would leave thick smeared walls.
    from scipy.ndimage import binary_erosion

    assert binary_erosion(occ, np.ones((3, 3))).sum() / occ.sum() < 0.1
    assert 0.01 < occ.mean() < 0.1
