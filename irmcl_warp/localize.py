"""``python -m irmcl_warp.localize +exp=<name> [mcl.weighting=nog_raymarch|likelihood_field|beam_model]``

Runs MCL over the recorded stream (scans + odometry) from ``mcl.num_starts`` start times spread over
the sequence, each for ``mcl.run_s`` seconds, globally (uniform over the free space) or tracking from a
noisy pose. The map comes from the training split only: the NOF of ``train=<preset>`` baked into a NOG
(nog_raymarch), or a log-odds grid of the training scans (grid baselines); particles start on the
grid's known free cells for every method. Writes outputs/<exp>/localize-<weighting>/: trajectories
(TUM: stamp x y z qx qy qz qw), metrics.json (per start and summary), start0.png.
"""

from __future__ import annotations

import time
from pathlib import Path

import hydra
import numpy as np
from omegaconf import OmegaConf

from eval.metrics import localization_metrics
from irmcl_warp.config import register
from irmcl_warp.io import load_log
from irmcl_warp.mapping import integrate_scans
from irmcl_warp.mapping.grid import laser_bounds
from irmcl_warp.mapping.mapio import atomic_write_bytes
from irmcl_warp.mcl import ParticleFilter
from irmcl_warp.nof.prepare import far_m, prepare_beams, recorded_inputs
from irmcl_warp.nog import NOG, bake_nog
from irmcl_warp.outputs import save_figure, stage_dir, write_json, write_manifest
from kernels import WEIGHTING, pick_device
from kernels.motion import odometry_step


def build_maps(cfg, device):
    """(free-space view for initialisation as a NOG, weighting object) from the training split."""
    train = prepare_beams(cfg)["train"]
    m, res, far = cfg.mcl, cfg.mcl.map_resolution_m, far_m(cfg)
    grid = integrate_scans(train.T_map_laser, train.ranges_m, train.angles_rad, resolution_m=res, max_range_m=far,
                           device=device)
    occupancy = np.where(grid.known, grid.probability, 1.0).astype(np.float32)  # unknown: not free
    centre = (grid.origin_xy[0] + res / 2, grid.origin_xy[1] + res / 2)
    free_view = NOG(np.where(grid.known & (grid.probability < 0.35), 0.0, 1.0).astype(np.float32), centre, res)
    n_beams = min(m.num_beams, len(train.angles_rad))
    if m.weighting == "nog_raymarch":
        from irmcl_warp.train import train_dir

        ckpt = train_dir(cfg) / "nof.pt"
        if not ckpt.is_file():
            raise FileNotFoundError(f"{ckpt}: train the NOF first (python -m irmcl_warp.train +exp={cfg.exp} train={cfg.train.name})")
        nog = bake_nog(ckpt, laser_bounds(train.T_map_laser, train.ranges_m, train.angles_rad, far), res,
                       cache_dir=stage_dir(cfg, "nog"), device="cuda" if device.startswith("cuda") else "cpu")
        weighting = WEIGHTING.build("nog_raymarch", nog=nog, num_particles=m.num_particles, num_beams=n_beams,
                                    num_samples=m.num_samples, near_m=m.near_m, far_m=far, t_min=m.t_min,
                                    sigma_m=m.sigma_m, device=device)
    else:
        weighting = WEIGHTING.build(m.weighting, occupancy=occupancy, origin_xy=grid.origin_xy, resolution_m=res,
                                    max_range_m=far, device=device)
    return free_view, weighting


def write_tum(path: Path, stamps, poses) -> None:
    lines = [f"{t:.6f} {x:.4f} {y:.4f} 0 0 0 {np.sin(a / 2):.6f} {np.cos(a / 2):.6f}" for t, (x, y, a) in zip(stamps, poses)]
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


def plot_run(path: Path, view: NOG, gt, est) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    H, W = view.shape
    x0, y0, r = view.origin_xy[0] - view.resolution_m / 2, view.origin_xy[1] - view.resolution_m / 2, view.resolution_m
    fig, ax = plt.subplots(figsize=(8, 8 * H / max(W, 1) + 1))
    ax.imshow(1 - view.occupancy, cmap="gray", origin="lower", extent=(x0, x0 + W * r, y0, y0 + H * r))
    ax.plot(gt[:, 0], gt[:, 1], "g-", lw=1.5, label="ground truth")
    ax.plot(est[:, 0], est[:, 1], "r.", ms=2, label="estimate")
    ax.legend()
    save_figure(fig, path)


def run_localize(cfg) -> Path:
    started, device = time.time(), pick_device(cfg.device)
    m = OmegaConf.merge(cfg.mcl, {"far_m": far_m(cfg)})  # the filter's valid-beam bound = the sensor's far
    out = stage_dir(cfg, f"localize-{m.weighting}")
    log = load_log(cfg)
    if log.ground_truth is None:
        raise ValueError(f"{log.source}: localization is scored against ground truth, and this log has none")
    view, weighting = build_maps(cfg, device)
    t = log.stamps - log.stamps[0]
    starts = np.linspace(0.0, max(t[-1] - m.run_s, 0.0), m.num_starts)
    runs = []
    for k, t0 in enumerate(starts):
        pf = ParticleFilter(view, m, log.T_base_laser, log.info.angles_rad, device, weighting=weighting)
        pf.rng = np.random.default_rng(m.seed * 1000 + k)
        idx = np.flatnonzero((t >= t0) & (t <= t0 + m.run_s))
        if m.mode == "global":
            pf.init_uniform()
        else:
            first = idx[np.all(np.isfinite(log.ground_truth[idx]), axis=1)][0]
            pf.init_gaussian(log.ground_truth[first], m.tracking_std)
        est = np.array([pf.step(odometry_step(log.odom[i - 1], log.odom[i]) if i > idx[0] else (0.0, 0.0, 0.0),
                                log.ranges_m[i])[0] for i in idx])
        write_tum(out / f"start{k}.tum", log.stamps[idx], est)
        metrics = localization_metrics(log.stamps[idx], est, log.ground_truth[idx])
        runs.append({"start_s": float(t0), **metrics})
        print(f"start {k} at {t0:.0f} s: " + (f"converged after {metrics['time_to_converge_s']:.1f} s, RMSE "
              f"{metrics['location_rmse_cm']:.1f} cm" if metrics["converged"] else "did not converge"))
        if k == 0:
            plot_run(out / "start0.png", view, log.ground_truth[idx], est)
    ok = [r for r in runs if r["success"]]
    summary = {"weighting": m.weighting, "mode": m.mode, "num_particles": m.num_particles, "device": device,
               "success_rate": len(ok) / len(runs), "starts": len(runs),
               "location_rmse_cm_mean": float(np.mean([r["location_rmse_cm"] for r in ok])) if ok else None,
               "time_to_converge_s_mean": float(np.mean([r["time_to_converge_s"] for r in ok])) if ok else None}
    write_json(out / "metrics.json", {"dataset": cfg.data.name, "summary": summary, "runs": runs})
    write_manifest(out, cfg, recorded_inputs(cfg), device, started)
    print(f"{cfg.data.name}, {m.weighting}: success {len(ok)}/{len(runs)} -> {out}")
    return out


register()


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg) -> None:
    run_localize(cfg)


if __name__ == "__main__":
    main()
