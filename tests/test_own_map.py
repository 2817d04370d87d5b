"""Your own log in your own map (localize.map_path): a bag without ground truth localized in a map_server
map, globally and from an initial pose, with trajectory, spread, plot and animation; map files read right or
refused loudly."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import SimConfig, register
from irmcl_warp.io import read_tum, write_bag
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.mapping.mapio import load_map
from irmcl_warp.mcl.stage import run_localize
from irmcl_warp.sim import simulate

CONF = Path(__file__).resolve().parents[1] / "conf"
SMALL = dict(width_m=14.0, height_m=10.0, duration_s=40.0)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A map_server map of a small office (from known poses) and a bag of a drive through it, no ground truth."""
    d = tmp_path_factory.mktemp("own")
    log, _ = simulate(OmegaConf.structured(SimConfig(**SMALL)), "cpu")
    files = save_map(build_map(log, log.ground_truth, resolution_m=0.05, far_m=20.0, device="cpu"), d / "office")
    bag = write_bag(dataclasses.replace(log, ground_truth=None), d / "drive.bag")  # a bag without the truth
    return d, files["yaml"], bag, log.ground_truth, log.stamps


def _cfg(bag, map_yaml, *overrides):
    register()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(
            "config",
            overrides=[
                "data=bag",
                f"data.path={bag}",
                f"localize.map_path={map_yaml}",
                "device=cpu",
                "mcl.weighting=likelihood_field",
                "localize.run_s=null",
                *overrides,
            ],
        )


@pytest.mark.parametrize("start", ["global", "pose"])
def test_a_bag_without_ground_truth_is_localized_in_a_map_server_map(world, tmp_path, monkeypatch, start):
    d, map_yaml, bag, truth, stamps = world
    monkeypatch.chdir(tmp_path)
    extra = (
        ["mcl.num_particles=4000"]
        if start == "global"
        else [
            "mcl.num_particles=500",
            f"localize.initial_pose=[{truth[0, 0] + 0.2},{truth[0, 1] - 0.2},{truth[0, 2] + 0.1}]",
        ]
    )
    out = run_localize(_cfg(bag, map_yaml, *extra))
    for name in ("trajectory.tum", "spread.csv", "run.png", "particles.gif", "metrics.json", "manifest.json"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    m = json.loads((out / "metrics.json").read_text())
    assert "aligned_to_ground_truth" not in m and m["scans"] == len(stamps)  # nothing to score against: no truth
    assert not (out / "ground_truth.tum").exists()
    st, est = read_tum(out / "trajectory.tum")
    err = np.hypot(*(est[:, :2] - truth[np.searchsorted(stamps, st), :2]).T)
    assert np.median(err[st - st[0] > 10]) < 0.1, np.median(err[st - st[0] > 10])  # the map is in the truth's frame
    assert m["final_spread_m"] < 0.3 and m["spread_below_0.3m_after_s"] is not None
    from PIL import Image

    assert Image.open(out / "particles.gif").n_frames >= 30


def test_map_files_are_read_right_or_refused(world, tmp_path):
    d, map_yaml, _, _, _ = world
    grid = load_map(map_yaml)
    text = Path(map_yaml).read_text()
    rotated = tmp_path / "rotated.yaml"
    rotated.write_text(
        text.replace("image: office.pgm", f"image: {d / 'office.pgm'}")
        .replace("origin: [", "origin: [")
        .replace(", 0.0]", ", 0.5]")
    )
    with pytest.raises(ValueError, match="rotated.yaml: origin yaw 0.5 is not supported"):
        load_map(rotated)
    missing = tmp_path / "missing.yaml"
    missing.write_text(text.replace("office.pgm", "nowhere.pgm"))
    with pytest.raises(FileNotFoundError, match="nowhere.pgm"):
        load_map(missing)
    import matplotlib.image

    png = tmp_path / "office.png"  # the same map as a PNG image: the same grid
    matplotlib.image.imsave(
        png,
        np.asarray(__import__("PIL.Image", fromlist=["Image"]).open(d / "office.pgm")),
        cmap="gray",
        vmin=0,
        vmax=255,
    )
    (tmp_path / "png.yaml").write_text(text.replace("office.pgm", "office.png"))
    again = load_map(tmp_path / "png.yaml")
    assert np.array_equal(np.sign(again.logodds), np.sign(grid.logodds)) and again.origin_xy == grid.origin_xy


def test_ground_truth_of_the_log_is_scored_after_alignment(world, tmp_path, monkeypatch):
    """A log with ground truth (the simulator) in a map of its own frame: scored after a rigid alignment, since
    a user's map need not share the ground truth's frame."""
    d, map_yaml, _, truth, _ = world
    monkeypatch.chdir(tmp_path)
    register()
    sim = [f"sim.{k}={v}" for k, v in SMALL.items()]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[
                "device=cpu",
                f"localize.map_path={map_yaml}",
                "localize.run_s=null",
                "mcl.weighting=likelihood_field",
                "mcl.num_particles=500",
                *sim,
                f"localize.initial_pose=[{truth[0, 0]},{truth[0, 1]},{truth[0, 2]}]",
            ],
        )
    m = json.loads((run_localize(cfg) / "metrics.json").read_text())
    assert m["aligned_to_ground_truth"]["poses"] == len(truth) and m["aligned_to_ground_truth"]["ate_rmse_m"] < 0.1
