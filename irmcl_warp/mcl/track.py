"""The particle filter as a robot runs it, one scan and one odometry reading at a time (``Localizer``), and over
a recorded log (``follow(pf, log, idx, mcl)``: the same class fed scan by scan; the localize stage and the
pipeline use it)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from irmcl_warp.geometry import compose, relative
from irmcl_warp.types import LaserLog
from irmcl_warp.kernels.motion import odometry_step
from irmcl_warp.mcl.confidence import AGREEMENT


def window(log: LaserLog, start_s: float, run_s: float | None, section: str) -> np.ndarray:
    """Indices of the scans from ``start_s`` for ``run_s`` seconds (None: to the end), times counted from the
    log's first scan; ``section`` names the settings in the error for an empty window."""
    t = log.stamps - log.stamps[0]
    end = np.inf if run_s is None else start_s + run_s
    idx = np.flatnonzero((t >= start_s) & (t <= end))
    if len(idx) < 2:
        raise ValueError(
            f"{section}.start_s={start_s}, run_s={run_s}: {len(idx)} scans of a {t[-1]:.0f} s log "
            f"({log.source}) in the window"
        )
    return idx


def moved(odom_step, min_trans: float, min_rot: float) -> bool:
    """Has the robot moved enough since the last update (AMCL's update_min_d / update_min_a)?"""
    rot1, trans, rot2 = odom_step
    return abs(trans) > min_trans or abs(rot1 + rot2) > min_rot


def between_updates(pose, odom_at_update, odom_now):
    """The pose at a scan the filter did not weigh: the last update's estimate moved by the odometry since
    (what AMCL's map -> odom transform gives a robot between updates). None yet: NaN (mcl.first_update=motion)."""
    if pose is None:
        return np.full(3, np.nan)
    delta = relative(np.asarray(odom_at_update, float)[None], np.asarray(odom_now, float)[None])[0]
    return pose if np.all(np.abs(delta) < 1e-12) else compose(np.asarray(pose, float)[None], delta[None])[0]


@dataclass
class Estimate:
    """What the localizer says after a scan: the base's pose in the map [x, y, yaw] (NaN before the first
    update, with ``mcl.first_update=motion``), whether this scan weighed the particles, and, where asked for,
    the particles' covariance [3, 3] (x, y, yaw about the pose; NaN between updates and before the first)."""

    pose: np.ndarray
    updated: bool
    covariance: np.ndarray | None = None
    confidence: float = float("nan")  # P(within 0.5 m / 10 deg) at the last update, where a judge was given


