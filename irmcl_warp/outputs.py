"""Stage outputs: ``outputs/<exp>/<stage>/`` with config.yaml, manifest.json and artifacts, written
atomically (temporary file + rename), so an interrupted run never leaves a half-written file."""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
import time
from pathlib import Path

from irmcl_warp.mapping.mapio import atomic_write_bytes

REPO = Path(__file__).resolve().parents[1]


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
    out = Path(root) / cfg.exp / stage
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_manifest(out: Path, cfg, inputs: list[Path], device: str, started: float) -> Path:
    """config.yaml (resolved) and manifest.json (git sha, versions, device, input hashes, wall time)."""
    from omegaconf import OmegaConf
    import numpy
    import warp

    atomic_write_bytes(out / "config.yaml", OmegaConf.to_yaml(cfg, resolve=True).encode())
    manifest = {
        "git_sha": _git_sha(), "python": platform.python_version(), "numpy": numpy.__version__,
        "warp": warp.config.version, "device": device, "wall_time_s": time.time() - started,
        "inputs": {str(p): file_digest(p) for p in inputs if Path(p).is_file()},
    }
    return write_json(out / "manifest.json", manifest)
