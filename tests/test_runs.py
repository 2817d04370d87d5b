"""Runs as records (irmcl_warp.runs): a run's identity is what it reads (settings, the content of its input
files, the runs it consumes), runs of other identities never share a folder, a finished run is never replaced,
a damaged or interrupted one is redone from scratch, runs of one identity started at once leave one run, and a
stage consumes only finished runs."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf
from omegaconf.errors import ConfigAttributeError

from irmcl_warp import runs
from irmcl_warp.config import ModelConfig, compose_config
from irmcl_warp.inspect import run_inspect
from irmcl_warp.io import LogDefectWarning
from irmcl_warp.mcl.stage import run_localize
from irmcl_warp.nof.model import NOF
from irmcl_warp.services.data import load_stream

REPO = Path(__file__).resolve().parents[1]
SMALL = ["sim.duration_s=20", "sim.width_m=14", "sim.height_m=10", "device=cpu"]
TINY_FIELD = ["model.width=16", "model.depth=2", "model.num_freqs=2", "model.skip_after=0"]


def _cfg(*overrides):
    return compose_config(list(overrides))


def _finish(cfg, stage, root, files=None, metrics=None) -> Path:
    """A finished run of ``stage`` for ``cfg`` made through runs.start (its body stands in for the stage's)."""
    with runs.start(cfg, stage, root) as run:
        for name, data in (files or {}).items():
            (run.dir / name).write_bytes(data)
        return run.finish(metrics or {"made": "by the test"}, "cpu")


# --- identity ------------------------------------------------------------------------------------------------


def test_identity_follows_what_the_stage_reads(tmp_path):
    """globloc reads mcl (its lidar filter): changing mcl.alphas makes it run again; localize reads neither
    mapping nor raycast: changing them returns the finished run; a likelihood-field run does not depend on a
    training recipe, a NOG run does (through the training run's id); validation changes a training."""
    base = _cfg("+exp=globloc_corridor")
    alphas = _cfg("+exp=globloc_corridor", "mcl.alphas=[0.1,0.01,0.1,0.01]")
    done = _finish(base, "globloc", tmp_path)
    assert runs.finished(runs.identify(base, "globloc"), tmp_path) == done
    assert runs.finished(runs.identify(alphas, "globloc"), tmp_path) is None  # a new run, not the old one
    lf = _cfg("+exp=sim_office", "mcl.weighting=likelihood_field", *SMALL)
    lf_done = _finish(lf, "localize", tmp_path)
    other_grids = _cfg(
        "+exp=sim_office",
        "mcl.weighting=likelihood_field",
        *SMALL,
        "mapping.resolution_m=0.1",
        "raycast.name=distance_field",
        "train.lr=0.05",
    )
    assert runs.finished(runs.identify(other_grids, "localize"), tmp_path) == lf_done
    nog = [runs.identify(_cfg("+exp=sim_office", *SMALL, f"train.lr={lr}"), "localize") for lr in (0.003, 0.05)]
    assert nog[0].id != nog[1].id and nog[0].upstream["train"].id != nog[1].upstream["train"].id
    val = [runs.identify(_cfg("+exp=sim_office", *SMALL, f"train.val_scans={k}"), "train").id for k in (2, 3)]
    assert val[0] != val[1]


def test_a_stage_body_cannot_read_a_setting_its_identity_leaves_out():
    """The stage runs on the settings it declares and nothing else, so the declaration cannot drift from the
    code: an undeclared read is an error, not a silent dependency."""
    ident = runs.identify(_cfg("+exp=sim_office", *SMALL), "slam")
    view = runs.restricted(ident.settings)
    assert view.slam.num_particles == 30 and view.data.name == "sim_office"
    for read in (lambda: view.mcl, lambda: view.train.lr, lambda: view.mapping.resolution_m):
        with pytest.raises(ConfigAttributeError):
            read()


def test_file_settings_count_by_content_not_by_name(tmp_path):
    """A log moved or renamed is the same input; another log under the same name is another run."""
    log = tmp_path / "a" / "run.bag"
    log.parent.mkdir()
    log.write_bytes(b"first log")
    cfg = lambda p: _cfg("data=bag", f"data.path={p}", "data.far_m=20")  # noqa: E731
    first = runs.identify(cfg(log), "slam")
    moved = tmp_path / "b" / "renamed.bag"
    moved.parent.mkdir()
    shutil.copy(log, moved)
    assert runs.identify(cfg(moved), "slam").id == first.id
    log.write_bytes(b"other log")
    assert runs.identify(cfg(log), "slam").id != first.id


def test_a_run_in_your_own_map_is_another_run_when_its_confidence_calibration_changes(tmp_path, monkeypatch):
    """A localization in your own map judges itself with the calibration shipped for its filter (the worlds stage's
    at its particle count): that file is one of the run's inputs, so a run made with another calibration is not
    reported as this one (a stale run reported finished), and a count without a calibration reads none."""
    import irmcl_warp.config as config

    cal_dir = tmp_path / "calibration"
    cal_dir.mkdir()
    monkeypatch.setattr(config, "CALIBRATION_DIR", cal_dir)
    grid = tmp_path / "map.pgm"
    grid.write_bytes(b"P5 2 2 255\n" + bytes([255, 0, 0, 255]))
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    cfg = _cfg(*SMALL, f"localize.map_path={tmp_path / 'map.yaml'}", "mcl=amcl", "mcl.num_particles=100000")
    (cal_dir / "likelihood_field-100k.json").write_text('{"coef": [1.0]}')
    first = runs.identify(cfg, "localize")
    assert [f["path"] for f in first.inputs[runs.OWN_MAP_CALIBRATION]] == [str(cal_dir / "likelihood_field-100k.json")]
    (cal_dir / "likelihood_field-100k.json").write_text('{"coef": [2.0]}')  # fitted again
    assert runs.identify(cfg, "localize").id != first.id
    fewer = _cfg(*SMALL, f"localize.map_path={tmp_path / 'map.yaml'}", "mcl=amcl", "mcl.num_particles=5000")
    assert runs.OWN_MAP_CALIBRATION not in runs.identify(fewer, "localize").inputs
    # its lost-robot rule reads the worlds stage's settings: that file is an input too, so a rule changed there is
    # another run
    assert [f["path"] for f in first.inputs[runs.OWN_MAP_LOST_RULE]] == [str(config.own_map_lost_rule_file())]
    rule = tmp_path / "worlds.yaml"
    rule.write_text("worlds:\n  lost_after_s: 2.0\n")
    monkeypatch.setattr(config, "own_map_lost_rule_file", lambda: rule)
    monkeypatch.setattr(runs, "own_map_lost_rule_file", lambda: rule)
    moved = runs.identify(cfg, "localize")
    assert moved.id == runs.identify(cfg, "localize").id
    rule.write_text("worlds:\n  lost_after_s: 3.0\n")
    assert runs.identify(cfg, "localize").id != moved.id
    assert runs.OWN_MAP_LOST_RULE not in runs.identify(fewer, "localize").inputs


# --- stages: folders of their own, never overwritten ------------------------------------------------------------


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    """Inspect runs of two drives through the simulated office (sim.path_seed 1 and 2), each writing its bag."""
    root = tmp_path_factory.mktemp("drives")
    cwd = os.getcwd()
    os.chdir(root)
    try:
        a, b = (run_inspect(_cfg(*SMALL, f"sim.path_seed={k}")) for k in (1, 2))
    finally:
        os.chdir(cwd)
    return root, root / a, root / b


def test_path_seeds_bags_and_maps_land_in_folders_of_their_own(drives, monkeypatch):
    root, a, b = drives
    monkeypatch.chdir(root)
    assert a != b and a.parent == b.parent == root / "outputs" / "sim_office" / "inspect"
    assert all(runs.intact(p)[0] for p in (a, b))
    # two bags under the one experiment every bag gets ("bag"): two runs
    bags = [run_inspect(_cfg("data=bag", f"data.path={p / 'sim.bag'}", "device=cpu")) for p in (a, b)]
    assert bags[0] != bags[1] and bags[0].parent == bags[1].parent and all(runs.intact(p)[0] for p in bags)
    # two maps both called map.yaml: two localizations, each in its own folder, both kept
    other = root / "other" / "map.yaml"
    other.parent.mkdir()
    image = (a / "map.pgm").read_bytes()
    (other.parent / "map.pgm").write_bytes(image[:-200] + bytes(200))  # another map under the same names
    other.write_text((a / "map.yaml").read_text())
    loc = [
        run_localize(
            _cfg(
                "data=bag",
                f"data.path={b / 'sim.bag'}",
                f"localize.map_path={m}",
                "device=cpu",
                "mcl.weighting=likelihood_field",
                "mcl.num_particles=300",
                "localize.run_s=4",
            )
        )
        for m in (a / "map.yaml", other)
    ]
    assert loc[0] != loc[1] and all(runs.intact(p)[0] for p in loc)
    images = {json.loads((p / "manifest.json").read_text())["inputs"]["localize.map_path"][1]["sha256"] for p in loc}
    assert len(images) == 2  # each names the image it read


def test_the_jobs_of_a_sweep_get_runs_of_their_own(tmp_path):
    """An untagged Hydra sweep through the joblib launcher: two jobs at once, two runs."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "irmcl_warp.inspect",
            "-m",
            *SMALL,
            "sim.path_seed=3,4",
            "hydra/launcher=joblib",
            "hydra.launcher.n_jobs=2",
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    made = [r for r in runs.records("inspect", root=tmp_path / "outputs")]
    assert sorted(r.setting("sim.path_seed") for r in made) == [3, 4]


def test_two_runs_of_one_identity_started_at_once_leave_one_intact_run(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    args = [sys.executable, "-m", "irmcl_warp.inspect", *SMALL, "sim.path_seed=5"]
    procs = [
        subprocess.Popen(args, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=600) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-1000:] for o in outs]
    stage = tmp_path / "outputs" / "sim_office" / "inspect"
    (folder,) = [p for p in stage.iterdir() if not p.name.startswith(".")]
    assert runs.intact(folder)[0] and not list(stage.glob(".*.partial"))
    assert sum("up to date" in o[0] for o in outs) == 1  # the second waited, then found the first's run


def test_a_redone_run_leaves_no_file_of_the_damaged_one(drives, monkeypatch, capsys):
    root, a, _ = drives
    monkeypatch.chdir(root)
    cfg = _cfg(*SMALL, "sim.path_seed=1")
    assert root / run_inspect(cfg) == a and "up to date" in capsys.readouterr().out
    (a / "stale.txt").write_text("left by hand")
    (a / "summary.json").write_text('{"scans": ')  # damaged: an edit or a crash mid-write
    assert root / run_inspect(cfg) == a and "redoing" in capsys.readouterr().out
    assert runs.intact(a)[0] and not (a / "stale.txt").exists()
    assert json.loads((a / "summary.json").read_text())["scans"] > 0


# --- consuming runs ---------------------------------------------------------------------------------------------


def _field(cfg) -> bytes:
    """A tiny NOF checkpoint (what a finished training leaves as nof.pt)."""
    import io

    mc = ModelConfig(**OmegaConf.to_container(cfg.model))
    buf = io.BytesIO()
    torch.save(
        {
            "model_config": dataclasses.asdict(mc),
            "model": NOF(mc).state_dict(),
            "near_m": 0.02,
            "far_m": 20.0,
            "epoch": 1,
        },
        buf,
    )
    return buf.getvalue()


def test_localize_refuses_an_unfinished_field_and_records_the_one_it_read(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = _cfg(
        "+exp=sim_office",
        *SMALL,
        *TINY_FIELD,
        "mcl.num_particles=200",
        "mcl.num_samples=16",
        "localize.num_starts=1",
        "localize.run_s=3",
    )
    with pytest.raises(RuntimeError, match="killed"):  # a training interrupted after writing its first field
        with runs.start(cfg, "train") as run:
            (run.dir / "nof.pt").write_bytes(_field(cfg))
            raise RuntimeError("killed")
    with pytest.raises(FileNotFoundError, match="interrupted"):
        run_localize(cfg)
    trained = _finish(cfg, "train", runs.OUTPUTS, {"nof.pt": _field(cfg)})
    out = run_localize(cfg)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["upstream"]["train"]["id"] == json.loads((trained / "manifest.json").read_text())["id"]
    assert manifest["device_name"] == runs.device_name(manifest["device"])  # None on the CPU; the card's on a GPU
    assert runs.device_name("cpu") is None


def test_a_changed_validation_trains_a_run_of_its_own(tmp_path, monkeypatch):
    """train.val_scans decides which epoch is kept: another value is another run, validated with its own scans
    (not the old run's checkpoint relabelled)."""
    from irmcl_warp.nof.stage import run_train

    monkeypatch.chdir(tmp_path)
    base = [
        "+exp=sim_office",
        *SMALL,
        *TINY_FIELD,
        "train.epochs=1",
        "train.steps_per_epoch=2",
        "train.batch_rays=64",
        "train.num_samples=16",
        "render.num_samples=16",
    ]
    two, three = (run_train(_cfg(*base, f"train.val_scans={k}")) for k in (2, 3))
    assert two != three
    assert [json.loads((p / "metrics.json").read_text())["val"]["scans"] for p in (two, three)] == [2, 3]


def test_a_damaged_checkpoint_is_an_error_naming_it_and_the_way_out(tmp_path, monkeypatch):
    from irmcl_warp.nof.stage import run_train

    monkeypatch.chdir(tmp_path)
    cfg = _cfg(
        "+exp=sim_office",
        *SMALL,
        *TINY_FIELD,
        "train.epochs=1",
        "train.steps_per_epoch=2",
        "train.batch_rays=64",
        "train.num_samples=16",
        "render.num_samples=16",
        "train.val_scans=2",
    )
    partial = runs.identify(cfg, "train").folder()
    partial = partial.with_name(f".{partial.name}.partial")
    partial.mkdir(parents=True)
    (partial / "last.pt").write_bytes(b"PK\x03\x04 cut short")
    with pytest.raises(ValueError, match=r"last.pt: damaged checkpoint .* delete it"):
        run_train(cfg)


# --- caches and inputs --------------------------------------------------------------------------------------------


def _carmen(ranges_cm: int) -> str:
    lines = []
    for k in range(6):
        t = 100.0 + 0.2 * k
        r = " ".join(f"{ranges_cm / 100 + 0.01 * b:.2f}" for b in range(8))
        p = f"{0.1 * k:.4f} 0.0000 0.0000"
        lines.append(f"FLASER 8 {r} {p} {p} {t:.6f} host {t:.6f}\n")
    return "".join(lines)


def test_a_log_replaced_by_one_of_the_same_size_and_time_is_read_again(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    log = tmp_path / "run.clf"
    log.write_text(_carmen(150))
    cfg = _cfg("data=carmen", f"data.path={log}", "data.far_m=20")
    first = load_stream(cfg)
    stamp = log.stat().st_mtime_ns
    log.write_text(_carmen(250))  # as long, and dated as the first
    os.utime(log, ns=(stamp, stamp))
    second = load_stream(cfg)
    assert first.ranges_m[0, 0] == pytest.approx(1.50) and second.ranges_m[0, 0] == pytest.approx(2.50)


def test_a_logs_defects_are_reported_by_every_run_that_reads_it(tmp_path, monkeypatch):
    """The stream cache keeps what the readers warned about: the second run, served from the cache, warns too."""
    monkeypatch.chdir(tmp_path)
    log = tmp_path / "odd.clf"
    text = _carmen(150).splitlines(keepends=True)
    log.write_text("".join([text[0], text[2], text[1], *text[3:]]))  # two scans out of order
    cfg = _cfg("data=carmen", f"data.path={log}", "data.far_m=20")
    for _ in range(2):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            load_stream(cfg)
        assert any(issubclass(w.category, LogDefectWarning) and "odd.clf" in str(w.message) for w in caught)


def test_a_full_disk_is_one_line_naming_the_file_and_nothing_half_written(tmp_path, monkeypatch, capsys):
    import errno

    import irmcl_warp.io.atomic as atomic
    from irmcl_warp.services.cli import run_entry

    monkeypatch.chdir(tmp_path)
    real = atomic.os.replace

    def full(src, dst):
        if str(dst).endswith("summary.json"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", full)
    with pytest.raises(SystemExit) as stop:
        run_entry(run_inspect, _cfg(*SMALL))
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1 and "no space left" in err[0] and "summary.json" in err[0]
    stage = tmp_path / "outputs" / "sim_office" / "inspect"
    assert not [p for p in stage.iterdir() if not p.name.startswith(".")]  # no finished run
    assert not list(stage.rglob(".summary.json.*"))  # no temporary file left


def test_a_finished_run_reused_by_other_code_is_a_loud_warning(tmp_path, monkeypatch):
    """A run's id is its settings and inputs, not its code: a finished run found by a later commit, or made or
    found with uncommitted changes, is reused with a warning naming both; the same clean commit reuses it quietly.
    A check study's record keeps the commit that made each run."""
    from eval.results.records import keep_check

    cfg = _cfg(*SMALL)
    monkeypatch.setenv("IRMCL_GIT_SHA", "1111111")
    folder = _finish(cfg, "inspect", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning at all
        with runs.start(cfg, "inspect", tmp_path) as run:
            assert run.done
    monkeypatch.setenv("IRMCL_GIT_SHA", "2222222")
    with pytest.warns(UserWarning, match="made by 1111111; this code is 2222222"):
        with runs.start(cfg, "inspect", tmp_path) as run:
            assert run.done and run.path == folder
    monkeypatch.setenv("IRMCL_GIT_SHA", "1111111-dirty")
    other = _finish(_cfg(*SMALL, "sim.path_seed=2"), "inspect", tmp_path)
    with pytest.warns(UserWarning, match="made with uncommitted changes"):
        assert runs.warn_if_other_code(other)
    doc = json.loads(keep_check("study", "sim_office", [(other, "inspect", [], None)], tmp_path).read_text())
    (entry,) = doc["records"].values()
    assert entry["manifest"]["git_sha"] == "1111111-dirty" and entry["manifest"]["device"] == "cpu"


def test_a_run_records_the_commit_it_started_from_and_says_when_the_checkout_moved(tmp_path, monkeypatch):
    """The manifest names the commit the run's code was loaded from, read when the run opens: a commit made while
    it runs is no longer recorded as its code; it is kept beside it (``git_sha_at_finish``) with a warning naming
    both. A run whose checkout did not change gets neither."""
    cfg = _cfg(*SMALL)
    monkeypatch.setenv("IRMCL_GIT_SHA", "aaaa111")
    with runs.start(cfg, "inspect", tmp_path) as run:
        monkeypatch.setenv("IRMCL_GIT_SHA", "bbbb222")  # committed while the run ran
        with pytest.warns(UserWarning, match="aaaa111 at its start, bbbb222 now"):
            folder = run.finish({"made": "by the test"}, "cpu")
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["git_sha"] == "aaaa111" and manifest["git_sha_at_finish"] == "bbbb222"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        other = _finish(_cfg(*SMALL, "sim.path_seed=2"), "inspect", tmp_path)
    manifest = json.loads((other / "manifest.json").read_text())
    assert manifest["git_sha"] == "bbbb222" and "git_sha_at_finish" not in manifest


def test_a_copy_without_its_history_records_the_commit_it_was_made_from(tmp_path, monkeypatch):
    """A lent GPU machine runs a copy of the working tree with a stale history: IRMCL_GIT_SHA (written here by
    eval/gpu/stamp_source.sh) is what a run records; without it, this checkout's own HEAD (and -dirty when tracked
    files differ). The stamp script writes HEAD with the same rule."""
    monkeypatch.delenv("IRMCL_GIT_SHA", raising=False)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=runs.REPO, capture_output=True, text=True).stdout.strip()
    assert runs._git_sha().split("-")[0] == head
    monkeypatch.setenv("IRMCL_GIT_SHA", "0123abc-dirty")
    assert runs._git_sha() == "0123abc-dirty"
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(runs.REPO), str(clone)], check=True)
    subprocess.run(["bash", "eval/gpu/stamp_source.sh"], cwd=clone, check=True, capture_output=True)
    assert (clone / ".gpu/b/source_env.sh").read_text() == f"export IRMCL_GIT_SHA={head}\n"
    (clone / "README.md").write_text("edited\n")
    subprocess.run(["bash", "eval/gpu/stamp_source.sh"], cwd=clone, check=True, capture_output=True)
    assert (clone / ".gpu/b/source_env.sh").read_text() == f"export IRMCL_GIT_SHA={head}-dirty\n"
