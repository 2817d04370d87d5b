"""Stage bookkeeping: a finished run is recognised by its manifest (its id, the digest of every file it
wrote), and an interrupted, edited or truncated one is not; TUM trajectories round-trip."""

import json
from pathlib import Path

import numpy as np
import pytest

from irmcl_warp import runs
from irmcl_warp.config import compose_config
from irmcl_warp.io import LogFormatError, read_tum
from irmcl_warp.io import write_tum


def _finished(root: Path, cfg) -> Path:
    with runs.start(cfg, "inspect", root) as run:
        (run.dir / "sub").mkdir()
        (run.dir / "sub" / "trajectory.tum").write_text("1.0 0 0 0 0 0 0 1\n")
        return run.finish({"value": 1.0}, "cpu")


def test_finished_run_is_recognised_and_damage_is_not(tmp_path):
    cfg = compose_config(["device=cpu"])
    ident = runs.identify(cfg, "inspect")
    assert runs.finished(ident, tmp_path) is None  # never run
    out = _finished(tmp_path, cfg)
    assert out == ident.folder(tmp_path) and runs.intact(out, ident.id) == (True, "")
    assert json.loads((out / "manifest.json").read_text())["id"] == ident.id
    assert "another run" in runs.intact(out, "0" * 64)[1]
    (out / "sub" / "trajectory.tum").write_text("1.0 0 0")  # half-rewritten by an interrupted rerun
    assert "differs" in runs.intact(out)[1]
    (out / "sub" / "trajectory.tum").write_text("1.0 0 0 0 0 0 0 1\n")
    assert runs.intact(out)[0]
    (out / "metrics.json").unlink()
    assert "missing" in runs.intact(out)[1]
    out = _finished(tmp_path, cfg)  # redone: whole again
    (out / "manifest.json").write_text('{"outputs": {')  # a manifest cut off mid-write by hand
    assert "malformed" in runs.intact(out)[1] and runs.finished(ident, tmp_path) is None


def test_a_run_left_unfinished_leaves_no_finished_run(tmp_path):
    cfg = compose_config(["device=cpu"])
    with pytest.raises(KeyboardInterrupt):
        with runs.start(cfg, "inspect", tmp_path) as run:
            (run.dir / "summary.json").write_text("{}")
            raise KeyboardInterrupt  # Ctrl-C in the middle of the stage
    assert runs.finished(runs.identify(cfg, "inspect"), tmp_path) is None
    out = _finished(tmp_path, cfg)  # the next run starts afresh: nothing of the interrupted one in it
    assert not (out / "summary.json").exists() and runs.intact(out)[0]


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
