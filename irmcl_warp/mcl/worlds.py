"""The worlds stage: ``python -m irmcl_warp.worlds +exp=worlds [worlds.split=tuning|test] [mcl.*=...]``

Global localization where nobody tuned (issue 33). For each world of ``worlds.split`` (irmcl_warp/sim/floors.py):
a mapping drive (path seed 0, past every node of the floor's roadmap: ``worlds.map_drive``) makes the map (log-odds
of its scans at their true poses, as a robot's mapping run would), then ``worlds.runs`` other drives (seeds 1..runs) are localized in it
from their first scan for ``worlds.run_s`` seconds, with the ``mcl`` settings given. With ``worlds.kidnap_at_s``
the robot is carried, that far into a run, to where another drive is (the odometry does not see it).

At every filter update the stage reads the particle set back and computes what the robot has (the modes, the
scan's agreement with the map: irmcl_warp/mcl/confidence.py); with a calibration it turns them into the
confidence, declares the robot localized at ``worlds.confident_above`` and lost when the confidence stays below
``worlds.lost_below`` for ``worlds.lost_after_s``, or the scan's agreement at the estimate below
``worlds.lost_agreement_below`` for ``worlds.lost_agreement_updates`` updates (``LostRule``; then, with
``worlds.relocalize``, starts again from a uniform spread and says so; its first update also weighs the places the
scan fits best over the map and the particles it had: ``RelocalizePlaces``). With ``worlds.rival_seed_below`` a rival
place that has explained the scans that much better than the estimate (the confidence's evidence) is given
``worlds.rival_seed_share`` of the particles (``seed_at``): resampling drops a look-alike place's particles before
the scans can tell the two apart, and a set without particles there cannot come back to it by itself. The estimate
is the heaviest mode's pose.

Writes outputs/<exp>/worlds/<split>-<weighting>-<particles>-<id>/: per world and run ``<world>-run<k>.npz``
(stamps, estimate, truth, features, confidence, updated, the log mean likelihood of each update's scan) and
``.tum``; metrics.json (per run: the protocol's
success, the verdict at the end, lost events, false alarms, kidnap detection, the share of the drive spent outside
the map's known cells; per world and overall counts). A drive that leaves the map is a loud warning: where the map
knows nothing, "right" cannot be judged by it (a room the map lacks looks like its mapped twin).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf
from tqdm import tqdm

from irmcl_warp import runs
from irmcl_warp.config import worlds_calibration
from irmcl_warp.geometry import compose, relative, wrap_angle
from irmcl_warp.io import write_tum
from irmcl_warp.mapping import integrate_scans
from irmcl_warp.mcl.confidence import (
    AGREEMENT,
    FEATURES,
    Confidence,
    FeatureTracker,
    ScanAgreement,
    auroc,
    normalised,
    reliability,
    search_grid,
    right,
    tracker_of,
)
from irmcl_warp.mcl.track import between_updates, moved
from irmcl_warp.services.filters import NOF_WEIGHTINGS, build_filter, free_space_view, grid_maps
from irmcl_warp.services.metrics import localization_metrics
from irmcl_warp.services.outputs import save_figure
from irmcl_warp.sim import drive_log
from irmcl_warp.sim import floors
from irmcl_warp.types import LaserLog
from irmcl_warp.kernels import pick_device
from irmcl_warp.kernels.motion import odometry_step

DRIVE_SLACK = 1.6  # a drive's path is this much longer than run_s at the set speed (turns in place take time)


def world_names(split: str) -> tuple[str, ...]:
    if split in floors.SPLIT:
        return floors.SPLIT[split]
    names = tuple(s for s in split.split("+") if s)
    for n in names:
        floors.parse(n)
    return names


def run_worlds(cfg) -> Path:
    if cfg.mcl.weighting in NOF_WEIGHTINGS:
        raise ValueError(
            f"worlds: mcl.weighting={cfg.mcl.weighting} reads a NOF trained on each world, which this "
            "stage does not train yet; use likelihood_field or beam_model"
        )
    with runs.start(cfg, "worlds") as run:
        return run.path if run.done else localize_worlds(run)


def calibration_of(cfg) -> Confidence | None:
    if cfg.worlds.calibration == "off":  # features only (tuning runs for a calibration of new features)
        return None
    path = cfg.worlds.calibration or worlds_calibration(cfg.mcl.weighting, cfg.mcl.num_particles)
    if not path:
        return None
    conf = Confidence.load(path)
    fitted_n = conf.meta.get("num_particles")
    if fitted_n is not None and int(fitted_n) != int(cfg.mcl.num_particles):
        # a larger cloud keeps a wider spread and weightier modes: the features read otherwise (until the 2026-12-02
        # session a 100k run that named none took the 20k file without a word)
        warnings.warn(
            f"worlds: {path} was fitted on a filter of {int(fitted_n):,} particles, this run has "
            f"{int(cfg.mcl.num_particles):,}: its confidence may not be calibrated (fit one at this count: "
            "python -m eval.confidence fit)",
            stacklevel=1,
        )
    mine = tracker_of(cfg.worlds)
    if conf.tracker != mine:
        raise ValueError(
            f"{path} was fitted on runs that tracked rivals as {conf.tracker}; this run tracks them as {mine} "
            "(worlds.refine_rivals, worlds.search_rivals_every, worlds.mode_pose): its features would not be the "
            "ones it was fitted on"
        )
    fitted = conf.meta.get("maps")
    mine = {"map_drive": cfg.worlds.map_drive, "map_logodds_limit": cfg.worlds.map_logodds_limit}
    if fitted is not None and fitted != mine:
        warnings.warn(
            f"worlds: {path} was fitted on runs whose maps were made as {fitted}, this run's are made as {mine}: "
            "the confidence may not be calibrated for them (fit it again on tuning runs of these maps)",
            stacklevel=1,
        )
    return conf


def world_map(world, cfg, device):
    """The occupancy grid of the world's mapping drive (path seed 0, true poses), at mcl.map_resolution_m: a drive
    past every roadmap node (``worlds.map_drive=cover``) or a random one ``worlds.map_drive_m`` long; its log-odds
    bounded by +-``worlds.map_logodds_limit`` (None: unbounded)."""
    rng = np.random.default_rng(0)
    if cfg.worlds.get("map_drive", "cover") == "cover":
        waypoints = floors.coverage_drive(world, rng)
    else:
        waypoints = floors.drive(world, rng, cfg.worlds.map_drive_m)
    log = drive_log(world, cfg.sim, waypoints, 0, device=device)
    T_map_laser = compose(log.ground_truth, log.T_base_laser)
    return integrate_scans(
        T_map_laser,
        log.ranges_m,
        log.info.angles_rad,
        resolution_m=cfg.mcl.map_resolution_m,
        far_m=cfg.sim.range_max_m,  # simulated floors: the far bound is the simulated lidar's range
        device=device,
        **logodds_bounds(cfg.worlds.get("map_logodds_limit", 4.0)),
    )


def logodds_bounds(limit) -> dict:
    """integrate_scans' l_min / l_max for ``worlds.map_logodds_limit`` (None: unbounded). A bound makes the map
    forget: on a long drive, beams that graze a wall end a little beyond it (range noise) and mark its cells free,
    and the last few hundred such beams clear a wall that thousands of hits had made (twin-1001's wall y = 5.27 m,
    x 4.1-9.4 m, in the coverage map: p 0.02 with +-4, 1.0 unbounded)."""
    if limit is None:
        return {"l_min": -np.inf, "l_max": np.inf}
    return {"l_min": -float(limit), "l_max": float(limit)}


def query_log(world, cfg, k: int, device) -> tuple[LaserLog, int | None]:
    """Drive ``k`` (path seed k) for worlds.run_s; with worlds.kidnap_at_s the rest of the run is drive
    ``k + 1000``'s, its odometry continuing the first's (the jump unseen). Returns (log, first scan after the jump)."""
    w, s = cfg.worlds, cfg.sim
    length = DRIVE_SLACK * s.speed_mps * w.run_s
    path = floors.drive(world, np.random.default_rng(k), length)
    first = drive_log(unmapped_for(world, path, w, k), s, path, k, w.run_s, device)
    if w.kidnap_at_s <= 0:
        return first, None
    cut = int(np.searchsorted(first.stamps - first.stamps[0], w.kidnap_at_s))
    path = floors.drive(world, np.random.default_rng(k + 1000), length)
    other = drive_log(
        unmapped_for(world, path, w, k + 1000),
        s,
        path,
        k + 1000,
        w.run_s - w.kidnap_at_s,
        device,
    )
    odom = np.vstack([first.odom[:cut], compose(first.odom[cut - 1], relative(other.odom[0], other.odom))])
    stamps = np.concatenate(
        [first.stamps[:cut], first.stamps[cut - 1] + (other.stamps - other.stamps[0] + 1 / s.rate_hz)]
    )
    log = LaserLog(
        stamps,
        np.vstack([first.ranges_m[:cut], other.ranges_m]),
        odom,
        first.info,
        first.T_base_laser,
        np.vstack([first.ground_truth[:cut], other.ground_truth]),
        f"{first.source} kidnapped",
    )
    return log, cut


UNMAPPED_SEEDS_FROM = 10_000  # drive k's unmapped objects come from the generator of this + k (its path and noise
# from k's own: a drive with them is the drive without them, plus the objects)


def unmapped_for(world, path, w, k: int):
    """The world drive ``k`` sees: with ``worlds.unmapped_per_m`` > 0, ``world`` plus objects its map does not hold
    near the drive's ``path`` (floors.with_unmapped); else ``world``, the map's own."""
    per_m = float(getattr(w, "unmapped_per_m", 0.0) or 0.0)  # (runs before it: none)
    return floors.with_unmapped(world, path, np.random.default_rng(UNMAPPED_SEEDS_FROM + k), per_m)


def localize_worlds(run: runs.Run) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    conf = calibration_of(cfg)
    names = world_names(cfg.worlds.split)
    per_world, rows, judged = {}, [], []
    bar = tqdm(total=len(names) * cfg.worlds.runs, desc="worlds", unit="run")
    for name in names:
        world = floors.build(name)
        grid = world_map(world, cfg, device)
        view = free_space_view(grid.probability, grid.origin_xy, grid.resolution_m, grid.known)
        maps = grid_maps(grid, cfg.mcl.weighting)
        agreement = ScanAgreement.of_grid(grid, cfg.mcl.field_occ_threshold)
        wants_grid = cfg.worlds.search_rivals_every > 0 or cfg.worlds.relocalize_places > 0
        search = search_grid(grid) if wants_grid else None
        results = []
        for k in range(1, cfg.worlds.runs + 1):
            log, cut = query_log(world, cfg, k, device)
            pf = build_filter(
                cfg.mcl,
                view,
                log.T_base_laser,
                log.info.angles_rad,
                cfg.sim.range_max_m,  # the far bound: the simulated lidar's range (these stages read no log)
                device,
                maps,
            )
            pf.rng = np.random.default_rng(cfg.mcl.seed * 1000 + k)
            pf.init_uniform()
            trace = follow_with_confidence(
                pf,
                log,
                cfg.mcl,
                cfg.worlds,
                FeatureTracker(
                    agreement,
                    refine_rivals=cfg.worlds.refine_rivals,
                    search_poses=search,
                    search_every=cfg.worlds.search_rivals_every,
                    mode_pose=cfg.worlds.mode_pose,
                ),
                conf,
                RelocalizePlaces(cfg.worlds, agreement, search, cfg.mcl.global_candidates),
            )
            np.savez_compressed(out / f"{name}-run{k}.npz", stamps=log.stamps, truth=log.ground_truth, **trace)
            write_tum(out / f"{name}-run{k}.tum", log.stamps, trace["estimate"])
            result = score_run(log, trace, cut, cfg.worlds)
            result["truth_unmapped_share"] = unmapped_share(grid, log.ground_truth)
            if result["truth_unmapped_share"] > UNMAPPED_WARN:
                warnings.warn(
                    f"worlds: {name} run {k}: {100 * result['truth_unmapped_share']:.0f} % of the drive lies outside "
                    "the map's known cells; whether it ends right says little about the localizer there",
                    stacklevel=1,
                )
            results.append({"world": name, "run": k, **result})
            judged.append(judged_updates(log, trace))
            bar.update()
            bar.set_postfix_str(f"{name}: {sum(r['success'] for r in results)}/{len(results)} right")
        per_world[name] = {**world_summary(results), **separation(judged[-len(results) :])}
        rows += results
    bar.close()
    plot_worlds(out / "worlds.png", names, out, cfg.worlds.confident_above)
    summary = {
        "split": cfg.worlds.split,
        "worlds": list(names),
        "weighting": cfg.mcl.weighting,
        "num_particles": cfg.mcl.num_particles,
        "device": device,
        "calibrated": conf is not None,
        "calibration": conf.meta.get("source") if conf else None,
        **world_summary(rows),
        **separation(judged),
    }
    settings = {"mcl": OmegaConf.to_container(cfg.mcl), "worlds": OmegaConf.to_container(cfg.worlds)}
    path = run.finish({"summary": summary, "per_world": per_world, "runs": rows, "settings": settings}, device)
    print(verdict_line(summary, cfg.worlds) + f" -> {path}")
    return path


UNMAPPED_WARN = 0.01  # a drive with more of its poses outside the map's known cells is reported loudly


def unmapped_share(grid, poses: np.ndarray) -> float:
    """The share of ``poses`` [n, >=2] (the drive's truth) on cells the map does not know (or off the map)."""
    ij = grid.cell_of(np.asarray(poses)[:, :2])
    h, w = grid.known.shape
    inside = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < w) & (ij[:, 1] < h)
    known = np.zeros(len(ij), bool)
    known[inside] = grid.known[ij[inside, 1], ij[inside, 0]]
    return float(1.0 - known.mean()) if len(ij) else 0.0


