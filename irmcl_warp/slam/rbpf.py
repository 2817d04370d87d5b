"""GMapping's Rao-Blackwellized particle filter (Grisetti, Stachniss, Burgard, T-RO 2007) on Warp kernels.

Every scan's odometry step moves the particles by the odometry motion model (the steps are queued on the
host and applied in one launch when a scan is processed: the same draws, one launch instead of one per
scan). Once the robot's path since the last processed scan is ``linear_update`` long or its turns add up
to ``angular_update`` (the released code's accumulated distances), the scan is processed:

1. scan matching: hill climbing over (x, y, theta) from each particle's pose on its own map, steps
   lstep / astep halved ``iterations`` times; each round scores all particles x 6 moves x beams in one
   launch (kernels/slam/score.py ``score``);
2. the proposal (``proposal``):
   * ``paper``: the scan likelihood (times the motion prior) at (2g + 1)^3 poses around the match defines
     a Gaussian (mean, covariance); the new pose is drawn from it and the weight multiplied by
     eta = the sum of those values (the paper's eqs. 19-21);
   * ``gmapping_code``: the pose becomes the match, the weight is multiplied by the likelihood there
     (what the released C++ does);
   * ``odometry``: the motion model's sample, weighted by its likelihood (the baseline);
3. weights smoothed as exp((log w - max) / (ogain * N)) (the released code); N_eff = 1 / sum w^2;
   low-variance resampling (maps copied on the device) when N_eff < threshold * N (``selective``) or
   every time (``always``);
4. each particle integrates the scan into its map (kernels/slam/maps.py ``integrate``), the maps first grown to
   hold the scan's end points (``ParticleMaps.cover``), as the released code's maps grow.

The host keeps only P-sized arrays (weights, hill-climbing state) and each processed scan's poses and
resampling parents, from which the best particle's trajectory is traced back at the end.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp
from omegaconf import OmegaConf

from irmcl_warp.config import SlamConfig
from irmcl_warp.geometry import compose, relative, relative_one, wrap_angle, wrap_angle_one
from irmcl_warp.kernels import SLAM, Registry, pick_device
from irmcl_warp.kernels.slam import MAX_BLOCK_BEAMS, ParticleMaps, climb_candidates_kernel, climb_update_kernel


def low_variance_parents(w: np.ndarray, offset: float) -> np.ndarray:
    """Thrun et al. Table 4.4 on the host (P is small): pointers (offset + i) / P into the cumulative
    normalised weights ``w``; returns each new particle's parent."""
    log_w = np.log(w)
    p = np.exp(log_w - np.max(log_w))
    cdf = np.cumsum(p / p.sum())
    u = (offset + np.arange(len(cdf))) / len(cdf)
    return np.minimum(np.searchsorted(cdf, u, side="right"), len(cdf) - 1)


@dataclass
class StepStats:
    processed: bool
    neff: float = float("nan")
    resampled: bool = False
    match_rounds: int = 0


@dataclass
class History:
    """Per processed scan: its index in the log, every particle's pose, and the parents chosen after it."""

    scans: list = field(default_factory=list)
    poses: list = field(default_factory=list)
    parents: list = field(default_factory=list)


def timed(part: str):
    """Decorator of an RBPF step's part: its wall time, with the device synchronised before and after, is added
    to ``self.timing[part]``, so the step itself holds no timing call."""

    def wrap(method):
        @functools.wraps(method)
        def run(self, *args, **kwargs):
            start = self._synced_clock()
            out = method(self, *args, **kwargs)
            self.timing[part] += self._synced_clock() - start
            return out

        return run

    return wrap


PROPOSALS = Registry("slam proposal")  # name -> factory(rbpf) -> Proposal (irmcl_warp/extend.py); built-in below


