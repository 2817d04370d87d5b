"""The simulated world's appearance and camera: wall paint, posters and furniture colours per segment
(``appearance``), per-session nuisances (``Session``), and ``Camera``: RGB-D frames of robot poses through
the camera's extrinsics, rendered by kernels/camera.py.

Posters hang on the walls, one per wall piece longer than 1.2 m (the outer walls too). ``lookalike_share``
of them copy another poster (look-alike bays); in the repetitive world the geometry of every bay is the
same, so the posters are what tells the bays apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irmcl_warp.geometry import compose
from irmcl_warp.kernels import SIM

WALL_HEIGHT_M, FURNITURE_HEIGHT_M, PERSON_HEIGHT_M = 2.5, 0.8, 1.7
POSTER_M = (0.8, 0.6, 1.2)  # a poster's width, height and the height of its lower edge (m)
POSTER_CELLS = (8, 6)  # its pattern's cells across and up


@dataclass
class Appearance:
    heights: np.ndarray  # [K] m
    colours: np.ndarray  # [K, 3] 0..1
    posters: np.ndarray  # [K, 2] (poster id or -1, u of its centre along the segment)


def appearance(world, seed: int = 0, lookalike_share: float = 0.2, poster_prob: float = 0.9) -> Appearance:
    rng = np.random.default_rng(seed + 7919)
    segs = world.segments
    K = len(segs)
    n_walls = K if world.n_walls < 0 else world.n_walls
    heights = np.where(np.arange(K) < n_walls, WALL_HEIGHT_M, FURNITURE_HEIGHT_M).astype(np.float32)
    paint = np.array([0.86, 0.83, 0.74])
    colours = np.tile(paint, (K, 1)) * rng.uniform(0.93, 1.0, (K, 1))
    colours[n_walls:] = rng.uniform(0.15, 0.8, (K - n_walls, 3))  # furniture
    posters = np.full((K, 2), -1.0)
    length = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    made = []
    for k in np.flatnonzero(length[:n_walls] > 1.2):
        if rng.uniform() > poster_prob:
            continue
        pid = int(rng.choice(made)) if made and rng.uniform() < lookalike_share else len(made) + 1
        made.append(pid)
        posters[k] = (pid, rng.uniform(0.5, length[k] - 0.5))
    return Appearance(heights, colours.astype(np.float32), posters.astype(np.float32))


@dataclass
class Session:
    """What changes between the mapping run and a query run."""

    exposure: float = 1.0
    tint: tuple = (1.0, 1.0, 1.0)
    noise_std: float = 0.01  # pixel noise, 0..1 units
    seed: int = 0

    @staticmethod
    def draw(rng, lighting: float = 0.0) -> "Session":
        """A session with lighting changes of relative size ``lighting`` (0: the mapping run's light)."""
        return Session(
            float(1.0 + lighting * rng.uniform(-1, 1)),
            tuple(float(v) for v in 1.0 + 0.5 * lighting * rng.uniform(-1, 1, 3)),
            0.01,
            int(rng.integers(1 << 30)),
        )


class Camera:
    """Pinhole RGB-D camera on the robot: ``T_base_cam`` (x, y, yaw in the base frame); 320 x 240 and a
    58 deg horizontal field of view by default."""

    def __init__(
        self,
        segments,
        look: Appearance,
        width: int = 320,
        height: int = 240,
        hfov_deg: float = 58.0,
        cam_height_m: float = 1.0,
        T_base_cam=(0.15, 0.0, 0.0),
        device: str = "auto",
    ):
        self.T_base_cam = np.asarray(T_base_cam, np.float64)
        self.kernel = SIM.build(
            "camera",
            segments=segments,
            heights=look.heights,
            colours=look.colours,
            posters=look.posters,
            poster_m=POSTER_M,
            poster_cells=POSTER_CELLS,
            width=width,
            height=height,
            hfov_rad=np.radians(hfov_deg),
            cam_height_m=cam_height_m,
            wall_height_m=WALL_HEIGHT_M,
            device=device,
        )

    @property
    def K(self) -> np.ndarray:
        return self.kernel.K

    @property
    def size_hw(self) -> tuple:
        return self.kernel.H, self.kernel.W

    def render(self, robot_poses, session: Session = Session(), batch: int = 256):
        """(rgb uint8 [F, H, W, 3], depth float32 [F, H, W]) at robot poses [F, 3]."""
        cams = compose(np.asarray(robot_poses, np.float64).reshape(-1, 3), self.T_base_cam)
        rgbs, depths = [], []
        for i in range(0, len(cams), batch):
            rgb, depth = self.kernel.render(
                cams[i : i + batch], session.exposure, session.tint, session.noise_std, session.seed + i
            )
            rgbs.append(np.round(rgb).astype(np.uint8))
            depths.append(depth)
        return np.concatenate(rgbs), np.concatenate(depths)
