"""``python -m eval.keep [--results results] RUN_DIR...``: keep finished runs in the repository, compactly.

``results/<group>/<exp>.json`` holds, per experiment, every kept run of one stage group (``nof``: train and
synthesis, ``mcl``, ``slam``, ``globloc``, ``pipeline``) as ``{"exp": ..., "runs": {folder: {"config": {...},
"metrics": {...}}}}``: the config sections the stage reads (its resolved ``config.yaml``) and its
``metrics.json``. An experiment whose runs pass MAX_FILE_BYTES goes on in ``<exp>.2.json``, ``<exp>.3.json``
(the same header, the next runs in folder order), so no file grows past what a repository should hold;
``load_kept`` reads them back as one.
That is all the tables, claims and plots read (eval/collect.py); trajectories, manifests and N_eff traces
stay in ``outputs/``. Files a document shows are kept beside the JSON: the map of a SLAM run
(``results/slam/maps/<exp>/<folder>.png``) when asked (``--maps``), the pipeline's report and figures
(``results/pipeline/<exp>/<run>/``).

Runs made before a setting existed lack it in their recorded config; ``migrate`` fills it with the value
they ran with and renames keys that were renamed since (each rule says why), so every kept run reads the
same way.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from omegaconf import OmegaConf

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.services.outputs import SECTIONS
from irmcl_warp.services.cli import guard

REPO = Path(__file__).resolve().parents[1]
GROUPS = {"train": "nof", "synthesis": "nof", "localize": "mcl", "slam": "slam", "globloc": "globloc",
          "pipeline": "pipeline"}  # a run folder's stage (its name up to the first "-") -> results/<group>/
PROTOCOL = ("mode", "tracking_std", "num_starts", "run_s", "kidnap_at_s", "reduce_after_s")  # mcl -> localize


MAX_FILE_BYTES = 800_000  # one results file at most (the repository keeps no file over 1 MB)


def stage_of(folder: str) -> str:
    return folder.split("-")[0]


def kept_files(group_dir: Path, exp: str) -> list[Path]:
    """The files holding ``exp``'s kept runs in results/<group>/: <exp>.json, then <exp>.2.json, ... in order."""
    more = [f for f in group_dir.glob(f"{exp}.*.json") if f.stem.rsplit(".", 1)[1].isdigit()]
    first = [group_dir / f"{exp}.json"] if (group_dir / f"{exp}.json").is_file() else []
    return first + sorted(more, key=lambda f: int(f.stem.rsplit(".", 1)[1]))


def load_kept(group_dir: Path, exp: str) -> dict | None:
    """``exp``'s kept runs in results/<group>/ as one document (its files merged), or None when none is kept."""
    files = kept_files(group_dir, exp)
    if not files:
        return None
    doc = json.loads(files[0].read_text())
    for f in files[1:]:
        doc["runs"].update(json.loads(f.read_text())["runs"])
    return doc


def migrate(config: dict, metrics: dict, stage: str) -> tuple[dict, dict]:
    """The config and metrics of a run in today's names, with settings that did not exist yet filled in."""
    c = json.loads(json.dumps(config))
    data = c.get("data", {})
    if "usable_range_m" in data:  # renamed: the one far bound of every stage
        data["far_m"] = data.pop("usable_range_m")
    c.get("render", {}).pop("far_m", None)  # always None: the stages used data's far bound
    if "localize" in c and ("mcl" in c and "mode" in c["mcl"]):  # the pipeline's second log was `localize`
        c["pipeline"] = c.pop("localize")
    if "mcl" in c:
        c["mcl"].pop("far_m", None)  # overwritten from data's far bound by every stage
        # runs from before `motion` existed moved their particles by Thrun's odometry model
        c["mcl"].setdefault("motion", "odometry")
        proto = {k: c["mcl"].pop(k) for k in PROTOCOL if k in c["mcl"]}
        if proto:
            c["localize"] = {**c.get("localize", {}), **proto}
    for section in ("slam", "globloc"):
        if "particles" in c.get(section, {}):
            c[section]["num_particles"] = c[section].pop("particles")
    if "slam" in c:
        c["slam"].pop("usable_range_m", None)  # always None: data's far bound
        # runs from before `generate_map` existed generated free space in every particle's map (their folders
        # say "-genmap"): that is the value they ran with
        c["slam"].setdefault("generate_map", True)
    m = json.loads(json.dumps(metrics))
    if stage == "slam" and isinstance(m.get("settings"), dict):
        m["settings"] = dict(c["slam"])
    if stage == "localize" and isinstance(m.get("settings"), dict):
        m["settings"].setdefault("motion", "odometry")  # as the config: the runs before `motion` used Thrun's
    return c, m


