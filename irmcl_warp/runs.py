"""Runs: what a run is, where it lives and how it is found. The one home of run identity.

A run of a stage is identified by what it reads, and nothing else:

* **the settings it reads**: the config sections (or single keys) that ``STAGES[stage].reads(cfg)`` names.
  The stage body runs on a copy of the config holding only those (``Run.cfg``, struct mode), so a stage
  that reads any other setting fails at once (``ConfigAttributeError``): the list cannot drift from what
  the code reads, and a setting outside it cannot change a result;
* **the content of the files those settings name** (``FILE_KEYS``): a moved or renamed log is the same
  input, a log replaced under the same name (same size, same time) is not;
* **the runs it consumes** (``STAGES[stage].upstream``): their ids. A stage consumes finished runs only.

The id is the sha256 of those three. The folder is ``outputs/<exp>/<stage>/<label>-<id[:10]>``; the label
is made of a few settings (``STAGES[stage].label``) so a person can tell runs apart. Nothing else in the
package or in eval builds a run folder's name.

``start(cfg, stage)`` opens a run: it takes a lock per id (a second run of the same id waits for the
first, then finds it finished), returns at once when the folder holds an intact finished run, and
otherwise hands the stage a fresh temporary folder ``.<label>-<id>.partial`` (a resumable stage, the
training, continues the one an interrupted run of the same id left). ``Run.finish`` writes config.yaml
(the settings read), metrics.json and manifest.json (id, package version, git sha, device, the inputs'
digests, the upstream runs, every output's digest) into it and swaps it in, so a run folder holds exactly
what one completed run wrote. A finished run is never replaced; a changed setting or input is a new run.

``find`` reads run records back by their settings (``find("localize", exp="fr079",
mcl__weighting="nog_raymarch")``), never by a folder's name.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.io.atomic import atomic_write_json as write_json
from irmcl_warp.config import own_map_calibration, own_map_lost_rule_file, worlds_calibration

REPO = Path(__file__).resolve().parents[1]
OUTPUTS = Path("outputs")  # relative to the working directory, as Hydra's run dir
ID_CHARS = 10  # of the id in folder names (40 bits: no collision among a project's runs)
NOF_WEIGHTINGS = ("nog_raymarch", "nog_table", "nof_direct")  # observation models that read a trained field


# --- what each stage reads ------------------------------------------------------------------------------


def _sim(cfg) -> tuple[str, ...]:
    """The simulator's settings matter to a run only when the log is simulated."""
    return ("sim",) if cfg.data.format == "sim" else ()


def _localize_reads(cfg) -> tuple[str, ...]:
    keys = ("data", *_sim(cfg), "mcl", "localize", "device")
    if cfg.localize.map_path:  # your own log in your own map: the map and the NOF are files
        return keys
    return keys + ("render.near_m",)  # the benchmark's maps come from the training split's beams


def _localize_upstream(cfg) -> tuple[str, ...]:
    return ("train",) if cfg.mcl.weighting in NOF_WEIGHTINGS and not cfg.localize.map_path else ()


def _localize_label(cfg) -> str:
    if cfg.localize.map_path:
        start = "pose" if cfg.localize.initial_pose is not None else "global"
        return f"{{mcl.weighting}}-{start}-{{mcl.num_particles}}-in-{{localize.map_path}}"
    return "{mcl.weighting}-{localize.mode}-{mcl.num_particles}-{mcl.map_resolution_m}m"


def _pipeline_label(cfg) -> str:
    second = cfg.data.format == "sim" and cfg.pipeline.path is None
    return "{data.name}" + (
        "-path{pipeline.sim_path_seed}" if second else "-{pipeline.path}" if cfg.pipeline.path else ""
    )


@dataclass(frozen=True)
class Stage:
    """What a stage reads (config sections or ``section.key``), the label its folders carry (a format over
    settings, or a function of the config giving one), the stages whose finished runs it consumes, and
    whether an interrupted run of the same id is continued rather than started again."""

    reads: Callable[..., tuple[str, ...]]
    label: str | Callable[..., str]
    upstream: Callable[..., tuple[str, ...]] = lambda cfg: ()
    resumable: bool = False
    command: str = ""  # how a user makes this stage's run (a format over the settings), for the stages that consume it


