"""Run records: every run the tables, claims and plots read, found by its settings.

A record (``irmcl_warp.runs.Record``) is a run's metrics with the settings it read (``config``), its stage,
experiment and id. Two places hold them:

* ``outputs/<exp>/<stage>/<run>/``: your own finished runs (``runs.records``; a run that consumed another,
  localization of a trained field, also carries that run's settings);
* ``results/<group>/<exp>.json``: the runs kept in the repository (``python -m eval.keep RUN_DIR...``),
  compactly: per record its stage, id, label, settings and metrics, continued in ``<exp>.2.json``, ... past
  ``MAX_FILE_BYTES``. Records kept before a setting existed hold it at its schema default, the value every
  new setting was introduced with (so the runs that predate it ran that way), unless the setting came with a
  new behaviour as its default: then they hold the value that names what they did (``BEFORE``); a setting
  renamed since is read under its new name (``RENAMED``), one removed since is dropped (``REMOVED``).

``load`` merges both (a run of yours replaces a kept one of the same settings); ``find`` picks records by
settings (``find("localize", "fr079", among=recs, mcl__weighting="nog_raymarch")``); ``off_defaults`` says
which settings of a record differ from what its experiment composes to, which is how tables tell a paper
cell from an ablation, never by a folder's name.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from pathlib import Path

from irmcl_warp import runs
from irmcl_warp.config import Config
from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.runs import Record, find, matches  # noqa: F401  (the query interface, re-exported)

REPO = Path(__file__).resolve().parents[2]
RESULTS, OUTPUTS = REPO / "results", REPO / "outputs"
GROUPS = {
    "train": "nof",
    "synthesis": "nof",
    "localize": "mcl",
    "slam": "slam",
    "globloc": "globloc",
    "pipeline": "pipeline",
    "worlds": "worlds",
}  # a stage's records are kept in results/<group>/<exp>.json
MAX_FILE_BYTES = 800_000  # one results file at most (the repository keeps no file over 1 MB)
# settings that decide how fast a run goes, never what it gives (the same bits: tests/test_weighting.py
# for the batched march, tests/test_mcl.py for the step's graph, the march order and the CPU threads): tables
# ignore them
PERF_ONLY = ("mcl.march_batch", "mcl.march_order", "mcl.step_graph", "mcl.cpu_threads")


def _schema_defaults() -> dict:
    out = {}
    for f in dataclasses.fields(Config):
        if f.default_factory is not dataclasses.MISSING:
            made = f.default_factory()
            out[f.name] = dataclasses.asdict(made) if dataclasses.is_dataclass(made) else made
    return out


DEFAULTS = _schema_defaults()


# settings renamed since runs were kept: old dotted name -> new one (same meaning, same value)
RENAMED = {"sim.max_range_m": "sim.range_max_m"}  # the simulated lidar's largest reading, not a far bound
# settings removed since: mapping.max_range_m was a second far bound (inspect now uses data.far_m)
REMOVED = ("mapping.max_range_m",)
# settings whose default is a new behaviour: what a record from before the setting did (twenty-sixth session: the
# worlds' maps from a drive past every roadmap node; the runs before mapped each floor with a random 400 m drive)
BEFORE = {"worlds.map_drive": "random", "worlds.map_logodds_limit": 4.0, "worlds.mode_pose": "block"}


def complete(config: dict) -> dict:
    """``config`` with settings renamed since under their new names, settings removed since dropped, and every
    schema setting its sections lack at the schema's default (see the module's docstring); sections it does not
    hold stay absent."""
    out = json.loads(json.dumps(config))
    for old, new in RENAMED.items():
        (s_old, k_old), (s_new, k_new) = old.split(".", 1), new.split(".", 1)
        if isinstance(out.get(s_old), dict) and k_old in out[s_old]:
            out.setdefault(s_new, {})[k_new] = out[s_old].pop(k_old)
    for gone in REMOVED:
        section, key = gone.split(".", 1)
        if isinstance(out.get(section), dict):
            out[section].pop(key, None)
    for dotted, value in BEFORE.items():
        section, key = dotted.split(".", 1)
        if isinstance(out.get(section), dict):
            out[section].setdefault(key, value)
    for section, values in out.items():
        if isinstance(values, dict) and section in DEFAULTS:
            for key, default in DEFAULTS[section].items():
                values.setdefault(key, default)
    return out


@functools.lru_cache(maxsize=None)
def _composed(exp: str, stage: str) -> str:
    from omegaconf import OmegaConf

    from irmcl_warp.config import CONF_DIR, compose_config

    overrides = [f"+exp={exp}"] if (CONF_DIR / "exp" / f"{exp}.yaml").is_file() else []
    return json.dumps(
        OmegaConf.to_container(compose_config(overrides, "pipeline" if stage == "pipeline" else "config"), resolve=True)
    )


def exp_defaults(exp: str, stage: str) -> dict:
    """The settings experiment ``exp`` composes to (``+exp=<exp>``; the primary config of ``stage`` when there
    is no conf/exp/<exp>.yaml): the defaults a run of it is compared with."""
    return json.loads(_composed(exp, stage))


def off_defaults(rec: Record, sections, ignore=()) -> dict:
    """{"section.key": value} of the settings of ``sections`` that differ from what the record's experiment
    composes to (``exp_defaults``), leaving out ``ignore`` and the settings that only decide speed (PERF_ONLY)."""
    base, out = exp_defaults(rec.exp, rec.stage), {}
    for section in sections:
        for key, value in (rec.config.get(section) or {}).items():
            dotted = f"{section}.{key}"
            if dotted in ignore or dotted in PERF_ONLY or key not in (base.get(section) or {}):
                continue
            if value != base[section][key]:
                out[dotted] = value
    return out


def describe(settings: dict) -> str:
    """``slam.srt=0.4, slam.stt=0.4`` -> ``srt=0.4, stt=0.4``: settings as a table labels them."""

    def value(v):
        return f"{v:g}" if isinstance(v, float) else str(v)

    return ", ".join(f"{k.split('.', 1)[1]}={value(v)}" for k, v in sorted(settings.items()))


# --- kept records ----------------------------------------------------------------------------------------


def kept_files(group_dir: Path, exp: str) -> list[Path]:
    """The files holding ``exp``'s kept records in results/<group>/: <exp>.json, then <exp>.2.json, ... in order."""
    more = [f for f in group_dir.glob(f"{exp}.*.json") if f.stem.rsplit(".", 1)[1].isdigit()]
    first = [group_dir / f"{exp}.json"] if (group_dir / f"{exp}.json").is_file() else []
    return first + sorted(more, key=lambda f: int(f.stem.rsplit(".", 1)[1]))


