"""The keyframe database of the offline mapping run: robot poses, RGB-D frames and their Gist descriptors,
with retrieval by L2 distance of the descriptors, and the clustering of the retrieved candidates."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irmcl_warp.globloc.gist import Gist, resize


def keyframe_indices(poses: np.ndarray, every_m: float = 0.5, every_rad: float = np.radians(15.0)) -> np.ndarray:
    """Indices of the poses that start a keyframe: the first, then each pose ``every_m`` away from or turned
    ``every_rad`` from the last keyframe."""
    keep, last = [0], poses[0]
    for i in range(1, len(poses)):
        d = np.hypot(*(poses[i, :2] - last[:2]))
        turn = abs((poses[i, 2] - last[2] + np.pi) % (2 * np.pi) - np.pi)
        if d >= every_m or turn >= every_rad:
            keep.append(i)
            last = poses[i]
    return np.array(keep)


@dataclass
class KeyframeDB:
    poses: np.ndarray  # [N, 3] robot poses in the map frame
    rgb: np.ndarray  # [N, H, W, 3] uint8
    depth: np.ndarray  # [N, H, W] float32, metres (0 or NaN = none)
    gists: np.ndarray  # [N, D]

    def __post_init__(self):
        n = len(self.poses)
        if n == 0:
            raise ValueError("keyframe database: empty (record a mapping run first)")
        if not (len(self.rgb) == len(self.depth) == len(self.gists) == n):
            raise ValueError(
                f"keyframe database: {n} poses, {len(self.rgb)} images, {len(self.depth)} depth maps, "
                f"{len(self.gists)} descriptors"
            )
        if self.depth.ndim != 3 or self.depth.shape[:3] != self.rgb.shape[:3]:
            raise ValueError(f"keyframe database: depth {self.depth.shape} does not match the images {self.rgb.shape}")
        empty = [i for i in range(n) if not np.any(np.isfinite(self.depth[i]) & (self.depth[i] > 0))]
        if empty:
            raise ValueError(f"keyframe database: keyframe(s) {empty[:5]} carry no depth; PnP needs the 3D points")

    def __len__(self) -> int:
        return len(self.poses)

    def retrieve(self, gist: np.ndarray, n: int = 20) -> np.ndarray:
        """Indices of the ``n`` keyframes nearest to a query descriptor (L2), nearest first."""
        g = np.asarray(gist, np.float32).reshape(-1)
        if g.shape[0] != self.gists.shape[1]:
            raise ValueError(
                f"retrieval: a descriptor of {g.shape[0]} values, the database holds {self.gists.shape[1]}"
            )
        d = np.sum((self.gists - g) ** 2, 1)
        n = min(n, len(d))
        top = np.argpartition(d, n - 1)[:n]
        return top[np.argsort(d[top])]


def build_database(poses, rgb, depth, gist: Gist) -> KeyframeDB:
    return KeyframeDB(np.asarray(poses, np.float64), rgb, depth, describe(rgb, gist))


def describe(rgb: np.ndarray, gist: Gist, batch: int = 64) -> np.ndarray:
    """Gist of images [N, H, W, 3] resized to the descriptor's size."""
    rgb = np.asarray(rgb)
    if rgb.ndim == 3:
        rgb = rgb[None]
    if rgb.ndim != 4 or rgb.shape[-1] != 3:
        raise ValueError(f"gist: expected RGB images [N, H, W, 3], got {rgb.shape}")
    out = []
    for i in range(0, len(rgb), batch):
        x = rgb[i : i + batch].astype(np.float32)
        if x.shape[1:3] != gist.size:
            x = resize(x, gist.size)
        out.append(gist(x))
    return np.concatenate(out)


def kmeans(x: np.ndarray, k: int, iters: int = 20) -> np.ndarray:
    """Labels [N] of k-means on rows of x (farthest-point start from the first row: deterministic)."""
    x = np.asarray(x, np.float64)
    k = min(k, len(x))
    centres = [x[0]]
    for _ in range(1, k):
        d = np.min([np.sum((x - c) ** 2, 1) for c in centres], 0)
        centres.append(x[int(np.argmax(d))])
    c = np.array(centres)
    labels = np.zeros(len(x), int)
    for _ in range(iters):
        labels = np.argmin(((x[:, None] - c[None]) ** 2).sum(-1), 1)
        new = np.array([x[labels == j].mean(0) if np.any(labels == j) else c[j] for j in range(k)])
        if np.allclose(new, c):
            break
        c = new
    return labels


def cluster_candidates(
    db: KeyframeDB, idx: np.ndarray, k: int = 3, space: str = "pose", heading_m: float = 1.0
) -> list[np.ndarray]:
    """Groups of candidate keyframes (each nearest-first): k-means in pose space (x, y and the heading as a
    point on a circle of ``heading_m``), or (the paper's) on the keyframe indices, i.e. along the mapping run."""
    idx = np.asarray(idx)
    if space == "pose":
        p = db.poses[idx]
        feats = np.column_stack([p[:, 0], p[:, 1], heading_m * np.cos(p[:, 2]), heading_m * np.sin(p[:, 2])])
    elif space == "index":
        feats = idx[:, None].astype(np.float64)
    else:
        raise ValueError(f"globloc.cluster={space!r}: choose pose or index")
    labels = kmeans(feats, k)
    return [idx[labels == j] for j in range(labels.max() + 1) if np.any(labels == j)]
