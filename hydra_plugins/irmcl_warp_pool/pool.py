"""``hydra/launcher=pool``: the jobs of a Hydra multirun as separate processes on this machine.

Where GPUs are seen, each worker slot is pinned to one GPU (``CUDA_VISIBLE_DEVICES=<index>`` in the job's
environment, so the job sees it as ``cuda:0``), ``jobs_per_gpu`` slots per GPU; elsewhere ``cpu_workers``
slots share the cores (each job's torch/OpenMP threads are set to its share). A job is the same command run
alone (``python -m <stage> <its overrides>``), so a job behaves exactly as it does run by hand: its run
folder comes from irmcl_warp.runs, and a job whose run is already finished returns at once.

While the sweep runs, a line reports jobs done / running / failed / waiting. Each job writes
``<sweep dir>/<job number>/job.log``; a job that fails is started again ``retries`` times, and one that
still fails is reported with its log's last lines. Once every job has had its turn, a sweep with failed jobs
ends with exit status 1 and a line naming each of them.
"""

# no `from __future__ import annotations`: Hydra's plugin scan runs this module outside sys.modules, where
# a dataclass cannot resolve string annotations
import logging
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Sequence

from hydra.core.hydra_config import HydraConfig
from hydra.core.utils import JobReturn, JobStatus, filter_overrides
from hydra.plugins.launcher import Launcher
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig, open_dict

log = logging.getLogger(__name__)


def visible_gpus() -> list[str]:
    """The GPUs this process may use, as the indices to give ``CUDA_VISIBLE_DEVICES``."""
    seen = os.environ.get("CUDA_VISIBLE_DEVICES")
    if seen is not None:
        return [g.strip() for g in seen.split(",") if g.strip() and g.strip() != "-1"]
    if shutil.which("nvidia-smi") is None:
        return []
    try:
        out = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return []
    return [str(i) for i, line in enumerate(out.stdout.splitlines()) if line.startswith("GPU ")]


