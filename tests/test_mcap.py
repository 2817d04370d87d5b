"""Runs and bags that open in ROS tools: an own-map localization writes replay/replay.mcap, read back here with an
independent decoder (mcap-ros2-support, not rosbags which wrote it) with every topic AMCL's users look for; bags
we write latch /tf_static (ROS 1) or offer it transient local (ROS 2), name their storage file after the bag, and
can be MCAP."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from irmcl_warp.config import SimConfig, register
from irmcl_warp.geometry import compose as compose_poses
from irmcl_warp.io import read_bag, read_tum, write_bag
from irmcl_warp.io.mcap_run import TOPICS
from irmcl_warp.mapping import build_map, save_map
from irmcl_warp.mcl.stage import run_localize
from irmcl_warp.sim import simulate

CONF = Path(__file__).resolve().parents[1] / "conf"
SMALL = dict(width_m=14.0, height_m=10.0, duration_s=25.0)


def _read_all(mcap_file: Path) -> dict:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    by_topic = defaultdict(list)
    with open(mcap_file, "rb") as f:
        for schema, channel, message, ros_msg in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            by_topic[channel.topic].append((message.log_time, ros_msg, schema.name))
    return by_topic


def _yaw(q) -> float:
    return float(np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2)))


def test_a_localization_run_reads_back_from_its_mcap_with_every_topic(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    log, _ = simulate(OmegaConf.structured(SimConfig(**SMALL)), "cpu")
    grid = build_map(log, log.ground_truth, resolution_m=0.05, far_m=20.0, device="cpu")
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
                "mcl.num_particles=3000",
                "localize.run_s=null",
                "mcl.update_min_trans_m=0.1",
            ],
        )
    out = run_localize(cfg)
    got = _read_all(out / "replay" / "replay.mcap")
    assert set(got) == set(TOPICS)
    types = {t: {s for _, _, s in v} for t, v in got.items()}
    assert types["/map"] == {"nav_msgs/msg/OccupancyGrid"} and types["/amcl_pose"] == {
        "geometry_msgs/msg/PoseWithCovarianceStamped"
    }
    assert types["/particlecloud"] == {"geometry_msgs/msg/PoseArray"} and types["/scan"] == {
        "sensor_msgs/msg/LaserScan"
    }

    ((_, grid_msg, _),) = got["/map"]
    H, W = grid.shape
    data = np.asarray(grid_msg.data, np.int8).reshape(H, W)
    assert (grid_msg.info.width, grid_msg.info.height) == (W, H) and set(np.unique(data)) <= {-1, 0, 100}
    assert np.array_equal(data == 100, grid.known & (grid.probability > 0.65))  # row 0 at the origin, as the grid

    stamps, est = read_tum(out / "trajectory.tum")
    poses = got["/amcl_pose"]
    assert len(poses) == len(stamps)
    amcl = np.array(
        [[p.pose.pose.position.x, p.pose.pose.position.y, _yaw(p.pose.pose.orientation)] for _, p, _ in poses]
    )
    assert np.allclose(amcl[:, :2], est[:, :2], atol=2e-6) and np.allclose(np.cos(amcl[:, 2] - est[:, 2]), 1.0)
    covs = np.array([np.asarray(p.pose.covariance).reshape(6, 6) for _, p, _ in poses])
    assert np.any(covs[:, 0, 0] > 0) and np.all(covs[:, 0, 0] >= 0) and np.allclose(covs, covs.transpose(0, 2, 1))

    # map -> odom composed with odom -> base_link is the estimate: what RViz shows the robot at
    tf = defaultdict(dict)
    for ns, msg, _ in got["/tf"]:
        for t in msg.transforms:
            tf[(t.header.frame_id, t.child_frame_id)][ns] = [
                t.transform.translation.x,
                t.transform.translation.y,
                _yaw(t.transform.rotation),
            ]
    map_odom, odom_base = tf[("map", "odom")], tf[("odom", "base_link")]
    ns = sorted(map_odom)[len(map_odom) // 2]
    base = compose_poses(np.array(map_odom[ns])[None], np.array(odom_base[ns])[None])[0]
    k = int(np.argmin(np.abs(stamps - ns * 1e-9)))
    assert np.allclose(base[:2], est[k, :2], atol=1e-5)
    ((_, static, _),) = got["/tf_static"]
    assert static.transforms[0].child_frame_id == "laser"
    assert len(got["/particlecloud"]) >= 30 and all(len(m.poses) > 0 for _, m, _ in got["/particlecloud"])
    assert len(got["/ground_truth"]) == len(stamps) and len(got["/scan"]) == len(got["/odom"]) == len(stamps)


@pytest.mark.parametrize("version, storage", [(1, "sqlite3"), (2, "sqlite3"), (2, "mcap")])
def test_bags_we_write_latch_tf_static_and_name_their_storage_after_the_bag(tmp_path, version, storage):
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability

    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=3.0, num_beams=20, width_m=12, height_m=8)), "cpu")
    bag = write_bag(log, tmp_path / ("drive.bag" if version == 1 else "drive"), version=version, storage=storage)
    if version == 2:
        assert sorted(p.name for p in bag.iterdir()) == sorted(
            ["metadata.yaml", f"drive.{'db3' if storage == 'sqlite3' else 'mcap'}"]
        )
        assert not list(tmp_path.glob(".*"))  # no partial left behind
    with AnyReader([bag]) as reader:
        (static,) = [c for c in reader.connections if c.topic == "/tf_static"]
        if version == 1:
            assert static.ext.latching == 1
        else:
            assert [q.durability for q in static.ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        (scan,) = [c for c in reader.connections if c.topic == "/scan"]
        assert (scan.ext.latching if version == 1 else list(scan.ext.offered_qos_profiles)) in (None, 0, [])
    back = read_bag(bag)
    assert np.array_equal(np.nan_to_num(back.ranges_m, nan=-1), np.nan_to_num(log.ranges_m, nan=-1))
    assert np.allclose(back.T_base_laser, log.T_base_laser)
    assert np.allclose(back.ground_truth, log.ground_truth)  # the simulator's truth travels on /ground_truth
    if storage == "mcap":
        assert set(_read_all(bag / "drive.mcap")) == {"/tf_static", "/scan", "/odom", "/tf", "/ground_truth"}


def test_a_ros1_bag_cannot_be_mcap(tmp_path):
    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=2.0, num_beams=20, width_m=12, height_m=8)), "cpu")
    with pytest.raises(ValueError, match="storage=mcap needs version=2"):
        write_bag(log, tmp_path / "x.bag", version=1, storage="mcap")
