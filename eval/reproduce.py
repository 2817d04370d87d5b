"""``python -m eval.reproduce``: run every paper experiment that has no finished output, then regenerate every
table and figure (``eval.tables --write``, ``eval.plots``).

Each experiment below is a Hydra sweep of one stage. A job counts as done when its output folder is a
finished run of its identity (irmcl_warp.runs: the settings it reads, its inputs' content) or when
a GPU run of it is kept in ``results/`` (pass ``--rerun-kept`` to run those too). A half-written or edited
folder is not done: it is run again. The remaining jobs of a sweep go to Hydra in one multirun through
the launcher you pick:

  --launcher pool            (default) local processes, one job per GPU slot on a GPU host (--gpus N,
                             --jobs-per-gpu K; CUDA_VISIBLE_DEVICES set per job), --jobs N CPU workers
                             elsewhere; progress, a log per job, a failed job retried once, then reported
                             (hydra_plugins/irmcl_warp_pool)
  --launcher slurm           a SLURM cluster (hydra-submitit-launcher, ``pip install -e .[cluster]``; set the
                             partition etc. in conf/hydra/launcher/slurm.yaml or with ``--hydra-arg``). The
                             repository, outputs/ and IRMCL_DATA must be on a filesystem the nodes share: each
                             job writes its run under outputs/ and the next call of this command looks there.
  --launcher submitit_local  submitit's local executor (what CI runs, to keep the submitit path honest)
  --launcher joblib | basic  hydra-joblib-launcher (--jobs N at a time) | one job after the other

  python -m eval.reproduce --list                 every job and whether it is done, kept or missing
  python -m eval.reproduce --only slam globloc    these groups only
  python -m eval.reproduce --tables-only          only the tables and figures

Groups marked GPU are sized for the paper (100k particles, the authors' training recipe): on a CPU they
take days. The commands of every kept figure are in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import itertools
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from hydra import compose, initialize_config_dir

from eval.results.records import OUTPUTS
from eval.results.records import kept as kept_records
from irmcl_warp import runs
from irmcl_warp.config import register
from irmcl_warp.io.atomic import atomic_write_json
from irmcl_warp.services.cli import guard

REPO = Path(__file__).resolve().parents[1]
STAGE = {
    "irmcl_warp.train": "train",
    "irmcl_warp.synthesis": "synthesis",
    "irmcl_warp.localize": "localize",
    "irmcl_warp.slam": "slam",
    "irmcl_warp.globloc": "globloc",
    "irmcl_warp.pipeline": "pipeline",
    "irmcl_warp.inspect": "inspect",
    "irmcl_warp.relations": "relations",
}  # module -> stage


@dataclass
class Sweep:
    group: str  # what --only selects
    module: str
    fixed: list[str]
    axes: dict[str, list] = field(default_factory=dict)  # swept overrides: their Cartesian product
    gpu: bool = False

    def describe(self) -> str:
        """What ``--match`` looks in: the stage's module, the fixed overrides, the swept keys."""
        return " ".join([self.module, *self.fixed, *self.axes])

    def jobs(self) -> list[list[str]]:
        keys = list(self.axes)
        return [
            self.fixed + [f"{k}={v}" for k, v in zip(keys, values)]
            for values in itertools.product(*(self.axes[k] for k in keys))
        ]


