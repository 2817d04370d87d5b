"""Finished run folders made by hand, for tests of what reads runs (records, tables, the reference tools):
the same files and manifest a stage leaves (irmcl_warp.runs), with contents the test chooses."""

from __future__ import annotations

import json
from pathlib import Path

from omegaconf import OmegaConf

from irmcl_warp import runs
from irmcl_warp.config import compose_config


def composed(*overrides) -> dict:
    """The resolved config of ``overrides`` as a container."""
    return OmegaConf.to_container(compose_config(list(overrides)), resolve=True)


def fake_run(root: Path, stage: str, config: dict, metrics: dict, files: dict | None = None, upstream=None) -> Path:
    """A finished run of ``stage`` under ``root`` (outputs/): the settings ``stage`` reads from ``config``,
    ``metrics`` as metrics.json, ``files`` ({name: text}) beside them, a manifest as Run.finish writes it."""
    settings = runs.read_settings(config, stage)
    run_id = runs.digest([stage, settings, metrics, sorted((files or {}).items())])
    label = runs.label_of(stage, config)
    folder = Path(root) / str(config["exp"]) / stage / f"{label}-{run_id[: runs.ID_CHARS]}"
    folder.mkdir(parents=True)
    for name, text in (files or {}).items():
        (folder / name).write_text(text)
    (folder / "metrics.json").write_text(json.dumps(metrics))
    (folder / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(settings)))
    manifest = {
        "id": run_id,
        "stage": stage,
        "exp": config["exp"],
        "label": label,
        "upstream": upstream or {},
        "outputs": runs.output_digests(folder),
    }
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder
