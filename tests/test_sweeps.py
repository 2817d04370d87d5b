"""Sweeps through the launchers a user picks with one Hydra override: the project's local pool (a process per
job, one per GPU where there are GPUs) and submitit's local executor (the path a SLURM cluster takes), each
leaving one run record per job that the tables read."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from eval.report.tables import pipeline_table
from hydra_plugins.irmcl_warp_pool.pool import slots
from irmcl_warp import runs

REPO = Path(__file__).resolve().parents[1]
SMALL_SIM = ["sim.duration_s=20", "sim.width_m=14", "sim.height_m=10", "device=cpu"]


def test_pool_slots_pin_one_gpu_per_worker(monkeypatch):
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "3,5")
    two = slots(None, 2, None)
    assert [s["CUDA_VISIBLE_DEVICES"] for s in two] == ["3", "3", "5", "5"]  # each job sees one GPU, as cuda:0
    assert [s["CUDA_VISIBLE_DEVICES"] for s in slots(1, 1, None)] == ["3"]
    with pytest.raises(ValueError, match="gpus=3, but this machine shows 2"):
        slots(3, 1, None)
    cpu = slots(0, 1, 3)  # gpus=0: CPU workers even where there are GPUs
    assert len(cpu) == 3 and all(s["CUDA_VISIBLE_DEVICES"] == "" for s in cpu)


def test_a_pool_sweep_reports_a_failed_job_with_its_log_and_a_rerun_runs_only_what_is_missing(tmp_path):
    """Two jobs on two CPU workers: the simulator's runs, and a log that is not there (fails, is retried once,
    then reported with its log's last lines). The other job's run is whole; the sweep ends with an error."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "IRMCL_DATA": str(tmp_path / "no-data")}
    cmd = [
        sys.executable,
        "-m",
        "irmcl_warp.inspect",
        "-m",
        *SMALL_SIM,
        "+exp=sim_office,fr079",
        "hydra/launcher=pool",
        "hydra.launcher.cpu_workers=2",
        "hydra.sweep.dir=sweep",
    ]
    done = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    said = done.stdout + done.stderr
    assert done.returncode == 1 and "Traceback" not in said, said[-3000:]
    assert "[pool] 2 job(s) on 2 worker(s)" in said and "starting it again (2 of 2)" in said
    assert "1 of 2 job(s) failed" in said and "+exp=fr079" in said
    (log,) = [p for p in (tmp_path / "sweep").glob("*/job.log") if "fr079" in p.read_text()]
    assert str(log) in said and log.read_text().count("# attempt") == 2
    assert "fr079.revfix.clf.gz not found" in log.read_text() and "| error: kuemmerle2009" in done.stderr
    (made,) = runs.records("inspect", root=tmp_path / "outputs")
    assert made.exp == "sim_office" and runs.intact(made.path)[0]
    # the same sweep again: the simulator's job finds its run finished
    again = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    logs = {p.parent.name: p.read_text() for p in (tmp_path / "sweep").glob("*/job.log")}
    assert any("up to date" in t for t in logs.values()), logs
    assert again.returncode != 0 and len(runs.records("inspect", root=tmp_path / "outputs")) == 1