STAGES: dict[str, Stage] = {
    "inspect": Stage(lambda c: ("data", *_sim(c), "mapping", "device"), "{data.name}"),
    "relations": Stage(lambda c: ("data", *_sim(c)), "{data.name}"),
    "slam": Stage(
        lambda c: ("data", *_sim(c), "slam", "device"),
        "{slam.proposal}-{slam.resample}-{slam.num_particles}p-seed{slam.seed}",
    ),
    "train": Stage(
        lambda c: ("data", *_sim(c), "model", "render", "train", "device"),
        "{train.name}",
        resumable=True,
        command="python -m irmcl_warp.train +exp={exp} train={train.name}",
    ),
    # the NOF of the finished training run with these settings beside grids (mapping, raycast)
    "synthesis": Stage(
        lambda c: ("data", *_sim(c), "render", "mapping", "raycast", "device", "train.name"),
        "{train.name}",
        lambda c: ("train",),
    ),
    "localize": Stage(_localize_reads, _localize_label, _localize_upstream),
    "globloc": Stage(lambda c: ("sim", "globloc", "mcl", "device"), "{globloc.scenario}"),
    "worlds": Stage(lambda c: ("sim", "worlds", "mcl", "device"), "{worlds.split}-{mcl.weighting}-{mcl.num_particles}"),
    # the pipeline runs slam and train itself; its own run reads what those and its localization read
    "pipeline": Stage(
        lambda c: (
            "data",
            *_sim(c),
            "slam",
            "model",
            "render",
            "train",
            "mcl",
            "localize.reduce_after_s",
            "pipeline",
            "device",
        ),
        _pipeline_label,
    ),
}

# settings that name files: a run depends on their content, not on where they lie
FILE_KEYS = (
    "data.path",
    "data.laser_frame_path",
    "data.ground_truth_path",
    "data.relations_path",
    "data.relation_stamps_path",
    "data.splits_path",
    "data.train_poses_path",
    "localize.map_path",
    "localize.nof_path",
    "pipeline.path",
    "pipeline.ground_truth_path",
    "worlds.calibration",
)


# --- digests --------------------------------------------------------------------------------------------