def slots(gpus: Optional[int], jobs_per_gpu: int, cpu_workers: Optional[int]) -> list[dict]:
    """One entry per job that may run at once: the environment it adds (its GPU, its CPU threads)."""
    seen = visible_gpus() if gpus != 0 else []
    if gpus is not None and gpus > len(seen):
        raise ValueError(
            f"hydra.launcher.gpus={gpus}, but this machine shows {len(seen)} GPU(s) (CUDA_VISIBLE_DEVICES / nvidia-smi)"
        )
    if seen:
        use = seen[:gpus] if gpus else seen
        cores = max(1, (os.cpu_count() or 1) // (len(use) * max(1, jobs_per_gpu)))
        return [
            {"CUDA_VISIBLE_DEVICES": g, "OMP_NUM_THREADS": str(cores), "name": f"gpu{g}"}
            for g in use
            for _ in range(max(1, jobs_per_gpu))
        ]
    n = cpu_workers or max(1, (os.cpu_count() or 1) // 2)
    cores = max(1, (os.cpu_count() or 1) // n)
    return [{"CUDA_VISIBLE_DEVICES": "", "OMP_NUM_THREADS": str(cores), "name": f"cpu{i}"} for i in range(n)]


def job_command(task_function: TaskFunction) -> tuple[list[str], dict]:
    """The command that runs the sweep's application alone (``python -m <module>``, or ``python <script>``),
    and the environment it needs to import the same code from any working directory."""
    module = task_function.__module__
    if module == "__main__":
        spec = getattr(sys.modules["__main__"], "__spec__", None)
        if spec is None:  # started as a script file
            return [sys.executable, str(Path(sys.argv[0]).resolve())], {}
        module = spec.name
    top = sys.modules.get(module.split(".")[0])
    env = {}
    if top is not None and getattr(top, "__file__", None):  # the folder holding the package: first on the path
        home = str(Path(top.__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join([home, *filter(None, [os.environ.get("PYTHONPATH")])])
    return [sys.executable, "-m", module], env


@dataclass
class Job:
    num: int
    overrides: list[str]
    folder: Path
    attempts: int = 0
    proc: Any = None
    slot: Optional[int] = None
    started: float = 0.0
    returncode: Optional[int] = None
    out: Any = None  # the open log file
    why: str = ""
    cfg: Any = field(default=None, repr=False)

    @property
    def log(self) -> Path:
        return self.folder / "job.log"


class PoolLauncher(Launcher):
    def __init__(self, **kwargs: Any) -> None:
        self.settings = kwargs
        self.config: Optional[DictConfig] = None
        self.task_function: Optional[TaskFunction] = None
        self.hydra_context: Optional[HydraContext] = None

    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig) -> None:
        self.config, self.task_function, self.hydra_context = config, task_function, hydra_context

    def _job(self, num: int, overrides: Sequence[str]) -> Job:
        """The job's own config (as Hydra would compose it), to name its folder under the sweep dir."""
        cfg = self.hydra_context.config_loader.load_sweep_config(self.config, list(overrides))
        with open_dict(cfg):
            cfg.hydra.job.id = f"{cfg.hydra.job.name}_{num}"
            cfg.hydra.job.num = num
        HydraConfig.instance().set_config(cfg)
        folder = (Path(str(cfg.hydra.sweep.dir)) / str(cfg.hydra.sweep.subdir)).resolve()
        return Job(num, list(overrides), folder, cfg=cfg)

    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int) -> Sequence[JobReturn]:
        s = self.settings
        places = slots(s.get("gpus"), int(s.get("jobs_per_gpu", 1)), s.get("cpu_workers"))
        retries, timeout = int(s.get("retries", 1)), s.get("timeout_min")
        jobs = [self._job(initial_job_idx + i, ov) for i, ov in enumerate(job_overrides)]
        command, env = job_command(self.task_function)
        print(
            f"[pool] {len(jobs)} job(s) on {len(places)} worker(s) "
            f"({', '.join(sorted({p['name'] for p in places}))}); logs under {jobs[0].folder.parent if jobs else '-'}",
            flush=True,
        )
        waiting, running, done, failed = list(jobs), {}, [], []
        free = list(range(len(places)))
        last = ""
        try:
            while waiting or running:
                while waiting and free:
                    job, slot = waiting.pop(0), free.pop(0)
                    self._start(job, slot, {**places[slot], **env}, command)
                    running[job.num] = job
                time.sleep(0.2)
                for job in list(running.values()):
                    rc = job.proc.poll()
                    over = timeout is not None and time.time() - job.started > 60 * float(timeout)
                    if rc is None and not over:
                        continue
                    if rc is None:  # over its time
                        job.proc.kill()
                        job.proc.wait()
                        rc, job.why = -9, f"stopped after {timeout} min (hydra.launcher.timeout_min)"
                    job.out.close()
                    del running[job.num]
                    free.append(job.slot)
                    job.returncode = rc
                    if rc == 0:
                        done.append(job)
                    elif job.attempts <= retries:
                        print(
                            f"[pool] job {job.num} failed (exit {rc}); starting it again "
                            f"({job.attempts + 1} of {retries + 1})",
                            flush=True,
                        )
                        waiting.insert(0, job)
                    else:
                        failed.append(job)
                        self._report(job, int(s.get("tail_lines", 25)))
                line = (
                    f"[pool] {len(done)}/{len(jobs)} done, {len(running)} running, {len(failed)} failed, "
                    f"{len(waiting)} waiting"
                )
                if line != last:
                    print(line, flush=True)
                    last = line
        except BaseException:  # Ctrl-C or an error here: leave no job running behind
            for job in running.values():
                job.proc.kill()
            raise
        summary = "; ".join(f"job {j.num} ({' '.join(j.overrides)}): exit {j.returncode}, log {j.log}" for j in failed)
        if failed:  # every job has had its turn: end the sweep here, with the list (not Hydra's traceback)
            print(f"[pool] {len(failed)} of {len(jobs)} job(s) failed: {summary}", file=sys.stderr, flush=True)
            raise SystemExit(1)
        return [self._result(job) for job in jobs]

    def _start(self, job: Job, slot: int, place: dict, command: list[str]) -> None:
        job.folder.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, **{k: v for k, v in place.items() if k != "name"}}
        env["PYTHONUNBUFFERED"] = "1"
        args = command + job.overrides + [f"hydra.run.dir={job.folder}"]
        out = job.log.open("a" if job.attempts else "w")  # a new sweep's job starts a new log
        out.write(f"# attempt {job.attempts + 1} on {place['name']}: {' '.join(args)}\n")
        out.flush()
        job.proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=os.getcwd())
        job.out, job.slot, job.started, job.attempts, job.why = out, slot, time.time(), job.attempts + 1, ""
        log.info(f"#{job.num} on {place['name']}: {' '.join(filter_overrides(job.overrides))}")

    @staticmethod
    def _report(job: Job, tail: int) -> None:
        lines = job.log.read_text(errors="replace").splitlines()[-tail:]
        print(
            f"[pool] job {job.num} failed after {job.attempts} attempt(s) (exit {job.returncode})"
            f"{': ' + job.why if job.why else ''}\n  overrides: {' '.join(job.overrides)}\n  log: {job.log}\n"
            + "\n".join("    | " + x for x in lines),
            file=sys.stderr,
            flush=True,
        )

    @staticmethod
    def _result(job: Job) -> JobReturn:
        ret = JobReturn(
            overrides=job.overrides,
            cfg=job.cfg,
            working_dir=str(job.folder),
            task_name=str(job.cfg.hydra.job.name),
            status=JobStatus.COMPLETED,
        )
        ret.return_value = 0
        return ret
