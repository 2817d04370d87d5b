"""``python -m irmcl_warp.localize +exp=<name> [mcl.weighting=nog_raymarch|likelihood_field|beam_model]``

Runs MCL over the recorded stream (scans + odometry) from ``mcl.num_starts`` start times spread over
the sequence, each for ``mcl.run_s`` seconds, globally (uniform over the free space) or tracking from a
noisy pose. The map comes from the training split only: the NOF of ``train=<preset>`` baked into a NOG
(nog_raymarch), or a log-odds grid of the training scans (grid baselines); particles start on the
grid's known free cells for every method. As IR-MCL's code, the filter weighs and resamples only after
the odometry moved (``mcl.update_min_*``), and a global run keeps the ``mcl.reduce_to`` heaviest
particles ``mcl.reduce_after_s`` into the run.

``mcl.kidnap_at_s`` > 0 teleports the robot: that far into each run the stream jumps to the next start
time (another place; the odometry does not see the jump), and metrics.json scores the recovery.

Writes outputs/<exp>/localize-<tag>/ (tag: weighting, mode, particles, resolution, kidnap; see
``run_tag``): trajectories (TUM: stamp x y z qx qy qz qw), metrics.json (per start and summary),
start0.png. The stream is cached in outputs/<exp>/stream/ (a GPU box can run without the raw log).
"""

from __future__ import annotations

import time
from pathlib import Path

import hydra
import numpy as np
from omegaconf import OmegaConf

from eval.metrics import localization_metrics
from irmcl_warp.config import MCLConfig, register
from irmcl_warp.io import apply_laser_geometry, read_log
from irmcl_warp.mapping import integrate_scans
from irmcl_warp.mapping.grid import laser_bounds
from irmcl_warp.mapping.mapio import atomic_write_bytes
from irmcl_warp.mcl import ParticleFilter
from irmcl_warp.nof.prepare import cache_key, far_m, prepare_beams, recorded_inputs
from irmcl_warp.nog import NOG, bake_nog
from irmcl_warp.types import LaserInfo, LaserLog
from irmcl_warp.outputs import save_figure, stage_dir, up_to_date, write_json, write_manifest
from kernels import WEIGHTING, pick_device
from kernels.motion import odometry_step


NOF_WEIGHTINGS = ("nog_raymarch", "nof_direct")  # the observation models that read the trained field


def free_space_view(grid) -> NOG:
    """The grid's known free cells (p_occ < 0.35) as 0, the rest 1, in a NOG whose nodes sit at the cell
    centres: the particle filter spreads its uniform start over the zeros."""
    res = grid.resolution_m
    centre = (grid.origin_xy[0] + res / 2, grid.origin_xy[1] + res / 2)
    return NOG(np.where(grid.known & (grid.probability < 0.35), 0.0, 1.0).astype(np.float32), centre, res)


def build_maps(cfg, device):
    """(free-space view for initialisation as a NOG, weighting object, occupancy image for plots: p_occ,
    0.5 where unknown) from the training split."""
    train = prepare_beams(cfg)["train"]
    m, res, far = cfg.mcl, cfg.mcl.map_resolution_m, far_m(cfg)
    grid = integrate_scans(train.T_map_laser, train.ranges_m, train.angles_rad, resolution_m=res, max_range_m=far,
                           device=device)
    # unknown cells stop the beam model's rays (AMCL's map_calc_range), but they are no obstacle for the
    # likelihood field, whose distance map counts occupied cells only (as AMCL's)
    unknown_as = 0.0 if m.weighting == "likelihood_field" else 1.0
    occupancy = np.where(grid.known, grid.probability, unknown_as).astype(np.float32)
    free_view = free_space_view(grid)
    image = np.where(grid.known, grid.probability, 0.5).astype(np.float32)
    n_beams = min(m.num_beams, len(train.angles_rad))
    if m.weighting in NOF_WEIGHTINGS:
        (ckpt,) = nof_inputs(cfg)
        if not ckpt.is_file():
            raise FileNotFoundError(f"{ckpt}: train the NOF first (python -m irmcl_warp.train +exp={cfg.exp} train={cfg.train.name})")
        shared = dict(num_particles=m.num_particles, num_beams=n_beams, num_samples=m.num_samples, near_m=m.near_m,
                      far_m=far, sigma_m=m.sigma_m, device=device)
        if m.weighting == "nof_direct":
            return free_view, WEIGHTING.build("nof_direct", checkpoint=ckpt, **shared), image
        nog = bake_nog(ckpt, laser_bounds(train.T_map_laser, train.ranges_m, train.angles_rad, far), res,
                       cache_dir=stage_dir(cfg, "nog"), device="cuda" if device.startswith("cuda") else "cpu")
        weighting = WEIGHTING.build("nog_raymarch", nog=nog, t_min=m.t_min, empty_below=m.empty_below, **shared)
    else:
        weighting = WEIGHTING.build(m.weighting, occupancy=occupancy, origin_xy=grid.origin_xy, resolution_m=res,
                                    max_range_m=far, device=device)
    return free_view, weighting, image


