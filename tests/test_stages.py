"""Stage bookkeeping: a finished stage is recognised (manifest digests, settings, inputs) and an
interrupted, edited or re-configured one is not; TUM trajectories round-trip."""

from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from irmcl_warp.config import register
from irmcl_warp.io import LogFormatError, read_tum
from irmcl_warp.io import write_tum
from irmcl_warp.services.outputs import stage_complete, write_json, write_manifest

CONF = Path(__file__).resolve().parents[1] / "conf"


def _cfg(*overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("config", overrides=list(overrides))


def _finished_stage(out: Path, cfg, inp: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "metrics.json", {"value": 1.0})
    (out / "sub").mkdir(exist_ok=True)
    (out / "sub" / "trajectory.tum").write_text("1.0 0 0 0 0 0 0 1\n")
    write_manifest(out, cfg, [inp], "cpu", 0.0)


def test_finished_stage_is_recognised_and_damage_is_not(tmp_path):
    cfg, inp = _cfg(), tmp_path / "input.log"
    inp.write_text("scan data\n")
    out = tmp_path / "stage"
    assert stage_complete(out, cfg)[0] is False  # never run
    _finished_stage(out, cfg, inp)
    assert stage_complete(out, cfg, [inp]) == (True, "")
    assert "other settings" in stage_complete(out, _cfg("mcl.num_particles=7"), [inp])[1]
    inp.write_text("another log\n")
    assert "input" in stage_complete(out, cfg, [inp])[1]
    inp.write_text("scan data\n")
    (out / "sub" / "trajectory.tum").write_text("1.0 0 0")  # half-rewritten by an interrupted rerun
    assert "differs" in stage_complete(out, cfg, [inp])[1]
    _finished_stage(out, cfg, inp)
    (out / "metrics.json").unlink()
    assert "missing" in stage_complete(out, cfg, [inp])[1]
    _finished_stage(out, cfg, inp)
    (out / "manifest.json").write_text('{"outputs": {')  # a manifest cut off mid-write by hand
    assert "malformed" in stage_complete(out, cfg, [inp])[1]


def test_tum_round_trip_and_errors(tmp_path, rng):
    stamps = 1000.0 + np.sort(rng.uniform(0, 100, 20))
    poses = np.column_stack([rng.uniform(-50, 50, (20, 2)), rng.uniform(-np.pi, np.pi, 20)])
    write_tum(tmp_path / "a.tum", stamps, poses)
    s, p = read_tum(tmp_path / "a.tum")
    assert np.allclose(s, stamps, atol=1e-6) and np.allclose(p[:, :2], poses[:, :2], atol=1e-4)
    assert np.allclose(np.angle(np.exp(1j * (p[:, 2] - poses[:, 2]))), 0, atol=1e-5), f"seed {rng.seed}"
    bad = tmp_path / "b.tum"
    bad.write_text("# stamp x y z qx qy qz qw\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n")
    with pytest.raises(LogFormatError, match=r"b.tum, line 3: expected 8 values"):
        read_tum(bad)
    bad.write_text("1 0 0 0 0.7071 0 0 0.7071\n")
    with pytest.raises(LogFormatError, match="rotation about z"):
        read_tum(bad)