class LostRule:
    """When a localized robot counts as lost (issue 33), update by update: ``rule(t, confidence, agreement)`` is True
    at the update where it is declared lost. Localized: the confidence reached ``confident_above``. Lost: either the
    confidence stayed below ``lost_below`` for ``lost_after_s`` (with ``lost_timeout_agreement_below``, counted only
    over updates whose scan agreement at the estimate is below it: an estimate that keeps explaining the scans while
    another mode is as likely is ambiguous, not lost), or
    (``agreement_below`` > 0) the scan's agreement
    with the map at the estimate stayed below ``agreement_below`` for ``agreement_updates`` updates in a row. The
    second trigger reads one feature, the one a kidnapping moves at once (from ~1 to 0.1-0.3 on the first scan after
    it, on the kidnapped test floors), where the calibrated confidence falls over several updates. After a lost
    event the rule waits for the confidence to reach ``confident_above`` again. The worlds stage runs it live; an
    analysis can run it again over a trace recorded with ``worlds.relocalize=false`` (eval.analyses.lost_rules)."""

    def __init__(self, w):
        self.confident_above, self.lost_below, self.lost_after_s = w.confident_above, w.lost_below, w.lost_after_s
        self.agreement_below, self.agreement_updates = float(w.lost_agreement_below), int(w.lost_agreement_updates)
        gate = getattr(w, "lost_timeout_agreement_below", None)  # (runs before it: none)
        self.timeout_below = np.inf if gate is None else float(gate)
        self.near_m = float(getattr(w, "lost_agreement_near_m", 0.0) or 0.0)  # (runs before it: 0, off)
        self.near_rad = float(getattr(w, "lost_agreement_near_rad", 0.0) or 0.0)
        self.near_fit = float(getattr(w, "lost_agreement_near_fit", 0.0) or 0.0) or self.agreement_below
        self.reset()

    def searches_near(self, at_estimate: float) -> bool:
        """Whether ``seen`` searches near an estimate whose scan agreed ``at_estimate`` (``worlds.lost_agreement_near_m``
        > 0, the agreement trigger on, and the agreement below it)."""
        return self.near_m > 0 and 0 < self.agreement_below and at_estimate < self.agreement_below

    def seen(self, agreement: ScanAgreement, pose, ranges_m, angles_rad, T_base_laser, at_estimate: float) -> float:
        """The scan agreement the rule reads at an update: ``at_estimate`` (the feature's, at the heaviest mode ``pose``),
        or, with ``worlds.lost_agreement_near_m`` > 0 and where it is below ``lost_agreement_below``, the best of the
        poses within +-near_m and +-near_rad of the estimate (``ScanAgreement.refine``'s grid of two steps each way,
        then a grid three times finer about its best: 250 poses; a heading 0.075 rad off misses walls 5 m away). MIT
        Killian's scans in its fastest turns (33-86 deg/s) agreed 0.07-0.42 at an estimate 6-17 deg behind them and
        0.60-0.93 at the best pose near it (thirty-first session): the estimate lagged, the robot was not lost, where a
        kidnapped robot's scan fits nowhere near the old estimate. Searched only where the agreement is low; the best
        counts only where it reaches ``lost_agreement_near_fit`` (0: ``lost_agreement_below``), since the best of 250
        poses reaches a bar more easily than one pose does (on the kidnapped tuning floors, 0.4 delayed 8 detections
        by an update and missed 3: a corridor's scan fits near any corridor pose). The two grids can miss a best pose
        that lies between the coarse grid's points: in a simulated box, 3-5 of 60 estimates lagging 0.1-0.25 rad and
        up to 0.15 m stayed below 0.6 (a denser search is not measured yet)."""
        if not self.searches_near(at_estimate) or not np.all(np.isfinite(pose)):
            return at_estimate
        scan = (ranges_m, angles_rad, T_base_laser)
        coarse, _ = agreement.refine(pose, *scan, step_m=self.near_m / 2, step_rad=self.near_rad / 2)
        best = agreement.refine(coarse, *scan, step_m=self.near_m / 6, step_rad=self.near_rad / 6)[1]
        return best if best >= self.near_fit else float(at_estimate)  # (the best of 250 poses: a bar of its own)

    def reset(self) -> None:
        self.localized, self.low_since, self.low_agreement = False, None, 0

    def __call__(self, t: float, p: float, agreement: float) -> bool:
        if p >= self.confident_above:
            self.localized, self.low_since = True, None
        elif self.localized and p < self.lost_below and agreement < self.timeout_below:
            self.low_since = t if self.low_since is None else self.low_since
        else:
            self.low_since = None
        low = self.agreement_below > 0 and agreement < self.agreement_below
        self.low_agreement = self.low_agreement + 1 if (self.localized and low) else 0
        timed_out = self.low_since is not None and t - self.low_since >= self.lost_after_s
        if self.localized and (timed_out or self.low_agreement >= self.agreement_updates):
            self.reset()
            return True
        return False


