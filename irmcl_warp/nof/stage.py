"""The train stage: ``python -m irmcl_warp.train +exp=<name> [train=paper|fast|cpu|quick] [render=warp|torch_ref]``

Trains the NOF on the ``train`` split (the benchmark ids) and writes ``outputs/<exp>/train/<preset>-<id>/``
(irmcl_warp.runs): nof.pt (best epoch on the validation split, with its model config), last.pt (to resume),
metrics.json (history per epoch), config.yaml, manifest.json. Run it again after an interruption and it
resumes the interrupted run (its ``.partial`` folder); a run that did not finish is never used by another
stage.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from irmcl_warp.config import ModelConfig
from irmcl_warp import runs
from irmcl_warp.nof.model import NOF
from irmcl_warp.nof.render import make_renderer, render_scans
from irmcl_warp.nof.trainer import Trainer
from irmcl_warp.services.data import far_bound_m, load_stream, prepare_beams
from irmcl_warp.services.metrics import scan_synthesis_metrics
from irmcl_warp.kernels import pick_device


def torch_device(cfg) -> torch.device:
    """The torch device matching Warp's choice (``device=cpu`` forces the CPU for both)."""
    return torch.device(pick_device(cfg.device))


def run_settings(cfg, train_split: str, far_m: float) -> dict:
    """What nof.pt stores beside the weights: the model config, the rendering bounds, the data and preset."""
    model_cfg = ModelConfig(**OmegaConf.to_container(cfg.model))
    return {
        "model_config": asdict(model_cfg),
        "near_m": cfg.render.near_m,
        "far_m": far_m,
        "render": OmegaConf.to_container(cfg.render),
        "data": cfg.data.name,
        "split": cfg.data.split,
        "train_split": train_split,
        "train_preset": cfg.train.name,
    }


def make_validator(beams, cfg, near_m, far_m, device):
    """Render ``train.val_scans`` evenly spread validation scans and score them."""
    k = min(len(beams), cfg.train.val_scans)
    sub = beams.subset(np.linspace(0, len(beams) - 1, k).round().astype(int))
    renderer = make_renderer(cfg.render.name, normalize=cfg.render.normalize, t_min=cfg.render.t_min)

    def validate(model):
        pred = render_scans(model, sub, renderer, cfg.render.num_samples, near_m, far_m, cfg.render.chunk_rays, device)
        return scan_synthesis_metrics(pred, sub.ranges_m, sub.valid, sub.angles_rad)

    return validate


def run_train(cfg) -> Path:
    with runs.start(cfg, "train") as run:
        return run.path if run.done else train(run)


def train(run: runs.Run) -> Path:
    """Train (or go on training, after an interruption of the same run) in ``run.dir``."""
    cfg, out = run.cfg, run.dir
    device = torch_device(cfg)
    if cfg.train.tf32:
        torch.backends.cuda.matmul.allow_tf32 = torch.backends.cudnn.allow_tf32 = True
    torch.manual_seed(cfg.train.seed)
    sets = prepare_beams(cfg)
    near, far_m = cfg.render.near_m, far_bound_m(cfg, load_stream(cfg).info.range_max_m)  # (data.far_m, else the log's)
    meta = run_settings(cfg, sets["train"].name, far_m)
    model_cfg = ModelConfig(**meta["model_config"])
    trainer = Trainer(
        NOF(model_cfg),
        sets,
        cfg.train,
        cfg.render,
        near,
        far_m,
        device,
        out,
        run.ident.id,
        make_validator(sets["val"], cfg, near, far_m, device),
        meta,
    )
    trainer.try_resume()
    print(
        f"{cfg.data.name}: training on {len(sets['train'])} scans ({sets['train'].num_rays:,} rays, split "
        f"{sets['train'].name}), {trainer.steps_per_epoch} steps of {cfg.train.batch_rays} rays per epoch, "
        f"preset {cfg.train.name}, renderer {cfg.render.name}, device {device}"
    )
    history = trainer.run()
    if not history:
        raise RuntimeError("no epoch finished: raise train.max_time_s or lower the batch")
    best = trainer.best
    metrics = {
        "preset": cfg.train.name,
        "device": str(device),
        "gpu": torch.cuda.get_device_name() if device.type == "cuda" else None,
        "epochs_done": len(history),
        "best_epoch": best["epoch"],
        "val": best["val"],
        "train_time_s": trainer.train_time_s,
        "train_rays": sets["train"].num_rays,
        "rays_per_s": float(np.mean([h["rays_per_s"] for h in history])),
        "history": history,
    }
    path = run.finish(metrics, str(device))
    print(
        f"best epoch {best['epoch']}: val MAE {best['val']['mae_m']:.3f} m -> {path / 'nof.pt'} "
        f"({trainer.train_time_s:.0f} s of training)"
    )
    return path
