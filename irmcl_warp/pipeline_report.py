"""The pipeline's report: outputs/<exp>/pipeline/report.md with two figures (map + trajectories, error over
time), the timing of every stage and the metrics of each, read from the stages' own metrics.json files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irmcl_warp.io.atomic import atomic_write_bytes
from irmcl_warp.services.outputs import save_figure
from irmcl_warp.services.plots import plot_error_axis


def _fmt(v, unit="", digits=2):
    return "-" if v is None else f"{v:.{digits}f}{unit}"


def plot_map(path: Path, slam_map, slam_poses, est, gt_map, particles) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    H, W = slam_map.shape
    r = slam_map.resolution_m
    x0, y0 = slam_map.origin_xy
    image = np.where(slam_map.known, slam_map.probability, 0.5)
    fig, ax = plt.subplots(figsize=(10, 10 * H / max(W, 1) + 1))
    ax.imshow(1 - image, cmap="gray", vmin=0, vmax=1, origin="lower", extent=(x0, x0 + W * r, y0, y0 + H * r))
    ax.plot(slam_poses[:, 0], slam_poses[:, 1], "-", color="tab:orange", lw=0.8, label="SLAM (mapping log)")
    keep = np.random.default_rng(0).permutation(len(particles))[:3000]
    ax.plot(particles[keep, 0], particles[keep, 1], ".", color="tab:blue", ms=1, alpha=0.4, label="particles (end)")
    if gt_map is not None:
        ok = np.all(np.isfinite(gt_map), 1)
        ax.plot(gt_map[ok, 0], gt_map[ok, 1], "-", color="tab:green", lw=1.2, label="ground truth (localized log)")
    ax.plot(est[:, 0], est[:, 1], ".", color="tab:red", ms=2, label="MCL estimate")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, SLAM map frame)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8, markerscale=3)
    save_figure(fig, path)


def plot_error(path: Path, stamps, est, gt_map, converged_s) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5))
    plot_error_axis(ax, stamps, est, gt_map, converged_s)
    save_figure(fig, path)


def failure_note(stamps, est, gt_map, loc: dict, reference: str = "truth") -> str | None:
    """None where the localization succeeded, else a plain sentence: whether it ever converged, when and
    where it was last more than 0.3 m off, and how far off it ended (``reference``: what ``gt_map`` is)."""
    if loc is None or loc["success"]:
        return None
    t = np.asarray(stamps) - stamps[0]
    ok = np.all(np.isfinite(gt_map), axis=1)
    err = np.full(len(t), np.nan)
    err[ok] = np.hypot(*(est[ok, :2] - gt_map[ok, :2]).T)
    off = np.flatnonzero(err > 0.3)
    last = off[-1] if len(off) else int(np.nanargmax(err))
    how = (
        f"converged after {loc['time_to_converge_s']:.1f} s but did not stay within 0.3 m"
        if loc["converged"]
        else "never converged"
    )
    return (
        f"Localization FAILED: it {how}; {err[last]:.2f} m off at {t[last]:.1f} s (estimate "
        f"({est[last, 0]:.2f}, {est[last, 1]:.2f}) m, {reference} ({gt_map[last, 0]:.2f}, {gt_map[last, 1]:.2f}) m), "
        f"{err[ok][-1]:.2f} m off at the end ({t[ok][-1]:.1f} s)."
    )


def scan_lag_line(slam: dict) -> str | None:
    """The report's sentence on a lag GMapping's matched poses named between the scans and the odometry (the SLAM
    summary's ``scan_lag``: slam/stage.py), or None."""
    lag = slam.get("scan_lag")  # (summaries before the check have no key)
    if not lag:
        return None
    s, applied = float(lag["lag_s"]), float(lag.get("applied_s") or 0.0)
    return (
        f"**The scans appear stamped {abs(s):.3f} s {'late' if s < 0 else 'early'} against the odometry** (GMapping's "
        f"matched poses turn as the odometry did then): every stage read each scan's odometry at another moment; set "
        f"data.scan_time_offset_s={applied + s:.3f} and run again."
    )


def write_report(out: Path, cfg, metrics: dict, slam_map, slam_poses, stamps, est, gt_map, particles) -> Path:
    """``metrics``: the pipeline's, with the SLAM and NOF stages' figures (pipeline.stage_summary)."""
    plot_map(out / "map.png", slam_map, slam_poses, est, gt_map, particles)
    loc = metrics.get("localization")
    if gt_map is not None:
        plot_error(out / "error.png", stamps, est, gt_map, loc["time_to_converge_s"])
    slam = metrics["slam"]
    lines = [
        f"# Pipeline report: {cfg.exp}",
        "",
        f"- mapping log: `{metrics['mapping_log']}`; localized: {metrics['localized_log']}",
        f"- device: {metrics['device']}; GMapping with {cfg.slam.num_particles} particles, NOF preset "
        f"`{cfg.train.name}`, MCL with {cfg.mcl.num_particles} particles ({cfg.mcl.weighting})",
        "",
        "## Stages",
        "",
        "| stage | time (s) | output |",
        "|---|---|---|",
    ]
    where = {
        "slam": f"{slam['run']}/",
        "train": f"{metrics['nof']['run']}/",
        "nog": "nog/",
        "localize": "localization.tum",
    }
    for name, t in metrics["timing"].items():
        took = "skipped (up to date)" if t["skipped"] else f"{t['s']:.1f}"
        lines.append(f"| {name} | {took} | `{where.get(name, '')}` |")
    lines += [
        "",
        "## SLAM",
        "",
        f"{slam['processed_scans']} of {slam['scans']} scans processed, {slam['resamplings']} resamplings.",
    ]
    if slam["ate_rmse_m"] is not None:
        lines.append(
            f"Trajectory error against the mapping log's ground truth after a rigid alignment: "
            f"{slam['ate_rmse_m']:.3f} m RMSE (odometry {slam['odometry_ate_rmse_m']:.3f} m)."
        )
    if slam["relations_m"] is not None:
        lines.append(f"Relations metric: {slam['relations_m']:.3f} m.")
    lag = scan_lag_line(slam)
    if lag:
        lines.append(lag)
    lines += ["", "## Localization (global, from a uniform start)", ""]
    own = metrics.get("against_slam_poses")
    if own:  # the mapping log localized again: its SLAM poses of the same scans, in the map's frame
        lines += [
            f"Against the mapping log's own SLAM poses (no alignment): {own['verdict']}."
            + (f" **{own['failure']}**" if own.get("failure") else ""),
            "",
        ]
    if metrics.get("failure"):
        lines += [f"**{metrics['failure']}**", ""]
    if loc is None:
        lines.append("The localized log has no ground truth: the estimate is in map.png, not scored.")
    else:
        lines += [
            f"- converged: {'after ' + _fmt(loc['time_to_converge_s'], ' s', 1) if loc['converged'] else 'no'}",
            f"- location RMSE after convergence: {_fmt(loc['location_rmse_cm'], ' cm', 1)}, yaw RMSE "
            f"{_fmt(loc['yaw_rmse_deg'], ' deg')}",
            f"- success (IR-MCL: converged within 60 s, RMSE < 0.3 m): {loc['success']}",
            "- scored in the SLAM map frame: the ground truth is moved there by the rigid alignment of the "
            f"mapping log's SLAM trajectory to its ground truth ({np.round(metrics['T_groundtruth_map'], 3).tolist()})",
            "",
            "![position error](error.png)",
        ]
    lines += ["", "![map, trajectories and final particles](map.png)", ""]
    path = out / "report.md"
    atomic_write_bytes(path, "\n".join(lines).encode())
    return path
