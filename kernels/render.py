"""Volume rendering of 1D occupancy along beams, for training the NOF: ``RENDER["composite"]``.

For one beam with occupancies p[0..N-1] at depths z[0..N-1] (IR-MCL, Kuang et al. 2023, eq. 2-3):

    T_k     = prod_{j<k} (1 - p_j)            probability that the beam passes sample k
    alpha_k = p_k * T_k                       probability that it ends at sample k
    W       = sum_k alpha_k                   accumulated opacity
    r       = sum_k alpha_k z_k / (W + eps)   (normalize=True, as the authors' code does)
              sum_k alpha_k z_k               (normalize=False, the paper's equation)

Example: p = [0.4, 0.3, 0.8] -> alpha = [0.4, 0.18, 0.336].

The backward pass is written by hand (one thread per beam, no autodiff). With the suffix sums
U_k = sum_{i>k} p_i prod_{k<j<i}(1 - p_j) z_i and V_k the same with z = 1 (both from the recursion
U_{k-1} = p_k z_k + (1 - p_k) U_k, so nothing is divided by 1 - p):

    dA/dp_k = T_k (z_k - U_k),  dW/dp_k = T_k (1 - V_k),  dr/dp_k = (dA/dp_k - r dW/dp_k) / (W + eps)

Early termination (``t_min`` > 0, an ablation): samples with T_k < t_min are skipped in both passes.
Torch twin and ablation ``render=torch_ref``: irmcl_warp/reference/render.py.

``RENDER["occupied_samples"]`` picks the samples worth asking the NOF about while training
(``train.sampler=occupancy``, irmcl_warp/nof/occupancy.py): one thread per beam walks its sample points
and keeps those whose cell of a coarse occupancy grid may be occupied, until the grid's own transmittance
prod (1 - value) over the kept samples falls below ``t_min``. The samples it drops are given p = 0, so the
compositing above stays exact wherever the grid is right.
"""

from __future__ import annotations

import torch
import warp as wp

from irmcl_warp.kernels.registry import RENDER, init_warp

WP_DTYPES = {torch.float32: wp.float32, torch.float64: wp.float64}


def make_kernels(dtype, normalize: bool, t_min: float, eps: float):
    """Forward and backward kernels specialised for one float type and setting."""

    @wp.kernel(module="unique")
    def forward(
        p: wp.array2d(dtype=dtype),
        z: wp.array2d(dtype=dtype),
        ranges: wp.array(dtype=dtype),
        opacity: wp.array(dtype=dtype),
    ):
        i = wp.tid()
        T = dtype(1.0)
        A = dtype(0.0)
        W = dtype(0.0)
        for k in range(p.shape[1]):
            if T < dtype(wp.static(t_min)):
                break
            a = p[i, k] * T
            A += a * z[i, k]
            W += a
            T *= dtype(1.0) - p[i, k]
        opacity[i] = W
        if wp.static(normalize):
            ranges[i] = A / (W + dtype(wp.static(eps)))
        else:
            ranges[i] = A

    @wp.kernel(module="unique")
    def backward(
        p: wp.array2d(dtype=dtype),
        z: wp.array2d(dtype=dtype),
        ranges: wp.array(dtype=dtype),
        opacity: wp.array(dtype=dtype),
        grad_r: wp.array(dtype=dtype),
        grad_w: wp.array(dtype=dtype),
        grad_p: wp.array2d(dtype=dtype),
    ):
        i = wp.tid()
        n = p.shape[1]
        # pass 1: transmittance T_k into grad_p (scratch); count the samples the forward pass used
        T = dtype(1.0)
        used = int(0)
        for k in range(n):
            if T >= dtype(wp.static(t_min)):
                used = k + 1
            grad_p[i, k] = T
            T *= dtype(1.0) - p[i, k]
        for k in range(used, n):
            grad_p[i, k] = dtype(0.0)
        # pass 2, back to front: suffix sums U (depth) and V (opacity)
        U = dtype(0.0)
        V = dtype(0.0)
        r = ranges[i]
        if wp.static(normalize):
            scale = grad_r[i] / (opacity[i] + dtype(wp.static(eps)))
        else:
            scale = grad_r[i]
        for j in range(used):
            k = used - 1 - j
            Tk = grad_p[i, k]
            dA = Tk * (z[i, k] - U)
            dW = Tk * (dtype(1.0) - V)
            if wp.static(normalize):
                grad_p[i, k] = scale * (dA - r * dW) + grad_w[i] * dW
            else:
                grad_p[i, k] = scale * dA + grad_w[i] * dW
            U = p[i, k] * z[i, k] + (dtype(1.0) - p[i, k]) * U
            V = p[i, k] + (dtype(1.0) - p[i, k]) * V

    return forward, backward