def file_digest(path, chunk=1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def content_digest(path: Path) -> str:
    """sha256 of a file, or of a folder's files (a ROS 2 bag) by relative path and content."""
    path = Path(path)
    if path.is_file():
        return file_digest(path)
    h = hashlib.sha256()
    for p in sorted(q for q in path.rglob("*") if q.is_file()):
        h.update(f"{p.relative_to(path)}\0{file_digest(p)}\0".encode())
    return h.hexdigest()


def digest(obj) -> str:
    """sha256 of a JSON-able object (sorted keys): settings keys and cache keys."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def map_files(map_file: Path) -> list[Path]:
    """A map_server YAML and its image (both decide a run in that map), or the one .npz."""
    if map_file.suffix in (".yaml", ".yml"):
        from omegaconf import OmegaConf

        try:
            image = OmegaConf.load(map_file).get("image")
        except Exception:  # a malformed YAML: the map reader names it when the run reads it
            image = None
        return [map_file] + ([map_file.parent / image] if image and (map_file.parent / image).is_file() else [])
    return [map_file]


# --- the settings a stage reads -------------------------------------------------------------------------


def _get(container: dict, dotted: str):
    node = container
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(dotted)
        node = node[part]
    return node


def _set(container: dict, dotted: str, value) -> None:
    *head, last = dotted.split(".")
    for part in head:
        container = container.setdefault(part, {})
    container[last] = value


def read_settings(cfg, stage: str, strict: bool = True) -> dict:
    """The resolved settings ``stage`` reads from ``cfg`` (nested like the config), ``exp`` included. With
    ``strict`` off, what the config lacks is left out (a record kept before the stage read it)."""
    from omegaconf import OmegaConf

    full = OmegaConf.to_container(cfg, resolve=True) if not isinstance(cfg, dict) else cfg
    view = restricted(cfg) if isinstance(cfg, dict) else cfg
    out = {"exp": full.get("exp")}
    for key in STAGES[stage].reads(view):
        try:
            _set(out, key, _get(full, key))
        except KeyError:
            if strict:
                raise KeyError(f"the {stage} stage reads {key}, which the config does not have") from None
    return out


def restricted(settings: dict):
    """The settings as a config in struct mode: reading a key it does not hold is an error."""
    from omegaconf import OmegaConf

    c = OmegaConf.create(settings)
    OmegaConf.set_struct(c, True)
    return c


def input_files(settings: dict) -> dict[str, list[Path]]:
    """{setting: the files it names} for every file setting among ``settings`` that is set."""
    from irmcl_warp.io import resolve

    out = {}
    for key in FILE_KEYS:
        try:
            value = _get(settings, key)
        except KeyError:
            continue
        if key == "worlds.calibration" and value == "off":  # features only: no file read
            continue
        if not value and key == "worlds.calibration":  # none given: the one shipped for the filter, if any
            value = worlds_calibration(_get(settings, "mcl.weighting"), _get(settings, "mcl.num_particles"))
        if value:
            path = resolve(value)  # as given (absolute, or from the working directory), else under IRMCL_DATA
            out[key] = map_files(path) if key == "localize.map_path" else [path]
    if "localize.map_path" in out:  # a run in your own map judges itself with the calibration for its filter
        try:
            calibration = own_map_calibration(_get(settings, "mcl.weighting"), _get(settings, "mcl.num_particles"))
        except KeyError:
            calibration = None
        if calibration is not None:
            out[OWN_MAP_CALIBRATION] = [calibration]
            out[OWN_MAP_LOST_RULE] = [own_map_lost_rule_file()]
    return out


OWN_MAP_CALIBRATION = "localize.calibration"  # an input no setting names: the file own_map_calibration picks
OWN_MAP_LOST_RULE = "localize.lost_rule"  # ... and the worlds stage's settings its lost-robot rule reads


def _by_name(key: str, value):
    """A file setting as records compare it: a path under the data root as given, else the file's name."""
    return value if not value or not Path(value).is_absolute() else Path(value).name


def settings_id(config: dict, stage: str) -> str:
    """The digest of the settings a run of ``stage`` and the runs it consumes read, files by name: what
    records are compared by (kept records carry no input digests; a run of yours replaces a kept one of the
    same settings id)."""
    return digest(settings_by_stage(config, stage))


def settings_by_stage(config: dict, stage: str) -> dict:
    """{stage and each stage it consumes: the settings it reads, files by name} (what ``settings_id`` digests;
    what the config lacks is left out)."""
    cfg = restricted(config)
    parts = {}
    for s in (stage, *STAGES[stage].upstream(cfg)):
        settings = read_settings(config, s, strict=False)
        settings.pop("exp", None)
        for key in FILE_KEYS:
            try:
                _set(settings, key, _by_name(key, _get(settings, key)))
            except KeyError:
                pass
        parts[s] = settings
    return parts


# --- identity -------------------------------------------------------------------------------------------


@dataclass
class Identity:
    stage: str
    exp: str
    settings: dict  # what the stage reads, resolved
    inputs: dict  # setting -> [{"path", "sha256"}]
    upstream: dict  # stage -> Identity of the run consumed
    id: str
    label: str

    @property
    def name(self) -> str:
        return f"{self.label}-{self.id[:ID_CHARS]}"

    def folder(self, root=OUTPUTS) -> Path:
        return Path(root) / self.exp / self.stage / self.name


def _short(key: str, value) -> str:
    if key in FILE_KEYS and isinstance(value, str):
        return Path(value).stem
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int) and value >= 1000 and value % 1000 == 0:
        return f"{value // 1000}k"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return "_".join(_short("", v) for v in value)
    return str(value)


