"""Occupancy-guided sampling for NOF training (``train.sampler=occupancy``), after nerfacc's occupancy grid.

Most of a training beam's 256 samples lie in free space before the wall or behind it, where the field is
already ~0 or the beam has already ended; the MLP spends most of a step there. A coarse grid over the
training rays keeps, per cell, a decaying maximum of the field itself:

    value <- max(decay * value, p_occ(random point in the cell))      every ``grid_every`` steps

A cell may be occupied when its value exceeds ``grid_threshold`` (then dilated by ``grid_dilate`` cells,
so the rise in front of a wall is sampled). ``RENDER["occupied_samples"]`` keeps the samples in such
cells. Where a beam ends is decided by ``grid_end``:

* ``field`` (default, nerfacc's way): the field is read without gradient at the kept samples, and those
  after its transmittance prod (1 - p) has fallen below ``grid_t_min`` are dropped;
* ``grid``: the kernel stops once the transmittance from each cell's latest reading is below
  ``grid_t_min``; cheaper, but a cell read inside a wall makes the free part of the cell look opaque,
  so a beam can end before it reaches the wall (a two-wall test field had beams render 0 m instead of 1.8);
* ``none``: every sample in an occupied cell.

Only the samples left go through the MLP with gradient; the rest count as p = 0, and the compositing is
the same exact formula as before. The first update
runs at step 0 on the untrained field (p ~ 0.5 everywhere), so training starts by sampling everything and
prunes as the field learns where it is empty. Values are read from the field in eval mode, as
evaluation reads it.

What it does in practice (twenty-second session, docs/benchmarks.md): at the presets' threshold (1e-4) the field
keeps p above it nearly everywhere, so 97-100 % of the cells stay occupied all run long (``grid_occupied_share`` in
every kept fr079 and intel run). The samples kept are then those inside the grid's extent, the rays' bounding box:
85 per beam on fr079 and 124 on intel with every cell occupied, the counts `minute` trains with. The savings of
`guided` come from the transmittance cut (``grid_end=field``).

A threshold that prunes (0.01) spoiled the test ranges while evaluation rendered the skipped cells' untrained p. With
``train.grid_masks_field`` (``MaskedField`` below; preset ``graph``) the grid is part of the field everywhere, and at
0.01 it keeps 71-80 % of the cells and ~54 samples per beam on fr079 with the same test MAE as every sample
(twenty-third session).
"""

from __future__ import annotations

import contextlib
import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from irmcl_warp.kernels import RENDER
from irmcl_warp.nof.render import sample_depths, sample_points


@contextlib.contextmanager
def evaluating(model):
    """The model in eval mode (batch norm from its running statistics, as evaluation reads it) for a block."""
    was_training = model.training
    model.eval()
    try:
        yield model
    finally:
        model.train(was_training)


