"""Figures the stages share: a localization run on its map, and the position error over time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from irmcl_warp.services.outputs import save_figure


def plot_run(path: Path, view, image: np.ndarray, stamps, gt, est, particles, converged_s=None, kidnap_s=None) -> None:
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


def _map_axes(ax, image: np.ndarray, extent) -> None:
    ax.imshow(1 - image, cmap="gray", vmin=0, vmax=1, origin="lower", extent=extent)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def plot_own_map(path: Path, image, extent, stamps, est, particles, spread_m, gt=None) -> None:
    """Left: the map with the estimated trajectory (and the ground truth where known) and the final
    particles; right: the particles' spread over time (how sure the filter is, with or without ground truth)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(14, 5.5), gridspec_kw={"width_ratios": [2.2, 1]})
    _map_axes(ax, image, extent)
    keep = np.random.default_rng(0).permutation(len(particles))[:3000]
    ax.plot(particles[keep, 0], particles[keep, 1], ".", color="tab:blue", ms=1, alpha=0.5, label="particles (end)")
    ax.plot(est[:, 0], est[:, 1], "-", color="tab:red", lw=1, label="estimate")
    if gt is not None:
        ok = np.all(np.isfinite(gt), axis=1)
        ax.plot(gt[ok, 0], gt[ok, 1], "-", color="tab:green", lw=1, label="ground truth")
    ax.legend(loc="upper right", fontsize=8, markerscale=2)
    t = np.asarray(stamps) - stamps[0]
    bx.semilogy(t, np.maximum(spread_m, 1e-3), "-", color="tab:blue", lw=1)
    bx.axhline(0.3, color="gray", lw=0.8, label="0.3 m")
    bx.set_xlabel("time since start (s)")
    bx.set_ylabel("particle spread (m)")
    bx.legend(fontsize=8)
    save_figure(fig, path)


def animate_particles(path: Path, image, extent, frames, stamps, est, fps: int = 8) -> None:
    """A GIF of the particles on the map (``frames``: [(t since start, xy [n, 2])]) with the estimate so far;
    written to a temporary file and renamed, as every output."""
    import os

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    t = np.asarray(stamps) - stamps[0]
    fig, ax = plt.subplots(figsize=(7, 5))
    _map_axes(ax, image, extent)
    (dots,) = ax.plot([], [], ".", color="tab:blue", ms=1.5, alpha=0.6)
    (line,) = ax.plot([], [], "-", color="tab:red", lw=1)
    title = ax.set_title("")

    def draw(k):
        tk, xy = frames[k]
        dots.set_data(xy[:, 0], xy[:, 1])
        upto = t <= tk
        line.set_data(est[upto, 0], est[upto, 1])
        title.set_text(f"{tk:.1f} s: {len(xy)} particles shown, estimate in red")
        return dots, line, title

    tmp = Path(path).with_name(f".{Path(path).name}.tmp.gif")
    FuncAnimation(fig, draw, frames=len(frames), blit=False).save(tmp, writer=PillowWriter(fps=fps), dpi=80)
    plt.close(fig)
    os.replace(tmp, path)