class RBPF:
    FIRST_LOOK = 24  # hill-climbing rounds launched before the host first reads the active flags (GPU way)

    def __init__(self, cfg, shape_hw, origin_xy, T_base_laser, angles_rad, far_m: float, device: str = "auto"):
        if cfg.proposal not in PROPOSALS.names():
            raise ValueError(f"slam.proposal={cfg.proposal!r}: choose one of {PROPOSALS.names()}")
        # (sampled poses, odometry since the last processed scan) -> (new, gain, rounds)
        self.propose = PROPOSALS.build(cfg.proposal, rbpf=self)
        if cfg.resample not in ("selective", "always"):
            raise ValueError(f"slam.resample={cfg.resample!r}: choose selective or always")
        if not isinstance(cfg, SlamConfig):  # a DictConfig: plain attributes instead (microseconds a read there)
            cfg = SlamConfig(**OmegaConf.to_container(cfg, resolve=True))
        self.cfg, self.device = cfg, pick_device(device)
        P, d = int(cfg.num_particles), self.device
        self.P, self.T_base_laser = P, tuple(map(float, T_base_laser))
        self.maps = ParticleMaps(P, shape_hw, origin_xy, cfg.resolution_m, device=d)
        self.integrator = SLAM.build(
            "integrate", far_m=far_m, line=cfg.line, free_space=bool(cfg.generate_map), device=d
        )
        self.scorer = SLAM.build(
            "score",
            far_m=far_m,
            kernel_size=cfg.kernel_size,
            fullness=cfg.fullness,
            sigma=cfg.sigma,
            lsigma=cfg.lsigma,
            null_likelihood=cfg.null_likelihood,
            free_delta_m=cfg.resolution_m * np.sqrt(2.0),
            lskip=cfg.lskip,
            free_check=bool(cfg.free_check),
            device=d,
        )
        self.motion = SLAM.build("motion", srr=cfg.srr, srt=cfg.srt, str_=cfg.str, stt=cfg.stt, device=d)
        self.angles = wp.array(np.asarray(angles_rad, np.float32), dtype=wp.float32, device=d)
        self.ranges = wp.zeros(len(angles_rad), dtype=wp.float32, device=d)
        self._angles_np, self._ranges_np = np.asarray(angles_rad, np.float64), np.zeros(len(angles_rad))
        self.poses = wp.zeros(P, dtype=wp.vec3, device=d)
        g = int(cfg.proposal_grid)
        offs = np.stack(np.meshgrid(*[np.arange(-g, g + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
        ls = cfg.lstep if cfg.proposal_lstep is None else cfg.proposal_lstep
        as_ = cfg.astep if cfg.proposal_astep is None else cfg.proposal_astep
        self.grid_offsets = offs * np.array([ls, ls, as_])
        self._buffers = {}
        self._cuda, self._mirrors = wp.get_device(d).is_cuda, {}  # pinned host mirrors of device arrays (_read)
        self._sources, self._in_flight = (
            {},
            set(),
        )  # pinned host sources of device arrays (_write), copies not yet waited for
        self.log_w = np.zeros(P)  # since the last resampling
        self.log_w_total = np.zeros(P)  # over the whole run (inherited on resampling): picks the best particle
        self.history = History()
        self.rng = np.random.default_rng(cfg.seed)
        self.steps = 0
        self.timing = {"motion": 0.0, "matching": 0.0, "weights_resampling": 0.0, "integration": 0.0}
        self.last_odom = None  # odometry at the last processed scan
        self.prev_odom = None  # odometry at the previous scan
        self.pending = []  # odometry steps not yet applied to the particles
        self.path_m = self.turn_rad = 0.0  # travelled and turned since the last processed scan
        self.last_stamp = None  # stamp of the last processed scan (temporal_update)
        self._graph = None  # CUDA graph of check_every hill-climbing rounds

    # --- device helpers -----------------------------------------------------------------------------
    def _read(self, a: wp.array) -> np.ndarray:
        """``a.numpy()`` without its cost on a GPU: a.numpy() allocates a host array and copies through
        pageable memory (about 170 us a call, thousands of calls a run); here each device array has one
        pinned host mirror, copied into and waited for. The returned view is overwritten by the next read of
        the same array. On the CPU, a.numpy() itself (a view, no copy)."""
        if not self._cuda:
            return a.numpy()
        mirror, view = self._pinned(self._mirrors, a)
        wp.copy(mirror, a)
        self._wait()
        return view

    def _write(self, a: wp.array, values: np.ndarray) -> None:
        """``a.assign(values)`` without its cost on a GPU: assign makes a device array of the values (an
        allocation and a copy through pageable memory) at every call; here each device array has one pinned
        host source, filled on the host and copied to the device in the stream's order. A source whose last
        copy may not have run yet is waited for before it is filled again. On the CPU, a.assign itself."""
        if not self._cuda:
            a.assign(values)
            return
        src, view = self._pinned(self._sources, a)
        if src.ptr in self._in_flight:
            self._wait()
        view[...] = values
        wp.copy(a, src)
        self._in_flight.add(src.ptr)

    @staticmethod
    def _pinned(store: dict, a: wp.array) -> tuple[wp.array, np.ndarray]:
        """The pinned host buffer of device array ``a`` in ``store`` (made on first use) and its numpy view."""
        key = (a.ptr, a.shape)
        if key not in store:
            host = wp.empty(a.shape, dtype=a.dtype, device="cpu", pinned=True)
            store[key] = (host, host.numpy())
        return store[key]

    def _wait(self) -> None:
        """Wait for the device's stream: every copy to or from a pinned buffer has run."""
        wp.synchronize_stream(wp.get_stream(self.device))
        self._in_flight.clear()

    def _buf(self, C: int):
        if C not in self._buffers:
            d = self.device
            self._buffers[C] = (
                wp.zeros((self.P, C), dtype=wp.vec3, device=d),
                wp.zeros((self.P, C), dtype=wp.float32, device=d),
                wp.zeros((self.P, C), dtype=wp.float32, device=d),
            )
        return self._buffers[C]

    def _set_ranges(self, ranges_m) -> None:
        r = np.asarray(ranges_m, np.float32)
        if r.shape != (self.ranges.shape[0],):
            raise ValueError(
                f"slam: a scan of {r.size} beams, the filter was built for {self.ranges.shape[0]} "
                f"(set data.beam_policy to reject or resample such scans when reading the log)"
            )
        self._write(self.ranges, r)
        self._ranges_np = r.astype(np.float64)

    def _cover_scan(self, poses: np.ndarray) -> None:
        """Grow the maps (ParticleMaps.cover) to hold the current scan's end points and the laser at
        ``poses`` [P, 3] before the scan is added: the released code's maps grow alike, so no end point is
        dropped at a border drawn in advance."""
        r, far_m = self._ranges_np, self.integrator.far_m
        keep = np.isfinite(r) & (r > 0)
        if not self.integrator.free_space:
            keep &= r <= far_m
        lp = compose(poses, np.asarray(self.T_base_laser)[None])
        rr = np.minimum(r[keep], far_m)
        reach = float(rr.max()) if rr.size else 0.0
        # most scans lie well inside: a box around every laser position, the scan's longest beam wide, holds all
        # end points (in floating point too), so where the frame holds it the end points need not be computed
        if self.maps.holds(
            ((lp[:, 0] - reach).min(), (lp[:, 1] - reach).min()), ((lp[:, 0] + reach).max(), (lp[:, 1] + reach).max())
        ):
            return
        a = lp[:, 2:3] + self._angles_np[keep][None]
        xs = np.concatenate([lp[:, 0], (lp[:, :1] + rr * np.cos(a)).ravel()])
        ys = np.concatenate([lp[:, 1], (lp[:, 1:2] + rr * np.sin(a)).ravel()])
        if self.maps.cover((xs.min(), ys.min()), (xs.max(), ys.max()), self.cfg.map_margin_m):
            self._graph = None  # the captured rounds read the old cells

    def _add_scan(self, poses: np.ndarray) -> None:
        """Add the current scan to every map at ``poses`` [P, 3] (the same poses already on the device), the
        maps first grown to hold it."""
        self._cover_scan(poses)
        self.integrator(self.maps, self.poses, self.T_base_laser, self.ranges, self.angles)

    def _score(self, candidates: np.ndarray) -> tuple[wp.array, wp.array]:
        """The device's (score, log-likelihood) [P, C] of candidate poses [P, C, 3], each on its particle's map."""
        cand, score, loglik = self._buf(candidates.shape[1])
        self._write(cand, candidates.astype(np.float32))
        self.scorer(self.maps, cand, self.T_base_laser, self.ranges, self.angles, score, loglik)
        return score, loglik

    def evaluate(self, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(score, log-likelihood) [P, C] of candidate poses [P, C, 3], each on its particle's map."""
        score, loglik = self._score(candidates)
        return self._read(score).astype(np.float64), self._read(loglik).astype(np.float64)

    def loglik_at(self, candidates: np.ndarray) -> np.ndarray:
        """evaluate's log-likelihood [P, C] alone: one read back from the device instead of two."""
        return self._read(self._score(candidates)[1]).astype(np.float64)

    # --- the filter ---------------------------------------------------------------------------------
    def start(self, odom_pose, ranges_m, stamp: float | None = None) -> None:
        """All particles at the first odometry pose; the first scan is integrated as it is."""
        pose = np.asarray(odom_pose, np.float64)
        poses = np.tile(pose, (self.P, 1))
        self._write(self.poses, poses.astype(np.float32))
        self._set_ranges(ranges_m)
        self._add_scan(poses)
        self.last_odom, self.prev_odom = pose, tuple(pose)
        self.pending, self.path_m, self.turn_rad = [], 0.0, 0.0
        self.last_stamp = stamp
        self._record(0, np.arange(self.P), poses)

    def step(self, k: int, odom_pose, ranges_m, stamp: float | None = None) -> StepStats:
        """Scan k with its odometry pose (and its stamp, which ``temporal_update`` needs); returns what
        happened. The four steps of the paper's SIR filter (Grisetti et al. 2007: sampling, importance
        weighting, resampling, map estimation), each part timed as a whole by ``timed``. A scan that is not
        processed costs a few scalar operations on the host: its odometry step is queued for the next one."""
        self._take_odometry(odom_pose)  # u_t-1: queued for the next processed scan, its path and turn counted
        if not self._should_process(stamp):  # linear_update / angular_update / temporal_update reached?
            return StepStats(processed=False)
        moved = self._drift()  # x'_t ~ p(x_t | x_t-1, u_t-1): the queued steps through the motion model
        new, gain, rounds = self._propose(ranges_m, moved)  # 1. sampling: scan match + the proposal around it
        w, neff, resampled = self._weigh(new, gain)  # 2. importance weighting: w_t = w_t-1 * gain; N_eff = 1 / sum w^2
        parents = self._resample_if_needed(new, w, resampled)  # 3. selective resampling: only when N_eff < threshold
        self._integrate(new[parents])  # 4. map estimation: each particle's map gets z_t at its pose x_t
        self._record(k, parents, new[parents])  # poses and parents: the best path is traced back at the end
        return StepStats(processed=True, neff=neff, resampled=resampled, match_rounds=rounds)

    def _take_odometry(self, odom_pose) -> None:
        """Queue the odometry step from the previous scan; count the path and the turn since the last
        processed scan."""
        x, y, a = odom_pose
        pose = (float(x), float(y), float(a))
        prev, self.prev_odom = self.prev_odom, pose
        self.steps += 1
        delta = relative_one(prev, pose)
        self.path_m += float(np.hypot(x - prev[0], y - prev[1]))
        self.turn_rad += abs(wrap_angle_one(pose[2] - prev[2]))
        if delta != (0.0, 0.0, 0.0):
            self.pending.append(delta)

    def _should_process(self, stamp: float | None) -> bool:
        """GMapping's decision: the path since the last processed scan is ``linear_update`` long, its turns add
        up to ``angular_update``, or ``temporal_update`` seconds went by."""
        c = self.cfg
        if self.path_m < c.linear_update and self.turn_rad < c.angular_update and not self._time_is_up(stamp):
            return False
        self.last_stamp = stamp
        return True

    @timed("motion")
    def _drift(self) -> np.ndarray:
        """The queued odometry steps applied to the particles (one launch); returns the odometry step from the
        last processed scan to this one (the paper's proposal centres its motion prior on it)."""
        if self.pending:
            self.motion(self.poses, np.array(self.pending), seed=self.cfg.seed * 1_000_003 + self.steps)
        self.pending, self.path_m, self.turn_rad = [], 0.0, 0.0
        odom_pose = np.array(self.prev_odom)
        moved = relative(self.last_odom[None], odom_pose[None])[0]
        self.last_odom = odom_pose
        return moved

    @timed("matching")
    def _propose(self, ranges_m, moved):
        """The scan to the device and the proposal (``slam.proposal``) from each particle's moved pose."""
        self._set_ranges(ranges_m)
        return self.propose(self._read(self.poses).astype(np.float64), moved)

    @timed("weights_resampling")
    def _weigh(self, new: np.ndarray, gain: np.ndarray) -> tuple[np.ndarray, float, bool]:
        """The log-weights' gain, the new poses to the device; returns the smoothed weights w, N_eff = 1 / sum w^2
        and whether to resample (``slam.resample``: selective or always)."""
        self.log_w += gain
        self.log_w_total += gain
        self._write(self.poses, new.astype(np.float32))
        w = self.smoothed_weights()
        neff = float(1.0 / np.sum(w**2))
        return w, neff, bool(self.cfg.resample == "always" or neff < self.cfg.resample_threshold * self.P)

    @timed("weights_resampling")
    def _resample_if_needed(self, new: np.ndarray, w: np.ndarray, resampled: bool) -> np.ndarray:
        """Low-variance resampling of poses and maps (the maps copied on the device); returns each particle's
        parent (itself when not resampled)."""
        if not resampled:
            return np.arange(self.P)
        parents = self.maps.resample(low_variance_parents(w, self.rng.uniform()))
        self._write(self.poses, new[parents].astype(np.float32))
        self.log_w = np.zeros(self.P)
        self.log_w_total = self.log_w_total[parents]
        return parents

    @timed("integration")
    def _integrate(self, poses: np.ndarray) -> None:
        self._add_scan(poses)

    def _time_is_up(self, stamp: float | None) -> bool:
        """temporal_update: more than that many seconds since the last processed scan (the released code's
        ``period_``; never when it is negative)."""
        period = self.cfg.temporal_update
        if period < 0:
            return False
        if stamp is None or self.last_stamp is None:
            raise ValueError("slam.temporal_update needs each scan's stamp: pass it to RBPF.start and RBPF.step")
        return stamp - self.last_stamp > period

    CLIMBS = ("blocks", "threads", "rounds")

    def match(self, start: np.ndarray, max_rounds: int = 200, check_every: int = 8, how: str | None = None):
        """GMapping's hill climbing for every particle at once; a particle stops when a round fails after
        ``iterations`` halvings of the steps. Returns (poses [P, 3], scores [P], rounds).
        Twin: irmcl_warp/reference/slam.py ``hill_climb``.

        Three ways to run it (``how``), the same poses bit for bit (tests/test_slam.py, on cuda:0 too):
        * ``blocks`` (the default on a GPU): one block per particle, a thread per beam, the whole climb in one
          launch (Scorer.climb_blocks); no launch and no look from the host per round (scans of up to
          MAX_BLOCK_BEAMS beams; longer ones, a 1081-beam Hokuyo's, climb in ``rounds`` by default);
        * ``threads`` (the default on the CPU): each particle's whole climb in one thread (Scorer.climb), one
          launch per block of particles on each core;
        * ``rounds``: round by round over particles x moves x beams (the moves, the scores, the update: three
          launches a round, ``check_every`` rounds per CUDA graph between looks at the active flags), the
          reference the other two are tested against.
        Rounds: the most any particle took (``rounds``: the rounds launched)."""
        c, d, P = self.cfg, self.device, self.P
        if not hasattr(self, "_climb"):
            self._climb = dict(
                pose=wp.zeros(P, dtype=wp.vec3, device=d),
                best=wp.zeros(P, dtype=wp.float32, device=d),
                steps=wp.zeros(P, dtype=wp.vec3, device=d),
                halvings=wp.zeros(P, dtype=wp.int32, device=d),
                active=wp.zeros(P, dtype=wp.int32, device=d),
                start=wp.zeros(P, dtype=wp.vec3, device=d),
                rounds=wp.zeros(P, dtype=wp.int32, device=d),
                steps0=wp.array(np.tile(np.float32([c.lstep, c.lstep, c.astep]), (P, 1)), dtype=wp.vec3, device=d),
            )  # every climb's first steps
        st = self._climb
        how = how or default_climb(wp.get_device(d).is_cuda, self.ranges.shape[0])
        if how not in self.CLIMBS:
            raise ValueError(f"RBPF.match: how={how!r}, choose one of {list(self.CLIMBS)}")
        if how == "rounds":
            rounds = self._climb_launching_rounds(start, max_rounds, check_every)
        else:
            self._write(st["start"], start.astype(np.float32))
            climb = self.scorer.climb_blocks if how == "blocks" else self.scorer.climb
            climb(
                self.maps,
                st["start"],
                self.T_base_laser,
                self.ranges,
                self.angles,
                (c.lstep, c.lstep, c.astep),
                int(c.iterations),
                int(max_rounds),
                st["pose"],
                st["best"],
                st["rounds"],
            )
            rounds = int(self._read(st["rounds"]).max())
        pose = self._read(st["pose"]).astype(np.float64)
        pose[:, 2] = wrap_angle(pose[:, 2])
        return pose, self._read(st["best"]).astype(np.float64), rounds

    def _climb_launching_rounds(self, start: np.ndarray, max_rounds: int, check_every: int) -> int:
        """match's GPU way: rounds launched over particles x moves x beams, ``check_every`` of them per CUDA
        graph between looks at the active flags; returns the rounds launched."""
        c, d, P, st = self.cfg, self.device, self.P, self._climb
        self._write(st["pose"], start.astype(np.float32))
        wp.copy(st["steps"], st["steps0"])
        st["halvings"].zero_()
        st["active"].fill_(1)
        cand1, score1, loglik1 = self._buf(1)
        wp.copy(cand1.flatten(), st["pose"])
        self.scorer(self.maps, cand1, self.T_base_laser, self.ranges, self.angles, score1, loglik1)
        wp.copy(st["best"], score1.flatten())
        cand, score, loglik = self._buf(6)

        def rounds_block():
            for _ in range(check_every):
                wp.launch(climb_candidates_kernel, (P, 6), [st["pose"], st["steps"], cand], device=d)
                self.scorer(self.maps, cand, self.T_base_laser, self.ranges, self.angles, score, loglik, st["active"])
                wp.launch(
                    climb_update_kernel,
                    P,
                    [cand, score, st["pose"], st["best"], st["steps"], st["halvings"], st["active"], int(c.iterations)],
                    device=d,
                )

        self.scorer.reserve(P, 6, self.ranges.shape[0])  # no allocation inside the captured block
        if self._graph is None and wp.get_device(d).is_cuda:
            # the block reads and writes the same arrays every time: captured once, replayed as one launch
            try:
                with wp.ScopedCapture(device=d) as capture:
                    rounds_block()
                self._graph = capture.graph
            except Exception as e:  # pragma: no cover - depends on the driver
                print(f"slam: CUDA graph capture failed ({e}); launching the rounds one by one")
                self._graph = False
        rounds = 0
        while rounds < max_rounds:
            if self._graph:
                wp.capture_launch(self._graph)
            else:
                rounds_block()
            rounds += check_every
            # the first look after FIRST_LOOK rounds: most climbs take 24-40 (intel, fr079), so earlier looks only
            # find particles still climbing; a round after a particle stopped leaves it as it is
            if rounds >= min(self.FIRST_LOOK, max_rounds) and not self._read(st["active"]).any():
                break
        return rounds

    # --- proposals: (poses sampled from the motion model, odometry step) -> (new poses, log-weight gain, rounds)
    def propose_odometry(self, sampled, moved):
        """The motion model alone (the paper's baseline)."""
        return sampled, self.loglik_at(sampled[:, None])[:, 0], 0

    def propose_match(self, sampled, moved):
        """The released code's: the scan matcher's pose where its score beats ``minimum_score``."""
        matched, score, rounds = self.match(sampled)
        new = np.where((score > self.cfg.minimum_score)[:, None], matched, sampled)
        return new, self.loglik_at(new[:, None])[:, 0], rounds

    def propose_paper(self, sampled, moved):
        """The paper's: a Gaussian fitted around the match (eq. 9-12), the motion prior centred on each
        particle's noise-free odometry prediction from its pose at the last processed scan (the sampled pose
        already carries the motion noise once)."""
        matched, score, rounds = self.match(sampled)
        ok = score > self.cfg.minimum_score
        predicted = compose(self.history.poses[-1], np.broadcast_to(moved, (self.P, 3)))
        new, gain = self.gaussian_proposal(matched, predicted, moved)
        if not ok.all():  # particles whose match scored too low keep their sample, weighted by its likelihood
            gain = np.where(ok, gain, self.loglik_at(sampled[:, None])[:, 0])
        return np.where(ok[:, None], new, sampled), gain, rounds

    def gaussian_proposal(self, matched: np.ndarray, predicted: np.ndarray, moved: np.ndarray):
        """Paper proposal: tau_j = p(z | m, x_j) p(x_j | x_{t-1}, u) at the grid around the match, the motion
        prior a Gaussian around ``predicted`` with GMapping's noise for the step ``moved``; new pose ~ N(mu,
        Sigma) of the normalised tau; log-weight gain = log sum tau_j."""
        cand = matched[:, None, :] + self.grid_offsets[None]  # [P, K, 3]
        loglik = self.loglik_at(cand)
        std = np.maximum(motion_std(moved, self.cfg), [0.01, 0.01, 0.005])
        d = cand - predicted[:, None, :]
        d[..., 2] = wrap_angle(d[..., 2])
        log_prior = -0.5 * np.sum((d / std) ** 2, -1) - np.sum(np.log(std))
        mu, cov, log_eta = fit_gaussian(cand, loglik + log_prior)
        z = self.rng.standard_normal((self.P, 3))
        new = mu + np.einsum("pij,pj->pi", np.linalg.cholesky(cov), z)
        new[:, 2] = wrap_angle(new[:, 2])
        return new, log_eta

    def smoothed_weights(self) -> np.ndarray:
        g = 1.0 / (self.cfg.ogain * self.P)
        w = np.exp(g * (self.log_w - self.log_w.max()))
        return w / w.sum()

    def _synced_clock(self) -> float:
        """A time stamp once the device has finished (the pinned copies in flight are then done too)."""
        wp.synchronize_device(self.device)
        self._in_flight.clear()
        return time.perf_counter()

    def _record(self, k: int, parents: np.ndarray, poses: np.ndarray) -> None:
        """History of scan k: ``poses`` [P, 3] are those just put on the device, recorded as the device holds
        them (float32) without reading them back."""
        self.history.scans.append(k)
        self.history.poses.append(np.asarray(poses).astype(np.float32).astype(np.float64))
        self.history.parents.append(np.asarray(parents))

    # --- results ------------------------------------------------------------------------------------
    def best_particle(self) -> int:
        return int(np.argmax(self.log_w_total))

    def trajectory(self, particle: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(scan indices, poses [K, 3]) of one particle's ancestry at the processed scans."""
        i = self.best_particle() if particle is None else particle
        h, out = self.history, []
        for t in range(len(h.scans) - 1, -1, -1):
            out.append(h.poses[t][i])
            i = int(h.parents[t][i])  # poses[t] were recorded after resampling at t: step to the parent before it
        return np.array(h.scans), np.array(out[::-1])


def default_climb(cuda: bool, beams: int) -> str:
    """RBPF.match's way on a device: ``threads`` on the CPU; on a GPU ``blocks`` (a thread per beam) where the
    scan fits in one block of threads, else ``rounds``."""
    if not cuda:
        return "threads"
    return "blocks" if beams <= MAX_BLOCK_BEAMS else "rounds"


def fit_gaussian(cand: np.ndarray, log_tau: np.ndarray, floor=(1e-6, 1e-6, 1e-7)):
    """The paper's eqs. 19-21 per particle: mu = sum tau_j x_j / eta, Sigma = sum tau_j (x_j - mu)(x_j - mu)^T
    / eta, eta = sum tau_j, from log tau [P, K] at poses cand [P, K, 3] (yaw offsets taken relative to the
    first pose, so that the mean does not wrap). Returns (mu [P, 3], Sigma [P, 3, 3] + floor, log eta [P])."""
    top = log_tau.max(1, keepdims=True)
    tau = np.exp(log_tau - top)
    eta = tau.sum(1)
    wn = tau / eta[:, None]
    ref = cand[:, :1, :]
    rel = cand - ref
    rel[..., 2] = wrap_angle(rel[..., 2])
    mu_rel = np.einsum("pk,pkd->pd", wn, rel)
    d = rel - mu_rel[:, None, :]
    cov = np.einsum("pk,pki,pkj->pij", wn, d, d) + np.diag(floor)
    mu = ref[:, 0, :] + mu_rel
    mu[:, 2] = wrap_angle(mu[:, 2])
    return mu, cov, top[:, 0] + np.log(eta)


def motion_std(delta, cfg) -> np.ndarray:
    ax, ay, at = np.abs(np.asarray(delta, np.float64))
    sxy = 0.3 * cfg.srr
    return np.array(
        [
            cfg.srr * ax + cfg.str * at + sxy * ay,
            cfg.srr * ay + cfg.str * at + sxy * ax,
            cfg.stt * at + cfg.srt * np.hypot(delta[0], delta[1]),
        ]
    )


def per_scan_poses(stamps_idx: np.ndarray, processed_idx: np.ndarray, processed_poses: np.ndarray, odom: np.ndarray):
    """A pose at every scan: the last processed scan's corrected pose plus the raw odometry since then."""
    out = np.full((len(stamps_idx), 3), np.nan)
    j = np.searchsorted(processed_idx, stamps_idx, side="right") - 1
    ok = j >= 0
    base = processed_poses[j[ok]]
    since = relative(odom[processed_idx[j[ok]]], odom[stamps_idx[ok]])
    out[ok] = compose(base, since)
    return out


@PROPOSALS.register("paper")
def _paper(rbpf: RBPF):
    return rbpf.propose_paper


@PROPOSALS.register("gmapping_code")
def _gmapping_code(rbpf: RBPF):
    return rbpf.propose_match


@PROPOSALS.register("odometry")
def _odometry(rbpf: RBPF):
    return rbpf.propose_odometry
