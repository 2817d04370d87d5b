"""Every experiment composes, and a key nothing reads is an error."""

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf.errors import ConfigKeyError, ConfigAttributeError

from irmcl_warp.config import register

CONF = Path(__file__).resolve().parents[1] / "conf"
EXPS = sorted(p.stem for p in (CONF / "exp").glob("*.yaml"))


def _compose(overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("config", overrides=overrides)


@pytest.mark.parametrize("exp", EXPS)
def test_experiment_composes(exp):
    cfg = _compose([f"+exp={exp}"])
    assert cfg.exp == exp
    assert cfg.data.format in ("sim", "carmen", "bag")
    if cfg.data.format != "sim":
        assert cfg.data.path


def test_default_is_the_simulator_and_needs_no_data():
    cfg = _compose([])
    assert cfg.data.format == "sim" and cfg.exp == "sim_office" and cfg.device == "auto"


def test_unknown_key_fails():
    with pytest.raises((ConfigKeyError, ConfigAttributeError, Exception), match="not_a_key"):
        _compose(["data.not_a_key=1"])


def test_derived_logs_where_odometry_matters():
    assert "derived/intel.fileorder" in _compose(["+exp=intel"]).data.path
    assert "derived/fr079.revfix" in _compose(["+exp=fr079"]).data.path