def label_of(stage: str, config) -> str:
    """The readable part of a run folder's name, from ``config`` (a config or its container)."""
    from omegaconf import OmegaConf

    full = OmegaConf.to_container(config, resolve=True) if not isinstance(config, dict) else config
    spec = STAGES[stage].label
    template = spec(restricted(full)) if callable(spec) else spec
    text = re.sub(r"\{([a-z_.]+)\}", lambda m: _short(m.group(1), _get(full, m.group(1))), template)
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text)


def identify(cfg, stage: str) -> Identity:
    """The identity of the run of ``stage`` that ``cfg`` describes (nothing is run or written)."""
    if stage not in STAGES:
        raise ValueError(f"no stage {stage!r}; stages: {', '.join(STAGES)}")
    settings = read_settings(cfg, stage)
    inputs = {
        k: [{"path": str(p), "sha256": content_digest(p)} for p in paths] for k, paths in input_files(settings).items()
    }
    upstream = {s: identify(cfg, s) for s in STAGES[stage].upstream(cfg)}
    # the id: the settings without the file names (their content stands for them), the inputs' content, the
    # upstream ids; exp only places the folder
    named = json.loads(json.dumps({k: v for k, v in settings.items() if k != "exp"}))  # a copy: settings stay whole
    for key in inputs:
        if key != OWN_MAP_CALIBRATION:  # (no setting to blank: the file is picked from mcl.*)
            _set(named, key, None)
    run_id = digest(
        {
            "stage": stage,
            "settings": named,
            "inputs": {k: [f["sha256"] for f in v] for k, v in inputs.items()},
            "upstream": {s: u.id for s, u in upstream.items()},
        }
    )
    return Identity(stage, str(settings["exp"]), settings, inputs, upstream, run_id, label_of(stage, cfg))


# --- finished runs ---------------------------------------------------------------------------------------


def output_digests(out: Path) -> dict[str, str]:
    """sha256 of every file under ``out`` except manifest.json, by relative path."""
    return {
        str(p.relative_to(out)): file_digest(p)
        for p in sorted(Path(out).rglob("*"))
        if p.is_file() and p.name != "manifest.json"
    }


def intact(folder: Path, run_id: str | None = None) -> tuple[bool, str]:
    """(finished and unchanged, why not): ``folder`` holds a manifest (of ``run_id`` when given) whose
    output digests match the files, and every JSON file parses."""
    path = Path(folder) / "manifest.json"
    if not path.is_file():
        return False, f"{path} missing: no run finished there"
    try:
        manifest = json.loads(path.read_text())
        outputs = manifest["outputs"]
    except (ValueError, KeyError, TypeError):
        return False, f"{path} is malformed"
    if run_id is not None and manifest.get("id") != run_id:
        return False, f"{path} is the manifest of another run ({manifest.get('id')})"
    for rel, d in outputs.items():
        f = Path(folder) / rel
        if not f.is_file():
            return False, f"{f} listed in the manifest but missing"
        if file_digest(f) != d:
            return False, f"{f} differs from what the run wrote (edited, truncated or half-rewritten)"
        if f.suffix == ".json":
            try:
                json.loads(f.read_text())
            except ValueError as e:
                return False, f"{f} is not valid JSON ({e})"
    return True, ""


def finished(ident: Identity, root=OUTPUTS) -> Path | None:
    """The folder of the finished, intact run of ``ident``, or None."""
    folder = ident.folder(root)
    return folder if intact(folder, ident.id)[0] else None


def require(ident: Identity, root=OUTPUTS) -> Path:
    """The folder of a finished run that another stage consumes; an error saying what to run when there is
    none (an interrupted run of these settings is never used)."""
    folder = ident.folder(root)
    ok, why = intact(folder, ident.id)
    if ok:
        return folder
    partial = folder.with_name(f".{folder.name}.partial")
    state = (
        f"a {ident.stage} run of these settings was interrupted ({partial}); finish it"
        if partial.exists()
        else f"no finished {ident.stage} run of these settings ({why}); make it"
    )
    template = STAGES[ident.stage].command
    command = (
        re.sub(r"\{([a-z_.]+)\}", lambda m: str(_get(ident.settings, m.group(1))), template)
        if template
        else f"the {ident.stage} stage"
    )
    raise FileNotFoundError(f"{folder}: {state}: {command} (with the same settings)")


