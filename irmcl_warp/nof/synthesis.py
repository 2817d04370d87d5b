"""The synthesis stage, ``python -m irmcl_warp.synthesis +exp=<name>``: scan synthesis on the test split (IR-MCL Table I protocol).

Every method renders the same test beams from the ground-truth laser poses:
* the NOF of the finished training run of these settings (``train=<preset>``: its nof.pt), ``render.num_samples``
  fixed depths over [near, far];
* occupancy grid maps built from the training split's scans and poses at 5 and 10 cm (log-odds mapping),
  rendered by ray casting (RAYCAST["dda"]); a cell never observed stops the beam, as in AMCL's
  map_calc_range, and a beam leaving the map returns ``far``.
Writes outputs/<exp>/synthesis/<preset>-<id>/metrics.json (one entry per method) and scan.png (one test scan).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from irmcl_warp.mapping import integrate_scans
from irmcl_warp.nof.beams import BeamSet
from irmcl_warp.nof.checkpoint import load_nof
from irmcl_warp.nof.render import make_renderer, render_scans
from irmcl_warp import runs
from irmcl_warp.services.data import far_bound_m, load_stream, prepare_beams
from irmcl_warp.services.metrics import scan_synthesis_metrics
from irmcl_warp.services.outputs import save_figure
from irmcl_warp.kernels import RAYCAST, pick_device

GRID_RESOLUTIONS_M = (0.05, 0.10)  # IR-MCL compares with occupancy grids at 5 and 10 cm


def grid_ranges(train: BeamSet, test: BeamSet, resolution_m: float, far_m: float, cfg, device) -> np.ndarray:
    m = cfg.mapping
    grid = integrate_scans(
        train.T_map_laser,
        train.ranges_m,
        train.angles_rad,
        resolution_m=resolution_m,
        far_m=far_m,
        l_occ=m.l_occ,
        l_free=m.l_free,
        l_min=m.l_min,
        l_max=m.l_max,
        kernel=m.kernel,
        device=device,
    )
    occupancy = np.where(grid.known, grid.probability, 1.0)  # unknown stops the beam (AMCL)
    caster = RAYCAST.build(
        "dda",
        occupancy=occupancy,
        origin_xy=grid.origin_xy,
        resolution_m=resolution_m,
        far_m=far_m,
        occ_threshold=cfg.raycast.occ_threshold,
        device=device,
    )
    return caster.cast_numpy(test.T_map_laser, test.angles_rad)


def nof_ranges(path: Path, test: BeamSet, cfg):
    import torch  # the stage imports torch only for the NOF rows

    device = torch.device(pick_device(cfg.device))
    model, meta = load_nof(path, device)
    r = cfg.render
    renderer = make_renderer(r.name, normalize=r.normalize, t_min=r.t_min)
    pred = render_scans(model, test, renderer, r.num_samples, meta["near_m"], meta["far_m"], r.chunk_rays, device)
    return pred, meta


def plot_scan(path: Path, test: BeamSet, preds: dict, k: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))
    a, v = test.angles_rad, test.valid[k]
    meas = test.ranges_m[k]
    ax.scatter(meas[v] * np.cos(a[v]), meas[v] * np.sin(a[v]), s=4, c="k", label="measured")
    for name, pred in preds.items():
        ax.scatter(pred[k][v] * np.cos(a[v]), pred[k][v] * np.sin(a[v]), s=2, label=name)
    ax.plot(0, 0, "r^")
    ax.set_aspect("equal")
    ax.set_title(f"test scan {k} (stamp {test.stamps[k]:.3f}), laser frame [m]")
    ax.legend(markerscale=4, fontsize=8)
    save_figure(fig, path)


def run_synthesis(cfg) -> Path:
    with runs.start(cfg, "synthesis") as run:
        return run.path if run.done else score_scans(run)


def score_scans(run: runs.Run) -> Path:
    cfg, out = run.cfg, run.dir
    device = pick_device(cfg.device)
    sets = prepare_beams(cfg)
    train, test, far_m = sets["train"], sets["test"], far_bound_m(cfg, load_stream(cfg).info.range_max_m)
    preds, methods = {}, {}
    nof_path = run.upstream["train"] / "nof.pt"
    t0 = time.time()
    pred, meta = nof_ranges(nof_path, test, cfg)
    name = f"NOF ({meta.get('train_preset', '?')})"
    preds[name] = pred
    methods[name] = {
        "kind": "nof",
        "render_s": time.time() - t0,
        "checkpoint": str(nof_path),
        "best_epoch": meta.get("epoch"),
    }
    for res in GRID_RESOLUTIONS_M:
        name = f"OGM {res * 100:.0f} cm"
        t0 = time.time()
        preds[name] = grid_ranges(train, test, res, far_m, cfg, device)
        methods[name] = {"kind": "grid", "resolution_m": res, "render_s": time.time() - t0}
    for name, pred in preds.items():
        methods[name].update(scan_synthesis_metrics(pred, test.ranges_m, test.valid, test.angles_rad))
    result = {
        "dataset": cfg.data.name,
        "split": test.name,
        "train_split": train.name,
        "test_scans": len(test),
        "far_m": far_m,
        "device": device,
        "methods": methods,
    }
    plot_scan(out / "scan.png", test, preds, k=len(test) // 2)
    path = run.finish(result, device)
    print(
        f"{cfg.data.name}, {test.name} ({len(test)} scans): "
        + "; ".join(f"{n}: MAE {m['mae_m']:.3f} m, acc {m['accuracy_pct']:.1f} %" for n, m in methods.items())
    )
    return path