PLACE_SHARE = 0.05  # of the particle count: the poses drawn about each place a relocalization's search found
PLACES_APART_M = 2.0  # the places a search keeps lie at least this far apart (FeatureTracker's rival_apart_m)


class RelocalizePlaces:
    """Where a relocalization looks first (issue 33), beside the uniform candidates of its first update
    (``ParticleFilter.add_candidates``; needs ``mcl.global_candidates`` > 1); the filter's likelihood decides among
    them all. Each part off unless set:

    * ``worlds.relocalize_places`` = k > 0: poses about the k places the first update's scan fits best over the whole
      map (``ScanAgreement.search`` over ``search_poses``, a 0.5 m / 22.5 deg grid of the free space; PLACE_SHARE of
      the particle count about each, SEED_STD apart), as the camera's hypotheses seed the lidar + camera
      relocalization. A search of a 100 m building's 586k poses takes about 1.2 s on one core of the 2-core machine,
      once per relocalization.
    * ``worlds.relocalize_keeps_particles``: the particles the filter had when it was declared lost, moved by the
      odometry since: a robot declared lost that was not (a scan or two the map does not explain) finds its place
      again on the first update, where a uniform start alone loses it."""

    def __init__(self, w, agreement: ScanAgreement, search_poses=None, global_candidates: int = 1):
        self.places = int(getattr(w, "relocalize_places", 0) or 0)
        self.keeps = bool(getattr(w, "relocalize_keeps_particles", False))
        if self.places > 0 and search_poses is None:
            raise ValueError("worlds.relocalize_places > 0 needs the map's search poses (search_grid)")
        if (self.places > 0 or self.keeps) and global_candidates <= 1:
            raise ValueError(
                "worlds.relocalize_places and worlds.relocalize_keeps_particles add to a global start's candidates: "
                f"they need mcl.global_candidates > 1 (it is {global_candidates})"
            )
        self.agreement, self.search_poses = agreement, search_poses
        self.kept = None  # (the particles when declared lost, the odometry then)

    def remember(self, pf, odom) -> None:
        """At a lost event, before the uniform start: the particles and the odometry's pose (with keeps_particles)."""
        self.kept = (pf.particles.numpy().astype(np.float64), np.asarray(odom, float)) if self.keeps else None

    def seed(self, pf, ranges_m, angles_rad, T_base_laser, odom=None) -> int:
        """Give a relocalization's first update the places this scan fits best and the particles remembered (moved
        by the odometry from then to ``odom``); returns how many places were searched out."""
        found = []
        if self.places > 0:
            found = self.agreement.search(
                self.search_poses,
                ranges_m,
                angles_rad,
                T_base_laser,
                away_from=np.full(2, np.inf),  # (none excluded)
                apart_m=PLACES_APART_M,
                count=self.places,
            )
            k = max(1, int(round(PLACE_SHARE * pf.num_particles)))
            about = [np.asarray(p, float) + pf.rng.normal(0.0, 1.0, (k, 3)) * np.asarray(SEED_STD) for p, _ in found]
            if about:
                poses = np.vstack(about)
                poses[:, 2] = wrap_angle(poses[:, 2])
                pf.add_candidates(poses)
        if self.kept is not None and odom is not None:
            particles, then = self.kept
            pf.add_candidates(compose(particles, relative(then, np.asarray(odom, float))))  # (compose wraps the yaw)
        self.kept = None
        return len(found)

    def describe(self) -> str:
        """What a relocalization's first update weighs beside the uniform candidates, in words ("" for nothing)."""
        parts = (["the places the scan fits best"] if self.places > 0 else []) + (
            ["the particles it had"] if self.keeps else []
        )
        return " and ".join(parts)


