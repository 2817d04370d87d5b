"""eval.analyses.own_slam_map: a log localized in its own SLAM map is scored against the SLAM poses in the map's
frame, so a filter that settled on a look-alike place and followed the robot there fails (a fitted alignment
would have called it right), and the README's table is made from its records."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from eval.analyses.own_slam_map import main as score
from eval.report.tables import own_slam_map_table
from irmcl_warp.io import write_tum


def _run(folder, stamps, poses, seed, confidence):
    folder.mkdir(parents=True)
    write_tum(folder / "trajectory.tum", stamps, poses)
    (folder / "metrics.json").write_text(
        json.dumps({"confidence_at_end": confidence, "localized_at_end": confidence >= 0.8})
    )
    (folder / "manifest.json").write_text(json.dumps({"device": "cpu", "wall_time_s": 1.0}))
    OmegaConf.save(
        OmegaConf.create({"mcl": {"seed": seed, "num_particles": 2000, "weighting": "likelihood_field"}}),
        folder / "config.yaml",
    )
    return folder


def test_a_run_on_a_look_alike_place_fails_where_an_alignment_would_pass_it(tmp_path, rng):
    t = np.arange(0.0, 60.0, 0.2)
    path = np.column_stack([np.cos(t / 10) * 5, np.sin(t / 10) * 3, t / 10 + np.pi / 2])  # the SLAM poses
    slam = tmp_path / "slam"
    slam.mkdir()
    write_tum(slam / "trajectory.tum", t, path)
    OmegaConf.save(OmegaConf.create({"data": {"name": "toy"}}), slam / "config.yaml")
    right = path + rng.normal(0, 0.03, path.shape)
    right[:20] += [3.0, -2.0, 1.0]  # a global start: wrong for 4 s, then right
    shifted = path + [4.0, 0.0, 0.0]  # the same path, 4 m along: a look-alike place followed to the end
    runs = [_run(tmp_path / "a", t, right, 0, 0.9), _run(tmp_path / "b", t, shifted, 1, 0.95)]
    out = tmp_path / "own.json"
    rows = score(["--slam", str(slam), "--runs", *map(str, runs), "--out", str(out)])
    good, wrong = rows
    assert good["success"] and 3.5 < good["time_to_converge_s"] < 5.0 and good["location_rmse_cm"] < 6
    assert not wrong["success"] and not wrong["converged"] and abs(wrong["error_at_end_m"] - 4.0) < 1e-4
    rec = json.loads(out.read_text())
    assert rec["log"] == "toy" and (rec["successes"], rec["of"]) == (1, 2)
    table = own_slam_map_table([rec])
    # both said localized at the end; the one 4 m along the look-alike path was wrong; no per-scan confidence here
    assert "| toy | likelihood field | 2k | cpu | 2 (0,1) | 1/2 |" in table and table.endswith(
        "| 2/2 | 1 | - | - / - | - |"  # no calibration judged these runs
    )


def test_a_record_names_the_calibration_that_judged_its_runs():
    """eval.analyses.own_slam_map.calibration_of_run: the own-map calibration's digest in a run's manifest is the
    shipped file's: named with what it was fitted on (its source: the tuning runs); a digest of a file since fitted again: named by its
    digest; none (no calibration, or a run made before the digest): None. The table shows it per record."""
    from eval.analyses.own_slam_map import calibration_of_run
    from irmcl_warp.config import own_map_calibration
    from irmcl_warp.runs import OWN_MAP_CALIBRATION, file_digest

    cfg = OmegaConf.create({"mcl": {"num_particles": 20000, "weighting": "likelihood_field"}})
    shipped = own_map_calibration("likelihood_field", 20000)
    source = json.loads(shipped.read_text())["source"]
    now = {"inputs": {OWN_MAP_CALIBRATION: [{"path": str(shipped), "sha256": file_digest(shipped)}]}}
    assert calibration_of_run(now, cfg) == f"{shipped.name} ({source})" and "tuning-" in source
    since = {"inputs": {OWN_MAP_CALIBRATION: [{"path": str(shipped), "sha256": "ab" * 32}]}}
    assert calibration_of_run(since, cfg) == "sha256 ababababab"
    assert calibration_of_run({"inputs": {}}, cfg) is None and calibration_of_run({}, cfg) is None
    row = {"seed": 0, "particles": 20000, "weighting": "likelihood_field", "device": "cpu", "time_to_converge_s": 3.0}
    row |= {"location_rmse_cm": 8.0, "localized_at_end": True, "error_at_end_m": 0.1, "calibration": "x.json"}
    rec = {"log": "toy", "runs": [row], "successes": 1, "of": 1}
    assert own_slam_map_table([rec]).endswith("| x.json |")


def test_a_record_names_the_lost_rule_its_runs_read_and_the_table_says_it():
    """eval.analyses.own_slam_map.lost_rule_of_run: the digest of conf/exp/worlds.yaml in a run's manifest is today's
    file: its rule's settings; a digest no version of the file has: the digest; none: None. The table names a re-seeding
    record's rule (two updates, the searched places, the particles kept)."""
    from eval.analyses.own_slam_map import RULE_SETTINGS, lost_rule_of_run
    from irmcl_warp.config import own_map_lost_rule_file, own_map_lost_rule_settings
    from irmcl_warp.runs import OWN_MAP_LOST_RULE, file_digest

    path = own_map_lost_rule_file()
    now = lost_rule_of_run({"inputs": {OWN_MAP_LOST_RULE: [{"path": str(path), "sha256": file_digest(path)}]}})
    w = own_map_lost_rule_settings()
    assert now == {k: w[k] for k in RULE_SETTINGS}
    unknown = lost_rule_of_run({"inputs": {OWN_MAP_LOST_RULE: [{"path": str(path), "sha256": "cd" * 32}]}})
    assert unknown == {"sha256": "cdcdcdcdcd"} and lost_rule_of_run({}) is None
    row = {"seed": 0, "particles": 20000, "weighting": "likelihood_field", "device": "cpu", "time_to_converge_s": 3.0}
    row |= {"location_rmse_cm": 8.0, "localized_at_end": True, "error_at_end_m": 0.1, "calibration": "x.json"}
    rule = {"lost_agreement_below": 0.4, "lost_agreement_updates": 2, "relocalize_places": 3}
    row |= {"relocalize": True, "lost_rule": {**rule, "relocalize_keeps_particles": True}}
    table = own_slam_map_table([{"log": "toy", "runs": [row], "successes": 1, "of": 1}])
    assert "re-seeded when lost (agreement < 0.4 for 2 updates, 3 searched places, keeping its particles)" in table
    row["lost_rule"] = None  # (a record before the rule was named)
    assert "re-seeded when lost |" in own_slam_map_table([{"log": "toy", "runs": [row], "successes": 1, "of": 1}])


