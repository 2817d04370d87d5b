"""Bag reader on corrupted input; relations, matched CSV, splits and g2o files on small cases."""

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from omegaconf import OmegaConf

from irmcl_warp.services.metrics import relations_error
from irmcl_warp.config import SimConfig
from irmcl_warp.geometry import relative
from irmcl_warp.io import LogFormatError, read_bag, read_g2o, read_matched_csv, read_relations, read_splits, write_bag
from irmcl_warp.io.groundtruth import Relations
from irmcl_warp.sim import simulate


@pytest.fixture(scope="module")
def sim_bag(tmp_path_factory):
    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=4.0, num_beams=30, width_m=12, height_m=8)), "cpu")
    return write_bag(log, tmp_path_factory.mktemp("bag") / "sim.bag"), log


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(frac=st.floats(0.05, 0.95))
def test_truncated_bag_is_a_clear_error(sim_bag, tmp_path, frac):
    path, _ = sim_bag
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * frac)])
    with pytest.raises(LogFormatError, match="cut.bag"):
        read_bag(cut)


def test_bag_without_laser_topic_and_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such bag"):
        read_bag(tmp_path / "none.bag")
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 100)
    with pytest.raises(LogFormatError, match="junk.bag"):
        read_bag(junk)


def test_relations_metric_is_zero_on_exact_poses_and_sees_an_offset(rng):
    poses = np.c_[np.cumsum(rng.normal(0, 1, (40, 2)), 0), rng.uniform(-np.pi, np.pi, 40)]
    stamps = 10.0 + np.arange(40) * 0.5
    i, j = rng.integers(0, 40, 30), rng.integers(0, 40, 30)
    rel = Relations(stamps[i], stamps[j], relative(poses[i], poses[j]))
    m = relations_error(stamps, poses, rel)
    assert m["trans_abs_mean_m"] < 1e-9 and m["relations_used"] == 30
    moved = poses.copy()
    moved[20:, 0] += 1.0  # a 1 m jump half way, in the world frame
    crossing = (i < 20) != (j < 20)
    m2 = relations_error(stamps, moved, rel)
    assert m2["trans_abs_mean_m"] == pytest.approx(crossing.mean(), abs=1e-9)


def test_relations_stamps_unmatched_are_counted():
    rel = Relations(np.array([1.0, 5.0]), np.array([2.0, 6.0]), np.zeros((2, 3)))
    m = relations_error(np.array([1.0, 2.0]), np.zeros((2, 3)), rel)
    assert m["relations_used"] == 1 and m["relations_unmatched"] == 1


def test_file_errors_name_file_and_line(tmp_path):
    p = tmp_path / "r.relations"
    p.write_text("1 2 0 0 0 0 0 0\n1 2 3\n")
    with pytest.raises(LogFormatError, match="r.relations, line 2: expected 8 values"):
        read_relations(p)
    c = tmp_path / "m.csv"
    c.write_text("# c\nbag_scan_index,ipc_stamp,x,y,theta\n1,2.0,0,0,0\n2,3.0,zz,0,0\n")
    with pytest.raises(LogFormatError, match="m.csv, line 4: matched pose: expected a number, found 'zz'"):
        read_matched_csv(c)
    c.write_text("a,b\n")
    with pytest.raises(LogFormatError, match="expected header"):
        read_matched_csv(c)
    s = tmp_path / "s.json"
    s.write_text(json.dumps({"train": [1.0], "val": [2.0], "test": []}))
    with pytest.raises(LogFormatError, match="split 'test' missing or empty"):
        read_splits(s)
    g = tmp_path / "x.g2o"
    g.write_text("EDGE_SE2 0 1 1 0 0\n")
    with pytest.raises(LogFormatError, match="no VERTEX_SE2"):
        read_g2o(g)


def test_g2o_reader(tmp_path):
    g = tmp_path / "x.g2o"
    g.write_text(
        "VERTEX_SE2 0 1 2 0.5\nVERTEX_SE2 1 2 2 0.5\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"
        "ROBOTLASER1 0 -1.5 3.1 0.01 50 0.1 0 2 1.0 1.0 0 0 0 0 0 0 0 0 0 0 0 0 12.25 h 0\n"
    )
    graph = read_g2o(g)
    np.testing.assert_array_equal(graph.vertex_ids, [0, 1])
    assert graph.edges.shape == (1, 5) and graph.laser_stamps.tolist() == [12.25]


def test_a_bag_scan_s_odometry_is_read_at_its_stamp_plus_the_offset(sim_bag, rng):
    """data.scan_time_offset_s on a bag: the odometry messages interpolated at each scan's stamp plus the offset
    (the simulator's bag holds one message per scan, at its stamp), the first scans clamped and counted."""
    from irmcl_warp.geometry import interpolate_poses, wrap_angle
    from irmcl_warp.io import LogDefectWarning

    path, _ = sim_bag
    plain = read_bag(path)
    offset = float(rng.uniform(-0.3, -0.02))
    with pytest.warns(LogDefectWarning, match="before the first or after the last odometry; clamped"):
        shifted = read_bag(path, scan_time_offset_s=offset)
    want = interpolate_poses(plain.stamps, plain.odom, plain.stamps + offset)
    np.testing.assert_allclose(shifted.odom[:, :2], want[:, :2], atol=1e-6)
    np.testing.assert_allclose(wrap_angle(shifted.odom[:, 2] - want[:, 2]), 0.0, atol=1e-6)
    assert np.abs(shifted.odom - plain.odom).max() > 1e-3  # (the offset moved them)