SEEDS = list(range(10))
NOF = [
    ("fr079", "paper"),
    ("intel", "paper"),
    ("mit_csail", "fast"),
    ("fr079", "fast"),
    ("fr079", "fast128"),
    ("fr079", "cpu"),
    ("fr079_block", "fast"),
]
MCL_EXPS = [("sim_office", "quick"), ("fr079", "paper"), ("intel", "paper"), ("mit_csail", "fast")]
WEIGHTINGS = ["nog_raymarch", "likelihood_field", "beam_model"]
ABLATIONS = {  # the first value is IR-MCL's (the base run); 1000 beams = every beam of the scan
    "mcl.map_resolution_m": [0.05, 0.025, 0.1],
    "mcl.num_beams": [32, 16, 64, 1000],
    "mcl.t_min": [0.001, 0.0],
    "mcl.empty_below": [0.0, 0.01],
    "mcl.weighting": ["nog_raymarch", "likelihood_field", "beam_model"],
    "mcl.resample": ["low_variance", "multinomial"],
}
GLOBLOC = ["globloc_corridor", "globloc_corridor_kidnap", "globloc_corridor_8m", "globloc_corridor_8m_kidnap"]
SWEEPS = (
    # IR-MCL Table I: scan synthesis of the NOF against occupancy grids
    [Sweep("nof", "irmcl_warp.train", [f"+exp={e}", f"train={p}"], gpu=p != "cpu") for e, p in NOF]
    + [Sweep("nof", "irmcl_warp.synthesis", [f"+exp={e}", f"train={p}"], gpu=p != "cpu") for e, p in NOF]
    # IR-MCL Tables II-III: global localization (100k particles) and pose tracking (10k), 5 and 10 cm maps
    + [
        Sweep(
            "mcl",
            "irmcl_warp.localize",
            [f"+exp={e}", f"train={p}", f"localize.mode={mode}", f"mcl.num_particles={n}"],
            {"mcl.weighting": WEIGHTINGS, "mcl.map_resolution_m": [0.05, 0.1]},
            gpu=True,
        )
        for e, p in MCL_EXPS
        for mode, n in (("global", 100000), ("tracking", 10000))
    ]
    + [
        Sweep(
            "mcl",
            "irmcl_warp.localize",
            [
                f"+exp={e}",
                f"train={p}",
                "localize.mode=tracking",
                "mcl.num_particles=10000",
                "localize.kidnap_at_s=30",
                "mcl.recovery_alpha_slow=0.01",
                "mcl.recovery_alpha_fast=0.2",
            ],
            {"mcl.weighting": WEIGHTINGS[:2]},
            gpu=True,
        )
        for e, p in MCL_EXPS[:2]
    ]
    # GMapping: relations error of both proposals, 30 particles, 10 seeds; particles vs success on intel
    + [
        Sweep(
            "slam",
            "irmcl_warp.slam",
            [f"+exp={e}"],
            {"slam.proposal": ["paper", "gmapping_code"], "slam.seed": SEEDS},
            gpu=True,
        )
        for e in ("gmapping_intel", "gmapping_fr079", "gmapping_mit_csail")
    ]
    + [
        Sweep(
            "slam",
            "irmcl_warp.slam",
            ["+exp=gmapping_intel"] + extra,
            {"slam.num_particles": n, "slam.seed": SEEDS},
            gpu=True,
        )
        for extra, n in (
            ([], [5, 10, 15, 60]),
            (["slam.resample=always"], [5, 10, 15, 30, 60]),
            (["slam.proposal=odometry"], [5, 10, 15, 30, 60]),
        )
    ]
    + [
        Sweep(
            "slam",
            "irmcl_warp.slam",
            ["+exp=gmapping_mit_killian", "slam.num_particles=30"],
            {"slam.seed": SEEDS[:5]},
            gpu=True,
        ),
        Sweep(
            "slam",
            "irmcl_warp.slam",
            ["+exp=gmapping_mit_killian", "slam.num_particles=60"],
            {"slam.proposal": ["paper", "gmapping_code"], "slam.seed": SEEDS},
            gpu=True,
        ),
    ]
    # lidar + camera global localization: the four corridor scenarios, and the paper's one-frame trigger
    + [Sweep("globloc", "irmcl_warp.globloc", [f"+exp={e}"]) for e in GLOBLOC]
    + [
        Sweep(
            "globloc",
            "irmcl_warp.globloc",
            [
                f"+exp={e}",
                "globloc.trigger_confirm_frames=1",
                "globloc.methods=[paper]",
                f"globloc.scenario={'kidnap' if 'kidnap' in e else 'random_starts'}_confirm1",
            ],
        )
        for e in GLOBLOC
    ]
    # ablations, one setting at a time around IR-MCL's global localization by the paper's march (100k particles, NOG
    # 5 cm, 32 beams; the package's default weighting is the march's range table since the thirty-fourth session)
    + [
        Sweep(
            "ablation",
            "irmcl_warp.localize",
            [f"+exp={e}", f"train={p}", "localize.mode=global", "mcl.num_particles=100000"]
            + ([] if key == "mcl.weighting" else ["mcl.weighting=nog_raymarch"]),
            {key: values},
            gpu=True,
        )
        for e, p in MCL_EXPS[1:]
        for key, values in ABLATIONS.items()
    ]
    + [
        Sweep("ablation", module, ["+exp=fr079", "train=fast"], {"render": ["warp", "torch_ref"]}, gpu=True)
        for module in ("irmcl_warp.train", "irmcl_warp.synthesis")
    ]
    # the end-to-end pipeline on the simulator and on the fr079 bag
    + [
        Sweep("pipeline", "irmcl_warp.pipeline", [], {"pipeline.sim_path_seed": list(range(1, 11))}),
        Sweep(
            "pipeline",
            "irmcl_warp.pipeline",
            [
                "+exp=pipeline_fr079",
                "train=fast",
                "slam.num_particles=30",
                "mcl.num_particles=100000",
                "mcl.num_samples=256",
                "pipeline.run_s=null",
            ],
            gpu=True,
        ),
    ]
)