STREAM_FIELDS = ("stamps", "ranges_m", "odom", "T_base_laser", "ground_truth")


def load_stream(cfg) -> LaserLog:
    """The log to localize in, from its cache when the settings and input files are unchanged (or when
    the raw files are absent and the settings match)."""
    import io

    key, no_raw = cache_key(cfg)
    path = stage_dir(cfg, "stream") / "stream.npz"
    try:
        with np.load(path) as z:
            stored = str(z["key"])
            if stored == key or (no_raw is not None and stored.split("-")[0] == key):
                v = z["info"].tolist()
                info = LaserInfo(int(v[0]), *map(float, v[1:]))
                gt = z["ground_truth"] if z["ground_truth"].size else None
                return apply_laser_geometry(LaserLog(z["stamps"], z["ranges_m"], z["odom"], info, z["T_base_laser"], gt,
                                                     source=f"{path} (cache of {cfg.data.path or cfg.data.name})"),
                                            cfg.data)
    except (OSError, KeyError, ValueError):
        pass
    if no_raw is not None:
        raise no_raw
    log = read_log(cfg)
    i = log.info
    buf = io.BytesIO()
    np.savez_compressed(buf, key=np.array(key), stamps=log.stamps, ranges_m=log.ranges_m, odom=log.odom,
                        T_base_laser=log.T_base_laser,
                        ground_truth=log.ground_truth if log.ground_truth is not None else np.zeros(0),
                        info=np.array([i.num_beams, i.angle_min_rad, i.angle_increment_rad, i.range_min_m,
                                       i.range_max_m, i.no_return_m], np.float64))
    atomic_write_bytes(path, buf.getvalue())
    return apply_laser_geometry(log, cfg.data)


ABLATION_TAGS = {"num_beams": "beams", "num_samples": "samples", "t_min": "tmin", "empty_below": "empty",
                 "resample": "", "estimate": "", "sigma_m": "sigma"}


def run_tag(m) -> str:
    """Output folder name of a localization run: what differs between the paper's table cells, then each
    ablation setting that differs from its default (``-beams16``, ``-tmin0``, ``-multinomial``)."""
    n = f"{m.num_particles // 1000}k" if m.num_particles % 1000 == 0 else str(m.num_particles)
    res = m.map_resolution_m * 100
    tag = f"localize-{m.weighting}-{m.mode}-{n}-{round(res) if abs(res - round(res)) < 1e-6 else f'{res:g}'}cm"
    tag += f"-kidnap{m.kidnap_at_s:g}s" if m.kidnap_at_s > 0 else ""
    tag += "-recovery" if m.recovery_alpha_slow > 0 and m.recovery_alpha_fast > 0 else ""
    defaults = MCLConfig()
    for key, short in ABLATION_TAGS.items():
        if m[key] != getattr(defaults, key):
            tag += f"-{short}{m[key]:g}" if short else f"-{m[key]}"
    return tag


def moved(odom_step, min_trans: float, min_rot: float) -> bool:
    """Has the robot moved enough since the last update (AMCL's update_min_d / update_min_a)?"""
    rot1, trans, rot2 = odom_step
    return abs(trans) > min_trans or abs(rot1 + rot2) > min_rot


def write_tum(path: Path, stamps, poses) -> None:
    lines = [f"{t:.6f} {x:.4f} {y:.4f} 0 0 0 {np.sin(a / 2):.6f} {np.cos(a / 2):.6f}" for t, (x, y, a) in zip(stamps, poses)]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