def load_doc(group_dir: Path, exp: str) -> dict | None:
    """``exp``'s kept records in results/<group>/ as one document (its files merged), or None."""
    files = kept_files(group_dir, exp)
    if not files:
        return None
    try:
        doc = json.loads(files[0].read_text())
        for f in files[1:]:
            doc["records"].update(json.loads(f.read_text())["records"])
    except (OSError, ValueError, KeyError) as e:
        raise ValueError(
            f"{files[0]}: unreadable results file ({e}); keep its runs again with python -m eval.keep"
        ) from e
    return doc


def write_doc(path: Path, doc: dict, max_bytes: int = MAX_FILE_BYTES) -> None:
    """An experiment's results file ``path`` (<exp>.json): its header, then one compact line per record (a
    diff names the records), in key order; the records that would take it past ``max_bytes`` go on in
    <exp>.2.json and so on, each with the same header. Files of a longer split no longer needed are removed."""
    head = json.dumps({k: v for k, v in doc.items() if k != "records"}, sort_keys=True)[:-1] + ', "records": {\n'
    tail = "\n}}\n"
    shards, lines, size = [], [], len(head) + len(tail)
    for k, v in sorted(doc["records"].items()):
        line = f" {json.dumps(k)}: {json.dumps(v, sort_keys=True, separators=(',', ':'))}"
        if lines and size + len(line) + 2 > max_bytes:
            shards.append(lines)
            lines, size = [], len(head) + len(tail)
        lines.append(line)
        size += len(line) + 2
    shards.append(lines)
    exp = path.name.removesuffix(".json")
    for i, part in enumerate(shards):
        atomic_write_bytes(
            path if i == 0 else path.with_name(f"{exp}.{i + 1}.json"), (head + ",\n".join(part) + tail).encode()
        )
    for stale in kept_files(path.parent, exp)[len(shards) :]:
        stale.unlink()


