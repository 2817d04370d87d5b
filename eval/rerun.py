"""``python -m eval.rerun [--exp gmapping_fr079 ...] > jobs.txt``: the Hydra overrides that make every kept SLAM
run again, one line per run, for a sweep after the code changed (``bash eval/gpu/slam_sweep.sh kept``).
``python -m eval.rerun --compare <outputs>``: whether the runs made again (``<outputs>/<exp>/<run>/metrics.json``,
e.g. a sweep's unpacked archive) give their kept runs' errors to the last digit; exits 1 where one does not.

A kept run records the config sections it ran with (``results/slam/<exp>.json``, eval.keep). Its line is
``+exp=<exp>`` and every slam setting and data field that differs from what that experiment composes to, so
the new run lands in a folder of the same name (checked here: a line whose folder name differs is an error,
not a silent new variant).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from omegaconf import OmegaConf

from eval.keep import load_kept
from irmcl_warp.config import compose_config
from irmcl_warp.services.cli import guard
from irmcl_warp.slam.stage import run_tag

REPO = Path(__file__).resolve().parents[1]


def hydra_value(v) -> str:
    """A value as a Hydra override writes it: null, true/false, [a,b,c], or the number / string."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(hydra_value(x) for x in v) + "]"
    return repr(v) if isinstance(v, float) else str(v)


def overrides(exp: str, config: dict, base=None) -> list[str]:
    """The overrides that turn ``+exp=<exp>`` into the kept run's ``config`` (its slam and data sections)."""
    base = base if base is not None else compose_config([f"+exp={exp}"])
    out = [f"+exp={exp}"]
    for section in ("slam", "data"):
        have = OmegaConf.to_container(base[section])
        for key, value in config.get(section, {}).items():
            if have.get(key) != value:
                out.append(f"{section}.{key}={hydra_value(value)}")
    return out


def kept_jobs(exps=None, results: Path = REPO / "results" / "slam") -> list[list[str]]:
    """One override list per kept run of ``exps`` (every experiment kept when None), in a stable order."""
    jobs = []
    for exp in sorted({f.name.split(".")[0] for f in results.glob("gmapping_*.json")}):  # <exp>[.<k>].json
        if exps and exp not in exps:
            continue
        base = compose_config([f"+exp={exp}"])
        for folder, run in sorted(load_kept(results, exp)["runs"].items()):
            line = overrides(exp, run["config"], base)
            cfg = compose_config(line)
            if run_tag(cfg.slam, cfg.data) != folder:
                raise ValueError(f"{results / exp}.json: kept run {folder} would run again as {run_tag(cfg.slam, cfg.data)} with {line}")
            jobs.append(line)
    return jobs


POSE_METRICS = ("relations", "trajectory")  # the parts of metrics.json that follow from the poses alone


def compare(outputs: Path, results: Path = REPO / "results" / "slam") -> tuple[list[str], list[str], list[str]]:
    """The runs under ``outputs`` (<exp>/<run>/metrics.json) against their kept metrics: the names of those whose
    relations and trajectory errors are the kept ones to the last digit, of those that differ, and of those not
    kept."""
    same, differ, not_kept, kept = [], [], [], {}
    for path in sorted(Path(outputs).glob("*/*/metrics.json")):
        exp, run = path.parent.parent.name, path.parent.name
        if exp not in kept:
            kept[exp] = (load_kept(results, exp) or {"runs": {}})["runs"]
        name, old = f"{exp}/{run}", kept[exp].get(run)
        if old is None:
            not_kept.append(name)
            continue
        new = json.loads(path.read_text())
        (same if all(new.get(k) == old["metrics"].get(k) for k in POSE_METRICS) else differ).append(name)
    return same, differ, not_kept


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m eval.rerun")
    ap.add_argument("--exp", nargs="+", help="only these experiments (e.g. gmapping_fr079)")
    ap.add_argument("--compare", metavar="OUTPUTS", help="check runs made again under OUTPUTS against the kept ones")
    a = ap.parse_args(argv)
    if a.compare:
        same, differ, not_kept = compare(Path(a.compare))
        print(f"{len(same)} of {len(same) + len(differ)} runs give their kept runs' relations and trajectory errors to "
              f"the last digit" + (f"; {len(not_kept)} not kept: {', '.join(not_kept)}" if not_kept else ""))
        for name in differ:
            print(f"differs: {name}")
        return 1 if differ or not (same or differ) else 0
    for line in kept_jobs(a.exp):
        print(" ".join(line))
    return 0


if __name__ == "__main__":
    raise SystemExit(guard(main))
