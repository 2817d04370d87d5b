"""The pipeline end to end on a small simulated office: every stage's artifact, the frame tie between the
SLAM map and the ground truth, the report, and a second run that skips what is finished."""

import json
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import register
from irmcl_warp.io import read_tum
from irmcl_warp.sim import simulate

CONF = Path(__file__).resolve().parents[1] / "conf"
SMALL = [
    "sim.duration_s=40",
    "sim.width_m=14",
    "sim.height_m=10",
    "device=cpu",
    "slam.num_particles=4",
    "train.max_time_s=8",
    "train.val_scans=4",
    "train.steps_per_epoch=40",
    "mcl.num_particles=2000",
    "mcl.reduce_to=500",
    "mcl.num_samples=64",
    "pipeline.run_s=15",
]


def test_pipeline_on_a_small_simulated_office(tmp_path, monkeypatch, capsys):
    from irmcl_warp.pipeline import run_pipeline

    monkeypatch.chdir(tmp_path)
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("pipeline", overrides=SMALL)
    out = run_pipeline(cfg)
    m = json.loads((out / "metrics.json").read_text())
    # SLAM beat its odometry, and the NOF was trained on the SLAM poses of the processed scans
    assert m["slam"]["ate_rmse_m"] < 0.5 * m["slam"]["odometry_ate_rmse_m"], m["slam"]
    trained = json.loads((out / "manifest.json").read_text())["stages"]["train"]["path"]
    posed = OmegaConf.load(Path(trained) / "config.yaml").data.train_poses_path
    stamps, poses = read_tum(posed)
    assert len(stamps) == m["training_scans"] == 200  # every scan, posed by SLAM (40 s at 5 Hz)
    # the simulator's odometry starts at zero, so the map frame sits at the first true pose
    first = simulate(cfg.sim, "cpu")[0].ground_truth[0]
    T = np.array(m["T_groundtruth_map"])
    assert np.hypot(*(T[:2] - first[:2])) < 0.2 and abs(np.angle(np.exp(1j * (T[2] - first[2])))) < np.radians(2), T
    # the localization covers the second drive's window and is scored
    assert len(read_tum(out / "localization.tum")[0]) == m["localized_scans"] == 76  # 15 s at 5 Hz, both ends
    assert m["localization"]["poses"] == m["localized_scans"]
    report = (out / "report.md").read_text()
    assert (
        all(f"| {s} |" in report for s in ("slam", "train", "nog", "localize"))
        and "![position error](error.png)" in report
    )
    assert (out / "map.png").stat().st_size > 10_000 and (out / "error.png").is_file()
    capsys.readouterr()
    # a second run finds everything finished; a removed NOF makes its stage and the pipeline run again
    run_pipeline(cfg)
    assert "pipeline up to date" in capsys.readouterr().out
    (out / "manifest.json").unlink()
    (Path(trained) / "nof.pt").unlink()
    run_pipeline(cfg)
    said = capsys.readouterr().out
    assert "[slam] up to date" in said and "redoing" in said and "[train] up to date" not in said
    # another second drive through the same office: the map and the NOF are the mapping log's, reused
    other = run_pipeline(_with(cfg, "pipeline.sim_path_seed", 2))
    said = capsys.readouterr().out
    assert other.name.startswith("sim_office-path2-") and other != out and (other / "localization.tum").is_file()
    assert "[slam] up to date" in said and "[train] up to date" in said


def _with(cfg, key, value):
    from omegaconf import OmegaConf

    new = OmegaConf.create(OmegaConf.to_container(cfg))
    OmegaConf.update(new, key, value, merge=False)
    return new


