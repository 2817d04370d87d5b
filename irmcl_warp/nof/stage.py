"""The train stage: ``python -m irmcl_warp.train +exp=<name> [train=paper|fast|cpu|quick] [render=warp|torch_ref]``

Trains the NOF on the ``train`` split (the benchmark ids) and writes ``outputs/<exp>/train-<preset>/``:
nof.pt (best epoch on the validation split, with its model config), last.pt (to resume), metrics.json
(history per epoch), config.yaml, manifest.json. Run it again after an interruption and it resumes.
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from omegaconf import OmegaConf

from irmcl_warp.config import ModelConfig
from irmcl_warp.io import resolve
from irmcl_warp.nof.folders import train_folder
from irmcl_warp.nof.model import NOF
from irmcl_warp.nof.render import make_renderer, render_scans
from irmcl_warp.nof.trainer import Trainer
from irmcl_warp.services.data import far_bound_m, prepare_beams, recorded_inputs
from irmcl_warp.services.metrics import scan_synthesis_metrics
from irmcl_warp.services.outputs import file_digest, settings_key, stage_dir, up_to_date, write_json, write_manifest
from kernels import pick_device


def torch_device(cfg) -> torch.device:
    """The torch device matching Warp's choice (``device=cpu`` forces the CPU for both)."""
    return torch.device(pick_device(cfg.device))


def train_dir(cfg) -> Path:
    """``outputs/<exp>/train-<preset>/``: one folder per recipe, so presets never overwrite each other."""
    return stage_dir(cfg, train_folder(cfg))


def run_settings(cfg, train_split: str, far: float) -> tuple[dict, str]:
    """(metadata stored in nof.pt, key of the settings that decide the result). Time limits, checkpoint
    period and validation size are not in the key: a run resumed with a longer max_time_s continues."""
    model_cfg = ModelConfig(**OmegaConf.to_container(cfg.model))
    meta = {"model_config": asdict(model_cfg), "near_m": cfg.render.near_m, "far_m": far,
            "render": OmegaConf.to_container(cfg.render), "data": cfg.data.name, "split": cfg.data.split,
            "train_split": train_split, "train_preset": cfg.train.name}
    recipe = {k: v for k, v in OmegaConf.to_container(cfg.train).items()
              if k not in ("max_time_s", "checkpoint_every_s", "val_scans")}
    data = OmegaConf.to_container(cfg.data)
    if data.get("train_poses_path"):  # the poses file is rewritten in place (the pipeline's SLAM): its content counts
        data["train_poses_sha256"] = file_digest(resolve(data["train_poses_path"]))
    return meta, settings_key(meta, recipe, data)


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
    started = time.time()
    device = torch_device(cfg)
    if cfg.train.tf32:
        torch.backends.cuda.matmul.allow_tf32 = torch.backends.cudnn.allow_tf32 = True
    torch.manual_seed(cfg.train.seed)
    out = train_dir(cfg)
    if up_to_date(out, cfg, recorded_inputs(cfg), "train"):
        return out
    sets = prepare_beams(cfg)
    near, far = cfg.render.near_m, far_bound_m(cfg)
    meta, key = run_settings(cfg, sets["train"].name, far)
    model_cfg = ModelConfig(**meta["model_config"])
    trainer = Trainer(NOF(model_cfg), sets, cfg.train, cfg.render, near, far, device, out, key,
                      make_validator(sets["val"], cfg, near, far, device), meta)
    trainer.try_resume()
    print(f"{cfg.data.name}: training on {len(sets['train'])} scans ({sets['train'].num_rays:,} rays, split "
          f"{sets['train'].name}), {trainer.steps_per_epoch} steps of {cfg.train.batch_rays} rays per epoch, "
          f"preset {cfg.train.name}, renderer {cfg.render.name}, device {device}")
    history = trainer.run()
    if not history:
        raise RuntimeError("no epoch finished: raise train.max_time_s or lower the batch")
    best = trainer.best
    metrics = {"preset": cfg.train.name, "device": str(device), "gpu": torch.cuda.get_device_name() if device.type == "cuda" else None,
               "epochs_done": len(history), "best_epoch": best["epoch"], "val": best["val"],
               "train_time_s": trainer.train_time_s, "train_rays": sets["train"].num_rays,
               "rays_per_s": float(np.mean([h["rays_per_s"] for h in history])), "history": history}
    write_json(out / "metrics.json", metrics)
    write_manifest(out, cfg, recorded_inputs(cfg), str(device), started)
    print(f"best epoch {best['epoch']}: val MAE {best['val']['mae_m']:.3f} m -> {out / 'nof.pt'} "
          f"({trainer.train_time_s:.0f} s of training)")
    return out