def follow_with_confidence(
    pf, log: LaserLog, m, w, tracker: FeatureTracker, conf: Confidence | None, places: RelocalizePlaces | None = None
) -> dict:
    """Drive the filter over the whole log (AMCL's gates and ``mcl.first_update`` as in mcl/track.follow); at
    every update the features, the confidence and the heaviest mode's pose; lost-robot detection by ``LostRule``
    (with ``worlds.relocalize``, a uniform spread again, whose first update also weighs what ``places`` gives).
    Returns per-scan arrays and the events."""
    n = len(log.stamps)
    est, feats = np.full((n, 3), np.nan), np.full((n, len(FEATURES)), np.nan)
    prob, updated, mean_lik = np.full(n, np.nan), np.zeros(n, bool), np.full(n, np.nan)
    particles = np.zeros(n, np.int64)  # the count each update ran with (mcl.kld_sampling moves it)
    lost_at, seeded_at, pose, p, weighed = [], [], None, np.nan, False
    rule, last_odom, restarting = LostRule(w), log.odom[0], False
    angles, T = log.info.angles_rad, log.T_base_laser
    for i in range(n):
        u = odometry_step(last_odom, log.odom[i])
        if (not weighed and m.first_update == "scan") or moved(u, m.update_min_trans_m, m.update_min_rot_rad):
            particles[i] = pf.num_particles
            if restarting and places is not None:  # a relocalization's first update: where it looks first
                places.seed(pf, log.ranges_m[i], angles, T, log.odom[i])
            restarting = False
            pf.step(u, log.ranges_m[i])
            delta = relative(last_odom[None], log.odom[i][None])[0]
            last_odom, weighed, updated[i] = log.odom[i], True, True
            f, md = tracker(pf.particles.numpy(), pf.log_w.numpy(), log.ranges_m[i], angles, T, delta)
            feats[i], pose = f, md.poses[0]
            mean_lik[i] = pf.log_mean_likelihood(pf.log_lik)  # what AMCL's w_slow / w_fast average (lost_rules)
            rival = tracker.best_rival() if getattr(w, "rival_seed_below", 0.0) > 0 else None
            if rival is not None and rival[1] <= -w.rival_seed_below:
                seed_at(pf, rival[0], w.rival_seed_share)
                tracker.forget_evidence()
                seeded_at.append(float(log.stamps[i] - log.stamps[0]))
            if conf is not None:
                p = float(conf(f))
                seen = rule.seen(tracker.agreement, pose, log.ranges_m[i], angles, T, f[AGREEMENT])
                if rule(log.stamps[i], p, seen):
                    lost_at.append(float(log.stamps[i] - log.stamps[0]))
                    if w.relocalize:
                        if places is not None:
                            places.remember(pf, log.odom[i])
                        pf.init_uniform()
                        tracker.reset()
                        weighed, pose, restarting = False, None, True
        est[i] = between_updates(pose, last_odom, log.odom[i])
        prob[i] = p
    return {
        "estimate": est,
        "features": feats,
        "confidence": prob,
        "updated": updated,
        "log_mean_likelihood": mean_lik,
        "particles": particles,
        "lost_at_s": np.array(lost_at, float),
        "rival_seeded_at_s": np.array(seeded_at, float),
    }


