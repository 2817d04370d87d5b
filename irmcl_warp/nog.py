"""The neural occupancy grid (IR-MCL Sec. III-C): the NOF evaluated once at the nodes of a regular grid,
so that MCL reads occupancy by a nearest-node lookup instead of running the MLP.

Node (ix, iy) holds p_occ at origin + (ix, iy) * resolution; a point is read from the nearest node
(round, as the authors' render_rays_grid). ``services.nog.bake_nog`` bakes a checkpoint's NOG and caches it.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from irmcl_warp.io.atomic import atomic_write_bytes


@dataclass
class NOG:
    occupancy: np.ndarray  # [H, W] float32 p_occ at the nodes
    origin_xy: tuple[float, float]  # world position of node (0, 0)
    resolution_m: float

    @property
    def shape(self):
        return self.occupancy.shape

    def node_of(self, xy) -> np.ndarray:
        """Nearest node (ix, iy) of world points [..., 2]."""
        return np.rint((np.asarray(xy) - np.asarray(self.origin_xy)) / self.resolution_m).astype(int)

    def save(self, path: Path) -> None:
        buf = io.BytesIO()
        np.savez_compressed(
            buf, occupancy=self.occupancy, origin_xy=np.array(self.origin_xy), resolution_m=np.array(self.resolution_m)
        )
        atomic_write_bytes(Path(path), buf.getvalue())

    @classmethod
    def load(cls, path: Path) -> "NOG":
        with np.load(path) as z:
            return cls(
                z["occupancy"].astype(np.float32), tuple(float(v) for v in z["origin_xy"]), float(z["resolution_m"])
            )


@torch.no_grad()
def evaluate_grid(model, bounds, resolution_m: float, device="cpu", chunk: int = 1 << 16) -> NOG:
    """p_occ of ``model`` at every node of the grid covering bounds (xmin, ymin, xmax, ymax)."""
    xmin, ymin, xmax, ymax = bounds
    if not (xmax > xmin and ymax > ymin and resolution_m > 0):
        raise ValueError(f"NOG bounds {bounds} / resolution {resolution_m} do not describe a grid")
    W, H = int(np.floor((xmax - xmin) / resolution_m)) + 1, int(np.floor((ymax - ymin) / resolution_m)) + 1
    if W * H > 200_000_000:
        raise ValueError(f"NOG of {W}x{H} nodes is too large: check nog.bounds_m and nog.resolution_m")
    model = model.to(device).eval()
    iy, ix = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    xy = np.stack([xmin + ix.ravel() * resolution_m, ymin + iy.ravel() * resolution_m], -1).astype(np.float32)
    out = np.empty(len(xy), np.float32)
    for s in range(0, len(xy), chunk):
        out[s : s + chunk] = model(torch.from_numpy(xy[s : s + chunk]).to(device)).float().cpu().numpy()
    return NOG(out.reshape(H, W), (float(xmin), float(ymin)), float(resolution_m))
