"""Where the NOF stages write, so that a stage reading a trained field finds it without importing the
training stage: ``outputs/<exp>/train-<preset>[-<renderer>]/`` and ``synthesis-<...>/``."""

from __future__ import annotations


def run_name(cfg) -> str:
    """The preset, plus the renderer when it is not the default (``fast-torch_ref``): folder names."""
    return cfg.train.name + ("" if cfg.render.name == "warp" else f"-{cfg.render.name}")


def train_folder(cfg) -> str:
    """One folder per recipe, so presets never overwrite each other's nof.pt."""
    return f"train-{run_name(cfg)}"


def synthesis_folder(cfg) -> str:
    return f"synthesis-{run_name(cfg)}"
