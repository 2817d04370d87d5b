"""The released-GMapping runner's plumbing, with a stand-in for the built driver: the log goes out in the driver's
format, the driver's best path comes back at the processed scans, and it is scored like our own runs (a pose at
every scan from the last processed pose plus odometry; the relations on the laser's path)."""

import json
import stat
import sys

import numpy as np
import pytest
from omegaconf import OmegaConf

import eval.reference.gmapping as ref
from eval.results.queries import TOOL, reference_variant, released_errors
from irmcl_warp import runs
from irmcl_warp.config import SimConfig
from irmcl_warp.geometry import compose, relative
from irmcl_warp.sim import simulate

FAKE = """#!{python}
import sys
import numpy as np
import pytest
rows = [l.split() for l in open(sys.argv[1])]
t = np.array([float(r[0]) for r in rows]); p = np.array([[float(v) for v in r[1:4]] for r in rows])
n = np.array([int(r[4]) for r in rows]); assert (n == n[0]).all() and all(len(r) == 5 + n[0] for r in rows)
keep = np.arange(0, len(t), 5)  # 'processed' scans: the driver reports the laser's true poses there
truth = np.loadtxt(sys.argv[1] + ".truth")
np.savetxt(sys.argv[2], np.column_stack([t[keep], truth[keep]]), fmt="%.9f")
np.savetxt(sys.argv[3], np.column_stack([t[keep], np.full(len(keep), 12.0)]), fmt="%.6f")
args = dict(a.split("=") for a in sys.argv[4:])
assert args["seed"] == "4" and float(args["maxRange"]) > 0, args
"""


def test_runner_scores_the_drivers_path_like_our_own_runs(tmp_path, monkeypatch):
    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=20.0, num_beams=24, width_m=12, height_m=8)), "cpu")
    log.T_base_laser = np.array([0.1, 0.0, 0.0])
    laser_truth = compose(log.ground_truth, log.T_base_laser)
    k = np.arange(0, len(log) - 6, 3)
    rel_file = tmp_path / "sim.relations"
    motion = relative(laser_truth[k], laser_truth[k + 6])
    rel_file.write_text(
        "".join(
            f"{log.stamps[a]:.6f} {log.stamps[a + 6]:.6f} {m[0]:.6f} {m[1]:.6f} 0 0 0 {m[2]:.6f}\n"
            for a, m in zip(k, motion)
        )
    )
    fake = tmp_path / "gmapping_replay"
    fake.write_text(FAKE.format(python=sys.executable))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    (tmp_path / "COMMIT").write_text("fake 0\n")
    monkeypatch.setattr(ref, "BINARY", fake)
    cfg = OmegaConf.create(
        {"exp": "sim", "data": {"name": "sim", "relations_path": str(rel_file), "relation_stamps_path": None}}
    )
    scans = tmp_path / "scans.txt"
    ref.export_scans(log, scans)
    np.savetxt(str(scans) + ".truth", laser_truth, fmt="%.9f")
    m = ref.run_seed(cfg, log, scans, 3, {"maxRange": "19.99", "maxUrange": "10"}, tmp_path)
    assert m["run"] == "30p-maxUrange10-seed3" and m["processed_scans"] == len(range(0, len(log), 5))
    # true poses at the processed scans, odometry in between: the error is the odometry's over < 5 scans
    r = m["relations"]
    assert r["relations_used"] == len(k) and r["relations_unmatched"] == 0
    assert r["trans_abs_mean_m"] < 0.05
    odometry_only = ref.relations_error(log.stamps, compose(log.odom, log.T_base_laser), ref.read_relations(rel_file))
    assert r["trans_abs_mean_m"] < odometry_only["trans_abs_mean_m"]
    # the no-return beams go out as the log's no-return value, every beam of every scan
    first = scans.read_text().splitlines()[0].split()
    assert int(first[4]) == 24 and len(first) == 5 + 24
    # a run with the log's data config overridden is a variant of its own: its own folder, not in the default rows
    other = ref.run_seed(
        cfg,
        log,
        scans,
        3,
        {"maxRange": "19.99", "maxUrange": "10"},
        tmp_path,
        data_overrides=["data.laser_offset=[0,0,0]"],
    )
    assert other["run"] == "30p-maxUrange10-laser_offset0_0_0-seed3" and other["data_overrides"] == [
        "data.laser_offset=[0,0,0]"
    ]
    runs = {("sim", r["run"]): r for r in (m, other)}
    assert len(released_errors(runs, "sim", variant="maxUrange=10")) == 1
    assert len(released_errors(runs, "sim", variant="maxUrange=10, data.laser_offset=[0,0,0]")) == 1