# --- running ---------------------------------------------------------------------------------------------


def _git_sha() -> str:
    """The commit the code was run from, "-dirty" when tracked files differ from it. ``IRMCL_GIT_SHA``, when set,
    is taken as is: a copy of a checkout made elsewhere (a lent GPU machine gets the working tree and a stale
    history; eval/gpu/stamp_source.sh writes the commit the copy was made from)."""
    given = os.environ.get("IRMCL_GIT_SHA", "").strip()
    if given:
        return given
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        return sha + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def package_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("irmcl-warp")
    except metadata.PackageNotFoundError:
        return "unknown"


@dataclass
class Run:
    """An open run: ``cfg`` (the settings it may read), ``dir`` (where it writes; swapped into ``path`` by
    ``finish``), ``upstream`` ({stage: folder of the finished run it consumes})."""

    ident: Identity
    cfg: object
    path: Path  # the finished run's folder
    dir: Path  # the folder being written
    done: bool  # ``path`` already held this run: nothing to do
    upstream: dict = field(default_factory=dict)
    started: float = field(default_factory=time.time)
    # the commit of the code the run loaded, read when it opens: a run of twenty minutes that read it at its end
    # named a commit made while it ran (thirty-ninth session, an MIT Killian run on the CPU)
    git_sha: str = field(default_factory=lambda: _git_sha())

    def _checkout_changed(self) -> dict:
        """``git_sha_at_finish`` and a loud warning where the checkout's commit (or its uncommitted changes) changed
        while the run ran: the manifest keeps the one it started from, the code Python had loaded."""
        import warnings

        now = _git_sha()
        if now == self.git_sha:
            return {}
        warnings.warn(
            f"{self.path}: the checkout changed while this run ran ({self.git_sha} at its start, {now} now); its "
            "manifest names the commit it started from",
            stacklevel=3,
        )
        return {"git_sha_at_finish": now}

    def finish(self, metrics: dict | None, device: str, extra: dict | None = None) -> Path:
        """Write metrics.json (when given), config.yaml and manifest.json, then swap the folder in."""
        from omegaconf import OmegaConf

        if metrics is not None:
            write_json(self.dir / "metrics.json", metrics)
        atomic_write_bytes(self.dir / "config.yaml", OmegaConf.to_yaml(restricted(self.ident.settings)).encode())
        manifest = {
            "id": self.ident.id,
            "stage": self.ident.stage,
            "exp": self.ident.exp,
            "label": self.ident.label,
            "package": {"name": "irmcl-warp", "version": package_version()},
            "git_sha": self.git_sha,
            **self._checkout_changed(),
            "python": platform.python_version(),
            "versions": _versions(),
            "device": device,
            "device_name": device_name(device),  # cuda:0 names no card: an H100 and an H200 differ in speed
            "wall_time_s": time.time() - self.started,
            "inputs": self.ident.inputs,
            "upstream": {s: {"id": u.id, "run": f"{u.exp}/{u.stage}/{u.name}"} for s, u in self.ident.upstream.items()},
            **(extra or {}),
            "outputs": output_digests(self.dir),
        }
        write_json(self.dir / "manifest.json", manifest)
        _swap(self.dir, self.path)
        self.dir, self.done = self.path, True
        return self.path


def device_name(device: str) -> str | None:
    """The card behind a CUDA device string (``"NVIDIA H100 80GB HBM3"``), as Warp names it; None for the CPU or
    when Warp cannot say."""
    if not str(device).startswith("cuda"):
        return None
    try:
        import warp as wp

        return str(wp.get_device(device).name)
    except Exception:  # (a manifest is written whatever the device query says)
        return None