SEED_STD = (0.2, 0.2, 0.05)  # m, m, rad: the particles given a rival's place, about its pose (ScanAgreement.refine's
# reach per update is 0.2 m and 0.1 rad)


def seed_at(pf, pose, share: float) -> None:
    """Give ``share`` of the filter's particles the place ``pose`` (normal about it, SEED_STD), the rest drawn from
    the current set by weight; equal weights after, so the next scans decide. Particles off the map sit at ``pose``."""
    n = pf.num_particles
    k = int(round(share * n))
    w = normalised(pf.log_w.numpy())
    kept = pf.particles.numpy()[pf.rng.choice(n, n - k, p=w)]
    new = np.asarray(pose, float) + pf.rng.normal(0.0, 1.0, (k, 3)) * np.asarray(SEED_STD)
    H, W = pf.free_space.shape
    cells = pf.free_space.node_of(new[:, :2])
    off = np.any((cells < 0) | (cells >= np.array([W, H])), 1)
    new[off] = pose
    new[:, 2] = np.angle(np.exp(1j * new[:, 2]))
    pf.set_particles(np.vstack([kept, new]))


def score_run(log: LaserLog, trace: dict, cut: int | None, w) -> dict:
    """The protocol's metrics (services.metrics) before any kidnapping, the verdict at the end, lost events."""
    t = log.stamps - log.stamps[0]
    end = cut if cut is not None else len(t)
    est, gt = trace["estimate"], log.ground_truth
    has = np.all(np.isfinite(est), 1)
    ok = right(np.where(has[:, None], est, 0.0), gt) & has
    m = (
        localization_metrics(log.stamps[:end], est[:end], gt[:end], success_within_s=w.run_s)
        if has[:end].sum() >= 2
        else {"converged": False, "success": False, "time_to_converge_s": None, "location_rmse_cm": None}
    )
    p_end = float(trace["confidence"][-1])
    out = {
        "success": bool(m["success"]),
        "converged": bool(m["converged"]),
        "time_to_converge_s": m["time_to_converge_s"],
        "location_rmse_cm": m.get("location_rmse_cm"),
        "right_at_end": bool(ok[-1]),
        "error_at_end_m": float(np.hypot(*(est[-1, :2] - gt[-1, :2]))) if has[-1] else None,
        "confidence_at_end": None if np.isnan(p_end) else p_end,
        "localized_at_end": bool(p_end >= w.confident_above) if not np.isnan(p_end) else None,
        "lost_at_s": trace["lost_at_s"].tolist(),
        "rival_seeded_at_s": trace.get("rival_seeded_at_s", np.zeros(0)).tolist(),
    }
    if "particles" in trace and trace["updated"].any():  # the particles an update ran with, on average
        out["particles_per_update"] = float(trace["particles"][trace["updated"]].mean())
    before = trace["lost_at_s"][trace["lost_at_s"] < (t[cut] if cut is not None else np.inf)]
    right_when = [
        bool(ok[np.searchsorted(t, s) - 1 - int(round(w.lost_after_s / max(np.median(np.diff(t)), 1e-9)))])
        for s in before
    ]  # was the estimate right when the confidence started to fall?
    out["false_alarms"] = int(sum(right_when))
    out["tracking_right_s"] = float(np.sum(np.diff(t, append=t[-1])[:end][ok[:end]]))
    if cut is not None:
        t_jump = t[cut]
        after = trace["lost_at_s"][trace["lost_at_s"] >= t_jump]
        out["kidnap_at_s"] = float(t_jump)
        out["right_before_kidnap"] = bool(ok[cut - 1])
        out["detected_after_s"] = float(after[0] - t_jump) if len(after) else None
        if len(after):
            i0 = int(np.searchsorted(t, after[0]))
            right_since = np.logical_and.accumulate(ok[::-1])[::-1]  # right from this scan to the end
            back = np.flatnonzero(right_since[i0:])
            out["reconverged_after_s"] = float(t[i0 + back[0]] - after[0]) if len(back) else None
        else:
            out["reconverged_after_s"] = None
    return out


