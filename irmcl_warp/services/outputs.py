"""Stage outputs: ``outputs/<exp>/<stage>/`` with config.yaml, manifest.json and artifacts, written
atomically (temporary file + rename), so an interrupted run never leaves a half-written file.

manifest.json is written last and is the mark of a finished stage: it holds the digest of the resolved
config, of every input file and of every file the stage wrote. ``stage_complete`` checks all three, so a
folder from an interrupted run, a file edited or truncated since, or a changed setting reads as not done
(the pipeline and ``eval.reproduce`` then run the stage again). The code version (git sha) is recorded but
not compared: a code change alone does not redo a finished stage.
"""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
import time
from pathlib import Path

from irmcl_warp.io.atomic import atomic_write_bytes

REPO = Path(__file__).resolve().parents[1]


def settings_key(*parts) -> str:
    """A short digest of settings (any JSON-able parts): cache keys and resume keys."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def write_json(path, obj) -> Path:
    atomic_write_bytes(Path(path), (json.dumps(obj, indent=2, sort_keys=True, default=float) + "\n").encode())
    return Path(path)


def save_figure(fig, path) -> Path:
    """A matplotlib figure as PNG, written atomically, then closed."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


def file_digest(path, chunk=1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def _git_sha() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def stage_dir(cfg, stage: str, root="outputs") -> Path:
    """``outputs/<exp>/<stage>``; not created here: the first file written makes it, so a stage that fails
    before writing anything leaves no empty folder behind."""
    return Path(root) / cfg.exp / stage


# the config sections each stage reads: a change elsewhere (say mcl.* for a SLAM run) leaves it finished
SECTIONS = {
    "slam": ("data", "sim", "slam", "device"),
    "train": ("data", "sim", "model", "render", "train", "device"),
    "synthesis": ("data", "sim", "model", "render", "train", "mapping", "raycast", "device"),
    "localize": ("data", "sim", "model", "render", "train", "mapping", "raycast", "mcl", "localize", "device"),
    "globloc": ("data", "sim", "globloc", "device"),
}


def config_digest(cfg) -> str:
    """sha256 of the resolved config."""
    from omegaconf import OmegaConf

    return hashlib.sha256(OmegaConf.to_yaml(cfg, resolve=True).encode()).hexdigest()


def section_digests(cfg, sections=None) -> dict[str, str]:
    """{top-level key: sha256 of that section alone} for ``sections`` (default: every key), from one
    resolution of the config."""
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True)
    return {k: hashlib.sha256(json.dumps({k: c.get(k)}, sort_keys=True, default=str).encode()).hexdigest()
            for k in (c if sections is None else sections)}


def output_digests(out: Path) -> dict[str, str]:
    """sha256 of every file under ``out`` except manifest.json and temporary files, by relative path."""
    return {str(p.relative_to(out)): file_digest(p) for p in sorted(Path(out).rglob("*"))
            if p.is_file() and p.name != "manifest.json" and not p.name.endswith(".tmp")}


def write_manifest(out: Path, cfg, inputs: list[Path], device: str, started: float) -> Path:
    """config.yaml (resolved) and manifest.json (git sha, versions, device, digests of the config, the
    inputs and the outputs, wall time); call it last, once every artifact is written."""
    from omegaconf import OmegaConf
    import numpy
    import warp

    atomic_write_bytes(out / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True).encode())
    manifest = {
        "git_sha": _git_sha(), "python": platform.python_version(), "numpy": numpy.__version__,
        "warp": warp.config.version, "device": device, "wall_time_s": time.time() - started,
        "config_sha256": config_digest(cfg),
        "config_sections_sha256": section_digests(cfg),
        "inputs": {str(p): file_digest(p) for p in inputs if Path(p).is_file()},
        "outputs": output_digests(out),
    }
    return write_json(out / "manifest.json", manifest)


def stage_complete(out, cfg=None, inputs=None, sections=None) -> tuple[bool, str]:
    """(finished, why not): ``out`` holds a manifest whose output digests match the files, every JSON file
    parses, and (when given) the config (all of it, or the ``sections`` the stage reads) and the input
    files are those it was made from."""
    out = Path(out)
    path = out / "manifest.json"
    if not path.is_file():
        return False, f"{path} missing: the stage never finished there"
    try:
        manifest = json.loads(path.read_text())
        outputs = manifest["outputs"]
    except (ValueError, KeyError, TypeError):
        return False, f"{path} is malformed or from before output digests were recorded"
    for rel, digest in outputs.items():
        f = out / rel
        if not f.is_file():
            return False, f"{f} listed in the manifest but missing"
        if file_digest(f) != digest:
            return False, f"{f} differs from what the stage wrote (edited, truncated or half-rewritten)"
        if f.suffix == ".json":
            try:
                json.loads(f.read_text())
            except ValueError as e:
                return False, f"{f} is not valid JSON ({e})"
    if cfg is not None:
        stored = manifest.get("config_sections_sha256", {}) if sections else {"all": manifest.get("config_sha256")}
        now = section_digests(cfg, sections) if sections else {"all": config_digest(cfg)}
        changed = [k for k in now if stored.get(k) != now[k]]
        if changed:
            return False, f"{out}: made with other settings ({', '.join(changed)}; config.yaml there shows them)"
    for p in inputs or []:
        if Path(p).is_file() and manifest["inputs"].get(str(p)) != file_digest(p):
            return False, f"{out}: input {p} changed since"
    return True, ""


def up_to_date(out, cfg, inputs=None, stage=None) -> bool:
    """True (and says so) when ``out`` is a finished ``stage`` (a key of SECTIONS; None: the whole config)
    of these settings and inputs: the stage then returns at once. An unfinished or damaged one is reported
    and redone."""
    done, why = stage_complete(out, cfg, inputs, SECTIONS.get(stage))
    if done:
        print(f"{out}: up to date (same settings and inputs; remove the folder to run it again)")
    elif (Path(out) / "manifest.json").exists():
        print(f"{out}: redoing, {why}")
    return done