def kept_entry(rec: Record) -> tuple[str, dict]:
    """(key, entry) of a record in a results file: ``<stage>/<label>-<id>``."""
    key = f"{rec.stage}/{rec.name}"
    entry = {"stage": rec.stage, "id": rec.id, "label": rec.label, "config": rec.config, "metrics": dict(rec)}
    for extra in ("manifest", "kept_from", "upstream"):
        if getattr(rec, extra, None):
            entry[extra] = getattr(rec, extra)
    return key, entry


def kept(stages=None, results: Path = RESULTS) -> list[Record]:
    """The records kept in ``results`` (of ``stages``)."""
    groups = sorted({GROUPS[s] for s in stages} if stages else set(GROUPS.values()))
    out = []
    for group in groups:
        for path in sorted((Path(results) / group).glob("*.json")):
            if path.stem.rsplit(".", 1)[-1].isdigit():
                continue  # a continuation, read with its first file
            doc = load_doc(path.parent, path.stem)
            for entry in doc["records"].values():
                if stages and entry["stage"] not in stages:
                    continue
                rec = Record(
                    entry["metrics"],
                    entry["stage"],
                    doc["exp"],
                    entry["id"],
                    complete(entry["config"]),
                    None,
                    "results",
                    entry["label"],
                )
                rec.manifest, rec.kept_from, rec.upstream = (
                    entry.get("manifest"),
                    entry.get("kept_from"),
                    entry.get("upstream"),
                )
                out.append(rec)
    return out


def yours(stages=None, outputs: Path = OUTPUTS) -> list[Record]:
    """Your finished runs under ``outputs`` (of ``stages``), each with the settings of the runs it consumed."""
    out = []
    for stage in stages or GROUPS:
        for rec in runs.records(stage, root=outputs):
            manifest = json.loads((rec.path / "manifest.json").read_text())
            for up in manifest.get("upstream", {}).values():
                upstream = Path(outputs) / up["run"]
                if (upstream / "config.yaml").is_file():
                    from omegaconf import OmegaConf

                    for section, values in OmegaConf.to_container(OmegaConf.load(upstream / "config.yaml")).items():
                        rec.config.setdefault(section, values)
            rec.manifest = {k: manifest.get(k) for k in ("git_sha", "device", "package", "wall_time_s")}
            rec.kept_from = None
            rec.upstream = {s: u["id"] for s, u in manifest.get("upstream", {}).items()}
            rec.config = complete(rec.config)  # a run made before a setting existed ran at its default, as kept ones
            out.append(rec)
    return out


def load(stages=None, results: Path | None = RESULTS, outputs: Path | None = OUTPUTS) -> list[Record]:
    """Kept records and yours (``None`` leaves a place out); one of yours replaces a kept record of the same
    settings."""
    mine = yours(stages, outputs) if outputs is not None else []
    replaced = {(r.exp, r.settings_id) for r in mine}
    base = [r for r in (kept(stages, results) if results is not None else []) if (r.exp, r.settings_id) not in replaced]
    return base + mine


def kept_map(rec: Record, results: Path = RESULTS) -> Path:
    """results/slam/maps/<exp>/<run>.png: the map of a kept SLAM record (docs/maps is made from these)."""
    return Path(results) / "slam" / "maps" / rec.exp / f"{rec.name}.png"


def checks(study: str, results: Path = RESULTS) -> list[Record]:
    """The records of a check study (results/checks/<study>.json: runs of ours and of the reference code made
    for one comparison, with the analyses made of them as ``artifacts``), each with ``study`` set."""
    path = Path(results) / "checks" / f"{study}.json"
    if not path.is_file():
        return []
    doc = json.loads(path.read_text())
    out = []
    for entry in doc["records"].values():
        rec = Record(
            entry["metrics"],
            entry["stage"],
            entry["exp"],
            entry["id"],
            complete(entry["config"]),
            None,
            "results",
            entry.get("label", ""),
        )
        rec.study, rec.artifacts, rec.kept_from = study, entry.get("artifacts", {}), entry.get("kept_from")
        rec.draw = entry.get("draw", 0)
        out.append(rec)
    return out