@pytest.mark.slow
def test_a_submitit_local_sweep_of_four_simulator_jobs_leaves_four_records_and_their_table(tmp_path):
    """The pipeline over four second drives of one simulated office through submitit's local executor: the
    four jobs share one SLAM run and one NOF (the first job makes them, the others wait for it and reuse
    them), each leaves a pipeline record, and the pipeline table is generated from those records."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    tiny = [
        "sim.duration_s=30",
        "sim.width_m=14",
        "sim.height_m=10",
        "device=cpu",
        "slam.num_particles=4",
        "train.max_time_s=5",
        "train.val_scans=4",
        "train.steps_per_epoch=20",
        "mcl.num_particles=1000",
        "mcl.reduce_to=300",
        "mcl.num_samples=32",
        "pipeline.run_s=8",
    ]
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "irmcl_warp.pipeline",
            "-m",
            *tiny,
            "pipeline.sim_path_seed=1,2,3,4",
            "hydra/launcher=submitit_local",
            "hydra.launcher.timeout_min=20",
            "hydra.sweep.dir=sweep",
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=1500,
    )
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    made = runs.records("pipeline", root=tmp_path / "outputs")
    assert sorted(r.setting("pipeline.sim_path_seed") for r in made) == [1, 2, 3, 4]
    assert all(runs.intact(r.path)[0] for r in made)
    assert len(runs.records("slam", root=tmp_path / "outputs")) == 1  # one map for the four drives
    assert len(runs.records("train", root=tmp_path / "outputs")) == 1
    assert list((tmp_path / "sweep" / ".submitit").iterdir())  # the jobs went through submitit
    table = pipeline_table(made).splitlines()
    rows = [r for r in table if r.startswith("| pipeline_sim_office (path seed")]
    assert [r.split("(path seed ")[1].split(")")[0] for r in rows] == ["1", "2", "3", "4"]
    (summary,) = [r for r in table if "median of 4 second drives" in r]
    assert "succeeded" in summary


def test_reproduce_runs_the_missing_jobs_of_a_sweep_in_its_workdir_and_then_finds_them_done(
    tmp_path, monkeypatch, capsys
):
    """eval.reproduce's runner on a sweep of two simulator jobs through the pool launcher, in a working folder
    outside the repository (the jobs import the repository's code from there): two runs; the same sweep again
    runs nothing."""
    import argparse

    from hydra import initialize_config_dir

    from eval.reproduce import Sweep, run_sweep
    from irmcl_warp.config import register

    monkeypatch.delenv("PYTHONPATH", raising=False)
    sweep = Sweep("test", "irmcl_warp.inspect", ["+exp=sim_office", *SMALL_SIM], {"sim.path_seed": [7, 8]})
    flags = argparse.Namespace(
        list=False, rerun_kept=False, launcher="pool", jobs=2, gpus=None, jobs_per_gpu=1, hydra_arg=[]
    )
    register()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        first = run_sweep(sweep, flags, tmp_path / "outputs", tmp_path / "results")
        assert first["missing"] == 2 and first["failed_commands"] == 0
        assert sorted(r.setting("sim.path_seed") for r in runs.records("inspect", root=tmp_path / "outputs")) == [7, 8]
        again = run_sweep(sweep, flags, tmp_path / "outputs", tmp_path / "results")
    assert again["done"] == 2 and again["jobs_run"] == 0 and again["wall_s"] < 1
    assert "2 done, 0 kept (results/), 0 to run" in capsys.readouterr().out


def test_the_sweeps_bench_takes_medians_over_whole_repeats_and_compares_like_with_like():
    """eval.bench sweeps: a repeat that found runs done (or failed) is left out; the speedup is against one GPU
    with the same jobs per GPU."""
    from eval.bench.sweeps import layouts, table

    def report(gpus, per, wall, done=0, failed=0):
        return {
            "gpus": gpus,
            "jobs_per_gpu": per,
            "wall_s": wall,
            "failed_commands": failed,
            "sweeps": [
                {"module": "irmcl_warp.slam", "fixed": ["+exp=x"], "jobs_run": 20 - done, "done": done, "kept": 0}
            ],
        }

    groups = layouts(
        [
            report(1, 8, 60.0),
            report(1, 8, 64.0),
            report(1, 8, 62.0),
            report(2, 8, 40.0),
            report(2, 8, 30.0, done=5),
            report(2, 8, 20.0, failed=1),
            report(2, 4, 50.0),
        ]
    )
    assert groups[("slam +exp=x", 20, 2, 8)] == [40.0] and ("slam +exp=x", 20, 2, 4) in groups
    text, rows = table(groups)
    (two,) = [r for r in rows if (r["gpus"], r["jobs_per_gpu"]) == (2, 8)]
    assert two["speedup_vs_1gpu_same_jobs_per_gpu"] == 62.0 / 40.0
    (four,) = [r for r in rows if r["jobs_per_gpu"] == 4]
    assert four["speedup_vs_1gpu_same_jobs_per_gpu"] is None  # no one-GPU run with 4 jobs per GPU
    assert "| slam +exp=x | 20 | 1 x 8 | 3 | 62 [60-64] | - |" in text and "1.55x" in text
