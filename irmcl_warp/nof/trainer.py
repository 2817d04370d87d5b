"""The NOF training loop (IR-MCL Sec. III-B): render each training beam from its pose through the NOF,
compare with the measured range, and add the occupancy regulariser.

    loss = SmoothL1(r_rendered, r_measured) + lambda * mean(log(0.1 + p) + log(1.1 - p) + 2.20727)

The regulariser (from the authors' code, zero at p = 0 and p = 1, largest at p = 0.5) pushes occupancy
towards certainty. Invalid (no return / out of range) beams are never in the training rays.
``train.sampler=occupancy`` asks the MLP only about the samples a coarse grid of the field says may be
occupied (irmcl_warp/nof/occupancy.py); the loss is the same formula over the same depths.
``train.bn_recalibrate=K`` recomputes batch norm's running statistics over K batches before each
validation (an average over K batches instead of the last ~10 steps' momentum average).
``train.lr_schedule=cosine`` changes the learning rate after every step (warm-up, then a cosine to
``lr * lr_final`` at the run's last step); ``train.ema_decay`` validates and keeps an average of the weights.
Resumable: ``last.pt`` is written at the end of every epoch and every ``checkpoint_every_s``.
"""

from __future__ import annotations

import contextlib
import copy
import itertools
import math
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from tqdm import tqdm

from irmcl_warp.nof.checkpoint import atomic_torch_save
from irmcl_warp.nof.occupancy import OccupancyGrid
from irmcl_warp.nof.render import make_renderer, render_rays, sample_depths, sample_points
from irmcl_warp.nof.step_graph import StepGraph


def opacity_regulariser(p: torch.Tensor) -> torch.Tensor:
    return torch.mean(torch.log(0.1 + p) + torch.log(1.1 - p) + 2.20727)


def range_loss(pred, target, kind: str):
    if kind == "smooth_l1":
        return F.smooth_l1_loss(pred, target)
    if kind == "l1":
        return F.l1_loss(pred, target)
    raise ValueError(f"train.loss={kind!r}: expected smooth_l1 or l1")


def make_scheduler(opt, tc, total_steps: int):
    """(scheduler, stepped after every optimiser step?): ``multistep`` is stepped once per epoch (the authors'),
    ``cosine`` once per step, over the run's ``total_steps``."""
    if tc.lr_schedule == "multistep":
        return torch.optim.lr_scheduler.MultiStepLR(opt, list(tc.lr_milestones), tc.lr_gamma), False
    if tc.lr_schedule != "cosine":
        raise ValueError(f"train.lr_schedule={tc.lr_schedule!r}: expected multistep or cosine")
    warm, final = int(tc.warmup_steps), float(tc.lr_final)

    def factor(step: int) -> float:
        if step < warm:
            return (step + 1) / warm
        t = min(1.0, (step - warm) / max(1, total_steps - 1 - warm))
        return final + (1.0 - final) * 0.5 * (1.0 + math.cos(math.pi * t))

    return torch.optim.lr_scheduler.LambdaLR(opt, factor), True


class WeightAverage:
    """An exponential moving average of a model's floating-point parameters and buffers (batch norm's
    running statistics too), updated after every step: avg <- avg + (1 - d) (w - avg) with
    d = min(decay, (1 + n) / (10 + n)) at the n-th update, so the first steps do not tie it to the initial
    weights. ``module`` is the averaged copy, always in eval mode."""

    def __init__(self, model, decay: float):
        if not 0.0 < decay < 1.0:
            raise ValueError(f"train.ema_decay={decay}: expected a value in (0, 1), or null for no average")
        self.module, self.decay, self.n = copy.deepcopy(model).eval(), float(decay), 0
        for p in self.module.parameters():
            p.requires_grad_(False)
        # detached views of the live tensors, made once: they share storage with the weights the optimiser
        # and batch norm update in place, so every update reads the current values
        self._avg, self._live = self._floats(self.module), [t.detach() for t in self._floats(model)]

    @staticmethod
    def _floats(model) -> list[torch.Tensor]:
        return [t for t in itertools.chain(model.parameters(), model.buffers()) if t.is_floating_point()]

    @torch.no_grad()
    def update(self) -> None:
        d = min(self.decay, (1 + self.n) / (10 + self.n))
        torch._foreach_lerp_(self._avg, self._live, 1.0 - d)
        self.n += 1

    def state_dict(self) -> dict:
        return {"model": self.module.state_dict(), "n": self.n}

    def load_state_dict(self, s: dict) -> None:
        self.module.load_state_dict(s["model"])
        self.n = int(s["n"])


