"""Colour GIST (Oliva & Torralba 2001) as computed by the LEAR implementation (Douze et al., CIVR 2009),
batched with torch.fft.

For each image [H, W, 3] (values 0..255):
1. prefilter (fc = 4): log(1 + I) per channel; symmetric padding by 5 pixels; whitening: subtract the
   image low-passed by the Gaussian transfer function exp(-|f|^2 / s^2), s = fc / sqrt(log 2) (f in
   cycles per padded image); local contrast normalisation: divide every channel by 0.2 + the square root
   of the same low-pass of the squared channel mean (its magnitude); crop the padding;
2. a Gabor bank in the Fourier domain of the unpadded size: for scale i (0-based) and orientation j of n_i,
   G = exp(-10 * 0.35 * (|f|/H/s_i - 1)(|f|/W/s_i - 1) - 2 pi (16 n_i^2 / 32^2) (angle(f) + pi j / n_i)^2)
   with s_i = 0.3 / 1.85^i and the angle wrapped to [-pi, pi];
3. per channel and filter: |ifft(fft(I) G)|, averaged over nblocks x nblocks blocks (block edges at
   k * size // nblocks).

Output order as LEAR's: channel, filter (scales then orientations), x block, y block: 3 x 32 x 16 = 960 values
for the defaults (nblocks 4, orientations [8, 8, 4]). Images of another size than the filters' are an error:
resize them first (``resize``).
"""

from __future__ import annotations

import math

import numpy as np
import torch


def _centered_grid(h: int, w: int, dtype=torch.float64):
    """(fx, fy) [h, w] = (column - w/2, row - h/2), then fftshift-ed so that (0, 0) sits at index [0, 0]."""
    fy, fx = torch.meshgrid(
        torch.arange(h, dtype=dtype) - h / 2.0, torch.arange(w, dtype=dtype) - w / 2.0, indexing="ij"
    )
    return torch.fft.fftshift(fx), torch.fft.fftshift(fy)


def gabor_bank(h: int, w: int, orientations=(8, 8, 4), dtype=torch.float64) -> torch.Tensor:
    """[F, h, w] transfer functions (LEAR's create_gabor)."""
    fx, fy = _centered_grid(h, w, dtype)
    fr = torch.sqrt(fx**2 + fy**2)
    angle = torch.atan2(fy, fx)
    out = []
    for i, n in enumerate(orientations):
        s = 0.3 / 1.85**i
        width = 16.0 * n * n / (32 * 32)
        for j in range(n):
            t = angle + math.pi / n * j
            t = torch.where(t < -math.pi, t + 2 * math.pi, torch.where(t > math.pi, t - 2 * math.pi, t))
            out.append(torch.exp(-10.0 * 0.35 * (fr / h / s - 1) * (fr / w / s - 1) - 2.0 * width * math.pi * t * t))
    return torch.stack(out)


def prefilter(img: torch.Tensor, fc: float = 4.0, pad: int = 5) -> torch.Tensor:
    """[B, 3, H, W] -> whitened, contrast-normalised images of the same size (LEAR's color_prefilt)."""
    x = torch.log(img + 1.0)
    x = torch.cat([x[..., :pad, :].flip(-2), x, x[..., -pad:, :].flip(-2)], -2)  # symmetric padding
    x = torch.cat([x[..., :pad].flip(-1), x, x[..., -pad:].flip(-1)], -1)
    h, w = x.shape[-2:]
    fx, fy = (v.to(x.device) for v in _centered_grid(h, w, x.dtype))
    s = fc / math.sqrt(math.log(2.0))
    g = torch.exp(-(fx**2 + fy**2) / (s * s))
    x = x - torch.fft.ifft2(torch.fft.fft2(x) * g).real
    m = x.mean(1, keepdim=True) ** 2
    local = torch.sqrt(torch.fft.ifft2(torch.fft.fft2(m) * g).abs())
    x = x / (0.2 + local)
    return x[..., pad : h - pad, pad : w - pad]


def block_means(x: torch.Tensor, n: int) -> torch.Tensor:
    """[..., H, W] -> [..., n (x blocks), n (y blocks)] means over blocks with edges at k * size // n."""
    H, W = x.shape[-2:]
    ys, xs = [k * H // n for k in range(n + 1)], [k * W // n for k in range(n + 1)]
    cols = [
        torch.stack([x[..., ys[r] : ys[r + 1], xs[k] : xs[k + 1]].mean((-2, -1)) for r in range(n)], -1)
        for k in range(n)
    ]
    return torch.stack(cols, -2)


class Gist:
    """Colour GIST of images of one size; ``__call__`` takes [H, W, 3] or [B, H, W, 3] (numpy or torch, 0..255)
    and returns float32 [B, 3 * sum(orientations) * nblocks^2] (numpy)."""

    def __init__(
        self, size_hw=(96, 96), nblocks: int = 4, orientations=(8, 8, 4), fc: float = 4.0, device: str = "cpu"
    ):
        self.size, self.nblocks, self.fc, self.device = tuple(map(int, size_hw)), int(nblocks), float(fc), device
        if min(self.size) < 8:
            raise ValueError(f"gist: images of {self.size} pixels are too small (LEAR needs at least 8 x 8)")
        self.orientations = tuple(map(int, orientations))
        self.G = gabor_bank(*self.size, self.orientations).to(device)

    @property
    def dim(self) -> int:
        return 3 * int(self.G.shape[0]) * self.nblocks**2

    def __call__(self, images) -> np.ndarray:
        x = torch.as_tensor(np.asarray(images) if not torch.is_tensor(images) else images, dtype=torch.float64)
        if x.ndim == 3:
            x = x[None]
        if x.ndim != 4 or x.shape[-1] != 3:
            raise ValueError(f"gist: expected images [B, H, W, 3] (or one [H, W, 3]), got {tuple(x.shape)}")
        if tuple(x.shape[1:3]) != self.size:
            raise ValueError(
                f"gist: an image of {tuple(x.shape[1:3])} pixels, this Gist was built for {self.size} "
                f"(resize the images to one size first, e.g. irmcl_warp.globloc.gist.resize)"
            )
        x = prefilter(x.permute(0, 3, 1, 2).to(self.device), self.fc)
        F = torch.fft.fft2(x)  # [B, 3, H, W]
        mag = torch.fft.ifft2(F[:, :, None] * self.G[None, None]).abs()  # [B, 3, F, H, W]
        return block_means(mag, self.nblocks).reshape(x.shape[0], -1).float().cpu().numpy()


def resize(images: np.ndarray, size_hw) -> np.ndarray:
    """Bilinear resize of [B, H, W, 3] images to size_hw (torch interpolate, align_corners=False)."""
    x = torch.as_tensor(np.asarray(images, np.float32)).permute(0, 3, 1, 2)
    y = torch.nn.functional.interpolate(x, size=tuple(size_hw), mode="bilinear", align_corners=False)
    return y.permute(0, 2, 3, 1).numpy()
