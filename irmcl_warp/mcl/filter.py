"""The particle filter: motion -> weighting -> (selective) resampling -> estimate, every part a Warp kernel
chosen from a registry once, in ``__init__``; particle arrays are allocated once (again only when
``reduce`` shrinks the set) and only launched on.

Per step the host sends what the step takes (``StepInputs``: the odometry step, the measured ranges of
the chosen beams, the motion seed and the resampling draw; one copy) and reads back once after
everything is launched: the eight weight sums (mean, N_eff, spread) and the estimate's five (one copy).
On a GPU a step is about ten dependent launches: the copy in, motion and weighting in one kernel (``_moving``),
the accumulate (which also counts the estimate's first select pass), then the weights' sums, scan and resampling
beside the estimate's select and sums on a second stream, and the copy back.
Resampling runs when N_eff < ``resample_threshold`` * N (selective resampling; 1.0 = every step),
decided on the device. With recovery on, the log mean likelihood is read back as well.

``mcl.step_graph``: since every kernel reads the step's values from device arrays, the launches of one
step can be captured once as a graph (a CUDA graph on a GPU, Warp's CPU graph on a CPU) and replayed for
each scan: one launch instead of ~15. Two graphs, one per ping-pong order of the particle buffers. The
same kernels in the same order: results are identical to launching them one by one (tested).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.config import MCLConfig
from irmcl_warp.kernels import ESTIMATE, MOTION, RESAMPLE, pick_device
from irmcl_warp.kernels.kld import OccupiedBins, levels, next_count
from irmcl_warp.kernels.resample import LogMeanLikelihood, ParticleWeights, Resampler, inject_kernel

# mcl.estimate -> (cfg, num_particles, map bounds, device, where its five sums go) -> the estimator (None: the
# weighted mean of all)
ESTIMATORS = {
    "top_share": lambda cfg, n, bounds, d, sums: ESTIMATE.build(
        "top_share", num_particles=n, share=cfg.estimate_share, device=d, sums=sums
    ),
    "best_cluster": lambda cfg, n, bounds, d, sums: ESTIMATE.build(
        "best_cluster",
        num_particles=n,
        bounds=bounds,
        cell_m=cfg.cluster_cell_m,
        yaw_bins=cfg.cluster_yaw_bins,
        device=d,
        sums=sums,
    ),
    "mean": lambda cfg, n, bounds, d, sums: None,
}


class StepInputs:
    """What one step takes from the host, written into one host buffer and copied to the device in one copy: float32
    [rot1, trans, rot2, resampling draw, measured ranges of the B beams, then two int32 (their bits): motion seed,
    multinomial seed]. The kernels get views of the device buffer (``odom``, ``draw``, ``measured``, and the int32
    ``motion_seed`` and ``resample_seed`` over its last eight bytes), so a captured step reads each scan's values. On a
    GPU the host buffer is pinned and ``send()``'s copy is the first launch of a step (a captured step copies the
    values the host wrote before replaying it); on a CPU it is the device buffer."""

    def __init__(self, num_beams: int, device: str):
        on_gpu = device.startswith("cuda")
        self.values = wp.zeros(4 + num_beams + 2, dtype=wp.float32, device=device)
        self.host_values = wp.zeros_like(self.values, device="cpu", pinned=True) if on_gpu else self.values
        self.odom, self.draw, self.measured = self.values[0:3], self.values[3:4], self.values[4 : 4 + num_beams]
        seeds = wp.array(  # the last two floats' bytes as int32 (a view: ``values`` owns the memory)
            ptr=self.values.ptr + 4 * (4 + num_beams), dtype=wp.int32, shape=(2,), device=device
        )
        self._keep = seeds  # (the views below are of it)
        self.motion_seed, self.resample_seed = seeds[0:1], seeds[1:2]
        self._values = self.host_values.numpy()  # a view, made once
        self._ranges = self._values[4 : 4 + num_beams]
        self._seeds = self._values[4 + num_beams :].view(np.uint32)
        self._bad, self._beyond = np.zeros(num_beams, bool), np.zeros(num_beams, bool)  # (upload_scan's scratch)

    def upload_scan(self, odom_step, draw, scan, beam_index, near_m, far_m, motion_seed, resample_seed) -> None:
        """Write a step's inputs into the host buffer (``send`` copies it to the device), the measured ranges being
        ``ParticleFilter.chosen_ranges(scan)`` written in place: the beams picked by ``beam_index``, NaN at or below
        ``near_m`` and at or beyond ``far_m`` (NaN stays NaN), by five small numpy calls that make no array (a
        step's host time counts on a GPU)."""
        r, bad, beyond = self._ranges, self._bad, self._beyond
        np.take(scan, beam_index, out=r)
        np.less_equal(r, near_m, out=bad)
        np.greater_equal(r, far_m, out=beyond)
        np.logical_or(bad, beyond, out=bad)
        np.copyto(r, np.float32(np.nan), where=bad)
        self._set(odom_step, draw, motion_seed, resample_seed)

    def _set(self, odom_step, draw: float, motion_seed: int, resample_seed: int) -> None:
        v = self._values
        v[0], v[1], v[2] = odom_step
        v[3] = draw
        seeds = self._seeds  # uint32 view: the seeds' low 32 bits, as an int32 cast wraps them
        seeds[0], seeds[1] = motion_seed & 0xFFFFFFFF, resample_seed & 0xFFFFFFFF

    def send(self) -> None:
        if self.host_values is not self.values:
            wp.copy(self.values, self.host_values)


def pick_beams(n_sensor: int, num_beams: int, how: str = "spread") -> np.ndarray:
    """Indices of the scan's beams the filter weighs: ``spread``: ``num_beams`` evenly spread from the first beam
    to the last (the paper's "32 beams evenly spread over the scan"); ``stride``: the authors' code, every
    (n_sensor // num_beams)-th beam from the first, the first ``num_beams`` of them, so the last part of the
    scan is left out (intel's 180 beams: every 5th, -90 to +65 deg)."""
    n = min(int(num_beams), int(n_sensor))
    if how == "spread":
        return np.unique(np.linspace(0, n_sensor - 1, n).round().astype(int))
    if how == "stride":
        return np.arange(0, n_sensor, n_sensor // n)[:n]
    raise ValueError(f"MCL: mcl.beam_pick={how!r}; choose spread or stride")


def systematic_draw(log_w: np.ndarray, n: int, u: float) -> np.ndarray:
    """``n`` indices into ``log_w`` by systematic (low-variance) resampling with the offset ``u`` in [0, 1): index i
    is drawn about n w_i times (Thrun et al. Table 4.4; a numpy twin of kernels/resample.py's draw). Weights that
    are all -inf or NaN are an error."""
    log_w = np.asarray(log_w, np.float64)
    finite = np.isfinite(log_w)
    if not finite.any():
        raise ValueError("MCL: no candidate has a finite log-weight")
    w = np.where(finite, np.exp(log_w - log_w[finite].max()), 0.0)
    cdf = np.cumsum(w / w.sum())
    cdf[-1] = 1.0
    return np.minimum(np.searchsorted(cdf, (np.arange(n) + u) / n, side="right"), len(w) - 1)


def log_running_average(l_old: float, l_new: float, rate: float) -> float:
    """AMCL's running average w <- (1 - rate) w + rate w_new, kept as logs (l = log w) so that likelihoods far below
    float32's range still compare (ParticleFilter.recovery_probability; eval.analyses.lost_rules' AmclRule)."""
    return float(np.logaddexp(np.log1p(-rate) + l_old, np.log(rate) + l_new))


class ParticleFilter:
    SECOND_STREAM = True  # on a GPU, the top-share estimate's sort and sums beside the rest of the step (_normalise)
    MOVE_IN_WEIGHTING = None  # the motion inside the weighting's kernel where it can (``moving``): None = on a GPU

    def __init__(
        self,
        free_space,
        cfg: MCLConfig,
        T_base_laser,
        scan_angles_rad,
        far_m: float,
        make_weighting,
        device: str = "auto",
    ):
        """``free_space``: a NOG whose zero nodes are free space (the uniform start and recovery draw there);
        ``far_m``: beams at or beyond are no return; ``make_weighting(num_particles, num_beams)``: the
        observation model sized for the filter (services.filters.build_filter makes it), called again by
        ``reduce``."""
        self.cfg, self.device, self.far_m = cfg, pick_device(device), float(far_m)
        n_sensor = len(scan_angles_rad)
        if n_sensor < 1:
            raise ValueError("MCL: the sensor has no beams")
        if cfg.estimate not in ESTIMATORS:
            raise ValueError(f"MCL: unknown estimate {cfg.estimate!r}; choose one of {sorted(ESTIMATORS)}")
        self.beam_index = pick_beams(n_sensor, cfg.num_beams, cfg.beam_pick)
        self.num_sensor_beams, self.free_space, self.T_base_laser = (
            n_sensor,
            free_space,
            tuple(map(float, T_base_laser)),
        )
        N, B, d = cfg.num_particles, len(self.beam_index), self.device
        if cfg.motion not in ("odometry", "irmcl"):
            raise ValueError(f"MCL: mcl.motion={cfg.motion!r}; choose odometry or irmcl")
        self.motion = (
            MOTION.build("odometry", alphas=cfg.alphas, device=d, cpu_threads=cfg.cpu_threads)
            if cfg.motion == "odometry"
            else MOTION.build("irmcl", noise=cfg.motion_noise, device=d, cpu_threads=cfg.cpu_threads)
        )
        self.make_weighting = make_weighting
        self.resampler = RESAMPLE.build(cfg.resample, device=d)
        H, W = free_space.shape
        lo = np.asarray(free_space.origin_xy, float)
        self.bounds = (
            lo[0],
            lo[1],
            lo[0] + (W - 1) * free_space.resolution_m,
            lo[1] + (H - 1) * free_space.resolution_m,
        )
        self._allocate(N)
        self.kld = None  # mcl.kld_sampling: the bins the resampled set occupies, and the counts it moves between
        if cfg.kld_sampling:
            if cfg.kld_min_particles > N:
                raise ValueError(
                    f"MCL: mcl.kld_min_particles={cfg.kld_min_particles} is more than mcl.num_particles={N}"
                )
            self.kld = OccupiedBins(self.bounds, cfg.kld_cell_m, cfg.kld_cell_deg, d)
            self.kld_levels = levels(N, cfg.kld_min_particles)
        self.bins = 0  # with KLD-sampling: the bins the last resampled set occupied
        self.angles = wp.array(np.asarray(scan_angles_rad, np.float32)[self.beam_index], dtype=wp.float32, device=d)
        self.inputs = StepInputs(B, d)
        self.measured = self.inputs.measured
        # read back per step: the 8 weight sums, then the estimator's 5 (pinned on a GPU: one async copy each)
        self.readback = wp.zeros(13, dtype=wp.float32, device="cpu", pinned=d.startswith("cuda"))
        self._readback = self.readback.numpy()  # a view, made once
        self.use_graph = self._graph_choice()
        self.graphs = {}  # the particle buffer a step starts from -> its captured launches
        self._side, self._forked = None, False  # the estimate's stream on a GPU (_side_stream); forked this step
        self.rng = np.random.default_rng(cfg.seed)
        self.steps = self.plain_steps = 0  # steps; those by move -> weigh -> resample (a graph replays only after one)
        self.global_start = False  # the particles are init_uniform's, not weighed yet
        self.extra_candidates = np.zeros((0, 3))  # add_candidates': weighed at a global start's first update
        self.spread = float("inf")  # sqrt(var x + var y) of the weighted particles after the last step
        self.l_slow = self.l_fast = None  # recovery: running averages of the log mean likelihood
        self.log_mean_likelihood = LogMeanLikelihood(d)
        self.free_nodes = np.nonzero(free_space.occupancy < 0.5)  # (iy, ix): where uniform poses and recovery draw
        free = np.column_stack(self.free_nodes[::-1]) * free_space.resolution_m + np.asarray(free_space.origin_xy)
        self.free_xy = wp.array(free.astype(np.float32), dtype=wp.vec2, device=d) if len(free) else None

    def _allocate(self, n: int) -> None:
        """The per-particle arrays and the objects sized by the particle count, the weighting's scratch
        included (again after ``reduce`` and when a run starts with another count)."""
        cfg, d = self.cfg, self.device
        centre = ((self.bounds[0] + self.bounds[2]) / 2, (self.bounds[1] + self.bounds[3]) / 2)
        # the weights' 8 sums, then the estimator's 5: one buffer, so one copy brings them back (``_copy_sums``)
        self.sums = wp.zeros(13, dtype=wp.float32, device=d)
        self.weights = ParticleWeights(n, device=d, centre=centre, sums=self.sums[0:8])
        self.estimator = ESTIMATORS[cfg.estimate](cfg, n, self.bounds, d, self.sums[8:13])
        if hasattr(self.estimator, "share_weights") and self.weights.keeps_cos_sin:  # w and the yaws' cos, sin
            self.estimator.share_weights(self.weights)
        self.weighting = None  # the old set's scratch is released before the new one is allocated
        self.weighting = self.make_weighting(n, len(self.beam_index))
        # one kernel that moves each particle and weighs it (kernels/weighting/ ``moving``): a GPU's step, one launch
        # and one pass over the particles fewer; the same particles and weights as the two launches (tested)
        fuse = wp.get_device(d).is_cuda if self.MOVE_IN_WEIGHTING is None else bool(self.MOVE_IN_WEIGHTING)
        moving = getattr(self.weighting, "moving", None) if fuse else None
        self._moving = moving(self.motion) if moving is not None else None
        self.graphs = {}  # captured on the old arrays: capture again
        self.particles = wp.zeros(n, dtype=wp.vec3, device=d)
        self.scratch = wp.zeros(n, dtype=wp.vec3, device=d)
        self.log_w = wp.zeros(n, dtype=wp.float32, device=d)  # accumulated since the last resampling
        self.log_lik = wp.zeros(n, dtype=wp.float32, device=d)  # this scan's
        self.injected = wp.zeros(n, dtype=wp.int32, device=d)  # recovery: drawn at random at the last resampling
        # whether the motion or the weighting splits this count over the CPU's cores (_replay; found once, not per step)
        self._split = self._moving is None and self._splits_on_cpu()

    @property
    def num_particles(self) -> int:
        return self.particles.shape[0]

    def reduce(self, keep: int) -> None:
        """Keep only the ``keep`` heaviest particles with their weights (IR-MCL: 100k -> 5k once converged;
        their code does it 20 s into the run). Done once per run, so a host-side sort is fine."""
        if keep >= self.num_particles:
            return
        order = np.argsort(-self.log_w.numpy(), kind="stable")[:keep]
        poses, log_w = self.particles.numpy()[order], self.log_w.numpy()[order]
        self._allocate(keep)  # a weighting sized for the smaller set: the larger set's scratch is released
        self.particles.assign(wp.array(poses, dtype=wp.vec3, device=self.device))
        self.log_w.assign(wp.array(log_w - log_w.max(), dtype=wp.float32, device=self.device))

    # --- initialisation ---------------------------------------------------------------------------
    def init_uniform(self) -> None:
        """Global localization: particles spread uniformly over the free nodes of the map, any heading. With
        ``mcl.global_candidates`` > 1 the next update draws its particles afresh (``_first_from_candidates``)."""
        self.set_particles(self.uniform_poses(self.cfg.num_particles))
        self.global_start = True

    def add_candidates(self, poses) -> None:
        """Poses [m, 3] the next update weighs beside the uniform candidates of a global start (places a search
        found, the particles a relocalization had: mcl/worlds.py RelocalizePlaces); needs ``init_uniform`` before and
        ``mcl.global_candidates`` > 1. Poses off the map's free space are dropped; calls add up."""
        if not (self.global_start and self.cfg.global_candidates > 1):
            raise ValueError("MCL: add_candidates needs a global start (init_uniform) with mcl.global_candidates > 1")
        poses = np.asarray(poses, np.float64).reshape(-1, 3)
        H, W = self.free_space.shape
        cells = self.free_space.node_of(poses[:, :2])
        inside = np.all((cells >= 0) & (cells < np.array([W, H])), 1)
        self.extra_candidates = np.vstack([self.extra_candidates, poses[inside]])  # (weighed in batches of N)

    def uniform_poses(self, n: int) -> np.ndarray:
        """``n`` poses uniform over the free nodes of the map (within each node's cell), any heading."""
        iy, ix = self.free_nodes
        if len(ix) == 0:
            raise ValueError("MCL: the map has no free space to spread particles over")
        k = self.rng.integers(0, len(ix), n)
        res = self.free_space.resolution_m
        xy = (
            np.stack([ix[k], iy[k]], -1) * res
            + np.asarray(self.free_space.origin_xy)
            + self.rng.uniform(-res / 2, res / 2, (len(k), 2))
        )
        return np.column_stack([xy, self.rng.uniform(-np.pi, np.pi, len(k))])

    def _outside(self, poses: np.ndarray) -> np.ndarray:
        """Which of ``poses`` [n, 3] lie off the map's nodes."""
        H, W = self.free_space.shape
        cells = self.free_space.node_of(np.asarray(poses, np.float32)[:, :2])
        return np.any((cells < 0) | (cells >= np.array([W, H])), axis=1)

    def init_gaussian(self, pose, std=(0.5, 0.5, 0.3)) -> None:
        """Pose tracking from a noisy initial pose. The draws that land off the map are drawn again (a start near
        the map's edge, e.g. a simulated floor's outer wall, once ended a tracking run with "particles outside the
        map"); the draws on the map are those of one plain draw, so a start away from the edge is as before."""
        pose, std = np.asarray(pose, float), np.asarray(std, float)
        if self._outside(pose[None])[0]:
            res, (H, W) = self.free_space.resolution_m, self.free_space.shape
            lo = np.asarray(self.free_space.origin_xy) - res / 2
            hi = lo + np.array([W, H]) * res
            raise ValueError(
                f"MCL: the initial pose {pose.round(3).tolist()} lies outside the map "
                f"(x {lo[0]:.2f} to {hi[0]:.2f} m, y {lo[1]:.2f} to {hi[1]:.2f} m)"
            )
        poses = pose + self.rng.normal(0, 1, (self.cfg.num_particles, 3)) * std
        for _ in range(100):
            off = self._outside(poses)
            if not off.any():
                break
            poses[off] = pose + self.rng.normal(0, 1, (int(off.sum()), 3)) * std
        self.set_particles(poses)

    def set_particles(self, poses: np.ndarray) -> None:
        """Equal-weight particles at ``poses`` [n, 3], n up to ``mcl.num_particles`` (the arrays follow n)."""
        poses = np.asarray(poses, np.float32)
        if poses.ndim != 2 or poses.shape[1] != 3 or not 1 <= len(poses) <= self.cfg.num_particles:
            raise ValueError(
                f"MCL: particles must be [n, 3] with 1 <= n <= {self.cfg.num_particles}, got {poses.shape}"
            )
        off = self._outside(poses)
        if off.any():
            raise ValueError(f"MCL: {int(off.sum())} of {len(poses)} particles lie outside the map")
        if len(poses) != self.num_particles:
            self._allocate(len(poses))
        self.particles.assign(wp.array(poses, dtype=wp.vec3, device=self.device))
        self.log_w.zero_()
        self.l_slow = self.l_fast = None
        self.global_start = False  # (init_uniform sets it again)
        self.extra_candidates = np.zeros((0, 3))

    # --- one filter step --------------------------------------------------------------------------
    def _graph_choice(self) -> bool:
        """``mcl.step_graph``: auto = when the step can be captured (a CUDA graph on a GPU, Warp's CPU graph on a
        CPU: there it saves the ~15 launches' Python, 0.5-1 ms a step at 10k particles), on = always (an error when it
        cannot), off = launch one by one. A step can be captured when nothing in it needs the host between
        launches: recovery off (it reads the mean likelihood back mid-step), an estimate that stays on the
        device (top_share or mean) and a weighting made only of Warp launches."""
        mode = self.cfg.step_graph
        if mode not in ("auto", "on", "off"):
            raise ValueError(f"MCL: mcl.step_graph={mode!r}; choose auto, on or off")
        blockers = [
            why
            for why, bad in [
                ("recovery is on (mcl.recovery_alpha_*)", self.recovery_on),
                (
                    f"mcl.estimate={self.cfg.estimate} finds its cluster on the host",
                    self.cfg.estimate == "best_cluster",
                ),
                (
                    f"the weighting {type(self.weighting).__name__} is not made of Warp launches only",
                    not getattr(self.weighting, "capturable", False),
                ),
            ]
            if bad
        ]
        if mode == "on" and blockers:
            raise ValueError("MCL: mcl.step_graph=on, but a step cannot be captured: " + "; ".join(blockers))
        return mode == "on" or (mode == "auto" and not blockers)

    @property
    def recovery_on(self) -> bool:
        return self.cfg.recovery_alpha_slow > 0 and self.cfg.recovery_alpha_fast > 0

    def step(self, odom_step, ranges_m) -> tuple[np.ndarray, float]:
        """One MCL step (Thrun et al., Probabilistic Robotics, Table 8.2; with recovery on, Augmented_MCL,
        Table 8.3). odom_step = (rot1, trans, rot2) since the last scan; ranges_m: the whole scan (NaN = no
        return). Returns (estimate [x, y, yaw] by ``mcl.estimate``, N_eff before resampling).

        ``_move``, ``_weigh`` and ``_resample`` only launch; on a GPU with ``mcl.step_graph`` (recovery off)
        they are one graph, captured once and replayed from the second step on (the same launches, the same
        bits). The host waits once per step, before the estimate is read back."""
        limit = self._upload(odom_step, ranges_m)  # u_t, z_t and the step's seeds; resample when N_eff < limit
        if self.global_start and self.cfg.global_candidates > 1:
            return self._first_from_candidates()  # a global start: K x N uniform candidates weighed, N kept
        p_inject = 0.0
        if self.use_graph and self.plain_steps > 0:  # (the first step launches one by one: it loads the kernels)
            self._replay(limit)  # the four calls below, captured once as one CUDA graph
        else:
            if self._moving is not None:  # the two below, motion and weighting in one kernel:
                self._move_and_observe()  # x_t ~ p(x_t | u_t, x_t-1), then p(z_t | x_t, m) of each particle
                self._normalise()  # w_t = w_t-1 p(z_t | x_t, m), N_eff and the estimate of the weighted set
            else:
                self._move()  # x_t ~ p(x_t | u_t, x_t-1): sample_motion_model_odometry (Table 5.6)
                self._weigh()  # w_t = w_t-1 p(z_t | x_t, m) (IR-MCL eq. 6), N_eff and the estimate of the weighted set
            p_inject = self.recovery_probability()  # max(0, 1 - w_fast / w_slow) (Table 8.3)
            self._resample(np.inf if p_inject > 0 else limit)  # low-variance resampling (Table 4.4) if N_eff < limit
        wp.synchronize_device(self.device)
        self.plain_steps += 1
        self.global_start = False
        self.particles, self.scratch = self.scratch, self.particles  # the resampled set is the new one
        self._inject(p_inject)  # each particle a random free pose with probability p_inject (Table 8.3)
        pose, neff = self._read_estimate(limit, p_inject)  # the estimate (mcl.estimate) and N_eff, read back once
        if self.kld is not None and (p_inject > 0 or neff < limit):  # resampled this step:
            self._adapt_count()  # KLD-sampling's count for the next steps (Fox 2003)
        return pose, neff

    def _first_from_candidates(self) -> tuple[np.ndarray, float]:
        """``mcl.global_candidates`` = K > 1, the first update after ``init_uniform``: K x N poses drawn uniformly
        over the free space are weighed by this scan (in K batches of N, through the filter's own weighting and
        its scratch), and N of them are kept by systematic resampling on their tempered weights (Thrun et al.
        Table 4.4), with equal weights after. That is one update of a K-times larger filter followed by its
        resampling: a global start covers the map K times more densely when the scan first decides, and every
        later update costs what N particles cost. The scan's evidence is in where the particles are, not in their
        weights; the odometry step is not applied (the candidates are drawn where the robot is now). Returns
        (the estimate, N_eff = N)."""
        n, k, d = self.num_particles, int(self.cfg.global_candidates), self.device
        self.inputs.send()
        extra, self.extra_candidates = self.extra_candidates, np.zeros((0, 3))  # (add_candidates': this update's)
        poses = np.empty((k * n + len(extra), 3), np.float64)
        lik = np.empty(len(poses), np.float64)
        for b in range(k):  # the filter's own arrays: the weighting's scratch is sized for N
            poses[b * n : (b + 1) * n] = self.uniform_poses(n)
            self.particles.assign(wp.array(poses[b * n : (b + 1) * n].astype(np.float32), dtype=wp.vec3, device=d))
            self._observe()
            lik[b * n : (b + 1) * n] = self.log_lik.numpy()
        poses[k * n :] = extra
        for b in range(0, len(extra), n):  # batches of N, the last padded by repeating its poses
            part = extra[b : b + n]
            self.particles.assign(wp.array(part[np.arange(n) % len(part)].astype(np.float32), dtype=wp.vec3, device=d))
            self._observe()
            lik[k * n + b : k * n + b + len(part)] = self.log_lik.numpy()[: len(part)]
        keep = systematic_draw(float(self.cfg.temper) * lik, n, float(self.rng.uniform()))
        self.set_particles(poses[keep])
        self.log_lik.zero_()  # the weights stay equal: the estimate of the kept set, unweighted
        self._normalise()
        self._resample(0.0)  # (never resamples: copies the set into the scratch buffer)
        wp.synchronize_device(d)
        self.particles, self.scratch = self.scratch, self.particles
        pose, neff = self._read_estimate(0.0, 0.0)
        self.log_lik.assign(wp.array(lik[keep].astype(np.float32), dtype=wp.float32, device=d))  # (what was weighed)
        return pose, neff

    def _adapt_count(self) -> None:
        """KLD-sampling (Fox 2003) on the resampled set: the bins it occupies give the count (kernels/kld.py), taken
        from ``kld_levels`` (grow at once, shrink with a margin of 2). Fox draws particles one by one until their
        bins' count is met; here the whole resampled set is binned. Where the set holds at least his count, its bins
        include those his draw would have seen, so the count is not below his; where it must grow, it grows at once
        and the next resampling counts the larger set again. A new count draws the set again, systematically
        from the equal-weight resampled one (each particle kept or copied in proportion), into arrays of that
        size (the step's graph is captured again)."""
        cfg = self.cfg
        self.bins = self.kld(self.particles)
        n = next_count(self.num_particles, self.bins, cfg.kld_err, cfg.kld_z, self.kld_levels)
        if n == self.num_particles:
            return
        poses = self.particles.numpy()
        pick = np.floor((np.arange(n) + self.rng.uniform()) * (len(poses) / n)).astype(np.int64)
        self._allocate(n)
        self.particles.assign(wp.array(poses[np.minimum(pick, len(poses) - 1)], dtype=wp.vec3, device=self.device))
        self.log_w.zero_()

    def _upload(self, odom_step, ranges_m) -> float:
        """The step's inputs into the host buffers (``StepInputs``); returns the resampling threshold on N_eff."""
        ranges_m = np.asarray(ranges_m, np.float32)
        if ranges_m.shape != (self.num_sensor_beams,):
            raise ValueError(
                f"MCL: scan of {ranges_m.shape[0] if ranges_m.ndim else 0} beams, the filter was built "
                f"for a sensor of {self.num_sensor_beams}"
            )
        self.steps += 1
        draw = self.rng.random()  # (uniform(0, 1)'s number: 0 + 1 x the same double)
        self.inputs.upload_scan(
            odom_step,
            draw,
            ranges_m,
            self.beam_index,
            self.cfg.near_m,
            self.far_m,
            self.cfg.seed * 1_000_003 + self.steps,
            Resampler.seed_of(draw),
        )
        return self.cfg.resample_threshold * self.num_particles

    def _move(self) -> None:
        """The inputs to the device (one copy on a GPU) and the motion model's launch."""
        self.inputs.send()
        self.motion.launch(self.particles, self.inputs.odom, self.inputs.motion_seed)

    def _weigh(self) -> None:
        """The observation model's log-likelihoods, accumulated into the log-weights (tempered by
        ``mcl.temper``), their normalisation and N_eff (``ParticleWeights``) and the estimator's sums."""
        self._observe()
        self._normalise()

    def _observe(self) -> None:
        """The observation model's log-likelihood of this scan per particle, into ``log_lik``."""
        self.weighting(self.particles, self.T_base_laser, self.angles, self.inputs.measured, self.log_lik)

    def _normalise(self) -> None:
        """``log_lik`` into the log-weights (tempered by ``mcl.temper``), their normalisation and N_eff, the cumulative
        weights and the estimator's sums. On a GPU with the top-share estimate, the launch that accumulates the
        log-weights also writes the estimate's keys, and the estimate sums the weights ``w`` already computed; its
        sort (a selection: ``TopShareMean.SELECT``) and sums run on a second stream (``_side_stream``) beside the weights' sums, the scan and the
        resampling, joined in ``_copy_sums``. Nothing on the filter's stream writes what the estimate reads (the
        keys, ``w``, the particles: resampling writes the scratch buffer) before the join, and no reduction depends
        on the order in which the streams run, so the bits are those of one stream (tested on cuda:0,
        ``test_the_estimate_on_a_second_stream_keeps_every_bit``; it was left out in the twenty-first session while
        CUB's scan, now ``ordered_scan``, rounded by the order its tiles finished)."""
        weights, estimator = self.weights, self.estimator
        ranks = estimator.rank_buffers() if weights.tiled and hasattr(estimator, "rank_buffers") else None
        weights.accumulate(self.log_w, self.log_lik, float(self.cfg.temper), ranks)
        side = self._side_stream() if ranks is not None else None
        self._forked = side is not None
        if side is not None:  # sorted (or selected) on the side while the weights are computed
            side.wait_event(wp.get_stream(self.device).record_event(self._ranked))
            with wp.ScopedStream(side, sync_enter=False):
                estimator.order(counted=len(ranks) == 3)
        weights.weigh(self.log_w, self.particles)
        if side is not None:  # summed on the side while the weights are scanned and the particles resampled
            side.wait_event(wp.get_stream(self.device).record_event(self._weighed))
            with wp.ScopedStream(side, sync_enter=False):
                estimator.sum(self.particles, self.log_w, weights.w)
        weights.cumulate()
        if estimator is None or side is not None:
            return
        if ranks is None:
            estimator.launch(self.particles, self.log_w)
        else:  # ranked by the accumulate launch
            estimator.order(counted=len(ranks) == 3)
            estimator.sum(self.particles, self.log_w, weights.w)

    def _side_stream(self):
        """The estimate's stream on a GPU (made on first use, with its two events), or None: on a CPU, or with
        ``SECOND_STREAM`` off (a test's switch)."""
        if not (self.SECOND_STREAM and wp.get_device(self.device).is_cuda):
            return None
        if self._side is None:
            self._side = wp.Stream(self.device)
            self._ranked, self._weighed = wp.Event(self.device), wp.Event(self.device)
        return self._side

    def _resample(self, limit: float) -> None:
        """Resampling into the scratch buffer (decided on the device: only when N_eff < ``limit``) and the
        copies of the weights' and the estimator's sums to read back."""
        inp = self.inputs
        self.resampler.launch(
            self.weights.cdf,
            self.particles,
            self.scratch,
            inp.draw,
            inp.resample_seed,
            self.weights.sums,
            limit,
            self.log_w,
        )
        self._copy_sums()

    def _copy_sums(self) -> None:
        """The weights' eight sums and the estimator's five (one device buffer, ``_allocate``) into the pinned read-back
        buffer in one copy, after the estimate's stream, where it has one, is joined to the filter's."""
        if self._forked:
            wp.get_stream(self.device).wait_stream(self._side)
            self._forked = False
        wp.copy(self.readback, self.sums, 0, 0, 8 if self.estimator is None else 13)

    def _replay(self, limit: float) -> None:
        """``_move``, ``_weigh`` and ``_resample`` as one graph from the current particle buffer, captured on
        first use (recovery is off whenever a graph is used: see ``_graph_choice``). On a CPU whose motion or
        weighting splits its particles over the cores (``ParticleBlocks``; a graph would record one core's
        launch), those two run split before the graph, which then holds the rest of the step."""
        key = self.particles.ptr
        split = self._split
        if split:
            self._move_and_observe()
        if key not in self.graphs:
            with wp.ScopedCapture(device=self.device) as capture:
                if self._moving is not None:  # (never split: one kernel moves and weighs)
                    self._move_and_observe()
                elif not split:
                    self._move()
                    self._observe()
                self._normalise()
                self._resample(limit)
            self.graphs[key] = capture.graph
        wp.capture_launch(self.graphs[key])

    def _move_and_observe(self) -> None:
        """``_move`` then ``_observe``: in one kernel where the weighting moves the particles itself (``_moving``, a
        GPU's step); where both split their particles into the same blocks, one pass: each core moves its block and
        weighs it at once (one wait for the cores instead of two, the block still in its cache)."""
        n, motion, weighting = self.num_particles, self.motion, self.weighting
        if self._moving is not None:
            self.inputs.send()
            inp = self.inputs
            self._moving(
                self.particles, inp.odom, inp.motion_seed, self.T_base_laser, self.angles, inp.measured, self.log_lik
            )
            return
        if not all(hasattr(part, "block") and hasattr(part, "blocks") for part in (motion, weighting)) or (
            motion.blocks.blocks_for(n) != weighting.blocks.blocks_for(n)
        ):
            self._move()
            self._observe()
            return
        self.inputs.send()
        move = motion.block(self.particles, self.inputs.odom, self.inputs.motion_seed)
        weigh = weighting.block(self.particles, self.T_base_laser, self.angles, self.inputs.measured, self.log_lik)

        def both(p0: int, p1: int) -> None:
            move(p0, p1)
            weigh(p0, p1)

        motion.blocks.run(both, n)

    def _splits_on_cpu(self) -> bool:
        """Whether the motion or the weighting launches this set's particles as more than one block."""
        n = self.num_particles
        return any(
            getattr(part, "blocks", None) is not None and part.blocks.blocks_for(n) > 1
            for part in (self.motion, self.weighting)
        )

    def _inject(self, p_inject: float) -> None:
        """Augmented MCL's random particles (uniform over the free space's cells), after resampling."""
        if p_inject > 0 and self.free_xy is not None:
            wp.launch(
                inject_kernel,
                self.particles.shape[0],
                [
                    self.particles,
                    self.free_xy,
                    self.free_space.resolution_m,
                    float(p_inject),
                    self.cfg.seed * 7919 + self.steps,
                    self.injected,
                ],
                device=self.device,
            )

    def _read_estimate(self, limit: float, p_inject: float) -> tuple[np.ndarray, float]:
        """(the estimate, N_eff before resampling) from the sums read back; the weighted mean's spread is kept
        in ``self.spread``."""
        sums = self._readback
        pose, neff, self.spread = self.weights.summary(sums[:8])
        if self.estimator is not None:
            pose = self.estimator.result(sums[8:])
        if self.recovery_on and p_inject <= 0 and neff < limit:
            self.injected.zero_()  # resampled without injection: every particle comes from the posterior
        return pose, neff

    def chosen_ranges(self, ranges_m: np.ndarray) -> np.ndarray:
        """The weighted beams' ranges of a whole scan, NaN (not weighted) at or below near and at or beyond far."""
        chosen = np.asarray(ranges_m, np.float32)[self.beam_index]
        return np.where((chosen > self.cfg.near_m) & (chosen < self.far_m), chosen, np.nan).astype(np.float32)

    def recovery_probability(self) -> float:
        """AMCL's augmented MCL (Thrun et al. Table 8.3): inject random particles with probability
        max(0, 1 - w_fast / w_slow), w_slow and w_fast running averages of the mean likelihood with rates
        alpha_slow < alpha_fast. The averages are kept as logs (l = log w) and updated as
        l <- log((1 - a) exp(l) + a exp(l_avg)), the same linear-domain average as AMCL, so likelihoods far
        below float32's range still compare; a rise of the mean likelihood (a particle near the truth)
        lifts w_fast at once, and the injection stops.

        One deviation: the mean likelihood leaves out the particles injected at the last resampling. They
        are random by construction; counted in, a drop makes injection, injection lowers the mean, and the
        loop feeds itself until a well-tracked set is replaced (measured on the simulator with IR-MCL's
        likelihood, whose random particles score e^-8 against ~1 near the truth)."""
        a_slow, a_fast = self.cfg.recovery_alpha_slow, self.cfg.recovery_alpha_fast
        if a_slow <= 0 or a_fast <= 0:
            return 0.0
        l_avg = self.log_mean_likelihood(self.log_lik, self.injected)
        if not np.isfinite(l_avg):
            return 0.0
        if self.l_slow is None:
            self.l_slow = self.l_fast = l_avg
        self.l_slow = log_running_average(self.l_slow, l_avg, a_slow)
        self.l_fast = log_running_average(self.l_fast, l_avg, a_fast)
        p = 1.0 - np.exp(self.l_fast - self.l_slow)
        return float(p) if p > 1e-9 else 0.0  # (a steady level leaves rounding noise only)