def compose_job(module: str, overrides: list[str]):
    """The config a job runs with (call inside ``initialize_config_dir``, as ``main`` does)."""
    return compose("pipeline" if module == "irmcl_warp.pipeline" else "config", overrides=overrides)


def job_state(sweep: Sweep, overrides: list[str], outputs: Path, results: Path, rerun_kept: bool) -> tuple[str, str]:
    """("done" | "kept" | "missing", where or why): done when a finished run of the job's identity is under
    ``outputs`` (irmcl_warp.runs: its settings and its inputs' content), kept when a record of the same
    settings is kept in ``results``."""
    from omegaconf import OmegaConf

    cfg = compose_job(sweep.module, overrides)
    stage = STAGE[sweep.module]
    try:
        ident = runs.identify(cfg, stage)
        folder = runs.finished(ident, outputs)
        if folder is not None:
            return "done", str(folder)
        why = f"no finished run at {ident.folder(outputs)}"
    except FileNotFoundError as e:  # an upstream run this job consumes is not there yet
        why = str(e)
    if not rerun_kept:
        job = _flat(runs.settings_by_stage(OmegaConf.to_container(cfg, resolve=True), stage))
        for rec, recorded in _kept(results):
            if rec.stage == stage and rec.exp == cfg.exp and same_settings(job, recorded):
                return "kept", f"{results}/{rec.exp} [{rec.stage}/{rec.label}]"
    return "missing", why


def same_settings(job: dict, recorded: dict) -> bool:
    """Whether a kept record ran the job (both as flat {"section.key": value}): every setting it recorded
    equals the job's, where it ran aside (``device``: kept runs are mostly GPU runs; the job asks for
    ``auto``). Keys a kept record lacks within its sections read at their schema default
    (eval.results.records.complete); a section it lacks entirely was read by the stage only later, and is
    not compared."""
    return all(job.get(k, _NONE) == v for k, v in recorded.items() if k.rsplit(".", 1)[-1] != "device")


_NONE = object()


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


_KEPT: dict = {}


def _kept(results: Path) -> list[tuple]:
    """The kept records under ``results``, each with its settings as ``same_settings`` compares them."""
    if results not in _KEPT:
        _KEPT[results] = [
            (rec, _flat(runs.settings_by_stage(rec.config, rec.stage))) for rec in kept_records(results=results)
        ]
    return _KEPT[results]


