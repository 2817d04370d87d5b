"""CUDA-only checks (marker ``gpu``; run on a lent GPU by eval/gpu/tests.sh, skipped elsewhere): a SLAM run
replays its seed bit for bit, and a short NOF training on the GPU learns the walls. The kernels' CUDA
parity with their twins is the regular kernel tests run with IRMCL_TEST_DEVICE=cuda:0."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from irmcl_warp.config import register

pytestmark = pytest.mark.gpu
CONF = Path(__file__).resolve().parents[1] / "conf"


def _cfg(*overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("config", overrides=["device=cuda:0", *overrides])


def test_slam_on_cuda_replays_its_seed(tmp_path, monkeypatch):
    from irmcl_warp.slam.stage import run_slam

    cfg = _cfg("+exp=gmapping_sim", "sim.duration_s=90", "slam.num_particles=30", "slam.seed=3")
    runs = []
    for k in range(2):
        (tmp_path / str(k)).mkdir()
        monkeypatch.chdir(tmp_path / str(k))
        out = run_slam(cfg)
        runs.append(((out / "trajectory.tum").read_bytes(), json.loads((out / "metrics.json").read_text())))
    assert runs[0][0] == runs[1][0]  # the same trajectory, byte for byte
    (_, a), (_, b) = runs
    assert a["resamplings"] == b["resamplings"] and a["trajectory"] == b["trajectory"]
    assert a["trajectory"]["ate_rmse_m"] < 0.5 * a["trajectory_odometry"]["ate_rmse_m"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["device"] == "cuda:0" and "NVIDIA" in manifest["device_name"]  # which card, not only cuda:0


@pytest.mark.parametrize(
    "preset", ["fast", "guided", "minute", "graph"]
)  # graph: added in the 23rd session, not yet run
def test_short_training_on_cuda_learns_the_walls(tmp_path, monkeypatch, preset):
    import torch

    from irmcl_warp.config import ModelConfig
    from irmcl_warp.nof.model import NOF
    from irmcl_warp.nof.render import make_renderer, render_scans
    from irmcl_warp.nof.stage import run_train
    from irmcl_warp.services.data import prepare_beams
    from irmcl_warp.services.metrics import scan_synthesis_metrics

    monkeypatch.chdir(tmp_path)
    cfg = _cfg(
        "+exp=sim_office",
        f"train={preset}",
        "sim.duration_s=120",
        "train.epochs=2",
        "train.steps_per_epoch=200",
        "train.val_scans=8",
        "train.max_time_s=null",
    )
    torch.manual_seed(0)
    val = prepare_beams(cfg)["val"].subset(np.arange(8))
    untrained = NOF(ModelConfig(**cfg.model)).cuda().eval()
    pred = render_scans(untrained, val, make_renderer("warp"), 256, 0.02, 20.0, device=torch.device("cuda"))
    mae_untrained = scan_synthesis_metrics(pred, val.ranges_m, val.valid, val.angles_rad)["mae_m"]
    metrics = json.loads((run_train(cfg) / "metrics.json").read_text())
    assert metrics["device"].startswith("cuda") and metrics["epochs_done"] == 2
    assert metrics["val"]["mae_m"] < 0.3 * mae_untrained, (metrics["val"]["mae_m"], mae_untrained)
    if cfg.train.sampler == "occupancy":  # the grid skipped samples: most of them where the field also ends the beams
        share = 0.5 if cfg.train.grid_end == "field" else 0.75
        assert metrics["history"][-1]["samples_per_beam"] < share * cfg.train.num_samples, metrics["history"][-1]


def test_a_wide_global_start_repeats_itself_and_one_stream(monkeypatch):
    """300k particles spread over the simulator's free space (above 2^18: the wide reductions and the ordered scan),
    the step as one CUDA graph: two runs with the estimate on a second stream give the same estimates, N_eff and
    particles as each other and as a run on one stream (ParticleFilter._normalise)."""
    from irmcl_warp.kernels.motion import odometry_step
    from irmcl_warp.mcl import MCLConfig
    from irmcl_warp.mcl.filter import ParticleFilter
    from irmcl_warp.services.filters import WeightingMaps, build_filter
    from irmcl_warp.sim import simulate
    from eval.bench.mcl import simulator_nog

    cfg = _cfg("sim.duration_s=6")
    log, _ = simulate(cfg.sim, "cuda:0")
    nog = simulator_nog(0.1, "cuda:0")
    corner = (nog.origin_xy[0] - nog.resolution_m / 2, nog.origin_xy[1] - nog.resolution_m / 2)
    maps = WeightingMaps(nog=nog, occupancy=nog.occupancy, origin_xy=corner, resolution_m=nog.resolution_m)
    runs = []
    for second in (True, True, False):
        monkeypatch.setattr(ParticleFilter, "SECOND_STREAM", second)
        mc = MCLConfig(num_particles=300_000, weighting="likelihood_field", seed=11, step_graph="on")
        pf = build_filter(mc, nog, log.T_base_laser, log.info.angles_rad, 10.0, "cuda:0", maps)
        pf.init_uniform()
        out = [pf.step(odometry_step(log.odom[k - 1], log.odom[k]), log.ranges_m[k]) for k in range(1, len(log))]
        assert (pf._side is not None) == second
        runs.append((np.array([o[0] for o in out]), np.array([o[1] for o in out]), pf.particles.numpy()))
    assert (runs[0][1] < 0.5 * 300_000).any(), "resampled at least once"
    for other in runs[1:]:
        for a, b in zip(runs[0], other):
            assert np.array_equal(a, b)


def _trainer(tmp_path, *overrides):
    import torch

    from tests.test_nof import sim_trainer

    cfg = _cfg(
        "+exp=sim_office",
        "sim.duration_s=40",
        "train=quick",
        "train.batch_rays=256",
        "train.num_samples=64",
        "render.num_samples=64",
        "train.val_scans=2",
        "train.fused_adam=true",
        *overrides,
    )
    torch.manual_seed(0)
    return sim_trainer(cfg, tmp_path)


def test_a_captured_training_step_does_what_the_launched_one_does(tmp_path, monkeypatch):
    """train.step_graph: with nothing random in a step (the uniform sampler, fixed depths), 12 replays of the
    captured step give the losses 12 launched steps give and leave the weights where they leave them (the warm-up
    steps of the capture undone), and the schedule's learning rate reaches the captured Adam. Left out of the
    comparison: the biases of the layers batch norm follows and its running means, which track them. Batch norm
    removes those biases, so their gradient is rounding noise, and Adam turns noise into steps of the learning rate's
    size in either direction."""
    import torch

    monkeypatch.chdir(tmp_path)
    runs = {}
    for graph in (False, True):
        tr = _trainer(
            tmp_path / str(graph),
            "train.perturb=false",
            "train.lr_schedule=cosine",
            "train.warmup_steps=4",
            f"train.step_graph={str(graph).lower()}",
        )
        gen = torch.Generator().manual_seed(1)
        losses = []
        for k in range(12):
            tr.step_in_epoch = k
            losses.append(float(tr.step(torch.randint(len(tr.ranges), (256,), generator=gen).cuda())))
        state = {k: v.detach().clone() for k, v in tr.model.state_dict().items()}
        runs[graph] = (state, float(tr.opt.param_groups[0]["lr"]), losses)
    (eager, lr_eager, loss_eager), (graphed, lr_graphed, loss_graphed) = runs[False], runs[True]
    assert lr_graphed == pytest.approx(lr_eager, rel=1e-6) and lr_eager > 0
    assert loss_graphed == pytest.approx(loss_eager, rel=1e-3) and loss_eager[-1] < loss_eager[0]
    noise = {f"{k[: -len('1.running_mean')]}0.bias" for k in eager if k.endswith(".1.running_mean")}
    compared = [k for k in eager if k not in noise and not k.endswith(("running_mean", "num_batches_tracked"))]
    assert "head.0.0.weight" in compared and "out.bias" in compared and "head.0.0.bias" not in compared
    for k in compared:
        torch.testing.assert_close(graphed[k].float(), eager[k].float(), rtol=1e-3, atol=1e-4)
    fresh = _trainer(tmp_path / "fresh").model.state_dict()["out.weight"].cuda()
    assert not torch.equal(eager["out.weight"], fresh)


def test_a_captured_guided_step_reads_the_grid_as_it_changes(tmp_path, monkeypatch):
    """train.step_graph with the occupancy sampler and a fixed count: the grid is read outside the graph, in place,
    so the captured pick follows it (the share of kept samples cut changes as the grid prunes), and validation finds
    a field."""
    import torch

    monkeypatch.chdir(tmp_path)
    tr = _trainer(
        tmp_path,
        "train.sampler=occupancy",
        "train.grid_end=none",
        "train.fixed_samples=16",
        "train.grid_every=5",
        "train.grid_threshold=0.05",
        "train.step_graph=true",
        "train.epochs=1",
        "train.steps_per_epoch=120",
    )
    tr.run_epoch()
    h = tr.history[-1]
    cuts = torch.stack(tr.cut).cpu()
    assert tr.step_graph is not None and h["samples_per_beam"] == 16
    assert len(set(cuts.tolist())) > 10 and h["grid_occupied_share"] < 1.0
    losses = h["loss"]
    assert np.isfinite(losses) and h["val"]["mae_m"] < 2.0
