"""``python -m eval.analyses.rerun [--exp gmapping_fr079 ...] > jobs.txt``: the Hydra overrides that make every kept SLAM
run again, one line per run, for a sweep after the code changed (``bash eval/gpu/slam_sweep.sh kept``).
``python -m eval.analyses.rerun --compare <outputs>``: whether the runs made again (the finished SLAM runs under
``<outputs>``, e.g. a sweep's unpacked archive) give their kept records' errors to the last digit; exits 1 where
one does not.

A kept record holds the settings its run read (``results/slam/<exp>.json``, eval.keep). Its line is
``+exp=<exp>`` and every slam setting and data field that differs from what that experiment composes to, so
the new run has the same settings (checked here: a line that composes to other settings is an error, not a
silent new variant); a run made again is matched to its kept record by those settings.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from omegaconf import OmegaConf

from eval.results.records import kept, yours
from irmcl_warp import runs
from irmcl_warp.config import compose_config
from irmcl_warp.services.cli import guard

REPO = Path(__file__).resolve().parents[2]


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


def kept_jobs(exps=None, results: Path = REPO / "results") -> list[list[str]]:
    """One override list per kept SLAM record of ``exps`` (every experiment kept when None), in a stable order."""
    jobs, bases = [], {}
    for rec in sorted(kept(("slam",), results), key=lambda r: (r.exp, r.label)):
        if exps and rec.exp not in exps:
            continue
        if rec.exp not in bases:
            bases[rec.exp] = compose_config([f"+exp={rec.exp}"])
        line = overrides(rec.exp, rec.config, bases[rec.exp])
        cfg = OmegaConf.to_container(compose_config(line), resolve=True)
        if runs.settings_id(cfg, "slam") != rec.settings_id:
            raise ValueError(
                f"{results}/slam/{rec.exp}.json: kept record {rec.label} would run again with other "
                f"settings with {line}"
            )
        jobs.append(line)
    return jobs


POSE_METRICS = ("relations", "trajectory")  # the parts of metrics.json that follow from the poses alone


def compare(outputs: Path, results: Path = REPO / "results") -> tuple[list[str], list[str], list[str]]:
    """The finished SLAM runs under ``outputs`` against the kept records of the same settings: the names of those
    whose relations and trajectory errors are the kept ones to the last digit, of those that differ, and of those
    not kept."""
    same, differ, not_kept = [], [], []
    by_settings = {(r.exp, r.settings_id): r for r in kept(("slam",), results)}
    for rec in yours(("slam",), Path(outputs)):
        name, old = f"{rec.exp}/{rec.label}", by_settings.get((rec.exp, rec.settings_id))
        if old is None:
            not_kept.append(name)
            continue
        (same if all(rec.get(k) == old.get(k) for k in POSE_METRICS) else differ).append(name)
    return same, differ, not_kept


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m eval.analyses.rerun")
    ap.add_argument("--exp", nargs="+", help="only these experiments (e.g. gmapping_fr079)")
    ap.add_argument("--compare", metavar="OUTPUTS", help="check runs made again under OUTPUTS against the kept ones")
    a = ap.parse_args(argv)
    if a.compare:
        same, differ, not_kept = compare(Path(a.compare))
        print(
            f"{len(same)} of {len(same) + len(differ)} runs give their kept runs' relations and trajectory errors to "
            f"the last digit" + (f"; {len(not_kept)} not kept: {', '.join(not_kept)}" if not_kept else "")
        )
        for name in differ:
            print(f"differs: {name}")
        return 1 if differ or not (same or differ) else 0
    for line in kept_jobs(a.exp):
        print(" ".join(line))
    return 0


if __name__ == "__main__":
    raise SystemExit(guard(main))