def judged_updates(log: LaserLog, trace: dict) -> tuple[np.ndarray, np.ndarray]:
    """(confidence, right) at the run's updates with an estimate and a confidence."""
    ok = trace["updated"] & np.isfinite(trace["confidence"]) & np.all(np.isfinite(trace["estimate"]), 1)
    return trace["confidence"][ok], right(trace["estimate"][ok], log.ground_truth[ok])


def separation(judged: list) -> dict:
    """How well the confidence told right from wrong over these updates: AUROC and the reliability curve
    (None without a calibration)."""
    if not judged or not sum(len(p) for p, _ in judged):
        return {"auroc": None}
    p, y = np.concatenate([p for p, _ in judged]), np.concatenate([y for _, y in judged])
    a = auroc(p, y)
    return {
        "auroc": None if np.isnan(a) else a,
        "updates": int(len(y)),
        "right_share": float(y.mean()),
        "reliability": reliability(p, y),
    }


def world_summary(rows: list[dict]) -> dict:
    n = len(rows)
    s = {
        "runs": n,
        "successes": int(sum(r["success"] for r in rows)),
        "right_at_end": int(sum(r["right_at_end"] for r in rows)),
        "localized_at_end": int(sum(bool(r["localized_at_end"]) for r in rows)),
        "confidently_wrong_at_end": int(sum(bool(r["localized_at_end"]) and not r["right_at_end"] for r in rows)),
        "false_alarms": int(sum(r["false_alarms"] for r in rows)),
        "tracking_right_h": float(sum(r["tracking_right_s"] for r in rows) / 3600),
    }
    s["rival_seeds"] = int(sum(len(r.get("rival_seeded_at_s", [])) for r in rows))
    unmapped = [r["truth_unmapped_share"] for r in rows if "truth_unmapped_share" in r]
    if unmapped:
        s["drives_leaving_map"] = int(sum(u > UNMAPPED_WARN for u in unmapped))
    per_update = [r["particles_per_update"] for r in rows if r.get("particles_per_update") is not None]
    if per_update:
        s["particles_per_update"] = float(np.mean(per_update))
    kid = [r for r in rows if "kidnap_at_s" in r and r["right_before_kidnap"]]
    if kid:
        s["kidnaps"] = len(kid)
        s["detected_within_2s"] = int(
            sum(r["detected_after_s"] is not None and r["detected_after_s"] <= 2.0 for r in kid)
        )
        s["reconverged_within_5s"] = int(
            sum(r["reconverged_after_s"] is not None and r["reconverged_after_s"] <= 5.0 for r in kid)
        )
    return s