def particle_covariance(particles: np.ndarray, log_w: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The weighted particles' covariance [3, 3] about ``pose`` (yaw differences wrapped to [-pi, pi]), as AMCL
    publishes with its pose."""
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    d = np.asarray(particles, float) - pose
    d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return (d * w[:, None]).T @ d


class Localizer:
    """A particle filter fed one scan and one odometry reading at a time, with AMCL's node in mind: ``update``
    returns the pose in the map (the map -> odom transform is that pose composed with the inverse odometry).
    The filter weighs and resamples only after the odometry moved (``m.update_min_*``; the first scan at once
    unless ``m.first_update=motion``); between updates the pose follows the odometry; ``reduce_after_s`` into
    the run it keeps the ``m.reduce_to`` heaviest particles (IR-MCL; None: never). The offline stages drive
    the same class (``follow``), so a robot and a benchmark run the same code.

        loc = Localizer(pf, cfg.mcl)          # pf: services.filters.build_filter(...), already initialised
        for stamp, ranges, odom in sensor:    # odom: the odometry's pose [x, y, yaw] in its own frame
            est = loc.update(stamp, ranges, odom)
    """

    def __init__(
        self,
        pf,
        m,
        reduce_after_s: float | None = None,
        covariance: bool = False,
        step_times: list | None = None,
        judge=None,
        report_pose: str = "filter",
        lost_rule=None,
        relocalize: bool = False,
        places=None,
    ):
        """``judge``: where given, ``judge(particles, log_w, ranges_m, odom_delta) -> probability`` after every
        update, on the particles as read back then (a calibrated confidence, mcl/confidence.Judge).
        ``report_pose``: with a judge, ``"mode"`` reports the pose the judge's confidence is about (its ``pose``,
        the heaviest mode's) at each update; ``"filter"`` the filter's estimate (``m.estimate``). ``lost_rule``:
        with a judge, ``lost_rule(t, confidence, agreement) -> bool`` after each update (mcl/worlds.LostRule); when
        it declares the robot lost, the time goes to ``lost_at_s`` and, with ``relocalize``, the filter starts again
        from a uniform spread (``global_start``). ``places`` (mcl/worlds.RelocalizePlaces), where given: a
        relocalization's first update also weighs the places its scan fits best and, where set, the particles it
        had when declared lost."""
        if report_pose not in ("mode", "filter"):
            raise ValueError(f"Localizer: report_pose {report_pose!r} is not one of ('mode', 'filter')")
        self.pf, self.m, self.covariance, self.step_times, self.judge = pf, m, covariance, step_times, judge
        self.report_mode = judge is not None and report_pose == "mode"
        self.lost_rule = lost_rule if judge is not None else None
        self.relocalize, self.lost_at_s = relocalize, []  # lost_at_s: seconds since the first scan
        self.places, self.restarting = places, False
        self.confidence = float("nan")
        self.reduce_pending = reduce_after_s is not None and 0 < m.reduce_to < pf.num_particles
        self.reduce_after_s = reduce_after_s
        self.odom_at_update = self.t_start = self.pose = None

    def initial_pose(self, pose, std=(0.5, 0.5, 0.3)) -> None:
        """Start again around ``pose`` (RViz's "2D pose estimate"): the next scan weighs at once."""
        self.pf.init_gaussian(np.asarray(pose, float), std)
        self.pose, self.odom_at_update = None, None

    def global_start(self) -> None:
        """Start again from particles spread over the map's free space (global localization)."""
        self.pf.init_uniform()
        self.pose, self.odom_at_update, self.confidence = None, None, float("nan")
        if self.judge is not None:
            self.judge.reset()

    def teleported(self, odom) -> None:
        """The robot was carried (a jump the odometry did not see): go on from ``odom`` as if nothing moved."""
        self.odom_at_update = np.asarray(odom, float)

    def update(self, stamp: float, ranges_m, odom) -> Estimate:
        """One scan (the whole scan, metres, NaN = no return) and the odometry's pose at its stamp."""
        odom = np.asarray(odom, float)
        if self.odom_at_update is None:
            self.odom_at_update = odom
        if self.t_start is None:
            self.t_start = stamp
        m = self.m
        u = odometry_step(self.odom_at_update, odom)
        weigh = (self.pose is None and m.first_update == "scan") or moved(u, m.update_min_trans_m, m.update_min_rot_rad)
        cov = np.full((3, 3), np.nan) if self.covariance else None
        if weigh:
            if self.restarting and self.places is not None:  # a relocalization's first update: where it looks first
                self.places.seed(self.pf, ranges_m, self.judge.angles, self.judge.T, odom)
            self.restarting = False
            t0 = time.perf_counter()
            self.pose = self.pf.step(u, ranges_m)[0]
            if self.step_times is not None:
                self.step_times.append(time.perf_counter() - t0)
            cloud = None  # the particles and their weights, read back once for whoever needs them
            if self.judge is not None:
                cloud = self.pf.particles.numpy(), self.pf.log_w.numpy()
                delta = relative(self.odom_at_update[None], odom[None])[0]
                self.confidence = float(self.judge(*cloud, ranges_m, delta))
                if self.report_mode:  # the pose the confidence judged, not a mean between two clusters
                    self.pose = self.judge.pose
                seen, rule = self.judge.features[AGREEMENT], self.lost_rule
                if hasattr(rule, "searches_near") and rule.searches_near(seen):  # (LostRule: the best near it)
                    j = self.judge
                    seen = rule.seen(j.tracker.agreement, j.pose, ranges_m, j.angles, j.T, seen)
                if rule is not None and rule(stamp, self.confidence, seen):
                    self.lost_at_s.append(float(stamp - self.t_start))
                    if self.relocalize:  # lost: a global start again (weighs once the robot moved)
                        if self.places is not None:
                            self.places.remember(self.pf, odom)
                        low = self.confidence
                        self.global_start()
                        self.confidence, self.restarting = low, True  # until the next update the robot is lost
                        return Estimate(np.full(3, np.nan), True, cov, low)
            self.odom_at_update = odom
            if self.reduce_pending and stamp - self.t_start >= self.reduce_after_s:
                self.pf.reduce(m.reduce_to)
                self.reduce_pending, cloud = False, None
            if self.covariance:
                cov = particle_covariance(*(cloud or (self.pf.particles.numpy(), self.pf.log_w.numpy())), self.pose)
        return Estimate(between_updates(self.pose, self.odom_at_update, odom), weigh, cov, self.confidence)


def follow(
    pf,
    log: LaserLog,
    idx: np.ndarray,
    m,
    reduce_after_s: float | None = None,
    watch=None,
    step_times: list | None = None,
    covariances: list | None = None,
    progress: str | None = None,
    judge=None,
    confidences: list | None = None,
    report_pose: str = "filter",
    lost_rule=None,
    relocalize: bool = False,
    lost_at_s: list | None = None,
    places=None,
) -> np.ndarray:
    """Estimates [len(idx), 3] of one run over the scans ``idx``: a ``Localizer`` fed the log scan by scan; the
    filter is already initialised. A jump in ``idx`` (kidnapping) is invisible to the odometry: the step across
    it is zero. ``watch(j, pf)``, when given, sees the filter after every scan (plots, animations).
    ``step_times``, when given, gets the wall time (s) of every filter step (each reads its estimate back, so
    the step is done when it returns). ``covariances``, when given, gets the particles' covariance [3, 3] at
    every scan (NaN where the scan weighed nothing). ``progress``: a progress bar with that label, on a terminal.
    ``judge`` and ``confidences``: the confidence after each update, appended per scan (the last update's);
    ``report_pose``, ``lost_rule``, ``relocalize``: Localizer's (with a judge, "mode" follows the pose the confidence
    judged; the rule declares the robot lost, and a relocalization starts again); ``lost_at_s``, when given, gets the
    times the rule declared the robot lost; ``places``: Localizer's."""
    loc = Localizer(
        pf,
        m,
        reduce_after_s,
        covariance=covariances is not None,
        step_times=step_times,
        judge=judge,
        report_pose=report_pose,
        lost_rule=lost_rule,
        relocalize=relocalize,
        places=places,
    )
    est = np.empty((len(idx), 3))
    scans = enumerate(idx)
    if progress is not None:
        from tqdm import tqdm

        scans = tqdm(scans, total=len(idx), desc=progress, unit="scan", mininterval=1.0, disable=None, leave=False)
    for j, i in scans:
        if j > 0 and idx[j - 1] != i - 1:  # teleported: continue from here as if nothing moved
            loc.teleported(log.odom[i])
        e = loc.update(log.stamps[i], log.ranges_m[i], log.odom[i])
        est[j] = e.pose
        if covariances is not None:
            covariances.append(e.covariance)
        if confidences is not None:
            confidences.append(e.confidence)
        if watch is not None:
            watch(j, pf)
    if lost_at_s is not None:
        lost_at_s.extend(loc.lost_at_s)
    return est
