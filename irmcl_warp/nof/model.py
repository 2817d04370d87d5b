"""The neural occupancy field of IR-MCL (Kuang et al., RA-L 2023, Sec. III-A).

gamma(p) = [p, sin(2^0 p), cos(2^0 p), ..., sin(2^{L-1} p), cos(2^{L-1} p)] for p = (x, y) in metres
(L = 10 -> 42 inputs), then ``depth`` fully connected layers of ``width`` units, each followed by batch
norm and ReLU, the encoded input concatenated again after layer ``skip_after``, and a linear layer with
a sigmoid giving p_occ in [0, 1]. The paper's network: depth 8, width 256, skip after 4.
"""

from __future__ import annotations

from dataclasses import asdict

import torch
from torch import nn

from irmcl_warp.config import ModelConfig


class PositionalEncoding(nn.Module):
    def __init__(self, num_freqs: int):
        super().__init__()
        self.register_buffer("freqs", 2.0 ** torch.arange(num_freqs, dtype=torch.float32), persistent=False)
        self.out_dim = 2 + 4 * num_freqs

    def forward(self, xy: torch.Tensor) -> torch.Tensor:
        """xy [B, 2] -> [B, 2 + 4L], ordered [x, y, sin(f0 x), sin(f0 y), cos(f0 x), cos(f0 y), ...]."""
        scaled = (xy[:, None, :] * self.freqs[None, :, None].to(xy.dtype)).flatten(1)  # [B, 2L]
        s, c = torch.sin(scaled).view(-1, len(self.freqs), 2), torch.cos(scaled).view(-1, len(self.freqs), 2)
        return torch.cat([xy, torch.cat([s, c], -1).flatten(1)], -1)


def _block(n_in: int, n_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(n_in, n_out), nn.BatchNorm1d(n_out), nn.ReLU(inplace=True))


class NOF(nn.Module):
    def __init__(self, cfg: ModelConfig | None = None):
        super().__init__()
        self.cfg = cfg = cfg or ModelConfig()
        if not 0 <= cfg.skip_after < cfg.depth:
            raise ValueError(f"model.skip_after={cfg.skip_after} must lie in [0, depth={cfg.depth})")
        self.encoding = PositionalEncoding(cfg.num_freqs)
        d = self.encoding.out_dim
        first = cfg.skip_after or cfg.depth
        self.head = nn.Sequential(*[_block(d if i == 0 else cfg.width, cfg.width) for i in range(first)])
        self.tail = nn.Sequential(
            *[_block(cfg.width + d if i == 0 else cfg.width, cfg.width) for i in range(cfg.depth - first)]
        )
        self.out = nn.Linear(cfg.width, 1)

    def forward(self, xy: torch.Tensor) -> torch.Tensor:
        """Occupancy probability p_occ [B] of world points xy [B, 2] (metres)."""
        g = self.encoding(xy)
        h = self.head(g)
        if len(self.tail):
            h = self.tail(torch.cat([g, h], -1))
        return torch.sigmoid(self.out(h)).squeeze(-1)

    def flops_per_point(self) -> int:
        """Multiply-adds x 2 of the linear layers for one point's forward pass (encoding and batch norm left out)."""
        return sum(2 * m.in_features * m.out_features for m in self.modules() if isinstance(m, nn.Linear))

    def config_dict(self) -> dict:
        return asdict(self.cfg)