def verdict_line(summary: dict, w) -> str:
    """The run's last line: how many runs ended right, and how many said so; never "localized" below the
    threshold (a run that is not confident says it is not)."""
    line = (
        f"{summary['split']}, {summary['weighting']} {summary['num_particles']} particles: "
        f"{summary['successes']}/{summary['runs']} runs localized correctly (protocol), "
        f"{summary['right_at_end']}/{summary['runs']} right at the end"
    )
    if summary["calibrated"]:
        line += (
            f"; {summary['localized_at_end']} ended confident (>= {w.confident_above}), "
            f"{summary['confidently_wrong_at_end']} of them wrong; {summary['runs'] - summary['localized_at_end']} "
            "ended NOT localized (confidence below the threshold)"
        )
    else:
        line += "; no confidence calibration for this weighting: no run is declared localized"
    if summary.get("drives_leaving_map"):
        line += f"; WARNING: {summary['drives_leaving_map']} drives left the map's known cells"
    return line


def plot_worlds(path: Path, names, out: Path, confident_above: float) -> None:
    """Each world's walls with, per run, where the robot ended (black dot) and where the estimate put it: a green
    circle when right, a red cross when wrong (a line joins the two), hollow when the run ended not confident."""
    import matplotlib.pyplot as plt

    cols = min(4, len(names))
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names):
        world = floors.build(name)
        for x0, y0, x1, y1 in world.segments:
            ax.plot([x0, x1], [y0, y1], "k-", lw=0.6)
        for f in sorted(out.glob(f"{name}-run*.npz")):
            z = np.load(f)
            est, gt, p = z["estimate"][-1], z["truth"][-1], z["confidence"][-1]
            if not np.all(np.isfinite(est)):
                continue
            ok = bool(right(est[None], gt[None])[0])
            sure = bool(np.isfinite(p) and p >= confident_above)
            ax.plot([gt[0], est[0]], [gt[1], est[1]], "-", color="0.6", lw=0.6)
            ax.plot(*gt[:2], "k.", ms=4)
            ax.plot(
                *est[:2],
                "o" if ok else "x",
                color="tab:green" if ok else "tab:red",
                ms=6,
                mfc=("tab:green" if ok else "tab:red") if sure else "none",
            )
        ax.set_title(f"{name} ({floors.split_of(name)})")
        ax.set_aspect("equal")
        ax.axis("off")
    for ax in list(axes.flat)[len(names) :]:
        ax.axis("off")
    save_figure(fig, path)