class Compositor:
    """Runs the kernels on torch tensors in place (zero copy through ``wp.from_torch``)."""

    def __init__(self, normalize: bool = True, t_min: float = 0.0, eps: float = 1e-10):
        init_warp()
        self.normalize, self.t_min, self.eps = normalize, float(t_min), float(eps)
        self._kernels = {}

    def kernels(self, torch_dtype):
        if torch_dtype not in WP_DTYPES:
            raise TypeError(f"render: occupancies must be float32 or float64, got {torch_dtype}")
        if torch_dtype not in self._kernels:
            self._kernels[torch_dtype] = make_kernels(WP_DTYPES[torch_dtype], self.normalize, self.t_min, self.eps)
        return self._kernels[torch_dtype]

    @staticmethod
    def _launch(kernel, dim, tensors, device):
        wp_dev = wp.device_from_torch(device)
        stream = wp.stream_from_torch(device) if wp_dev.is_cuda else None
        arrays = [wp.from_torch(t.detach(), dtype=WP_DTYPES[t.dtype]) for t in tensors]
        wp.launch(kernel, dim=dim, inputs=arrays, device=wp_dev, stream=stream)

    def forward(self, p: torch.Tensor, z: torch.Tensor):
        """p, z [R, N] -> (ranges [R], opacity [R])."""
        p, z = p.contiguous(), z.contiguous().to(p.dtype)
        ranges = torch.empty(p.shape[0], dtype=p.dtype, device=p.device)
        opacity = torch.empty_like(ranges)
        if p.shape[0]:
            self._launch(self.kernels(p.dtype)[0], p.shape[0], [p, z, ranges, opacity], p.device)
        return ranges, opacity

    def backward(self, p, z, ranges, opacity, grad_r, grad_w):
        grad_p = torch.empty_like(p)
        if p.shape[0]:
            tensors = [p, z.to(p.dtype), ranges, opacity, grad_r.contiguous(), grad_w.contiguous(), grad_p]
            self._launch(self.kernels(p.dtype)[1], p.shape[0], tensors, p.device)
        return grad_p


@wp.kernel
def occupied_samples_kernel(
    points: wp.array2d(dtype=wp.vec2),
    values: wp.array2d(dtype=wp.float32),
    occupied: wp.array2d(dtype=wp.uint8),
    x0: float,
    y0: float,
    inv_res: float,
    t_min: float,
    keep: wp.array2d(dtype=wp.uint8),
):
    i = wp.tid()
    T = float(1.0)
    for k in range(points.shape[1]):
        keep[i, k] = wp.uint8(0)
        if T >= t_min:
            q = points[i, k]
            ix = int(wp.floor((q[0] - x0) * inv_res))
            iy = int(wp.floor((q[1] - y0) * inv_res))
            if ix >= 0 and ix < values.shape[1] and iy >= 0 and iy < values.shape[0]:
                if occupied[iy, ix] != wp.uint8(0):
                    keep[i, k] = wp.uint8(1)
                    T *= 1.0 - values[iy, ix]


class OccupiedSamples:
    """keep [R, N] (bool) for torch sample points [R, N, 2] on a grid of ``values`` and ``occupied`` [H, W]."""

    def __init__(self, origin_xy, resolution_m: float, t_min: float = 0.0):
        init_warp()
        self.x0, self.y0 = (float(c) for c in origin_xy)
        self.inv_res, self.t_min = 1.0 / float(resolution_m), float(t_min)

    def __call__(self, points: torch.Tensor, values: torch.Tensor, occupied: torch.Tensor) -> torch.Tensor:
        R, N = points.shape[:2]
        keep = torch.zeros((R, N), dtype=torch.uint8, device=points.device)
        if R and N:
            wp_dev = wp.device_from_torch(points.device)
            stream = wp.stream_from_torch(points.device) if wp_dev.is_cuda else None
            wp.launch(
                occupied_samples_kernel,
                dim=R,
                device=wp_dev,
                stream=stream,
                inputs=[
                    wp.from_torch(points.detach().float().contiguous(), dtype=wp.vec2),
                    wp.from_torch(values.float().contiguous()),
                    wp.from_torch(occupied.to(torch.uint8).contiguous(), dtype=wp.uint8),
                    self.x0,
                    self.y0,
                    self.inv_res,
                    self.t_min,
                    wp.from_torch(keep, dtype=wp.uint8),
                ],
            )
        return keep.bool()


@RENDER.register("occupied_samples")
def occupied_samples(origin_xy, resolution_m: float, t_min: float = 0.0) -> OccupiedSamples:
    return OccupiedSamples(origin_xy, resolution_m, t_min)


@RENDER.register("composite")
def composite(normalize: bool = True, t_min: float = 0.0, eps: float = 1e-10) -> Compositor:
    return Compositor(normalize=normalize, t_min=t_min, eps=eps)
