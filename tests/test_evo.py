"""Our TUM files scored by evo (Grupp, github.com/MichaelGrupp/evo), the tool a reader checks us with: an own-map
run's trajectory.tum against the ground_truth.tum beside it, aligned as evo's --align from the time the run
says it settled, gives the figure in its metrics.json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import SimConfig, register
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.mcl.stage import run_localize
from irmcl_warp.sim import simulate

CONF = Path(__file__).resolve().parents[1] / "conf"
SMALL = dict(width_m=14.0, height_m=10.0, duration_s=40.0)


def test_evo_scores_an_own_map_run_as_its_metrics_say(tmp_path, monkeypatch):
    from evo.core import metrics, sync
    from evo.tools import file_interface

    monkeypatch.chdir(tmp_path)
    log, _ = simulate(OmegaConf.structured(SimConfig(**SMALL)), "cpu")
    grid = build_map(log, log.ground_truth, resolution_m=0.05, far_m=20.0, device="cpu")
    grid.origin_xy = (grid.origin_xy[0] - 3.0, grid.origin_xy[1] + 2.0)  # a map frame that is not the truth's
    files = save_map(grid, tmp_path / "office")
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[
                *(f"sim.{k}={v}" for k, v in SMALL.items()),
                f"localize.map_path={files['yaml']}",
                "device=cpu",
                "mcl.weighting=likelihood_field",
                "mcl.num_particles=4000",
                "localize.run_s=null",
            ],
        )
    out = run_localize(cfg)
    m = json.loads((out / "metrics.json").read_text())
    scored, whole = m["aligned_to_ground_truth"], m["aligned_whole_run"]
    assert scored["ate_rmse_m"] < 0.1 and scored["from_s"] >= 0  # scored from the convergence on ...
    assert whole["ate_rmse_m"] >= scored["ate_rmse_m"] - 1e-9  # ... the whole run reported beside it

    ref = file_interface.read_tum_trajectory_file(str(out / "ground_truth.tum"))
    est = file_interface.read_tum_trajectory_file(str(out / "trajectory.tum"))
    t0 = ref.timestamps[0]
    for traj in (ref, est):
        traj.reduce_to_time_range(t0 + scored["from_s"] - 1e-6)
    ref, est = sync.associate_trajectories(ref, est, max_diff=1e-4)
    assert est.num_poses == scored["poses"]
    est.align(ref, correct_scale=False)  # evo_ape tum ground_truth.tum trajectory.tum --align
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    assert np.isclose(ape.get_statistic(metrics.StatisticsType.rmse), scored["ate_rmse_m"], atol=1e-5)


def test_an_own_map_run_is_scored_from_its_convergence_in_another_frame():
    """A trajectory in a frame of its own (a SLAM map's), 3 m off for its first 12 s, then within centimetres:
    scored from the scan where it converged (the protocol's 0.5 m for 5 s), the transient only in the whole-run
    figure."""
    from irmcl_warp.geometry import compose
    from irmcl_warp.mcl.own_map import converged_index
    from irmcl_warp.services.metrics import aligned_error

    rng = np.random.default_rng()
    t = 100.0 + np.arange(0, 60, 0.2)
    gt = np.column_stack([np.cos(t / 9) * 6, np.sin(t / 7) * 4, np.unwrap(t / 5) % (2 * np.pi) - np.pi])
    T_map_gt = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(-np.pi, np.pi)])
    est = compose(T_map_gt, gt) + np.column_stack([rng.normal(0, 0.02, (len(t), 2)), np.zeros(len(t))])
    lost = t - t[0] < 12.0
    est[lost, :2] += rng.uniform(2.5, 3.5, (lost.sum(), 2))
    s = converged_index(t, est, gt)
    assert s == int(lost.sum())
    assert aligned_error(est[s:], gt[s:])["ate_rmse_m"] < 0.05 < 1.0 < aligned_error(est, gt)["ate_rmse_m"]
    est[:, :2] += rng.uniform(2.5, 3.5, (len(t), 2)) * (np.arange(len(t)) % 2)[:, None]  # never settles
    assert converged_index(t, est, gt) is None