def test_neff_check_reads_the_released_resamplings_from_its_post_resampling_trace(tmp_path):
    """The released driver logs N_eff after resampling (a resampled scan reads N); ours logs it before, with a
    resampled flag. Two released runs (3 and 1 resamplings) against two of ours (2 and 2), found by their
    settings: a run of ours with another beam layout and a released run with other settings are left out."""
    from runfakes import composed, fake_run

    traces = {0: [30, 22.5, 30, 18.0, 30, 30], 1: [30, 25.0, 30, 21.0, 19.5, 17.0]}
    neff = "scan,neff,resampled,match_rounds\n" + "".join(
        f"{k},{v},{int(v < 15)},3\n" for k, v in enumerate([29.0, 12.0, 24.0, 11.0, 20.0])
    )
    for seed, values in traces.items():
        d = runs.tool_dir("gmapping_intel", TOOL, f"30p-seed{seed}", seed, tmp_path)
        d.mkdir(parents=True)
        np.savetxt(d / "neff.txt", np.column_stack([np.arange(len(values)), values]), fmt="%.6f")
        (d / "metrics.json").write_text(
            json.dumps({"particles": 30, "settings": {}, "data_overrides": [], "run": d.name})
        )
        cfg = composed("+exp=gmapping_intel", "slam.proposal=gmapping_code", f"slam.seed={seed}")
        fake_run(tmp_path, "slam", cfg, {}, {"neff.csv": neff})
    other = composed("+exp=gmapping_intel", "slam.proposal=gmapping_code", "data.laser_offset=[0,0,0]")
    fake_run(tmp_path, "slam", other, {}, {"neff.csv": neff.replace("24.0", "2.0")})
    d = runs.tool_dir("gmapping_intel", TOOL, "30p-delta0.1-seed0", "delta", tmp_path)
    d.mkdir(parents=True)
    np.savetxt(d / "neff.txt", np.column_stack([np.arange(3), [30, 30, 30]]), fmt="%.6f")
    (d / "metrics.json").write_text(json.dumps({"particles": 30, "settings": {"delta": 0.1}, "run": d.name}))
    r = ref.neff_check("gmapping_intel", outputs=tmp_path)
    assert sorted(r["resamplings_released"]) == [1, 3] and r["resamplings_ours"] == [2, 2]
    assert r["scans_released"] == 6 and r["scans_ours"] == 6  # 2 + 4 not resampled; 3 + 3 of ours
    assert r["neff_quartiles_ours"][1] == 24.0 and 0 <= r["neff_ks_p"] <= 1


def test_gfs_path_is_read_from_gfs2logs_odom_lines(tmp_path):
    """gfs2log's CARMEN log: one ODOM line per reading (the start, stamped 0, dropped; a stamp given twice
    keeps its last pose); a broken line is an error naming the file and the line; its runs form their own
    variant, apart from the wrapper replay's runs."""
    f = tmp_path / "best.log"
    f.write_text(
        "ODOM 0 0 0 0 0 0 0.000000 pippo 0\nNEFF 29.5 0 pippo 0\n"
        "ODOM 1.0 2.0 0.5 0 0 0 10.250000 pippo 10.25\nROBOTLASER1 0 0\n"
        "ODOM 1.5 2.0 0.6 0 0 0 10.500000 pippo 10.5\nODOM 1.6 2.1 0.7 0 0 0 10.500000 pippo 10.5\n"
    )
    stamps, poses = ref.read_gfs_path(f)
    assert stamps.tolist() == [10.25, 10.5] and poses.tolist() == [[1.0, 2.0, 0.5], [1.6, 2.1, 0.7]]
    f.write_text("ODOM 1.0 2.0 0.5 0 0 0 10.25 pippo 10.25\nODOM 1.0 x 0.5\n")
    with pytest.raises(ValueError, match="best.log, line 2"):
        ref.read_gfs_path(f)
    assert reference_variant({"tool": "gfs_nogui", "settings": {}}) == "gfs"
    assert reference_variant({"settings": {}}) == ""