class Trainer:
    """Owns the model, optimiser, schedule and rays of one run; ``run()`` trains and returns the history."""

    def __init__(self, model, sets, tc, rc, near_m, far_m, device, out: Path, key: str, validate, meta: dict):
        self.meta = meta  # stored in nof.pt beside the weights (model config, rendering bounds, data)
        self.model, self.tc, self.rc, self.device, self.out, self.key = model.to(device), tc, rc, device, out, key
        self.near_m, self.far_m, self.validate = near_m, far_m, validate
        self.renderer = make_renderer(rc.name, normalize=rc.normalize, t_min=rc.t_min)
        o, d, r, _ = sets["train"].rays()
        self.origins, self.dirs, self.ranges = (torch.from_numpy(a).to(device) for a in (o, d, r))
        # train.fixed_samples: the same number of samples through the MLP at every step (render_rays' count)
        self.count = round(tc.fixed_samples * tc.batch_rays) if tc.fixed_samples > 0 else 0
        if self.count and tc.sampler != "occupancy":
            raise ValueError(
                f"train.fixed_samples={tc.fixed_samples} needs train.sampler=occupancy (the uniform sampler sends "
                f"all {tc.num_samples} samples of every beam)"
            )
        if tc.grid_masks_field and tc.sampler != "occupancy":
            raise ValueError(
                "train.grid_masks_field=true needs train.sampler=occupancy (it reads the field through its grid)"
            )
        if tc.fixed_samples > tc.num_samples:
            raise ValueError(f"train.fixed_samples={tc.fixed_samples}: more than the {tc.num_samples} samples per beam")
        self.grid = OccupancyGrid(o, o + d * r[:, None], tc, device) if tc.sampler == "occupancy" else None
        if self.grid is not None:  # its readings grow with the map's area: say what they cost
            cells = self.grid.values.numel()
            print(
                f"occupancy grid: {self.grid.shape[0]} x {self.grid.shape[1]} cells of {tc.grid_resolution_m} m, "
                f"read every {tc.grid_every} steps ({cells:,} points, {cells / (tc.batch_rays * tc.num_samples):.0%} "
                f"of a batch's samples)"
            )
        if tc.fixed_samples_share > 0:  # the fixed count from this log's geometry, not typed per log
            if self.grid is None:
                raise ValueError("train.fixed_samples_share needs train.sampler=occupancy")
            start = self.grid.starting_samples_per_beam(self.origins, self.dirs, tc.num_samples, near_m, far_m)
            fixed = min(tc.num_samples, math.ceil(tc.fixed_samples_share * start))
            self.count = fixed * tc.batch_rays
            print(
                f"train.fixed_samples_share={tc.fixed_samples_share:g}: {fixed} samples per beam through the MLP "
                f"(the starting grid keeps {start:.1f} per beam on this log's rays)"
            )
        # the training pass may run compiled (for fixed shapes with fixed_samples); the grid's readings (eval mode, no
        # gradient) use the module as is
        self.net = torch.compile(self.model, dynamic=not self.count, mode=tc.compile_mode) if tc.compile else self.model
        # CUDA graphs (reduce-overhead, max-autotune) replay into the same output buffers: each step says it begins
        self.graphed = tc.compile and tc.compile_mode in ("reduce-overhead", "max-autotune")
        self.kept, self.read = [], []  # per step of the epoch: samples per beam through the MLP with / without gradient
        self.cut = []  # per step, with train.fixed_samples: the share of the kept samples left out
        if tc.step_graph:  # what a captured step needs (irmcl_warp/nof/step_graph.py)
            why = [
                (torch.device(device).type != "cuda", "a CUDA device"),
                (tc.sampler == "occupancy" and not self.count, "fixed shapes: train.fixed_samples > 0"),
                (tc.sampler == "occupancy" and tc.grid_end == "field", "train.grid_end none or grid (field syncs)"),
                (self.graphed, "train.compile_mode without CUDA graphs of its own (default)"),
            ]
            missing = [w for bad, w in why if bad]
            if missing:
                raise ValueError(f"train.step_graph=true needs {', '.join(missing)}")
        self.step_graph = None  # captured at the first step with train.step_graph
        self.opt = torch.optim.Adam(
            model.parameters(),
            # a captured Adam reads its learning rate from a tensor the schedule fills in place
            lr=torch.tensor(tc.lr, device=device) if tc.step_graph else tc.lr,
            weight_decay=tc.weight_decay,
            fused=True if tc.fused_adam and torch.device(device).type == "cuda" else None,
            capturable=bool(tc.step_graph),
        )
        self.epoch, self.step_in_epoch, self.history, self.best, self.train_time_s = 0, 0, [], None, 0.0
        self.epoch_loss = (
            0.0,
            0,
        )  # (sum, steps) of the epoch's losses before an interruption: a resumed epoch's mean is the whole epoch's
        # an epoch is one pass over the rays, or ``steps_per_epoch`` batches (fewer or more than a pass)
        self.steps_per_epoch = tc.steps_per_epoch or -(-len(self.ranges) // tc.batch_rays)
        self.sched, self.sched_per_step = make_scheduler(self.opt, tc, tc.epochs * self.steps_per_epoch)
        self.ema = WeightAverage(self.model, tc.ema_decay) if tc.ema_decay is not None else None

    @property
    def kept_model(self):
        """The weights validated and written to nof.pt: the average when ``train.ema_decay`` is set."""
        return self.ema.module if self.ema is not None else self.model

    def field(self):
        """The field validated: the kept weights, read through the grid with ``train.grid_masks_field``."""
        return self.grid.masked(self.kept_model) if self.tc.grid_masks_field else self.kept_model

    # --- checkpointing -------------------------------------------------------------------------
    def state(self) -> dict:
        rng = {"cpu": torch.get_rng_state()}
        if torch.cuda.is_available():
            rng["cuda"] = torch.cuda.get_rng_state_all()
        return {
            "key": self.key,
            "model": self.model.state_dict(),
            "opt": self.opt.state_dict(),
            "sched": self.sched.state_dict(),
            "epoch": self.epoch,
            "step_in_epoch": self.step_in_epoch,
            "history": self.history,
            "best": self.best,
            "train_time_s": self.train_time_s,
            "rng": rng,
            "epoch_loss": self.epoch_loss,
            "grid": None if self.grid is None else self.grid.state_dict(),
            "ema": None if self.ema is None else self.ema.state_dict(),
        }

    def try_resume(self) -> bool:
        path = self.out / "last.pt"
        if not path.is_file():
            return False
        try:
            s = torch.load(path, map_location=self.device, weights_only=False)
        except Exception as e:  # truncated by a full disk or a copy cut short: say what to do, no traceback
            raise ValueError(
                f"{path}: damaged checkpoint ({type(e).__name__}: {e}); delete it to train this run afresh (rm {path})"
            ) from e
        if s.get("key") != self.key:
            print(f"{path}: made with other settings; starting afresh")
            return False
        if s["best"] is not None and not (self.out / "nof.pt").is_file():
            print(f"{path}: its best checkpoint nof.pt is gone; starting afresh")
            return False
        self.model.load_state_dict(s["model"])
        self.opt.load_state_dict(s["opt"])
        self.sched.load_state_dict(s["sched"])
        self.epoch, self.step_in_epoch, self.history = s["epoch"], s["step_in_epoch"], s["history"]
        self.best, self.train_time_s = s["best"], s["train_time_s"]
        self.epoch_loss = tuple(s.get("epoch_loss", (0.0, 0)))
        if self.grid is not None and s.get("grid") is not None:
            self.grid.load_state_dict(s["grid"])
        if self.ema is not None:
            self.ema.load_state_dict(s["ema"])
        torch.set_rng_state(s["rng"]["cpu"].cpu())  # map_location moved it to the device
        if "cuda" in s["rng"] and torch.cuda.is_available():
            torch.cuda.set_rng_state_all([t.cpu() for t in s["rng"]["cuda"]])
        print(f"resuming {path}: epoch {self.epoch}, step {self.step_in_epoch}")
        return True

    # --- one optimisation step -----------------------------------------------------------------
    def amp(self):
        if self.tc.amp == "bf16" and self.device.type == "cuda":
            return torch.autocast("cuda", dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def step(self, idx: torch.Tensor) -> float:
        tc = self.tc
        if self.graphed:
            torch.compiler.cudagraph_mark_step_begin()
        if tc.step_graph and self.step_graph is None:
            self.step_graph = StepGraph(self, idx)
        due = self.grid is not None and (self.epoch * self.steps_per_epoch + self.step_in_epoch) % tc.grid_every == 0
        if self.step_graph is None:
            self.opt.zero_grad(set_to_none=True)
            out = self._body(idx, read_grid=due)
        else:
            if due:  # in place: the captured step reads the grid's tensors where they are
                self.grid.update(self.model, self.amp)
            out = [t.clone() if t is not None else None for t in self.step_graph.replay(idx)]
        loss, kept, read, cut = out
        if self.grid is not None:
            self.kept.append(kept)
            self.read.append(read)
            if cut is not None:
                self.cut.append(cut)
        if self.sched_per_step:
            self.sched.step()
        if self.ema is not None:
            self.ema.update()
        return loss

    def _body(self, idx: torch.Tensor, read_grid: bool = False) -> tuple:
        """One step's device work: sample (reading the grid first with ``read_grid``), render, loss, backward, Adam.
        Returns (loss, samples per beam through the MLP, read without gradient, the share of kept ones cut) as
        tensors, with no sync, so ``train.step_graph`` can capture it whole (and reads the grid before a replay)."""
        tc = self.tc
        z = sample_depths(len(idx), tc.num_samples, self.near_m, self.far_m, tc.perturb, device=self.device)
        if read_grid:
            self.grid.update(self.model, self.amp)
        o, d, keep = self.origins[idx], self.dirs[idx], None
        kept = read = cut = None
        if self.grid is not None:
            keep = self.grid.keep(sample_points(o, d, z), self.model, self.amp)
            n_kept = keep.sum()
            kept = n_kept / len(idx) if not self.count else torch.full((), self.count / len(idx), device=self.device)
            read = self.grid.read / len(idx)
            if self.count:  # the kept samples left out for the fixed count, as a share of those kept
                cut = (n_kept - self.count).clamp(min=0) / n_kept.clamp(min=1)
        with self.amp():
            pred, _, p = render_rays(self.net, self.renderer, o, d, z, keep, self.count)
        loss = range_loss(pred, self.ranges[idx], tc.loss) + tc.lambda_opacity * opacity_regulariser(p)
        loss.backward()
        self.opt.step()
        return loss.detach(), kept, read, cut

    @torch.no_grad()
    def recalibrate_batch_norm(self, batches: int) -> None:
        """Batch norm's running statistics of the kept weights as the plain average over ``batches`` fresh
        training batches (sampled as a step samples them, from a generator of their own; the MLP in train
        mode, no gradient). The batches are drawn first: the occupancy sampler reads the field with the
        statistics as they were."""
        gen = torch.Generator(device=self.device).manual_seed(self.tc.seed * 7919 + self.epoch)
        drawn = []
        for _ in range(batches):
            idx = torch.randint(len(self.ranges), (self.tc.batch_rays,), device=self.device, generator=gen)
            z = sample_depths(
                len(idx),
                self.tc.num_samples,
                self.near_m,
                self.far_m,
                self.tc.perturb,
                device=self.device,
                generator=gen,
            )
            o, d = self.origins[idx], self.dirs[idx]
            keep = None if self.grid is None else self.grid.keep(sample_points(o, d, z), self.model, self.amp)
            drawn.append((o, d, z, keep))
        model = self.kept_model
        bns = [m for m in model.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)]
        momenta, was_training = [m.momentum for m in bns], model.training
        for m in bns:
            m.reset_running_stats()
            m.momentum = None  # a cumulative average
        model.train()
        for o, d, z, keep in drawn:
            with self.amp():
                render_rays(model, self.renderer, o, d, z, keep)
        for m, mom in zip(bns, momenta):
            m.momentum = mom
        model.train(was_training)

    def run(self) -> list[dict]:
        tc = self.tc
        while self.epoch < tc.epochs:
            if tc.max_time_s is not None and self.train_time_s >= tc.max_time_s:
                print(f"train.max_time_s={tc.max_time_s} reached after {self.epoch} epochs")
                break
            self.run_epoch()
        return self.history

    def run_epoch(self) -> bool:
        tc, B = self.tc, self.tc.batch_rays
        gen = torch.Generator().manual_seed(tc.seed * 1000 + self.epoch)  # the same order when resumed
        passes = -(-self.steps_per_epoch * B // len(self.ranges))
        perm = torch.cat([torch.randperm(len(self.ranges), generator=gen) for _ in range(passes)]).to(self.device)
        self.model.train()
        bar = tqdm(
            range(self.step_in_epoch, self.steps_per_epoch),
            desc=f"epoch {self.epoch + 1}/{tc.epochs}",
            unit="step",
            dynamic_ncols=True,
            mininterval=1.0,
        )
        t_epoch, t_ckpt, losses, self.kept, self.read, self.cut = time.time(), time.time(), [], [], [], []
        first = self.step_in_epoch  # a resumed epoch starts part way (the bar itself may be off: TQDM_DISABLE=1)
        for b in bar:
            losses.append(self.step(perm[b * B : (b + 1) * B]))
            self.step_in_epoch = b + 1
            if (b % 20 == 0 or b + 1 == self.steps_per_epoch) and losses:
                elapsed = time.time() - t_epoch
                bar.set_postfix(
                    loss=f"{float(losses[-1]):.3f}",
                    rays_s=f"{(b + 1 - first) * B / max(elapsed, 1e-9):,.0f}",
                    refresh=False,
                )
            if time.time() - t_ckpt > tc.checkpoint_every_s:
                self.train_time_s += time.time() - t_ckpt
                t_ckpt = time.time()
                self.epoch_loss = (
                    self.epoch_loss[0] + float(torch.stack(losses).sum()),
                    self.epoch_loss[1] + len(losses),
                )
                losses = []
                atomic_torch_save(self.state(), self.out / "last.pt")
            if tc.max_time_s is not None and self.train_time_s + time.time() - t_ckpt >= tc.max_time_s:
                break
        bar.close()
        steps = self.step_in_epoch - first
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)  # the epoch's time includes the work still queued
        self.train_time_s += time.time() - t_ckpt
        epoch_s = time.time() - t_epoch
        if not self.sched_per_step:
            self.sched.step()
        loss_sum = self.epoch_loss[0] + (float(torch.stack(losses).sum()) if losses else 0.0)
        loss_steps = self.epoch_loss[1] + len(losses)
        self.epoch_loss = (0.0, 0)
        record = {
            "epoch": self.epoch + 1,
            "steps": steps,
            "loss": loss_sum / loss_steps if loss_steps else None,
            "epoch_s": epoch_s,
            "rays_per_s": steps * B / max(epoch_s, 1e-9),
            "train_time_s": self.train_time_s,
            "lr": float(self.opt.param_groups[0]["lr"]),
            "samples_per_beam": float(torch.stack(self.kept).float().mean()) if self.kept else self.tc.num_samples,
        }
        # the MLP's work: forward + backward (~3x a forward) per sample with gradient, a forward per sample read
        # without (ending the beams), and the grid's readings; against the epoch's time, the rate achieved
        read = float(torch.stack(self.read).float().mean()) if self.read else 0.0
        grid_points = 0 if self.grid is None else self.grid.values.numel() * -(-steps // tc.grid_every)
        flop = self.model.flops_per_point() * ((3 * record["samples_per_beam"] + read) * B * steps + grid_points)
        record.update(
            {
                "read_per_beam": read,
                "mlp_gflop_per_step": flop / max(steps, 1) / 1e9,
                "mlp_tflop_per_s": flop / max(epoch_s, 1e-9) / 1e12,
            }
        )
        if self.grid is not None:
            record["grid_occupied_share"] = self.grid.occupied_share()
        if self.cut:
            record["fixed_samples_cut_share"] = cut = float(torch.stack(self.cut).mean())
            if cut > 0.02:
                print(
                    f"WARNING: {self.count // B} samples per beam (train.fixed_samples, fixed_samples_share) left out "
                    f"{cut:.1%} of the samples the grid kept in "
                    f"epoch {self.epoch + 1} (they counted as free space); raise it above the samples per beam the grid "
                    "keeps (train=guided with fixed_samples=0 prints them)"
                )
        if tc.bn_recalibrate:  # part of making the field: counted as training time
            t0 = time.time()
            self.recalibrate_batch_norm(tc.bn_recalibrate)
            if self.device.type == "cuda":
                torch.cuda.synchronize(self.device)
            self.train_time_s += time.time() - t0
            record["train_time_s"] = self.train_time_s
        record["val"] = self.validate(self.field())
        self.epoch, self.step_in_epoch = self.epoch + 1, 0
        self.history.append(record)
        improved = self.best is None or record["val"]["mae_m"] < self.best["val"]["mae_m"]
        if improved:
            self.best = record
            atomic_torch_save(
                {
                    **self.meta,
                    "model": self.kept_model.state_dict(),
                    "epoch": record["epoch"],
                    "val": record["val"],
                    "field_mask": self.grid.mask() if self.tc.grid_masks_field else None,
                },
                self.out / "nof.pt",
            )
        print(
            f"epoch {record['epoch']}: loss {record['loss']:.4f}, val MAE {record['val']['mae_m']:.3f} m, "
            f"accuracy {record['val']['accuracy_pct']:.1f} %, {record['rays_per_s']:,.0f} rays/s, "
            f"{record['samples_per_beam']:.1f} samples per beam through the MLP" + (" (best)" if improved else "")
        )
        atomic_torch_save(self.state(), self.out / "last.pt")
        return improved