LAUNCHER_ARGS = {  # this command's flags as each launcher's settings
    "pool": lambda a: (
        ([f"hydra.launcher.cpu_workers={a.jobs}"] if a.jobs else [])
        + ([f"hydra.launcher.gpus={a.gpus}"] if a.gpus is not None else [])
        + [f"hydra.launcher.jobs_per_gpu={a.jobs_per_gpu}"]
    ),
    "joblib": lambda a: [f"hydra.launcher.n_jobs={a.jobs or 2}"],
}


def multirun_commands(sweep: Sweep, missing: list[list[str]], launcher: str, a, extra: list[str]) -> list[list[str]]:
    """The Hydra multiruns that run the missing jobs: one for the whole sweep when every job is missing (so
    that a launcher sees all of them at once), else one per set of jobs that differ only in their last
    override (seeds, mostly)."""
    launch = [] if launcher == "basic" else [f"hydra/launcher={launcher}"]
    launch += LAUNCHER_ARGS.get(launcher, lambda a: [])(a)
    if sweep.axes and len(missing) == len(sweep.jobs()):
        swept = [f"{k}={','.join(str(v) for v in values)}" for k, values in sweep.axes.items()]
        return [[sys.executable, "-m", sweep.module, "-m", *sweep.fixed, *swept, *launch, *extra]]
    groups: dict[tuple, list[str]] = {}
    for ov in missing:
        key, last = (tuple(ov[:-1]), ov[-1]) if len(ov) > len(sweep.fixed) else (tuple(ov), None)
        groups.setdefault(key, [])
        if last is not None:
            groups[key].append(last)
    cmds = []
    for key, lasts in groups.items():
        swept = [f"{lasts[0].split('=')[0]}={','.join(x.split('=', 1)[1] for x in lasts)}"] if lasts else []
        cmds.append([sys.executable, "-m", sweep.module, "-m", *key, *swept, *launch, *extra])
    return cmds