def test_pipeline_on_bags_without_a_far_bound(tmp_path, monkeypatch):
    """Your own bags (here two simulated drives written as ROS 1 bags), data.far_m left unset: every stage takes
    the sensor's range_max as the far bound, and the run records it (the error used to come after SLAM)."""
    from irmcl_warp.config import SimConfig
    from irmcl_warp.io import write_bag
    from irmcl_warp.pipeline import run_pipeline

    monkeypatch.chdir(tmp_path)
    sim = dict(duration_s=40.0, width_m=14.0, height_m=10.0, range_max_m=12.5)
    bags = [
        write_bag(simulate(OmegaConf.structured(SimConfig(**sim, path_seed=s)), "cpu")[0], tmp_path / f"d{s}.bag")
        for s in (0, 1)
    ]
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "pipeline",
            overrides=[o for o in SMALL if not o.startswith("sim.")]
            + ["data=bag", f"data.path={bags[0]}", f"pipeline.path={bags[1]}"],
        )
    assert cfg.data.far_m is None
    out = run_pipeline(cfg)
    m = json.loads((out / "metrics.json").read_text())
    assert m["localized_scans"] > 50 and m["localization"]["poses"] == m["localized_scans"]  # the bags carry the truth
    trained = json.loads((out / "manifest.json").read_text())["stages"]["train"]["path"]
    import torch

    assert (
        torch.load(Path(trained) / "nof.pt", map_location="cpu", weights_only=False)["far_m"] == 12.0
    )  # floor(range_max)
    assert (out / "localization.tum").is_file() and (out / "report.md").is_file()
    assert "against_slam_poses" not in m  # another drive: scored against its own truth only
    # the mapping log localized again (no pipeline.path; SLAM and NOF reused): scored against its own SLAM poses too
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        again = compose(
            "pipeline", overrides=[o for o in SMALL if not o.startswith("sim.")] + ["data=bag", f"data.path={bags[0]}"]
        )
    out2 = run_pipeline(again)
    own = json.loads((out2 / "metrics.json").read_text())["against_slam_poses"]
    assert own["poses"] == json.loads((out2 / "metrics.json").read_text())["localized_scans"]
    assert own["verdict"] in (out2 / "report.md").read_text()


def test_the_mapping_log_localized_again_is_scored_against_its_own_slam_poses(rng):
    """Issue 33: a pipeline that localizes its mapping log again compares the estimate with the SLAM poses it
    already holds (the same scans, the map's frame, no alignment); a run that followed a look-alike place 4 m
    along says so, with its distance at the end, where before it reported "no ground truth to score"."""
    from omegaconf import OmegaConf

    from irmcl_warp.pipeline import against_slam_poses, localizes_mapping_log

    t = np.arange(0.0, 80.0, 0.2)
    slam = np.column_stack([np.cos(t / 12) * 6, np.sin(t / 12) * 4, t / 12 + np.pi / 2])
    right = slam + rng.normal(0, 0.03, slam.shape)
    right[:25] += [5.0, 1.0, 0.5]  # the global start: 5 s off, then right
    good = against_slam_poses(t, right, slam)
    assert good["success"] and good["failure"] is None and "converged after" in good["verdict"]
    along = slam + [4.0, 0.0, 0.0]
    bad = against_slam_poses(t, along, slam)
    assert not bad["success"] and abs(bad["error_at_end_m"] - 4.0) < 1e-6
    assert "FAILED, 4.00 m from its own SLAM pose" in bad["verdict"] and "SLAM pose (" in bad["failure"]
    cfg = lambda path, fmt: OmegaConf.create({"pipeline": {"path": path}, "data": {"format": fmt}})  # noqa: E731
    assert localizes_mapping_log(cfg(None, "bag")) and not localizes_mapping_log(cfg("other.bag", "bag"))
    assert not localizes_mapping_log(cfg(None, "sim"))  # the simulator's second session is another drive


def test_the_report_says_when_slam_named_the_scans_late():
    from irmcl_warp.pipeline_report import scan_lag_line

    assert scan_lag_line({"scan_lag": None}) is None and scan_lag_line({}) is None
    line = scan_lag_line({"scan_lag": {"lag_s": -0.1394, "applied_s": -0.05, "warned": True}})
    assert "stamped 0.139 s late" in line and "data.scan_time_offset_s=-0.189" in line