def amend(folder: Path, metrics: dict, why: str) -> None:
    """Rewrite a finished run's metrics.json (a rescoring with today's rules) and record it in its manifest: the
    new digest, so the run stays intact, and what was amended and why, so the record says it was."""
    folder = Path(folder)
    ok, reason = intact(folder)
    if not ok:
        raise ValueError(f"{folder}: not a finished run to amend ({reason})")
    write_json(folder / "metrics.json", metrics)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["outputs"]["metrics.json"] = file_digest(folder / "metrics.json")
    manifest.setdefault("amended", []).append(
        {"file": "metrics.json", "why": why, "when": time.time(), "git_sha": _git_sha()}
    )
    write_json(folder / "manifest.json", manifest)


def _versions() -> dict:
    out = {}
    for name in ("numpy", "warp", "torch"):
        mod = sys.modules.get(name)
        if mod is not None:
            out[name] = getattr(getattr(mod, "config", None), "version", None) or getattr(mod, "__version__", "?")
    return out


def _swap(partial: Path, final: Path) -> None:
    """Put the finished ``partial`` folder at ``final``; a damaged run there is removed, never mixed in."""
    old = None
    if final.exists():
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        os.replace(final, old)
    os.replace(partial, final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def _lock(path: Path) -> Iterator[None]:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"{path.parent}: another run of these settings is running; waiting for it", flush=True)
            fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@contextlib.contextmanager
def start(cfg, stage: str, root=OUTPUTS) -> Iterator[Run]:
    """Open the run of ``stage`` that ``cfg`` describes (see the module's docstring). Inside the block,
    ``run.done`` says the finished run is already there (``run.path``); otherwise the stage writes into
    ``run.dir`` and calls ``run.finish``. Leaving the block without finishing leaves no finished run."""
    ident = identify(cfg, stage)
    final = ident.folder(root)
    upstream = {s: require(u, root) for s, u in ident.upstream.items()}
    with _lock(final.with_name(f".{final.name}.lock")):
        ok, why = intact(final, ident.id)
        if ok:
            print(f"{final}: up to date (a finished run of these settings and inputs)")
            now = _git_sha()  # read once: the reuse's warning and the Run's record
            warn_if_other_code(final, now)
            yield Run(ident, restricted(ident.settings), final, final, True, upstream, git_sha=now)
            return
        if final.exists():
            print(f"{final}: redoing ({why})")
        partial = final.with_name(f".{final.name}.partial")
        if partial.exists() and not STAGES[stage].resumable:
            shutil.rmtree(partial)  # what an interrupted run left: never mixed into this one
        partial.mkdir(parents=True, exist_ok=True)
        run = Run(ident, restricted(ident.settings), final, partial, False, upstream)
        yield run


def warn_if_other_code(folder: Path, now: str | None = None) -> str | None:
    """A finished run reused by code other than the code that made it (another commit, or either checkout with
    uncommitted changes) is a loud warning: a run's identity is what it reads, not its code, so a changed program
    finds the old result "up to date" (the thirty-sixth session kept four runs made by uncommitted code under ids
    the committed code reuses, with other drives). ``now``: this code's commit, when the caller has read it already.
    Returns the warning, or None."""
    import warnings

    made = json.loads((Path(folder) / "manifest.json").read_text()).get("git_sha", "unknown")
    now = _git_sha() if now is None else now
    if (made == now and not now.endswith("-dirty")) or "unknown" in (made, now):
        return None
    why = "with uncommitted changes" if made == now else f"by {made}; this code is {now}"
    msg = (
        f"{folder}: reused, but it was made {why}: a run's identity is its settings and inputs, not its code, so "
        "its results may not be what this code makes. Remove the folder to make it again"
    )
    warnings.warn(msg, stacklevel=4)  # (this, start, contextlib: the caller of runs.start)
    return msg


def cache_dir(cfg, name: str, root=OUTPUTS) -> Path:
    """``outputs/<exp>/<name>/``: caches shared by an experiment's runs (the stream, NOGs); their files are
    named by the digest of what they hold."""
    return Path(root) / str(cfg.exp) / name