def keep_check(study: str, exp: str, entries, results: Path = RESULTS) -> Path:
    """Merge runs into the check study results/checks/<study>.json: ``entries`` of (folder, stage, artifact file
    names kept beside its metrics, draw), each folder holding metrics.json and config.yaml (its settings)."""
    from omegaconf import OmegaConf

    path = Path(results) / "checks" / f"{study}.json"
    doc = json.loads(path.read_text()) if path.is_file() else {"group": "checks", "study": study, "records": {}}
    for folder, stage, artifacts, draw in entries:
        folder = Path(folder)
        config = OmegaConf.to_container(OmegaConf.load(folder / "config.yaml"), resolve=True)
        config["exp"] = exp
        metrics = json.loads((folder / "metrics.json").read_text())
        manifest = json.loads((folder / "manifest.json").read_text()) if (folder / "manifest.json").is_file() else {}
        entry = {
            "stage": stage,
            "exp": exp,
            "config": config,
            "metrics": metrics,
            "kept_from": folder.name,
            "artifacts": {name: json.loads((folder / name).read_text()) for name in artifacts},
        }
        if manifest:  # the code that made it (the id is the settings', not the code's)
            entry["manifest"] = {k: manifest.get(k) for k in ("git_sha", "device", "package", "wall_time_s")}
        if draw:
            entry["draw"] = draw
        entry["id"] = runs.digest({k: entry[k] for k in ("stage", "config", "kept_from")} | {"draw": draw})
        entry["label"] = folder.name
        doc["records"][f"{stage}/{folder.name}-{entry['id'][: runs.ID_CHARS]}"] = entry  # a tool's own folder name
        print(f"kept {folder} -> {path} ({stage})")
    atomic_write_bytes(path, (json.dumps(doc, sort_keys=True, indent=0) + "\n").encode())
    return path


def _unkeepable(folder: Path) -> str:
    """Why ``folder`` cannot be kept, or "": a finished run's manifest, and the files a record holds (its settings
    and metrics) as the run wrote them. Its other files may stay behind (a GPU machine sends back few files)."""
    try:
        manifest = json.loads((folder / "manifest.json").read_text())
        written = manifest["outputs"]
    except (OSError, ValueError, KeyError) as e:
        return f"no readable manifest.json ({e})"
    for name in ("config.yaml", "metrics.json"):
        if name in written and (not (folder / name).is_file() or runs.file_digest(folder / name) != written[name]):
            return f"{name} is not what the run wrote"
    return "" if "config.yaml" in written else "its manifest lists no config.yaml"


def keep(folders, results: Path = RESULTS, maps: bool = False) -> list[Path]:
    """Merge finished run folders into results/<group>/<exp>.json (a record of the same key is replaced);
    ``maps``: a SLAM run's map.png goes beside them (results/slam/maps/<exp>/<run>.png), for docs/maps."""
    by_file: dict[Path, dict] = {}
    for folder in folders:
        folder = Path(folder)
        why = _unkeepable(folder)
        if why:
            raise ValueError(f"{folder}: not a finished run ({why})")
        (rec,) = [
            r
            for r in yours([json.loads((folder / "manifest.json").read_text())["stage"]], folder.parents[2])
            if r.path.resolve() == folder.resolve()
        ]
        rec.kept_from = f"{folder.parent.name}/{folder.name}"
        group = GROUPS.get(rec.stage)
        if group is None:
            raise ValueError(f"{folder}: {rec.stage} runs are not kept (stages kept: {', '.join(GROUPS)})")
        path = Path(results) / group / f"{rec.exp}.json"
        if path not in by_file:
            by_file[path] = load_doc(path.parent, rec.exp) or {"group": group, "exp": rec.exp, "records": {}}
        key, entry = kept_entry(rec)
        by_file[path]["records"][key] = entry
        if maps and rec.stage == "slam" and (folder / "map.png").is_file():
            atomic_write_bytes(kept_map(rec, results), (folder / "map.png").read_bytes())
    for path, doc in by_file.items():
        write_doc(path, doc)
    return sorted(by_file)