class OccupancyGrid:
    def __init__(self, origins: np.ndarray, ends: np.ndarray, tc, device):
        self.res, self.threshold, self.decay, self.dilate = (
            float(tc.grid_resolution_m),
            float(tc.grid_threshold),
            float(tc.grid_decay),
            int(tc.grid_dilate),
        )
        pts = np.concatenate([origins, ends])
        margin = 2 * self.res * (1 + self.dilate)
        lo = pts.min(0) - margin
        self.shape = tuple(int(math.ceil(v)) for v in ((pts.max(0) + margin - lo) / self.res)[::-1])  # (H, W)
        self.origin_xy = (float(lo[0]), float(lo[1]))
        self.device, self.read = device, torch.zeros((), device=device)  # samples the last keep() read without gradient
        self.values = torch.zeros(self.shape, dtype=torch.float32, device=device)  # decaying maximum: the mask
        self.latest = torch.zeros(self.shape, dtype=torch.float32, device=device)  # last reading: the transmittance
        self.occupied = torch.ones(self.shape, dtype=torch.bool, device=device)
        self.end, self.t_min = tc.grid_end, float(tc.grid_t_min)
        self.keep_fn = RENDER.build(
            "occupied_samples",
            origin_xy=self.origin_xy,
            resolution_m=self.res,
            t_min=self.t_min if self.end == "grid" else 0.0,
        )
        H, W = self.shape
        iy, ix = torch.meshgrid(torch.arange(H, device=device), torch.arange(W, device=device), indexing="ij")
        self._corners = torch.stack([lo[0] + ix * self.res, lo[1] + iy * self.res], -1).reshape(-1, 2).float()

    @torch.no_grad()
    def update(self, model, amp=contextlib.nullcontext, chunk: int = 1 << 16) -> None:
        """Read the field once at a random point of every cell and refresh values and the occupied mask."""
        pts = self._corners + torch.rand(self._corners.shape, device=self.device) * self.res
        with evaluating(model), amp():
            p = torch.cat([model(pts[s : s + chunk]).float() for s in range(0, len(pts), chunk)])
        # in place, here and below: a step captured as a CUDA graph (train.step_graph) reads these tensors
        self.latest.copy_(p.view(self.shape))
        torch.maximum(self.values * self.decay, self.latest, out=self.values)
        self._refresh_mask()

    def _refresh_mask(self) -> None:
        occ = (self.values > self.threshold).float()[None, None]
        if self.dilate:
            occ = F.max_pool2d(occ, 2 * self.dilate + 1, stride=1, padding=self.dilate)
        self.occupied.copy_(occ[0, 0] > 0)

    def keep(self, points: torch.Tensor, model=None, amp=contextlib.nullcontext) -> torch.Tensor:
        """keep [R, N] for sample points [R, N, 2]: the samples the MLP is asked about (``model`` is read
        without gradient to end the beams when ``grid_end=field``)."""
        keep = self.keep_fn(points, self.latest, self.occupied)
        if self.end != "field" or not self.t_min:
            self.read = torch.zeros((), device=points.device)
            return keep
        self.read = keep.sum()
        with torch.no_grad():
            flat = keep.reshape(-1).nonzero().squeeze(1)
            with evaluating(model), amp():
                p_kept = (
                    model(points.reshape(-1, 2)[flat]).float() if len(flat) else torch.zeros(0, device=points.device)
                )
            p = torch.zeros(keep.numel(), device=points.device).index_copy(0, flat, p_kept).view(keep.shape)
            T = torch.cumprod(torch.cat([torch.ones_like(p[:, :1]), 1.0 - p[:, :-1]], 1), 1)
        return keep & (T >= self.t_min)

    @torch.no_grad()
    def starting_samples_per_beam(self, origins, dirs, num_samples: int, near_m: float, far_m: float) -> float:
        """Samples per beam the grid keeps before its first reading (every cell occupied: those inside the rays'
        bounding box), over up to 8 batches of 4096 beams drawn by a generator of its own (the run's random draws
        stay as they were), at the bins' midpoints."""
        gen = torch.Generator().manual_seed(0)
        every = torch.ones(self.shape, dtype=torch.bool, device=self.device)
        kept = beams = 0
        for _ in range(8):
            idx = torch.randint(len(origins), (min(4096, len(origins)),), generator=gen).to(origins.device)
            z = sample_depths(len(idx), num_samples, near_m, far_m, perturb=False, device=origins.device)
            keep = self.keep_fn(sample_points(origins[idx], dirs[idx], z), self.latest, every)
            kept, beams = kept + int(keep.sum()), beams + len(idx)
        return kept / beams

    def occupied_share(self) -> float:
        return float(self.occupied.float().mean())

    def mask(self) -> dict:
        """What ``MaskedField`` needs (stored in nof.pt with ``train.grid_masks_field``): the occupied cells now."""
        return {"occupied": self.occupied.detach().clone().cpu(), "origin_xy": self.origin_xy, "res": self.res}

    def masked(self, model) -> "MaskedField":
        """``model`` read through the grid's occupied cells as they are now."""
        return MaskedField(model, **self.mask()).to(self.device)

    def state_dict(self) -> dict:
        return {
            "values": self.values,
            "latest": self.latest,
            "origin_xy": self.origin_xy,
            "res": self.res,
            "shape": self.shape,
        }

    def load_state_dict(self, s: dict) -> None:
        if tuple(s["shape"]) != self.shape or s["origin_xy"] != self.origin_xy or s["res"] != self.res:
            raise ValueError("occupancy grid of another extent or resolution in the checkpoint")
        self.values.copy_(s["values"])
        self.latest.copy_(s["latest"])
        self._refresh_mask()


class MaskedField(nn.Module):
    """A field read through its training grid (``train.grid_masks_field``): p = 0 outside the grid's occupied cells,
    as the occupancy sampler counts the samples it skips while training; the field's own p inside them.

    Without it the samples a trained field never saw with gradient (the skipped cells' p, which the grid only keeps
    below its threshold) are rendered at evaluation and baked into the NOG: at a threshold of 0.01, a dozen samples in
    front of a wall swallow 10 % of a beam's weight. With it, training, validation, the test renders and the NOG read
    the same field, and the grid is part of the model (nof.pt stores it). A cell is found as the sampler's kernel
    finds it (floor((x - x0) / res), outside the grid: free)."""

    def __init__(self, field: nn.Module, occupied: torch.Tensor, origin_xy, res: float):
        super().__init__()
        self.field = field
        self.register_buffer("occupied", torch.as_tensor(occupied).bool())
        self.origin_xy, self.res = (float(origin_xy[0]), float(origin_xy[1])), float(res)

    def forward(self, xy: torch.Tensor) -> torch.Tensor:
        p = self.field(xy)
        return torch.where(self.cell_occupied(xy), p, torch.zeros((), dtype=p.dtype, device=p.device))

    def cell_occupied(self, xy: torch.Tensor) -> torch.Tensor:
        """[B] bool: the point's grid cell is occupied (points outside the grid are not)."""
        H, W = self.occupied.shape
        inv = 1.0 / self.res  # as the kernel: (x - x0) * (1 / res), in float32
        ix = torch.floor((xy[:, 0].float() - self.origin_xy[0]) * inv).long()
        iy = torch.floor((xy[:, 1].float() - self.origin_xy[1]) * inv).long()
        inside = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
        return inside & self.occupied[iy.clamp(0, H - 1), ix.clamp(0, W - 1)]

    def flops_per_point(self) -> int:
        return self.field.flops_per_point()

    @property
    def cfg(self):
        return self.field.cfg
