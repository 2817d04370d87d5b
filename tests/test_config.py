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


TRAIN_PRESETS = sorted(p.stem for p in (CONF / "train").glob("*.yaml"))


@pytest.mark.parametrize("preset", TRAIN_PRESETS)
def test_training_presets_compose_and_name_themselves(preset):
    cfg = _compose(["+exp=fr079", f"train={preset}"])
    assert cfg.train.name == preset  # the output folder train-<name> must not collide
    assert cfg.model.skip_after < cfg.model.depth and cfg.train.batch_rays > 0


def test_paper_recipe_is_the_authors_script():
    cfg = _compose(["+exp=fr079", "train=paper"])
    t, r, m = cfg.train, cfg.render, cfg.model
    assert (t.epochs, t.batch_rays, t.num_samples, t.lr, list(t.lr_milestones), t.lr_gamma, t.weight_decay) == (
        32,
        1024,
        256,
        1e-4,
        [4, 8],
        0.5,
        1e-3,
    )
    assert (t.loss, t.lambda_opacity, r.near_m, cfg.data.far_m) == ("smooth_l1", 1e-5, 0.02, 40.0)
    assert (m.num_freqs, m.width, m.depth, m.skip_after) == (10, 256, 8, 4)


def test_block_experiments_hold_out_the_time_block():
    cfg = _compose(["+exp=fr079_block"])
    assert cfg.data.split == "block" and cfg.exp == "fr079_block" and cfg.data.name == "fr079"


def test_config_choices_are_what_the_code_implements():
    """config.CHOICES (checked before a stage runs) names exactly the registry entries and strategies the
    stages choose from, so a new kernel or strategy cannot be refused, nor a removed one accepted."""
    import irmcl_warp.nof.direct  # noqa: F401  (registers nof_direct)
    from irmcl_warp.config import CHOICES
    from irmcl_warp.mcl.filter import ESTIMATORS
    from irmcl_warp.nof.beams import SPLITS
    from irmcl_warp.nof.render import RENDERERS
    from irmcl_warp.slam.rbpf import PROPOSALS
    from irmcl_warp.kernels import MAPPING, RAYCAST, RESAMPLE, WEIGHTING

    implemented = {
        "mcl.weighting": WEIGHTING.names(),
        "mcl.estimate": ESTIMATORS,
        "mcl.resample": RESAMPLE.names(),
        "render.name": RENDERERS,
        "raycast.name": RAYCAST.names(),
        "mapping.kernel": MAPPING.names(),
        "data.split": SPLITS,
        "slam.proposal": PROPOSALS.names(),
    }
    for key, names in implemented.items():
        assert sorted(CHOICES[key]) == sorted(names), key


def test_the_amcl_preset_is_the_worlds_stage_s_filter():
    """mcl=amcl (for your own map) and +exp=worlds (where it was measured on held-out floors) are one filter."""
    from irmcl_warp.config import compose_config

    assert compose_config(["mcl=amcl"]).mcl == compose_config(["+exp=worlds"]).mcl
    assert compose_config(["mcl=amcl"]).mcl != compose_config([]).mcl
