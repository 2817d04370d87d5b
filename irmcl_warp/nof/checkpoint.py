"""Checkpoints: ``nof.pt`` (the model to use: weights + the config that builds it + rendering bounds) and
``last.pt`` (everything needed to resume training). Both are written atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import torch

from irmcl_warp.config import ModelConfig
from irmcl_warp.io.atomic import raise_disk_full
from irmcl_warp.nof.model import NOF


def atomic_torch_save(obj, path: Path) -> None:
    """``torch.save`` through a temporary file of its own (named for this process) and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    os.close(fd)
    try:
        torch.save(obj, tmp)
        os.replace(tmp, path)
    except BaseException as e:
        Path(tmp).unlink(missing_ok=True)
        raise_disk_full(e, path)
        raise


def load_nof(path, device="cpu"):
    """(model in eval mode, metadata dict) from a ``nof.pt``; the model is rebuilt from its stored config (and read
    through its training grid when the checkpoint holds one: ``train.grid_masks_field``, nof/occupancy.py)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no NOF checkpoint (train one: python -m irmcl_warp.train +exp=<name>)")
    try:
        ckpt = torch.load(path, map_location=device, weights_only=False)
        model = NOF(ModelConfig(**ckpt["model_config"]))
        model.load_state_dict(ckpt["model"])
    except (KeyError, RuntimeError, EOFError) as e:
        raise ValueError(f"{path}: not a usable nof.pt ({type(e).__name__}: {e})") from e
    mask = ckpt.get("field_mask")
    if mask is not None:  # trained with train.grid_masks_field: the grid is part of the field
        from irmcl_warp.nof.occupancy import MaskedField

        model = MaskedField(model, **mask)
    return model.to(device).eval(), {k: v for k, v in ckpt.items() if k not in ("model", "field_mask")}


def check_trained_far_bound(path, meta: dict, far_m: float) -> None:
    """A NOF answers for the ranges it was trained on: localizing with another far bound than its training's
    (``far_m`` in nof.pt) renders and scores beams the field never learned, so it is an error naming both."""
    trained = meta.get("far_m")
    if trained is not None and abs(float(trained) - float(far_m)) > 1e-6:
        raise ValueError(
            f"{path}: this NOF was trained with the far bound {float(trained):g} m, and this run localizes with "
            f"{float(far_m):g} m (data.far_m, else the floor of the log's range_max): localize with "
            f"data.far_m={float(trained):g}, or train a NOF for {float(far_m):g} m"
        )


def load_nof_for(path, far_m: float, device="cpu"):
    """``load_nof``, refused (``check_trained_far_bound``) when the NOF was trained for another far bound."""
    model, meta = load_nof(path, device)
    check_trained_far_bound(path, meta, far_m)
    return model, meta
