"""The extension points are real (irmcl_warp/extend.py): an observation model and a SLAM proposal, each one file
outside the package (tests/plugins/), named in ``plugins`` and chosen by config, run through localize and slam."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import ConfigError, SimConfig, register
from irmcl_warp.extend import ObservationModel, Proposal, load_plugins
from irmcl_warp.io import write_bag
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.mcl.stage import run_localize
from irmcl_warp.services.cli import run_entry
from irmcl_warp.sim import simulate
from irmcl_warp.slam.stage import run_slam
from tests.devices import DEVICE

CONF = Path(__file__).resolve().parents[1] / "conf"
PLUGINS = Path(__file__).resolve().parent / "plugins"


@pytest.fixture(autouse=True)
def plugins_forgotten():
    """A plugin registers into the package's registries for the rest of the process: each test leaves them (and
    the plugin modules) as it found them, so no other test sees a toy."""
    from irmcl_warp.kernels import WEIGHTING
    from irmcl_warp.slam.rbpf import PROPOSALS

    saved = {r: dict(r._factories) for r in (WEIGHTING, PROPOSALS)}
    yield
    for registry, factories in saved.items():
        registry._factories.clear()
        registry._factories.update(factories)
    for name in [m for m in sys.modules if m.startswith("irmcl_plugin_")]:
        del sys.modules[name]


def _compose(*overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("config", overrides=[f"device={DEVICE}", *overrides])


def _tum(path: Path) -> np.ndarray:
    return np.loadtxt(path, ndmin=2)


def test_an_observation_model_from_a_file_of_its_own_localizes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    log, _ = simulate(OmegaConf.structured(SimConfig(width_m=12.0, height_m=9.0, duration_s=20.0)), DEVICE)
    files = save_map(build_map(log, log.ground_truth, resolution_m=0.05, far_m=20.0, device=DEVICE), tmp_path / "m")
    bag = write_bag(log, tmp_path / "drive.bag")
    x, y, yaw = (float(v) for v in log.ground_truth[0])
    cfg = _compose(
        "data=bag",
        f"data.path={bag}",
        f"localize.map_path={files['yaml']}",
        f"plugins=[{PLUGINS / 'toy_weighting.py'}]",
        "mcl.weighting=toy_endpoint",
        "mcl.num_particles=500",
        f"localize.initial_pose=[{x + 0.2},{y - 0.15},{yaw}]",
    )
    out = run_entry(run_localize, cfg)
    toy = sys.modules["irmcl_plugin_toy_weighting"]
    assert toy.CALLS[0] > 20  # it scored the scans
    assert isinstance(toy.EndPointOccupancy(np.zeros((2, 2)), (0, 0), 0.1, "cpu"), ObservationModel)
    est, truth = _tum(out / "trajectory.tum"), _tum(out / "ground_truth.tum")
    last = np.hypot(*(est[-20:, 1:3] - truth[-20:, 1:3]).T)
    assert np.median(last) < 0.3, last  # it tracks: the crude model still holds the robot


def test_a_slam_proposal_from_a_file_of_its_own_maps(tmp_path, monkeypatch):
    """The plugin re-states the odometry baseline outside the package: the same poses bit for bit, by its calls."""
    monkeypatch.chdir(tmp_path)
    common = ("+exp=gmapping_sim", "sim.duration_s=15", "slam.num_particles=8")
    toy_out = run_entry(
        run_slam, _compose(*common, f"plugins=[{PLUGINS / 'toy_proposal.py'}]", "slam.proposal=toy_odometry")
    )
    toy = sys.modules["irmcl_plugin_toy_proposal"]
    assert toy.CALLS[0] > 5
    assert isinstance(toy.make_toy(None), Proposal)
    built_in = run_entry(run_slam, _compose(*common, "slam.proposal=odometry"))
    assert toy_out != built_in  # two runs of their own (the proposal is part of the run's identity)
    assert (toy_out / "trajectory.tum").read_bytes() == (built_in / "trajectory.tum").read_bytes()


def test_a_missing_plugin_or_an_unregistered_name_is_a_clear_error(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match=r"plugins: nowhere\.py: no such file"):
        load_plugins(["nowhere.py"])
    with pytest.raises(ValueError, match="plugins: 'no_such_module' is neither a .py file nor an importable module"):
        load_plugins(["no_such_module"])
    with pytest.raises(SystemExit) as ended:  # a choice no registry holds: one line, exit status 2
        run_entry(run_localize, _compose("mcl.weighting=toy_nowhere"))
    assert ended.value.code == 2
    assert "mcl.weighting='toy_nowhere': expected one of" in capsys.readouterr().err
    with pytest.raises(ConfigError):
        from irmcl_warp.config import validate

        validate(_compose("slam.proposal=toy_nowhere"))