def tool_dir(exp: str, tool: str, label: str, settings=None, root=OUTPUTS) -> Path:
    """``outputs/<exp>/<tool>/<label>[-<digest of settings>]/``: a run of a tool outside the stages (the
    released GMapping, the authors' IR-MCL), named by its readable ``label`` and the digest of the
    ``settings`` the tool ran with (any JSON-able value), so two settings never share a folder."""
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", label)
    if settings is not None:
        name += f"-{digest(settings)[:ID_CHARS]}"
    return Path(root) / exp / tool / name


def tool_runs(tool: str, exp: str = "*", root=OUTPUTS) -> list[Path]:
    """The run folders of ``tool`` (of ``exp``) that hold a metrics.json, in order."""
    return sorted(p.parent for p in Path(root).glob(f"{exp}/{tool}/*/metrics.json"))


# --- records ---------------------------------------------------------------------------------------------


class Record(dict):
    """A run's metrics.json, with ``stage``, ``exp``, ``id``, ``config`` (the settings it read), ``path``
    (its folder, None for a kept record) and ``source`` ("outputs" or "results")."""

    def __init__(
        self,
        metrics: dict,
        stage: str,
        exp: str,
        run_id: str,
        config: dict,
        path: Path | None = None,
        source: str = "outputs",
        label: str = "",
    ):
        super().__init__(metrics)
        self.stage, self.exp, self.id, self.config, self.path, self.source = stage, exp, run_id, config, path, source
        self.label = label

    def setting(self, dotted: str, default=None):
        try:
            return _get(self.config, dotted)
        except KeyError:
            return default

    @property
    def settings_id(self) -> str:
        return settings_id(self.config, self.stage)

    @property
    def name(self) -> str:
        """The run's folder name, as ``Identity.name`` (its results-file key and kept files carry it too)."""
        return f"{self.label}-{self.id[:ID_CHARS]}"


def read_record(folder: Path) -> Record:
    """The record of a finished run folder (manifest.json, config.yaml, metrics.json)."""
    from omegaconf import OmegaConf

    folder = Path(folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    config = OmegaConf.to_container(OmegaConf.load(folder / "config.yaml"))
    metrics = json.loads((folder / "metrics.json").read_text()) if (folder / "metrics.json").is_file() else {}
    return Record(
        metrics,
        manifest["stage"],
        manifest["exp"],
        manifest["id"],
        config,
        folder,
        "outputs",
        manifest.get("label", ""),
    )


def records(stage: str | None = None, exp: str | None = None, root=OUTPUTS) -> list[Record]:
    """Every finished run under ``root`` (of ``stage``, of ``exp``), in folder order."""
    pattern = f"{exp or '*'}/{stage or '*'}/*/manifest.json"
    out = []
    for m in sorted(Path(root).glob(pattern)):
        if m.parent.name.startswith("."):
            continue
        try:
            out.append(read_record(m.parent))
        except Exception as e:  # a file cut short or edited by hand (JSON, YAML): say which run, not a parser's trace
            raise ValueError(
                f"{m.parent}: unreadable run record ({e}); remove the folder or run its stage again"
            ) from e
    return out


def matches(record: Record, **where) -> bool:
    """``where``: settings as keyword arguments, ``section__key=value`` (``mcl__weighting="nog_raymarch"``)."""
    for key, value in where.items():
        missing = object()
        got = record.setting(key.replace("__", "."), missing)
        if got is missing or got != value:
            return False
    return True


def find(stage: str, exp: str | None = None, root=OUTPUTS, among: list[Record] | None = None, **where) -> list[Record]:
    """The records of ``stage`` (of ``exp``) whose settings have the values ``where`` names."""
    pool = (
        records(stage, exp, root)
        if among is None
        else [r for r in among if r.stage == stage and (exp is None or r.exp == exp)]
    )
    return [r for r in pool if matches(r, **where)]
