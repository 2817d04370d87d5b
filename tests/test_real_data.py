"""The readers and the relations metric on the real logs of ../shared/data (IRMCL_DATA)."""

import warnings

import numpy as np
import pytest

from irmcl_warp.services.metrics import relations_error
from irmcl_warp.io import read_bag, read_carmen, read_matched_csv, read_relations
from irmcl_warp.io.rosbag import read_bag_extrinsic

pytestmark = pytest.mark.data


def quiet(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **k)


@pytest.mark.parametrize(
    "log, scans, beams",
    [
        ("kuemmerle2009/derived/fr079.revfix.clf.gz", 4934, 360),
        ("kuemmerle2009/derived/intel.fileorder.clf.gz", 13631, 180),
        ("kuemmerle2009/mit-csail.clf.gz", 1988, 361),
    ],
)
def test_carmen_logs_counts(data_dir, log, scans, beams):
    L = quiet(read_carmen, data_dir / log)
    assert (len(L), L.info.num_beams) == (scans, beams)
    assert 0.9 < L.valid.mean() < 1.0  # no-return beams masked, most beams kept


def test_intel_stamp_defect_is_detected_in_both_files(data_dir):
    derived = quiet(read_carmen, data_dir / "kuemmerle2009/derived/intel.fileorder.clf.gz")
    assert derived.defects.counts["scans_stamps_backwards"] == 631
    bag = quiet(read_bag, data_dir / "kuemmerle2009/bags/intel.bag")
    assert bag.defects.counts["scans_stamps_backwards"] == 631
    assert bag.defects.counts["odom_stamps_backwards"] == 602
    assert len(bag) == 13631


def test_fr079_bag_odometry_contradicts_its_velocity(data_dir):
    bag = quiet(read_bag, data_dir / "kuemmerle2009/bags/fr079.bag")
    assert len(bag) == 4934 and bag.info.num_beams == 360
    assert bag.defects.counts["odometry_contradicts_velocity"] > 300  # the README: 328 reversing steps
    np.testing.assert_allclose(read_bag_extrinsic(data_dir / "kuemmerle2009/bags/fr079.bag"), [0.04, 0, 0], atol=1e-6)


def test_fr079_bag_repaired_on_reading_equals_the_derived_log(data_dir):
    """data.repair_reversing rebuilds, from the bag's own velocities, the odometry of derived/fr079.revfix."""
    from irmcl_warp.geometry import relative
    from irmcl_warp.types import match_stamps

    bag = quiet(read_bag, data_dir / "kuemmerle2009/bags/fr079.bag", repair_reversing=True)
    ref = quiet(read_carmen, data_dir / "kuemmerle2009/derived/fr079.revfix.clf.gz")
    idx = match_stamps(bag.stamps, ref.stamps)
    assert (idx >= 0).all() and bag.defects.counts["odometry_steps_reversed"] > 300
    got, want = bag.odom[idx], ref.odom
    np.testing.assert_allclose(
        relative(got[:-1], got[1:]), relative(want[:-1], want[1:]), atol=1e-5
    )  # the log prints 6 decimals


def test_relations_of_fr079_against_corrected_poses_and_odometry(data_dir):
    stamps, poses = read_matched_csv(data_dir / "corrected/matched/fr079.gmapping_corrected_keyframes.csv")
    assert len(stamps) == 4791
    rel = read_relations(data_dir / "kuemmerle2009/relations/fr079.relations")
    m = relations_error(stamps, poses, rel)
    assert m["relations_used"] == 1672
    assert abs(m["trans_abs_mean_m"] - 0.058) <= 0.005
    odo = quiet(read_carmen, data_dir / "kuemmerle2009/derived/fr079.revfix.clf.gz")
    assert relations_error(odo.stamps, odo.odom, rel)["trans_abs_mean_m"] > 2.0  # several metres


