"""Particle motion. Two models, both fed the odometry step (rot1, trans, rot2) between two scans:

* ``MOTION["odometry"]`` (AMCL's ``diff`` model): the sample_motion_model_odometry of Thrun, Burgard & Fox,
Probabilistic Robotics, Table 5.6. The odometry step between two scans is (rot1, trans, rot2); each
particle draws its own noisy version with standard deviations

    s_rot1 = sqrt(a1 rot1^2 + a2 trans^2),  s_trans = sqrt(a3 trans^2 + a4 (rot1^2 + rot2^2)),
    s_rot2 = sqrt(a1 rot2^2 + a2 trans^2)

and moves by it.

* ``MOTION["irmcl"]``: the model of IR-MCL's code (its particle-filter library, as Range-MCL's): the step as
  a rigid motion u = (dx, dy, dtheta) in the robot's frame (dx = trans cos rot1, dy = trans sin rot1,
  dtheta = rot1 + rot2), each component disturbed by a Gaussian of variance C |u| (a 3 x 3 matrix of
  coefficients times the absolute step; the authors' C by default), and composed onto the pose. Its
  heading noise grows with the square root of the turn (variance 0.05 |dtheta|), far wider for the small
  turns between scans than Thrun's a1 rot^2.

Random numbers: Warp's per-thread generator seeded by (seed, particle index), so that a launch split into blocks
of particles on the CPU's cores (``cpu_threads``) draws the same numbers. The step and the
seed are read from device arrays, so that a captured filter step (irmcl_warp/mcl/filter.py) replays with
each scan's values; ``__call__`` takes host values and writes them there first.
Numpy twin: irmcl_warp/reference/motion.py.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from irmcl_warp.kernels.registry import CPU_MIN_BLOCK, MOTION, ParticleBlocks, pick_device


def _wrap(a) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


def odometry_step(odom_from, odom_to, min_trans_m: float = 0.01) -> tuple[float, float, float]:
    """(rot1, trans, rot2) between two odometry poses. As in AMCL: below ``min_trans_m`` the robot only
    turned (rot1 = 0; otherwise the direction of a tiny drift would set rot1 and its noise), and a step
    backwards is a negative translation rather than a half turn, a drive and a half turn back."""
    dx, dy = odom_to[0] - odom_from[0], odom_to[1] - odom_from[1]
    trans = float(np.hypot(dx, dy))
    rot1 = _wrap(np.arctan2(dy, dx) - odom_from[2]) if trans >= min_trans_m else 0.0
    if abs(rot1) > np.pi / 2:
        rot1, trans = _wrap(rot1 + np.pi), -trans
    rot2 = _wrap(odom_to[2] - odom_from[2] - rot1)
    return rot1, trans, rot2


def make_move(a1: float, a2: float, a3: float, a4: float):
    """Thrun's odometry sample for one particle: a function (pose, step [3], seed [1], particle index) -> pose, which
    the motion kernel launches and an observation model may call before it weighs (``Motion.move``)."""

    @wp.func
    def move(p: wp.vec3, step: wp.array(dtype=wp.float32), seed: wp.array(dtype=wp.int32), index: int) -> wp.vec3:
        state = wp.rand_init(seed[0], index)  # the particle's numbers, whatever block or kernel moves it
        r1 = step[0]
        t = step[1]
        r2 = step[2]
        s1 = wp.sqrt(wp.static(a1) * r1 * r1 + wp.static(a2) * t * t)
        st = wp.sqrt(wp.static(a3) * t * t + wp.static(a4) * (r1 * r1 + r2 * r2))
        s2 = wp.sqrt(wp.static(a1) * r2 * r2 + wp.static(a2) * t * t)
        r1h = r1 - s1 * wp.randn(state)
        th = t - st * wp.randn(state)
        r2h = r2 - s2 * wp.randn(state)
        heading = p[2] + r1h
        yaw = p[2] + r1h + r2h
        yaw = wp.atan2(wp.sin(yaw), wp.cos(yaw))
        return wp.vec3(p[0] + th * wp.cos(heading), p[1] + th * wp.sin(heading), yaw)

    return move


def make_kernel(move):
    """The motion kernel of a per-particle ``move`` (``make_move``, ``make_irmcl_move``): particle first + i moved."""

    @wp.kernel(module="unique")
    def sample(
        particles: wp.array(dtype=wp.vec3),
        step: wp.array(dtype=wp.float32),
        seed: wp.array(dtype=wp.int32),
        first: int,
    ):
        i = wp.tid()
        particles[i] = move(particles[i], step, seed, first + i)

    return sample


class Motion:
    """One motion kernel (``kernel(particles, step [3], seed [1])``) made of a per-particle ``move`` (a Warp function
    (pose, step, seed, index) -> pose, which an observation model may call itself: kernels/weighting/ ``moving``),
    with the host-side call and the device-side launch every model shares."""

    def __init__(self, move, device: str = "auto", cpu_threads: int | None = None):
        self.device = pick_device(device)
        self.move = move
        self.kernel = make_kernel(move)
        # on the CPU a block per core, from 2 x CPU_MIN_BLOCK particles (kernels/registry.py says why)
        self.blocks = ParticleBlocks(self.device, cpu_threads, min_block=CPU_MIN_BLOCK)
        self._step = wp.zeros(3, dtype=wp.float32, device=self.device)
        self._seed = wp.zeros(1, dtype=wp.int32, device=self.device)

    def __call__(self, particles: wp.array, step, seed: int) -> None:
        """Move ``particles`` by a noisy version of ``step`` = (rot1, trans, rot2) each."""
        self._step.assign(np.asarray(step, np.float32).reshape(3))
        self._seed.assign(np.array([seed], np.int32))
        self.launch(particles, self._step, self._seed)

    def launch(self, particles: wp.array, step: wp.array, seed: wp.array) -> None:
        """The same with (rot1, trans, rot2) in ``step`` [3] and the seed in ``seed`` [1], both on the device."""
        self.blocks.run(self.block(particles, step, seed), particles.shape[0])

    def block(self, particles: wp.array, step: wp.array, seed: wp.array):
        """``launch`` for one block of particles: a function (p0, p1) -> None (``ParticleBlocks.block``)."""
        return self.blocks.block(
            self.kernel, particles.shape[0], [particles, step, seed, 0], per_particle=(0,), first=3
        )


class OdometryMotion(Motion):
    def __init__(self, alphas=(0.05, 0.005, 0.05, 0.005), device: str = "auto", cpu_threads: int | None = None):
        if len(alphas) != 4 or min(alphas) < 0:
            raise ValueError(f"motion: expected 4 non-negative alphas (Thrun a1..a4), got {list(alphas)}")
        super().__init__(make_move(*map(float, alphas)), device, cpu_threads)


@MOTION.register("odometry")
def make_odometry(**settings) -> OdometryMotion:
    return OdometryMotion(**settings)


# IR-MCL's code (mcl/srrg_utils/pf_library, MotionModelAndResample): variance of (dx, dy, dtheta) = C |u|, row by row
IRMCL_NOISE = (0.01, 0.0005, 0.0002, 0.0005, 0.0001, 0.0001, 0.001, 0.00001, 0.05)


def make_irmcl_move(c):
    """IR-MCL's motion for one particle (see the module's docstring): a function (pose, step, seed, index) -> pose."""
    c = [float(v) for v in c]

    @wp.func
    def move(p: wp.vec3, step: wp.array(dtype=wp.float32), seed: wp.array(dtype=wp.int32), index: int) -> wp.vec3:
        state = wp.rand_init(seed[0], index)  # the particle's numbers, whatever block or kernel moves it
        dx = step[1] * wp.cos(step[0])
        dy = step[1] * wp.sin(step[0])
        dt = step[0] + step[2]
        ax = wp.abs(dx)
        ay = wp.abs(dy)
        at = wp.abs(dt)
        nx = dx + wp.sqrt(wp.static(c[0]) * ax + wp.static(c[1]) * ay + wp.static(c[2]) * at) * wp.randn(state)
        ny = dy + wp.sqrt(wp.static(c[3]) * ax + wp.static(c[4]) * ay + wp.static(c[5]) * at) * wp.randn(state)
        nt = dt + wp.sqrt(wp.static(c[6]) * ax + wp.static(c[7]) * ay + wp.static(c[8]) * at) * wp.randn(state)
        co = wp.cos(p[2])
        si = wp.sin(p[2])
        yaw = p[2] + nt
        return wp.vec3(p[0] + co * nx - si * ny, p[1] + si * nx + co * ny, wp.atan2(wp.sin(yaw), wp.cos(yaw)))

    return move


class IrmclMotion(Motion):
    """IR-MCL's motion model (see the module's docstring); ``noise``: the 9 coefficients of C, row by row."""

    def __init__(self, noise=IRMCL_NOISE, device: str = "auto", cpu_threads: int | None = None):
        if len(noise) != 9 or min(noise) < 0:
            raise ValueError(
                f"motion irmcl: expected 9 non-negative noise coefficients (C row by row), got {list(noise)}"
            )
        super().__init__(make_irmcl_move(noise), device, cpu_threads)


@MOTION.register("irmcl")
def make_irmcl(**settings) -> IrmclMotion:
    return IrmclMotion(**settings)
