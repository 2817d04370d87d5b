"""The reproduction runner and the stages it drives: a finished stage is skipped, a damaged one is redone,
jobs are told apart as done / kept / missing, and the missing ones go to Hydra's launchers."""

import argparse
import json
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from eval.results.records import keep
from eval.reproduce import SWEEPS, Sweep, job_state, multirun_commands
from irmcl_warp import runs
from irmcl_warp.config import register
from runfakes import fake_run

CONF = Path(__file__).resolve().parents[1] / "conf"
SMALL_SIM = ["sim.duration_s=20", "sim.width_m=14", "sim.height_m=10", "device=cpu"]


def _compose(*overrides, name="config", hydra=False):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(name, overrides=list(overrides), return_hydra_config=hydra)


def test_a_finished_stage_is_skipped_and_a_damaged_one_redone(tmp_path, monkeypatch, capsys):
    from irmcl_warp.slam.stage import run_slam

    monkeypatch.chdir(tmp_path)  # outputs/ lands in the temporary folder
    cfg = _compose("+exp=gmapping_sim", "slam.num_particles=3", *SMALL_SIM)
    out = run_slam(cfg)
    traj = out / "trajectory.tum"
    first, stamp = traj.read_text(), traj.stat().st_mtime_ns
    assert runs.intact(out)[0]
    assert run_slam(cfg) == out and "up to date" in capsys.readouterr().out
    assert traj.stat().st_mtime_ns == stamp  # not rewritten
    traj.write_text(first[: len(first) // 2])  # as an interrupted copy or a crash mid-write would leave it
    run_slam(cfg)
    assert "redoing" in capsys.readouterr().out
    assert traj.read_text() == first and runs.intact(out)[0]  # the same run, whole again


def test_runner_tells_done_kept_and_missing_apart(tmp_path):
    """done: a finished run of the job's identity; kept: a record of its settings in results/; a damaged run
    of it is missing (run again)."""
    sweep = Sweep("slam", "irmcl_warp.slam", ["+exp=gmapping_sim"], {"slam.seed": [0, 1, 2, 3]})
    outputs, results = tmp_path / "outputs", tmp_path / "results"
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfgs = [compose("config", overrides=ov) for ov in sweep.jobs()]
        for k in (0, 3):  # finished runs; seed 3's is then damaged
            with runs.start(cfgs[k], "slam", outputs) as run:
                run.finish({"seed": k}, "cpu")
        (runs.identify(cfgs[3], "slam").folder(outputs) / "metrics.json").write_text('{"seed": ')
        kept_cfg = OmegaConf.to_container(cfgs[1], resolve=True)
        kept_cfg["device"] = "cuda:0"  # ran on a GPU; the job asks for device=auto: still the same run
        other = {**kept_cfg, "slam": {**kept_cfg["slam"], "seed": 2, "num_particles": 31}}  # seed 2, but not its job
        (doc,) = keep(
            [fake_run(tmp_path / "gpu", "slam", c, {"seed": c["slam"]["seed"]}) for c in (kept_cfg, other)], results
        )  # kept in the repository (eval.keep)
        kept_doc = json.loads(doc.read_text())
        for rec in kept_doc["records"].values():
            del rec["config"]["sim"]  # a section the stage reads only since these runs: not compared
        doc.write_text(json.dumps(kept_doc))
        states = [job_state(sweep, ov, outputs, results, rerun_kept=False)[0] for ov in sweep.jobs()]
        assert states == ["done", "kept", "missing", "missing"]
        assert job_state(sweep, sweep.jobs()[1], outputs, results, rerun_kept=True)[0] == "missing"
    missing = [ov for ov, s in zip(sweep.jobs(), states) if s == "missing"]
    flags = argparse.Namespace(jobs=3, gpus=2, jobs_per_gpu=4)
    (cmd,) = multirun_commands(sweep, missing, "joblib", flags, ["device=cpu"])
    assert cmd[2:] == [
        "irmcl_warp.slam",
        "-m",
        "+exp=gmapping_sim",
        "slam.seed=2,3",
        "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=3",
        "device=cpu",
    ]
    (cmd,) = multirun_commands(sweep, sweep.jobs(), "basic", flags, [])  # all missing: one multirun, all at once
    assert cmd[2:] == ["irmcl_warp.slam", "-m", "+exp=gmapping_sim", "slam.seed=0,1,2,3"]
    (cmd,) = multirun_commands(sweep, missing, "pool", flags, [])
    assert cmd[-4:] == [
        "hydra/launcher=pool",
        "hydra.launcher.cpu_workers=3",
        "hydra.launcher.gpus=2",
        "hydra.launcher.jobs_per_gpu=4",
    ]


@pytest.mark.parametrize(
    "launcher,target",
    [
        ("joblib", "JoblibLauncher"),
        ("slurm", "SlurmLauncher"),
        ("pool", "PoolLauncher"),
        ("submitit_local", "LocalLauncher"),
    ],
)
def test_launcher_configs_compose(launcher, target):
    cfg = _compose(f"hydra/launcher={launcher}", hydra=True)
    assert cfg.hydra.launcher._target_.endswith(target)


@pytest.mark.data  # the jobs' identities hold the digests of the real logs they read
def test_every_sweep_composes_and_its_jobs_are_runs_of_their_own(rng, data_dir):
    """Two jobs share a run only when they read the same settings (the ablations' base run is also a cell of the
    localization table). Every ablation job and a fresh random sample of the others: jobs with the same
    identity read the same settings, and jobs of different settings have different identities."""
    import json

    jobs = [(s, ov) for s in SWEEPS for ov in s.jobs()]
    others = [j for j in jobs if j[0].group != "ablation"]
    pick = [j for j in jobs if j[0].group == "ablation"] + [
        others[i] for i in rng.choice(len(others), 40, replace=False)
    ]
    seen = {}
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        for sweep, ov in pick:
            cfg = compose("pipeline" if sweep.module == "irmcl_warp.pipeline" else "config", overrides=ov)
            stage = sweep.module.rsplit(".", 1)[1]
            settings = json.dumps(runs.read_settings(cfg, stage), sort_keys=True)
            ident = runs.identify(cfg, stage).id
            first = seen.setdefault(ident, (settings, ov))
            assert first[0] == settings, f"seed {rng.seed}: {ov} and {first[1]} would share a run"
        assert len(seen) > 30