def plot_run(path: Path, view: NOG, image: np.ndarray, stamps, gt, est, particles, converged_s=None,
             kidnap_s=None) -> None:
    """Left: the map (white free, black occupied, grey unknown) with ground truth, estimates and the final
    particles; right: position error over time, the convergence (and kidnapping) time marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    H, W = view.shape
    r = view.resolution_m
    x0, y0 = view.origin_xy[0] - r / 2, view.origin_xy[1] - r / 2
    ok = np.all(np.isfinite(gt), axis=1)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(14, 5.5), gridspec_kw={"width_ratios": [2.2, 1]})
    ax.imshow(1 - image, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(x0, x0 + W * r, y0, y0 + H * r))
    keep = np.random.default_rng(0).permutation(len(particles))[:3000]
    ax.plot(particles[keep, 0], particles[keep, 1], ".", color="tab:blue", ms=1, alpha=0.5, label="particles (end)")
    ax.plot(est[:, 0], est[:, 1], ".", color="tab:red", ms=2, label="estimate")
    ax.plot(gt[ok, 0], gt[ok, 1], "-", color="tab:green", lw=1.2, label="ground truth")
    ax.plot(*gt[ok][0, :2], "o", color="tab:green", mfc="none", ms=4, label="start")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper right", fontsize=8, markerscale=2)
    plot_error_axis(bx, stamps, est, gt, converged_s, kidnap_s)
    save_figure(fig, path)


def plot_error_axis(ax, stamps, est, gt, converged_s=None, kidnap_s=None) -> None:
    """Position error over time (log scale) where the ground truth is known, with the convergence (and
    kidnapping) time marked and IR-MCL's 0.3 m success bound."""
    ok = np.all(np.isfinite(gt), axis=1)
    t = np.asarray(stamps) - stamps[0]
    ax.semilogy(t[ok], np.maximum(np.hypot(*(est[ok, :2] - gt[ok, :2]).T), 1e-3), "-", color="tab:red", lw=1)
    if converged_s is not None:
        ax.axvline(converged_s, color="tab:green", ls="--", lw=1, label=f"converged ({converged_s:.1f} s)")
    if kidnap_s is not None:
        ax.axvline(kidnap_s, color="k", ls=":", lw=1, label=f"kidnapped ({kidnap_s:.1f} s)")
    ax.axhline(0.3, color="gray", lw=0.8, label="0.3 m (success)")
    ax.set_xlabel("time since start (s)")
    ax.set_ylabel("position error (m)")
    ax.legend(fontsize=8)


def run_one(pf: ParticleFilter, log: LaserLog, idx: np.ndarray, m) -> np.ndarray:
    """Estimates [len(idx), 3] of one run over the scans ``idx``; the filter is already initialised.
    A jump in ``idx`` (kidnapping) is invisible to the odometry: the step across it is zero."""
    est = np.empty((len(idx), 3))
    last_odom, t_start, pose = log.odom[idx[0]], log.stamps[idx[0]], None
    reduce_pending = m.mode == "global" and 0 < m.reduce_to < pf.num_particles
    for j, i in enumerate(idx):
        if j > 0 and idx[j - 1] != i - 1:  # teleported: continue from here as if nothing moved
            last_odom = log.odom[i]
        u = odometry_step(last_odom, log.odom[i])
        if pose is None or moved(u, m.update_min_trans_m, m.update_min_rot_rad):
            pose = pf.step(u, log.ranges_m[i])[0]
            last_odom = log.odom[i]
            if reduce_pending and log.stamps[i] - t_start >= m.reduce_after_s:
                pf.reduce(m.reduce_to)
                reduce_pending = False
        est[j] = pose
    return est


def nof_inputs(cfg) -> list[Path]:
    """The trained field a NOF-weighted run reads (its digest decides whether the run is up to date)."""
    if cfg.mcl.weighting not in NOF_WEIGHTINGS:
        return []
    from irmcl_warp.train import train_dir

    return [train_dir(cfg) / "nof.pt"]


