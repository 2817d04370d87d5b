"""Is the estimate right? The modes of a particle set, the scan's agreement with the map, and a calibrated
confidence built on them (issue 33).

* ``modes(particles, log_w)``: the particle set's hypotheses, heaviest first: a weighted histogram of the
  positions in ``cell_m`` cells; the heaviest 3 x 3 block of cells is a mode (its weight), its particles are taken
  out, and so on. A mode's pose (``pose="densest"``) is that of its densest cluster: from its heaviest
  ``DENSEST_CELL_M`` cell and ``DENSEST_YAW_BINS`` heading bin (each counted with its 26 neighbours, so that a
  cluster straddling cell borders counts whole), the weighted mean of its particles within
  ``DENSEST_RADIUS_M`` and ``DENSEST_YAW_RAD`` of the pose, three times (a mean shift). The block's plain weighted
  mean (``pose="block"``, before the twenty-eighth session) lands between two clusters a block holds, or at a heading
  between two, where no scan fits. The heaviest mode's pose is the estimate a multi-hypothesis user reads.
* ``ScanAgreement``: the share of a scan's end points, placed from a pose, that lie within ``tolerance_m`` of a
  wall of the map (its distance transform). Near 1 where the scan fits the map at that pose.
* ``FEATURES``: what the robot has at each update: the heaviest mode's weight, the second's, the scan's agreement
  at the heaviest mode and at the second, that agreement over the last updates, its margin over the best rival
  place the set once held (``FeatureTracker``), how many updates the filter has made, the spread, and the evidence
  summed since a rival appeared: how much better the estimate has explained the scans than its best rival (negative
  while a rival explains them better: the set dropped the right place and cannot come back by itself). ``Confidence``: a logistic model of these (fitted by ``fit_logistic`` on the tuning worlds'
  runs, eval.confidence) giving a number meant as the probability that the estimate lies within
  ``RIGHT_M`` / ``RIGHT_DEG`` of the truth.
* ``auroc``, ``reliability``: how well a confidence separates right from wrong, and how well it is calibrated.
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt


MAX_PARTICLES = 20_000  # the features read every k-th particle of a larger set (k = ceil(n / this)): 40 ms of
# host work per update at 100k, 9 ms at 20k (2-core CPU); resampling keeps a set's copies together, so a stride
# samples it evenly
COARSE_TOLERANCE_M = 0.5  # ScanAgreement.search's first pass: poses 0.5 m and 22.5 deg apart are scored this loosely
MODE_POSES = ("densest", "block")  # how a mode's pose is read (``modes``)
DENSEST_CELL_M, DENSEST_YAW_BINS = 0.25, 16  # where the mean shift of a mode's pose starts: its heaviest such cell
DENSEST_RADIUS_M, DENSEST_YAW_RAD = 0.5, 0.35  # ... and the window it averages over: RIGHT_M, and 20 deg (twice
# RIGHT_DEG), so a cluster the estimate would count right with is one mode's pose
RIGHT_M = 0.5  # issue 33: the estimate counts as right within 0.5 m ...
RIGHT_DEG = 10.0  # ... and 10 deg of the truth
FEATURES = (
    "top_weight",
    "second_weight",
    "agreement",
    "agreement_margin",
    "agreement_recent",
    "rival_margin",
    "log_updates",
    "log_spread",
    "rival_evidence",
)
AGREEMENT = FEATURES.index("agreement")  # the scan's agreement at the heaviest mode, in a feature row
SEARCH_BUDGET = 40_000  # the look-alike search scores at most this many poses per search; a larger grid is covered in
# turns (a fixed shuffle of it, the next slice each search). Every simulated floor's grid holds fewer (34k at most:
# the calibrations' runs searched whole maps); MIT Killian's holds 586k, 1.6 s a search on the 2-core CPU
EVIDENCE_CAP = 3.0  # rival_evidence is read within +-this, and this without a rival: a rival the estimate has
# out-explained by this much (in scan shares summed over updates) is ruled out


@dataclass
class Modes:
    poses: np.ndarray  # [k, 3] weighted mean pose of each mode, heaviest first
    weights: np.ndarray  # [k] their share of the total weight


def normalised(log_w: np.ndarray) -> np.ndarray:
    w = np.exp(np.asarray(log_w, float) - np.max(log_w))
    return w / w.sum()


def circular_mean(w: np.ndarray, yaw: np.ndarray) -> float:
    return float(np.arctan2(np.sum(w * np.sin(yaw)), np.sum(w * np.cos(yaw))))


def densest_pose(p: np.ndarray, w: np.ndarray, steps: int = 3) -> np.ndarray:
    """The pose of the densest cluster of particles ``p`` [n, 3] weighted ``w`` [n] (see the module's text)."""
    cells = np.floor(p[:, :2] / DENSEST_CELL_M).astype(np.int64)
    cells -= cells.min(0) - 1  # (a mode's block: a few metres, so a dense histogram; one empty cell of margin)
    bins = np.minimum(np.floor(np.mod(p[:, 2], 2 * np.pi) / (2 * np.pi / DENSEST_YAW_BINS)), DENSEST_YAW_BINS - 1)
    bins = bins.astype(np.int64)
    nx, ny = cells.max(0) + 2
    key = (cells[:, 0] * ny + cells[:, 1]) * DENSEST_YAW_BINS + bins
    hist = np.bincount(key, w, minlength=nx * ny * DENSEST_YAW_BINS).reshape(nx, ny, DENSEST_YAW_BINS)
    # each cell with its 26 neighbours (the heading wraps round): a cluster that straddles cell borders (up to 8
    # cells) is not outweighed by a smaller one that one cell holds whole
    near = sum(
        np.roll(hist, (dx, dy, dyaw), (0, 1, 2)) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dyaw in (-1, 0, 1)
    )
    heaviest = key == np.argmax(np.where(hist > 0, near, -1.0))  # (a cell with weight of its own)
    pose = np.array([*(w[heaviest] @ p[heaviest, :2] / w[heaviest].sum()), circular_mean(w[heaviest], p[heaviest, 2])])
    for _ in range(steps):
        d = p - pose
        near = (d[:, 0] ** 2 + d[:, 1] ** 2 <= DENSEST_RADIUS_M**2) & (
            np.abs(np.mod(d[:, 2] + np.pi, 2 * np.pi) - np.pi) <= DENSEST_YAW_RAD
        )
        if w[near].sum() <= 0:
            break
        ww = w[near] / w[near].sum()
        pose = np.array([*(ww @ p[near, :2]), circular_mean(ww, p[near, 2])])
    return pose


def modes(particles: np.ndarray, log_w: np.ndarray, cell_m: float = 1.0, k: int = 3, pose: str = "densest") -> Modes:
    """The ``k`` heaviest modes of the weighted particles (see the module's text)."""
    if pose not in MODE_POSES:
        raise ValueError(f"modes: pose {pose!r} is not one of {MODE_POSES}")
    p = np.asarray(particles, float)
    w = normalised(log_w)
    cells = np.floor(p[:, :2] / cell_m).astype(np.int64)
    cells -= cells.min(0)
    nx, ny = cells.max(0) + 3
    flat = (cells[:, 1] + 1) * nx + cells[:, 0] + 1  # one empty cell of margin all round
    left = np.ones(len(p), bool)
    poses, weights = [], []
    for _ in range(k):
        if not left.any():
            break
        hist = np.bincount(flat[left], w[left], minlength=nx * ny).reshape(ny, nx)
        block = sum(np.roll(np.roll(hist, dy, 0), dx, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        iy, ix = np.unravel_index(np.argmax(block), block.shape)
        mine = left & (np.abs(cells[:, 0] + 1 - ix) <= 1) & (np.abs(cells[:, 1] + 1 - iy) <= 1)
        if not mine.any() or w[mine].sum() <= 0:
            break
        ww = w[mine] / w[mine].sum()
        if pose == "densest":
            poses.append(densest_pose(p[mine], ww))
        else:
            poses.append([*(ww @ p[mine, :2]), circular_mean(ww, p[mine, 2])])
        weights.append(float(w[mine].sum()))
        left &= ~mine
    return Modes(np.array(poses).reshape(-1, 3), np.array(weights))


def spread(particles: np.ndarray, log_w: np.ndarray) -> float:
    """sqrt(var x + var y) of the weighted particles (m)."""
    w = normalised(log_w)
    xy = np.asarray(particles, float)[:, :2]
    mean = w @ xy
    return float(np.sqrt(w @ np.sum((xy - mean) ** 2, 1)))


class ScanAgreement:
    """Share of a scan's end points within ``tolerance_m`` of a wall (cells at or above ``occ_threshold``) of
    an occupancy grid ``occupancy`` [H, W] (p_occ; lower-left corner ``origin_xy``). Every ``beam_step``-th
    beam is used; end points off the grid count as not agreeing."""

    def __init__(
        self,
        occupancy,
        origin_xy,
        resolution_m: float,
        occ_threshold: float = 0.65,
        tolerance_m: float = 0.2,
        beam_step: int = 4,
    ):
        walls = np.asarray(occupancy) >= occ_threshold
        if not walls.any():
            raise ValueError("scan agreement: the map has no wall")
        dist = distance_transform_edt(~walls) * resolution_m
        self.near = dist <= tolerance_m
        self.near_coarse = dist <= COARSE_TOLERANCE_M  # for a search over poses 0.5 m and 22.5 deg apart
        self.origin, self.res, self.step = np.asarray(origin_xy, float), float(resolution_m), int(beam_step)

    @classmethod
    def of_grid(cls, grid, occ_threshold: float = 0.65) -> "ScanAgreement":
        """The agreement with an occupancy grid's known cells (``grid.known``; unknown cells hold no wall)."""
        return cls(np.where(grid.known, grid.probability, 0.0), grid.origin_xy, grid.resolution_m, occ_threshold)

    def __call__(self, pose, ranges_m, angles_rad, T_base_laser) -> float:
        return float(self.many(np.asarray(pose, float)[None], ranges_m, angles_rad, T_base_laser)[0])

    def many(self, poses, ranges_m, angles_rad, T_base_laser, coarse: bool = False) -> np.ndarray:
        """The agreement at each of ``poses`` [k, 3]: [k] (``coarse``: within COARSE_TOLERANCE_M of a wall)."""
        r = np.asarray(ranges_m, float)[:: self.step]
        a = np.asarray(angles_rad, float)[:: self.step]
        ok = np.isfinite(r)
        poses = np.asarray(poses, float)
        if not ok.any():
            return np.zeros(len(poses))
        x, y, yaw = poses[:, :1], poses[:, 1:2], poses[:, 2:3]
        c, s = np.cos(yaw), np.sin(yaw)
        lx, ly = x + c * T_base_laser[0] - s * T_base_laser[1], y + s * T_base_laser[0] + c * T_base_laser[1]
        heading = yaw + T_base_laser[2] + a[ok][None]
        ix = np.floor((lx + r[ok] * np.cos(heading) - self.origin[0]) / self.res).astype(int)
        iy = np.floor((ly + r[ok] * np.sin(heading) - self.origin[1]) / self.res).astype(int)
        near = self.near_coarse if coarse else self.near
        H, W = near.shape
        inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
        hits = np.zeros(ix.shape, bool)
        hits[inside] = near[iy[inside], ix[inside]]
        return hits.mean(1)

    def search(
        self,
        candidates,
        ranges_m,
        angles_rad,
        T_base_laser,
        away_from,
        apart_m: float,
        count: int = 3,
        chunk: int = 4096,
    ) -> list[tuple[np.ndarray, float]]:
        """Look-alike places: the ``count`` best agreeing of ``candidates`` [k, 3] (a coarse grid of the map's free
        space), each at least ``apart_m`` from ``away_from`` [x, y] and from each other, refined twice (0.2 m /
        0.1 rad steps, then 0.1 m / 0.05 rad): [(pose, agreement)], best first."""
        scan = (ranges_m, angles_rad, T_base_laser)
        score = np.concatenate(
            [self.many(candidates[i : i + chunk], *scan, coarse=True) for i in range(0, len(candidates), chunk)]
        )
        order = np.argsort(-score, kind="stable")
        picked = []
        for i in order[:200]:
            xy = candidates[i, :2]
            if np.hypot(*(xy - away_from[:2])) < apart_m or any(np.hypot(*(xy - p[:2])) < apart_m for p, _ in picked):
                continue
            pose, _ = self.refine(candidates[i], *scan, step_m=0.2, step_rad=0.1)
            picked.append(self.refine(pose, *scan))
            if len(picked) == count:
                break
        return sorted(picked, key=lambda pa: -pa[1])

    def refine(self, pose, ranges_m, angles_rad, T_base_laser, step_m: float = 0.1, step_rad: float = 0.05):
        """(the pose of best agreement among ``pose`` and its 124 neighbours on a grid of +-2 steps in x, y and
        yaw, its agreement): a hypothesis kept aligned with the scans without particles."""
        d = np.arange(-2, 3)
        grid = np.stack(np.meshgrid(d * step_m, d * step_m, d * step_rad, indexing="ij"), -1).reshape(-1, 3)
        cand = np.asarray(pose, float) + grid
        score = self.many(cand, ranges_m, angles_rad, T_base_laser)
        best = int(np.argmax(score + 1e-6 * (np.abs(grid).sum(1) == 0)))  # ties: stay
        return cand[best], float(score[best])


def search_grid(grid, spacing_m: float = 0.5, headings: int = 16) -> np.ndarray:
    """Poses [k, 3] on the map's known free cells every ``spacing_m``, each at ``headings`` headings: where the
    confidence looks for look-alike places."""
    step = max(1, int(round(spacing_m / grid.resolution_m)))
    free = grid.known & (grid.probability < 0.35)
    free[np.arange(free.shape[0]) % step != 0] = False
    free[:, np.arange(free.shape[1]) % step != 0] = False
    iy, ix = np.nonzero(free)
    xy = np.column_stack([ix, iy]) * grid.resolution_m + np.asarray(grid.origin_xy) + grid.resolution_m / 2
    yaw = np.linspace(-np.pi, np.pi, headings, endpoint=False)
    return np.column_stack([np.repeat(xy, headings, 0), np.tile(yaw, len(xy))])


class FeatureTracker:
    """The confidence's features at each filter update, with what they remember across updates:

    * the scan's agreement at the heaviest mode over the last ``recent`` updates;
    * rivals: the places the particle set once held as a mode of at least ``rival_weight`` away from the
      heaviest one, kept after their particles are gone (resampling drifts a set onto one of two look-alike
      places without any evidence against the other). Each is moved by the odometry and its scan agreement kept
      up to date; a rival whose recent agreement falls ``rule_out`` below the heaviest mode's has been ruled out
      by the scans and is dropped. ``rival_margin`` is the heaviest mode's recent agreement less the best rival's
      (1 without a rival): near 0 while another place explains the scans as well. With ``refine_rivals`` each
      rival is moved, at every update, to the best agreeing pose near it (``ScanAgreement.refine``): the odometry's
      drift and a mode's rough mean pose would otherwise rule a true place out. With ``search_every`` = k > 0,
      every k-th update also searches ``search_poses`` (a coarse grid of the map's free space) for places the
      scan fits as well as the estimate's, and keeps them as rivals (``ScanAgreement.search``): a look-alike place
      the particle set never held, or dropped before it became a mode.

    Each rival also carries its evidence: the heaviest mode's agreement less the rival's, summed over the updates
    since it appeared (with ``refine_rivals`` the heaviest mode's agreement is also its best near it, as the rival's
    is, so that neither is favoured). ``rival_evidence`` is the smallest over the rivals (EVIDENCE_CAP without
    one; a rival whose evidence reaches EVIDENCE_CAP is dropped); ``best_rival()`` the pose whose evidence it is.
    ``mode_pose``: how the modes' poses are read (``modes``; "block" for calibrations fitted before it)."""

    def __init__(
        self,
        agreement: ScanAgreement,
        recent: int = 10,
        rival_weight: float = 0.02,
        rival_apart_m: float = 2.0,
        rule_out: float = 0.25,
        max_rivals: int = 16,
        refine_rivals: bool = False,
        search_poses=None,
        search_every: int = 0,
        mode_pose: str = "densest",
    ):
        if mode_pose not in MODE_POSES:
            raise ValueError(f"FeatureTracker: mode_pose {mode_pose!r} is not one of {MODE_POSES}")
        self.agreement, self.refine_rivals, self.mode_pose = agreement, refine_rivals, mode_pose
        self.search_poses, self.search_every = search_poses, int(search_every)
        if search_poses is not None and len(search_poses) > SEARCH_BUDGET:  # covered in turns, SEARCH_BUDGET a search
            self.search_poses = np.asarray(search_poses)[np.random.default_rng(0).permutation(len(search_poses))]
        self.search_from = 0  # where the next search's slice starts
        self.recent, self.rival_weight, self.rival_apart_m = recent, rival_weight, rival_apart_m
        self.rule_out, self.max_rivals = rule_out, max_rivals
        self.reset()

    def reset(self) -> None:
        """After a fresh uniform start (relocalization): the history belongs to the old hypotheses."""
        self.history = deque(maxlen=self.recent)
        self.rivals = np.zeros((0, 3))
        self.rival_history = np.zeros((0, self.recent))  # NaN-padded recent agreements, newest last
        self.rival_evidence = np.zeros(0)  # the heaviest mode's agreement less the rival's, summed since it appeared
        self.updates = 0

    def __call__(
        self, particles, log_w, ranges_m, angles_rad, T_base_laser, odom_delta=(0.0, 0.0, 0.0)
    ) -> tuple[np.ndarray, Modes]:
        """``odom_delta``: the odometry's motion since the last update, in the robot's frame (x, y, yaw)."""
        stride = -(-len(log_w) // MAX_PARTICLES)  # a systematic sample of a large set (a GPU's 100k)
        particles, log_w = np.asarray(particles)[::stride], np.asarray(log_w)[::stride]
        m = modes(particles, log_w, pose=self.mode_pose)
        self.updates += 1
        scan = (ranges_m, angles_rad, T_base_laser)
        top = self.agreement(m.poses[0], *scan)
        second = self.agreement(m.poses[1], *scan) if len(m.weights) > 1 else 0.0
        self.history.append(top)
        recent_top = float(np.mean(self.history))
        rival_margin, evidence = self._rivals(m, odom_delta, scan, recent_top, top)
        f = np.array(
            [
                m.weights[0],
                m.weights[1] if len(m.weights) > 1 else 0.0,
                top,
                top - second,
                recent_top,
                rival_margin,
                np.log1p(self.updates),
                np.log(spread(particles, log_w) + 0.01),
                evidence,
            ]
        )
        return f, m

    def best_rival(self) -> tuple[np.ndarray, float] | None:
        """(the pose of the rival with the least evidence against it, that evidence), or None without a rival."""
        if not len(self.rivals):
            return None
        i = int(np.argmin(self.rival_evidence))
        return self.rivals[i].copy(), float(self.rival_evidence[i])

    def forget_evidence(self) -> None:
        """Start every rival's evidence again from 0 (after the particle set was given a rival's place: the
        filter's own weights judge it from there)."""
        self.rival_evidence[:] = 0.0

    def _search_slice(self) -> np.ndarray:
        """The poses this search scores: all of them when they are at most SEARCH_BUDGET, else the next slice of
        SEARCH_BUDGET of the shuffled grid (wrapping around)."""
        n = len(self.search_poses)
        if n <= SEARCH_BUDGET:
            return self.search_poses
        pick = (self.search_from + np.arange(SEARCH_BUDGET)) % n
        self.search_from = int((self.search_from + SEARCH_BUDGET) % n)
        return self.search_poses[pick]

    def _rivals(self, m: Modes, odom_delta, scan, recent_top: float, top: float) -> tuple[float, float]:
        if len(self.rivals):  # moved as the robot moved
            self.rivals = compose_rows(self.rivals, np.asarray(odom_delta, float))
        found = []
        if self.search_every > 0 and self.search_poses is not None and self.updates % self.search_every == 0:
            found = [
                (p, 1.0)
                for p, a in self.agreement.search(self._search_slice(), *scan, m.poses[0], self.rival_apart_m)
                if a > recent_top - self.rule_out
            ]
        for pose, w in [*zip(m.poses[1:], m.weights[1:]), *found]:
            if w < self.rival_weight or np.hypot(*(pose[:2] - m.poses[0, :2])) < self.rival_apart_m:
                continue
            if len(self.rivals) and np.min(np.hypot(*(self.rivals[:, :2] - pose[:2]).T)) < self.rival_apart_m:
                continue
            if len(self.rivals) < self.max_rivals:
                self.rivals = np.vstack([self.rivals, pose])
                self.rival_history = np.vstack([self.rival_history, np.full(self.recent, np.nan)])
                self.rival_evidence = np.append(self.rival_evidence, 0.0)
        if not len(self.rivals):
            return 1.0, EVIDENCE_CAP
        if self.refine_rivals:
            refined = [self.agreement.refine(p, *scan) for p in self.rivals]
            self.rivals = np.array([p for p, _ in refined])
            scores = np.array([a for _, a in refined])
            top = self.agreement.refine(m.poses[0], *scan)[1]  # the estimate's best near it, as the rivals' are
        else:
            scores = self.agreement.many(self.rivals, *scan)
        self.rival_evidence = self.rival_evidence + (top - scores)
        near_top = np.hypot(*(self.rivals[:, :2] - m.poses[0, :2]).T) < self.rival_apart_m  # the set came to it
        self.rival_history = np.column_stack([self.rival_history[:, 1:], scores])
        recent = np.nansum(self.rival_history, 1) / np.maximum(np.isfinite(self.rival_history).sum(1), 1)
        keep = ~near_top & (recent > recent_top - self.rule_out) & (self.rival_evidence < EVIDENCE_CAP)
        self.rivals, self.rival_history = self.rivals[keep], self.rival_history[keep]
        self.rival_evidence = self.rival_evidence[keep]
        if not keep.any():
            return 1.0, EVIDENCE_CAP
        return float(recent_top - recent[keep].max()), float(max(self.rival_evidence.min(), -EVIDENCE_CAP))


def compose_rows(poses: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Each pose [k, 3] moved by ``delta`` (x, y, yaw) in its own frame."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.column_stack(
        [
            poses[:, 0] + c * delta[0] - s * delta[1],
            poses[:, 1] + s * delta[0] + c * delta[1],
            np.angle(np.exp(1j * (poses[:, 2] + delta[2]))),
        ]
    )


def right(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Is each estimate [n, 3] within RIGHT_M and RIGHT_DEG of the truth [n, 3]?"""
    d_yaw = np.degrees(np.abs(np.angle(np.exp(1j * (est[:, 2] - gt[:, 2])))))
    return (np.hypot(*(est[:, :2] - gt[:, :2]).T) < RIGHT_M) & (d_yaw < RIGHT_DEG)


def tracker_of(w) -> dict:
    """How a worlds run tracked rivals and read modes (``Confidence.tracker``'s keys), from its worlds settings (a
    dict or a config); a setting a record lacks reads as runs before it did."""
    return {
        "refine_rivals": bool(w.get("refine_rivals", False)),
        "search_every": int(w.get("search_rivals_every", 0)),
        "mode_pose": w.get("mode_pose", "block"),
    }


class Confidence:
    """p(right | features) = sigmoid(coef . (f - mean) / scale + intercept), the model of a calibration file.

    ``lo``, ``hi``: the range of each feature in the data it was fitted on; a feature outside is read at the
    nearest end, so the model is never extrapolated. (The simulated tuning drives make at most ~135 updates; a
    real log makes thousands, and a 100k model fitted without bounds read ``log_updates`` 4-5 standard deviations
    past its data and called every long right run unsure: 0.12 at the end of MIT Killian, 0.6 on intel.)
    Calibrations fitted before the bounds were kept have none and are read as they were.

    ``tracker``: how the runs it was fitted on tracked their rivals and read their modes (``FeatureTracker``'s
    ``refine_rivals``, ``search_every`` and ``mode_pose``; a file without ``mode_pose`` was fitted on "block"):
    features made otherwise are not the ones it was fitted on."""

    def __init__(
        self, coef, intercept: float, mean, scale, meta: dict | None = None, lo=None, hi=None, features=FEATURES
    ):
        self.features = tuple(features)  # the names of the features it reads, a subset of FEATURES in that order
        self.columns = np.array([FEATURES.index(f) for f in self.features], int)
        self.coef, self.intercept = np.asarray(coef, float), float(intercept)
        self.mean, self.scale = np.asarray(mean, float), np.asarray(scale, float)
        self.lo = None if lo is None else np.asarray(lo, float)
        self.hi = None if hi is None else np.asarray(hi, float)
        self.meta = meta or {}

    def __call__(self, features: np.ndarray) -> np.ndarray:
        """``features``: rows of all FEATURES (a calibration fitted on fewer reads its own columns)."""
        f = np.asarray(features, float)[..., self.columns]
        if self.lo is not None:
            f = np.clip(f, self.lo, self.hi)
        z = (f - self.mean) / self.scale @ self.coef + self.intercept
        return 1.0 / (1.0 + np.exp(-z))

    @property
    def tracker(self) -> dict:
        """{"refine_rivals", "search_every"} of the runs it was fitted on (calibrations older than the setting: none)."""
        return {"refine_rivals": False, "search_every": 0, "mode_pose": "block", **self.meta.get("tracker", {})}

    @classmethod
    def load(cls, path) -> "Confidence":
        path = Path(path)
        try:
            doc = json.loads(path.read_text())
            unknown = [f for f in doc["features"] if f not in FEATURES]
            if unknown:
                raise ValueError(
                    f"features {unknown} are not among those this code computes ({list(FEATURES)}): fit it again "
                    "(python -m eval.confidence fit)"
                )
            return cls(
                doc["coef"],
                doc["intercept"],
                doc["mean"],
                doc["scale"],
                doc,
                doc.get("lo"),
                doc.get("hi"),
                doc["features"],
            )
        except (OSError, KeyError, json.JSONDecodeError) as e:
            raise ValueError(f"{path}: not a confidence calibration ({e})") from None

    def to_json(self) -> dict:
        return {
            **self.meta,
            "features": list(self.features),
            "coef": self.coef.tolist(),
            "intercept": self.intercept,
            "mean": self.mean.tolist(),
            "scale": self.scale.tolist(),
            **({} if self.lo is None else {"lo": self.lo.tolist(), "hi": self.hi.tolist()}),
        }


def fit_logistic(X: np.ndarray, y: np.ndarray, l2: float = 1e-3, iterations: int = 50) -> Confidence:
    """Logistic regression by Newton's method (IRLS) on standardised features, a little L2 on the weights."""
    X, y = np.asarray(X, float), np.asarray(y, float)
    if len(np.unique(y)) < 2:
        raise ValueError("calibration: every sample is right (or every one wrong): nothing to separate")
    mean, scale = X.mean(0), X.std(0)
    scale[scale == 0] = 1.0
    Z = np.column_stack([(X - mean) / scale, np.ones(len(X))])
    beta = np.zeros(Z.shape[1])
    reg = np.full(Z.shape[1], l2 * len(X))
    reg[-1] = 0.0
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-Z @ beta))
        grad = Z.T @ (p - y) + reg * beta
        hess = (Z * (p * (1 - p))[:, None]).T @ Z + np.diag(reg) + 1e-9 * np.eye(Z.shape[1])
        delta = np.linalg.solve(hess, grad)
        beta -= delta
        if np.max(np.abs(delta)) < 1e-8:
            break
    return Confidence(beta[:-1], beta[-1], mean, scale, lo=X.min(0), hi=X.max(0))


def auroc(score: np.ndarray, label: np.ndarray) -> float:
    """Area under the ROC curve: the probability that a random right sample scores above a random wrong one
    (ties count half); from the ranks (Mann-Whitney U)."""
    score, label = np.asarray(score, float), np.asarray(label, bool)
    n_pos, n_neg = label.sum(), (~label).sum()
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(score, kind="mergesort")
    ranks = np.empty(len(score))
    s = score[order]
    i = 0
    while i < len(s):  # average ranks over ties
        j = i
        while j + 1 < len(s) and s[j + 1] == s[i]:
            j += 1
        ranks[order[i : j + 1]] = (i + j) / 2 + 1
        i = j + 1
    return float((ranks[label].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def reliability(prob: np.ndarray, label: np.ndarray, bins: int = 10) -> list[dict]:
    """Per bin of predicted probability: the mean prediction, the observed share right, and the count."""
    prob, label = np.asarray(prob, float), np.asarray(label, bool)
    edges = np.linspace(0, 1, bins + 1)
    which = np.clip(np.digitize(prob, edges) - 1, 0, bins - 1)
    return [
        {
            "from": float(edges[b]),
            "to": float(edges[b + 1]),
            "predicted": float(prob[which == b].mean()),
            "observed": float(label[which == b].mean()),
            "count": int((which == b).sum()),
        }
        for b in range(bins)
        if (which == b).any()
    ]


class Judge:
    """A localizer's confidence after each update (track.Localizer's ``judge``): the features of a
    ``FeatureTracker`` on the map, through a calibrated ``Confidence``, from the filter's particles and weights
    as read back after the update (a systematic sample of at most MAX_PARTICLES is used). ``pose``: the heaviest
    mode's pose, the one the confidence is about (the worlds stage's estimate, which the calibration judged)."""

    def __init__(self, tracker: FeatureTracker, confidence: Confidence, angles_rad, T_base_laser):
        self.tracker, self.confidence = tracker, confidence
        self.angles, self.T = np.asarray(angles_rad, float), tuple(map(float, T_base_laser))
        self.pose = None  # the pose the last confidence is about: the heaviest mode's [x, y, yaw]
        self.features = None  # the last update's feature row (FEATURES)

    def __call__(self, particles, log_w, ranges_m, odom_delta) -> float:
        self.features, m = self.tracker(particles, log_w, ranges_m, self.angles, self.T, odom_delta)
        self.pose = np.array(m.poses[0], float)
        return float(self.confidence(self.features))

    def reset(self) -> None:
        self.tracker.reset()
        self.pose = self.features = None