def test_killian_relations_match_only_through_g2o_stamps(data_dir):
    from irmcl_warp.io import read_g2o
    from irmcl_warp.types import match_stamps

    g = read_g2o(data_dir / "kuemmerle2009/killian.g2o.zip")
    rel = read_relations(data_dir / "kuemmerle2009/relations/mit-killian.relations")
    both = (match_stamps(g.laser_stamps, rel.t1) >= 0) & (match_stamps(g.laser_stamps, rel.t2) >= 0)
    assert both.sum() == 658


@pytest.mark.parametrize(
    "name, count, backwards, repeated",
    [("fr079", 1685, 0, 4), ("intel", 2984, 6, 0), ("mit-csail", 1172, 0, 1), ("mit-killian", 4677, 0, 4)],
)
def test_every_real_file_reads_with_its_known_oddities_reported(data_dir, name, count, backwards, repeated):
    """Every relations, split and ground-truth file of the shared data reads; what is odd in it is warned about
    (intel's 6 relations whose t1 is later than t2: its logger's clock steps back), not refused."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rel = read_relations(data_dir / f"kuemmerle2009/relations/{name}.relations")
    said = " ".join(str(w.message) for w in caught)
    assert len(rel) == count
    assert (f"{backwards} relations whose t1 is later than t2" in said) == bool(backwards)
    assert (f"{repeated} relations given more than once" in said) == bool(repeated)
    assert int(np.sum(rel.t1 > rel.t2)) == backwards
    if name != "mit-killian":
        from irmcl_warp.io import read_splits

        splits = read_splits(data_dir / f"splits/{name}.json")
        stamps, _ = quiet(read_matched_csv, data_dir / f"corrected/matched/{name}.gmapping_corrected_keyframes.csv")
        assert set(np.round(splits["test"], 6)) <= set(np.round(stamps, 6))


@pytest.mark.parametrize(
    "log, reader, truth",
    [
        ("kuemmerle2009/bags/mit-csail.bag", read_bag, "corrected/matched/mit-csail.gmapping_corrected_keyframes.csv"),
        ("kuemmerle2009/mit-csail.clf.gz", read_carmen, "corrected/matched/mit-csail.gmapping_corrected_keyframes.csv"),
        (
            "kuemmerle2009/derived/fr079.revfix.clf.gz",
            read_carmen,
            "corrected/matched/fr079.gmapping_corrected_keyframes.csv",
        ),
    ],
)
def test_the_freiburg_recordings_scans_read_late_against_their_odometry(data_dir, log, reader, truth):
    """The GMapping-corrected poses, stamped as the scans they pose, turn as the odometry did 0.13 s before the
    stamps in mit-csail (bag and CARMEN log alike) and fr079; intel's do not (below). The lag names the setting, and
    with it applied the turns line up (what conf/data/mit_csail.yaml and fr079.yaml set)."""
    from irmcl_warp.io.clock import estimate_clock_offset, scan_lag_note

    raw = quiet(reader, data_dir / log)
    stamps, poses = read_matched_csv(data_dir / truth)
    c = estimate_clock_offset(raw.stamps, raw.odom, stamps, poses)
    assert c.convincing and -0.15 < c.offset_s < -0.11
    assert "data.scan_time_offset_s=-0.1" in scan_lag_note(raw.stamps, raw.odom, stamps, poses)
    shifted = quiet(reader, data_dir / log, scan_time_offset_s=round(c.offset_s, 3))
    assert scan_lag_note(shifted.stamps, shifted.odom, stamps, poses, round(c.offset_s, 3)) is None


def test_intel_s_scans_are_not_said_to_read_late(data_dir):
    from irmcl_warp.io.clock import scan_lag_note

    raw = quiet(read_carmen, data_dir / "kuemmerle2009/derived/intel.fileorder.clf.gz")
    stamps, poses = read_matched_csv(data_dir / "corrected/matched/intel.gmapping_corrected_keyframes.csv")
    assert scan_lag_note(raw.stamps, raw.odom, stamps, poses) is None