FAKE_GFS = """#!{python}
import sys
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
assert args["-randseed"] == "5" and open(args["-filename"]).readline().startswith("FLASER"), args
open(args["-outfilename"], "w").write("stand-in\\n")
open("rawpath.dat", "w").write("x\\n")
print("DONE!")
"""
FAKE_GFS2LOG = """#!{python}
import sys
import numpy as np
truth = np.loadtxt({truth!r})
stamps = np.loadtxt({stamps!r})
with open(sys.argv[2], "w") as out:
    out.write("ODOM 0 0 0 0 0 0 0.000000 pippo 0\\n")
    for t, (x, y, a) in zip(stamps{cut}, truth):
        out.write(f"ODOM {{x:.6f}} {{y:.6f}} {{a:.6f}} 0 0 0 {{t:.6f}} pippo {{t:.6f}}\\n")
        out.write("NEFF 20.0 0 pippo 0\\n")
"""


def test_gfs_runner_scores_the_tools_path_and_names_a_log_it_does_not_cover(tmp_path, monkeypatch):
    """--gfs plumbing with stand-ins for gfs_nogui and gfs2log: the tool reads the plain-text log in its own
    folder, seeded with seed + 1; the best path comes back from gfs2log's ODOM lines and is scored on the
    relations like our runs; its scratch files are removed. A path that misses scans of the log is an error
    naming the file, not a partial score."""
    import gzip

    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=12.0, num_beams=16, width_m=12, height_m=8)), "cpu")
    k = np.arange(0, len(log) - 4, 2)
    rel_file = tmp_path / "sim.relations"
    motion = relative(log.ground_truth[k], log.ground_truth[k + 4])
    rel_file.write_text(
        "".join(
            f"{log.stamps[a]:.6f} {log.stamps[a + 4]:.6f} {m[0]:.6f} {m[1]:.6f} 0 0 0 {m[2]:.6f}\n"
            for a, m in zip(k, motion)
        )
    )
    clf = tmp_path / "sim.clf.gz"
    clf.write_bytes(gzip.compress(b"FLASER 16 " + b"1.0 " * 16 + b"0 0 0 0 0 0 1.0 host 1.0\n"))
    np.savetxt(tmp_path / "truth.txt", log.ground_truth, fmt="%.9f")
    np.savetxt(tmp_path / "stamps.txt", log.stamps, fmt="%.6f")
    for name, text in (
        ("gfs_nogui", FAKE_GFS.format(python=sys.executable)),
        (
            "gfs2log",
            FAKE_GFS2LOG.format(
                python=sys.executable, truth=str(tmp_path / "truth.txt"), stamps=str(tmp_path / "stamps.txt"), cut=""
            ),
        ),
    ):
        (tmp_path / name).write_text(text)
        (tmp_path / name).chmod(0o755)
    (tmp_path / "COMMIT").write_text("fake 0\n")
    monkeypatch.setattr(ref, "GFS", tmp_path / "gfs_nogui")
    monkeypatch.setattr(ref, "GFS2LOG", tmp_path / "gfs2log")
    monkeypatch.setattr(ref, "BINARY", tmp_path / "gmapping_replay")
    cfg = OmegaConf.create(
        {
            "exp": "sim",
            "data": {
                "name": "sim",
                "format": "carmen",
                "path": str(clf),
                "relations_path": str(rel_file),
                "relation_stamps_path": None,
            },
        }
    )
    out = tmp_path / "runs"
    out.mkdir()
    plain = ref.gfs_log(cfg, out)  # the log in plain text, once for every seed
    assert plain.read_bytes() == gzip.decompress(clf.read_bytes())
    m = ref.run_gfs_seed(cfg, log, plain, 4, out)
    assert m["run"] == "gfs-30p-seed4" and m["randseed"] == 5 and m["tool"] == "gfs_nogui"
    assert m["processed_scans"] == len(log) and m["relations"]["trans_abs_mean_m"] < 1e-4  # the true path back
    folder = runs.tool_dir("sim", TOOL, "gfs-30p-seed4", {"tool": "gfs_nogui", "seed": 4}, out)
    assert folder.is_dir() and not list(folder.glob("*.dat"))  # its own folder, scratch removed
    # a path that misses the last scans: an error naming gfs2log's file (a finished run is kept, not run again)
    (tmp_path / "gfs2log").write_text(
        FAKE_GFS2LOG.format(
            python=sys.executable, truth=str(tmp_path / "truth.txt"), stamps=str(tmp_path / "stamps.txt"), cut="[:-3]"
        )
    )
    assert ref.run_gfs_seed(cfg, log, plain, 4, out) == m
    (folder / "metrics.json").unlink()
    with pytest.raises(RuntimeError, match="best.log: poses at"):
        ref.run_gfs_seed(cfg, log, plain, 4, out)
    with pytest.raises(ValueError, match="gfs_nogui reads CARMEN logs"):
        ref.gfs_log(OmegaConf.create({"data": {"name": "sim", "format": "sim"}}), out)