def run_localize(cfg) -> Path:
    started, device = time.time(), pick_device(cfg.device)
    m = OmegaConf.merge(cfg.mcl, {"far_m": far_m(cfg)})  # the filter's valid-beam bound = the sensor's far
    out = stage_dir(cfg, run_tag(m))
    inputs = recorded_inputs(cfg) + nof_inputs(cfg)
    if up_to_date(out, cfg, inputs, "localize"):
        return out
    log = load_stream(cfg)
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: localization is scored against ground truth, and this log has none")
    view, weighting, image = build_maps(cfg, device)
    t = log.stamps - log.stamps[0]
    starts = np.linspace(0.0, max(t[-1] - m.run_s, 0.0), m.num_starts)
    runs, kidnapped = [], m.kidnap_at_s > 0
    if kidnapped and not (0 < m.kidnap_at_s < m.run_s and m.num_starts >= 2):
        raise ValueError(f"mcl.kidnap_at_s={m.kidnap_at_s} must lie inside the run (mcl.run_s={m.run_s}) and the "
                         f"robot needs another start time to be teleported to (mcl.num_starts={m.num_starts})")
    for k, t0 in enumerate(starts):
        pf = ParticleFilter(view, m, log.T_base_laser, log.info.angles_rad, device, weighting=weighting)
        pf.rng = np.random.default_rng(m.seed * 1000 + k)
        idx = np.flatnonzero((t >= t0) & (t <= t0 + m.run_s))
        if kidnapped:  # the rest of the run from the next start time on: another place
            t1 = starts[(k + 1) % len(starts)]
            idx = np.concatenate([idx[t[idx] < t0 + m.kidnap_at_s],
                                  np.flatnonzero((t >= t1) & (t <= t1 + m.run_s - m.kidnap_at_s))])
        if m.mode == "global":
            pf.init_uniform()
        else:
            first = idx[np.all(np.isfinite(log.ground_truth[idx]), axis=1)][0]
            pf.init_gaussian(log.ground_truth[first], m.tracking_std)
        t_run = time.perf_counter()
        est = run_one(pf, log, idx, m)  # synchronous: every step reads its estimate back
        ms_per_scan = 1e3 * (time.perf_counter() - t_run) / len(idx)
        stamps = log.stamps[idx]
        cut = int(np.argmax(np.diff(idx) != 1) + 1) if kidnapped else len(idx)  # the first scan after a jump
        if kidnapped:  # a continuous clock over the jump: the second part follows the first
            dt = np.diff(stamps, prepend=stamps[0])
            dt[cut] = np.median(dt[1:cut])
            stamps = stamps[0] + np.cumsum(dt)
        write_tum(out / f"start{k}.tum", stamps, est)
        gt = log.ground_truth[idx]
        metrics = localization_metrics(stamps, est, gt)
        if kidnapped:
            before = localization_metrics(stamps[:cut], est[:cut], gt[:cut])
            recovery = localization_metrics(stamps[cut:], est[cut:], gt[cut:])
            metrics = {**metrics, "localized_before_kidnap": before["converged"],
                       "recovered": bool(before["converged"] and recovery["success"]),
                       "recovery_time_s": recovery["time_to_converge_s"]}
        runs.append({"start_s": float(t0), "ms_per_scan": ms_per_scan, **metrics})
        print(f"start {k} at {t0:.0f} s: " + (f"converged after {metrics['time_to_converge_s']:.1f} s, RMSE "
              f"{metrics['location_rmse_cm']:.1f} cm" if metrics["converged"] else "did not converge")
              + (f"; recovered from the kidnapping: {metrics['recovered']}" if kidnapped else ""))
        if k == 0:
            plot_run(out / "start0.png", view, image, stamps, gt, est, pf.particles.numpy(),
                     metrics["time_to_converge_s"], stamps[cut] - stamps[0] if kidnapped else None)
    summary = summarise(runs, m, device)
    write_json(out / "metrics.json", {"dataset": cfg.data.name, "summary": summary, "runs": runs,
                                      "settings": OmegaConf.to_container(m)})
    write_manifest(out, cfg, inputs, device, started)
    print(f"{cfg.data.name}, {m.weighting} ({m.mode}): success {summary['successes']}/{len(runs)} -> {out}")
    return out


def summarise(runs: list[dict], m, device: str) -> dict:
    ok = [r for r in runs if r["success"]]

    def mean(key, rows):
        vals = [r[key] for r in rows if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    summary = {"weighting": m.weighting, "mode": m.mode, "num_particles": m.num_particles,
               "map_resolution_m": m.map_resolution_m, "device": device, "starts": len(runs), "successes": len(ok),
               "success_rate": len(ok) / len(runs), "divergences": int(sum(r["divergences"] for r in runs))}
    summary["ms_per_scan_median"] = float(np.median([r["ms_per_scan"] for r in runs]))  # the first start also compiles
    for key in ("location_rmse_cm", "yaw_rmse_deg", "time_to_converge_s", "within_5cm_pct", "within_10cm_pct",
                "within_20cm_pct", "within_0.5deg_pct", "within_1deg_pct", "within_2deg_pct"):
        summary[f"{key}_mean"] = mean(key, ok)
    if m.kidnap_at_s > 0:
        summary["kidnap_at_s"] = m.kidnap_at_s
        summary["recovered"] = int(sum(r["recovered"] for r in runs))
        summary["recovery_time_s_mean"] = mean("recovery_time_s", [r for r in runs if r["recovered"]])
    return summary


register()


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg) -> None:
    run_localize(cfg)


if __name__ == "__main__":
    main()