def test_the_record_says_how_the_confidence_separates_right_scans_from_wrong(tmp_path, rng):
    """Per scan, the run's confidence (spread.csv) against whether the estimate lies within 0.5 m / 10 deg of the
    SLAM pose, pooled over the runs: a confidence high exactly where the estimate is right has AUROC 1, the same
    numbers turned upside down 0; scans before the first update (NaN) are left out."""
    t = np.arange(0.0, 40.0, 0.2)
    path = np.column_stack([t / 4, np.zeros_like(t), np.zeros_like(t)])
    slam = tmp_path / "slam"
    slam.mkdir()
    write_tum(slam / "trajectory.tum", t, path)
    OmegaConf.save(OmegaConf.create({"data": {"name": "toy"}}), slam / "config.yaml")
    est = path + rng.normal(0, 0.02, path.shape)
    wrong = rng.random(len(t)) < 0.3
    est[wrong, 0] += 2.0  # 2 m off on these scans
    good_conf = np.where(wrong, rng.uniform(0.0, 0.3, len(t)), rng.uniform(0.6, 1.0, len(t)))
    good_conf[:5] = np.nan  # before the filter's first update
    for name, conf in (("fits", good_conf), ("upside_down", 1.0 - good_conf)):
        run = _run(tmp_path / name, t, est, 0, 0.9)
        lines = "".join(f"{s:.6f},0.1,1000,{c:.4f}\n" for s, c in zip(t, conf))
        (run / "spread.csv").write_text("stamp,spread_m,particles,confidence\n" + lines)
        out = tmp_path / f"{name}.json"
        score(["--slam", str(slam), "--runs", str(run), "--out", str(out)])
        judged = json.loads(out.read_text())["confidence"]
        assert judged["scans"] == len(t) - 5 and judged["scans_right"] == int((~wrong[5:]).sum())
        assert judged["auroc"] == (1.0 if name == "fits" else 0.0), f"seed {rng.seed}"
        assert "scan_confidence" not in json.loads(out.read_text())["runs"][0]  # pooled, not kept per scan


def test_a_lost_event_on_a_right_estimate_is_a_false_alarm():
    """false_alarms counts the lost events whose last scan before held an estimate right by the SLAM pose; an event
    after wrong scans, or before any estimate, is no false alarm; a run without the record has None."""
    from eval.analyses.own_slam_map import false_alarms

    stamps = np.arange(0.0, 10.0, 1.0) + 100.0
    ref = np.zeros((10, 3))
    est = np.zeros((10, 3))
    est[5:8, 0] = 3.0  # wrong from 5 s to 7 s
    est[0] = np.nan  # no estimate at the first scan
    assert false_alarms([0.0, 3.5, 6.0, 8.5], stamps, est, ref) == 2  # 3.5 (right at 3 s), 8.5 (right at 8 s)
    assert false_alarms([], stamps, est, ref) == 0 and false_alarms(None, stamps, est, ref) is None


def test_false_alarms_are_counted_per_hour_of_right_tracking():
    """Issue 33 counts false alarms per hour of good tracking: a run right for a quarter of its scans contributes a
    quarter of its hours; runs without the rule's record are left out, and none with it gives None."""
    from eval.analyses.own_slam_map import false_alarm_rate

    def run(log_s, right, judged, false, events, relocalize=False):
        return dict(
            log_s=log_s,
            scans_judged_right=right,
            scans_judged=judged,
            false_alarms=false,
            lost_at_s=[1.0] * events,
            relocalize=relocalize,
        )

    rows = [run(3600.0, 250, 1000, 1, 3), run(7200.0, 1000, 1000, 2, 2), dict(run(3600.0, 0, 10, 0, 0), lost_at_s=None)]
    rate = false_alarm_rate(rows)
    assert rate["hours"] == pytest.approx(3.0) and rate["hours_right"] == pytest.approx(2.25)
    assert rate["false"] == 3 and rate["events"] == 5 and rate["per_hour_right"] == pytest.approx(3 / 2.25)
    assert false_alarm_rate([rows[2]]) is None
