"""The released-GMapping runner's plumbing, with a stand-in for the built driver: the log goes out in the driver's
format, the driver's best path comes back at the processed scans, and it is scored like our own runs (a pose at
every scan from the last processed pose plus odometry; the relations on the laser's path)."""

import stat
import sys

import numpy as np
from omegaconf import OmegaConf

import eval.reference.gmapping as ref
from irmcl_warp.config import SimConfig
from irmcl_warp.geometry import compose, relative
from irmcl_warp.sim import simulate

FAKE = """#!{python}
import sys
import numpy as np
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
    rel_file.write_text("".join(f"{log.stamps[a]:.6f} {log.stamps[a + 6]:.6f} {m[0]:.6f} {m[1]:.6f} 0 0 0 {m[2]:.6f}\n"
                                for a, m in zip(k, motion)))
    fake = tmp_path / "gmapping_replay"
    fake.write_text(FAKE.format(python=sys.executable))
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    (tmp_path / "COMMIT").write_text("fake 0\n")
    monkeypatch.setattr(ref, "BINARY", fake)
    cfg = OmegaConf.create({"data": {"name": "sim", "relations_path": str(rel_file), "relation_stamps_path": None}})
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
