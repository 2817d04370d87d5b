"""``train.step_graph``: a NOF training step captured once as a CUDA graph and replayed (issue 36).

Profiled on an H100 (fr079, 64 samples per beam through the compiled MLP), a step does about 3 ms of GPU work
and takes 7-9 ms: the host launching some 300 kernels (the compiled passes, the Warp sampler and compositor,
batch norm, Adam) is the limit. Replaying the whole step (depths, the grid's pick, the fixed-count gather, the
MLP forward and backward, the compositing, the loss, Adam) as one graph leaves the host one launch per step.

What a captured step needs, and the trainer checks: fixed shapes (``train.fixed_samples`` with the occupancy
sampler, or the uniform sampler), no reads by the host inside the step (``grid_end`` none or grid, not field,
whose beam ends need ``nonzero``), Adam made capturable with its learning rate a device tensor (the schedule
writes it in place), and the grid read outside the graph into its own tensors (``OccupancyGrid.update`` writes in
place). The capture follows PyTorch's whole-network recipe: a few warm-up steps on a side stream (they compile
and load every kernel and create Adam's state), the weights, batch norm and Adam put back as they were, then the
capture. The random draws of a replay come from the graph's own Philox offsets, so a run with the graph is
repeatable but does not draw the numbers an eager run draws.
"""

from __future__ import annotations

import copy

import torch


class StepGraph:
    def __init__(self, trainer, idx: torch.Tensor, warmup: int = 3):
        tr = self.trainer = trainer
        self.idx = idx.clone()  # the batch's ray indices: a replay reads them from here
        weights = {k: v.detach().clone() for k, v in tr.model.state_dict().items()}
        adam = copy.deepcopy(tr.opt.state_dict())
        side = torch.cuda.Stream(tr.device)
        side.wait_stream(torch.cuda.current_stream(tr.device))
        with torch.cuda.stream(side):
            for _ in range(warmup):
                tr.opt.zero_grad(set_to_none=True)
                tr._body(self.idx)
        torch.cuda.current_stream(tr.device).wait_stream(side)
        tr.model.load_state_dict(weights)  # copies into the same tensors: the graph sees them where they are
        tr.opt.load_state_dict(adam)
        if not tr.opt.state:  # Adam's moments exist before the capture, as after a first step, but are zero
            tr.opt.zero_grad(set_to_none=True)
            for p in tr.model.parameters():
                p.grad = torch.zeros_like(p)
            for g in tr.opt.param_groups:
                for p in g["params"]:
                    st = tr.opt.state[p]
                    st["step"] = torch.zeros((), dtype=torch.float32, device=p.device)
                    st["exp_avg"] = torch.zeros_like(p, memory_format=torch.preserve_format)
                    st["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.preserve_format)
        tr.opt.zero_grad(set_to_none=True)
        self.graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(self.graph):
            self.out = tr._body(self.idx)

    def replay(self, idx: torch.Tensor) -> tuple:
        """The step on these rays; its outputs live in the graph's memory until the next replay."""
        if not all(isinstance(g["lr"], torch.Tensor) for g in self.trainer.opt.param_groups):
            raise RuntimeError("train.step_graph: the schedule replaced Adam's learning-rate tensor (torch too old?)")
        self.idx.copy_(idx)
        self.graph.replay()
        return self.out