def run_sweep(sweep: Sweep, a, outputs: Path, results: Path) -> dict:
    """Report the sweep's jobs; unless listing, run the missing ones. Returns what ran: jobs, failed commands,
    wall time."""
    states = [(ov, *job_state(sweep, ov, outputs, results, a.rerun_kept)) for ov in sweep.jobs()]
    missing = [ov for ov, state, _ in states if state == "missing"]
    counts = {s: sum(1 for _, st, _ in states if st == s) for s in ("done", "kept", "missing")}
    print(
        f"[{sweep.group}] {sweep.module} {' '.join(sweep.fixed)}: {counts['done']} done, {counts['kept']} kept "
        f"(results/), {counts['missing']} to run" + ("  [sized for a GPU]" if sweep.gpu and missing else "")
    )
    ran = {
        "group": sweep.group,
        "module": sweep.module,
        "fixed": sweep.fixed,
        "jobs_run": len(missing),
        **counts,
        "failed_commands": 0,
        "wall_s": 0.0,
    }
    if a.list:
        for ov, state, where in states:
            print(f"    {state:8s} {' '.join(ov[len(sweep.fixed) :]) or '-':50s} {where}")
        return ran
    t0 = time.perf_counter()
    # the jobs run in --workdir and import this repository's code from there
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])}
    for cmd in multirun_commands(sweep, missing, a.launcher, a, a.hydra_arg):
        print("  $ " + " ".join(cmd[1:]), flush=True)
        ran["failed_commands"] += subprocess.run(cmd, cwd=outputs.parent, env=env).returncode != 0
    ran["wall_s"] = time.perf_counter() - t0
    return ran


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m eval.reproduce", description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="+", help="groups to run: nof mcl slam globloc pipeline")
    ap.add_argument(
        "--match",
        help="only the sweeps whose stage, fixed overrides or swept keys contain this, "
        "e.g. +exp=fr079 or pipeline.sim_path_seed",
    )
    ap.add_argument("--list", action="store_true", help="show every job and its state; run nothing")
    ap.add_argument("--no-tables", action="store_true", help="run the experiments, leave tables and figures")
    ap.add_argument("--tables-only", action="store_true", help="only regenerate tables and figures")
    ap.add_argument("--launcher", default="pool", choices=["pool", "slurm", "submitit_local", "joblib", "basic"])
    ap.add_argument(
        "--jobs", type=int, help="local jobs at once without a GPU (pool: default half the cores; joblib: 2)"
    )
    ap.add_argument("--gpus", type=int, help="pool: GPUs to use (default every visible one; 0: CPU workers)")
    ap.add_argument("--jobs-per-gpu", type=int, default=1, help="pool: jobs sharing one GPU at once")
    ap.add_argument("--report", help="write what ran (per sweep: jobs run, failed, wall time) to this JSON file")
    ap.add_argument("--rerun-kept", action="store_true", help="also run jobs whose GPU results are kept in results/")
    ap.add_argument("--hydra-arg", action="append", default=[], help="extra override for every job, e.g. device=cpu")
    ap.add_argument("--workdir", default=str(REPO), help="where the jobs run: their runs land in its outputs/")
    ap.add_argument("--results", default=str(REPO / "results"))
    a = ap.parse_args(argv)
    outputs, results = Path(a.workdir).resolve() / "outputs", Path(a.results)
    register()
    sweeps = [
        s
        for s in SWEEPS
        if not a.tables_only and (not a.only or s.group in a.only) and (not a.match or a.match in s.describe())
    ]
    t0 = time.perf_counter()
    ran = []
    # composing only in this process: the jobs run in their own (in --workdir, so their runs land in its
    # outputs/). A job shared by several sweeps (the ablations' base run) is found done by the later ones.
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        for sweep in sweeps:
            ran.append(run_sweep(sweep, a, outputs, results))
    failed = sum(r["failed_commands"] for r in ran)
    tables_s = None
    if not a.list and not a.no_tables and outputs != OUTPUTS.resolve():
        print(
            f"tables and figures left: they read {OUTPUTS} and results/, and these runs are in {outputs} "
            f"(python -m eval.keep <run folders> keeps them in results/)"
        )
    elif not a.list and not a.no_tables:
        t1 = time.perf_counter()
        failed += subprocess.run([sys.executable, "-m", "eval.tables", "--write"], cwd=REPO).returncode != 0
        failed += subprocess.run([sys.executable, "-m", "eval.plots"], cwd=REPO).returncode != 0
        tables_s = time.perf_counter() - t1
    wall = time.perf_counter() - t0
    if not a.list:
        print(
            f"reproduce: {len(ran)} sweep(s), {sum(r['jobs_run'] for r in ran)} job(s) run, {failed} command(s) "
            f"failed, {wall:.0f} s wall" + (f" ({tables_s:.0f} s of it tables and figures)" if tables_s else "")
        )
    if a.report:
        doc = {
            "argv": sys.argv[1:] if argv is None else list(argv),
            "launcher": a.launcher,
            "gpus": a.gpus,
            "jobs_per_gpu": a.jobs_per_gpu,
            "host_cores": os.cpu_count(),
            "gpu_names": gpu_names(),
            "sweeps": ran,
            "tables_s": tables_s,
            "wall_s": wall,
            "failed_commands": failed,
        }
        atomic_write_json(Path(a.report), doc)
    if failed:
        print(f"{failed} command(s) failed: see their output above", file=sys.stderr)
    return 1 if failed else 0


def gpu_names() -> list[str]:
    """The GPUs the jobs may use, by name (nvidia-smi), for the report."""
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True, text=True, timeout=30
        )
    except (OSError, subprocess.SubprocessError):
        return []
    return [x.strip() for x in out.stdout.splitlines() if x.strip()]


if __name__ == "__main__":
    raise SystemExit(guard(main))