def read_run(run: Path, config_from: Path | None = None) -> dict:
    """{"config": the sections its stage reads, "metrics": ...} of a finished run folder (config.yaml of
    ``config_from`` where the run has none: synthesis runs of old kept its train run's)."""
    stage = stage_of(run.name)
    metrics = json.loads((run / "metrics.json").read_text())
    src = run / "config.yaml" if (run / "config.yaml").is_file() else (config_from / "config.yaml" if config_from else None)
    full = OmegaConf.to_container(OmegaConf.load(src)) if src is not None and src.is_file() else {}
    sections = SECTIONS.get(stage)
    config = {k: v for k, v in full.items() if sections is None or k in sections or k == "exp"}
    config, metrics = migrate(config, metrics, stage)
    return {"config": config, "metrics": metrics}


def keep(runs: list[Path], results: Path, maps: bool = False) -> list[Path]:
    """Merge finished run folders (``<exp>/<folder>/`` with metrics.json) into results/<group>/<exp>.json."""
    by_file: dict[Path, dict] = {}
    for run in runs:
        run = Path(run)
        group = GROUPS.get(stage_of(run.name))
        if group is None or not (run / "metrics.json").is_file():
            raise SystemExit(f"{run}: not a finished stage folder (<stage>-...[/metrics.json]); stages: {sorted(GROUPS)}")
        exp = run.parent.name
        path = results / group / f"{exp}.json"
        if path not in by_file:
            by_file[path] = load_kept(results / group, exp) or {"group": group, "exp": exp, "runs": {}}
        pair = run.parent / ("train-" + run.name.split("-", 1)[1]) if stage_of(run.name) == "synthesis" else None
        by_file[path]["runs"][run.name] = read_run(run, pair)
        if group == "slam" and maps and (run / "map.png").is_file():
            (results / "slam" / "maps" / exp).mkdir(parents=True, exist_ok=True)
            shutil.copyfile(run / "map.png", results / "slam" / "maps" / exp / f"{run.name}.png")
        if group == "pipeline":
            for name in ("report.md", "map.png", "error.png"):
                if (run / name).is_file():
                    (results / "pipeline" / exp / run.name).mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(run / name, results / "pipeline" / exp / run.name / name)
    for path, doc in by_file.items():
        write_kept(path, doc)
    return sorted(by_file)


def write_kept(path: Path, doc: dict, max_bytes: int = MAX_FILE_BYTES) -> None:
    """An experiment's results file ``path`` (<exp>.json): its header, then one compact line per run (small, and a
    diff names the runs), in folder order; the runs that would take it past ``max_bytes`` go on in <exp>.2.json
    and so on, each with the same header. Files of a longer split that are no longer needed are removed."""
    head = json.dumps({k: v for k, v in doc.items() if k != "runs"}, sort_keys=True)[:-1] + ', "runs": {\n'
    tail = "\n}}\n"
    shards, lines, size = [], [], len(head) + len(tail)
    for k, v in sorted(doc["runs"].items()):
        line = f" {json.dumps(k)}: {json.dumps(v, sort_keys=True, separators=(',', ':'))}"
        if lines and size + len(line) + 2 > max_bytes:
            shards.append(lines)
            lines, size = [], len(head) + len(tail)
        lines.append(line)
        size += len(line) + 2
    shards.append(lines)
    exp = path.name.removesuffix(".json")
    for i, part in enumerate(shards):
        atomic_write_bytes(path if i == 0 else path.with_name(f"{exp}.{i + 1}.json"),
                           (head + ",\n".join(part) + tail).encode())
    for stale in kept_files(path.parent, exp)[len(shards):]:
        stale.unlink()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m eval.keep", description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="finished run folders, e.g. outputs/fr079/localize-*")
    ap.add_argument("--results", type=Path, default=REPO / "results")
    ap.add_argument("--maps", action="store_true", help="also keep the map.png of SLAM runs")
    a = ap.parse_args(argv)
    for p in keep(a.runs, a.results, a.maps):
        print(f"-> {p}")


if __name__ == "__main__":
    guard(main)
