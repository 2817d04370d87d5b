"""The authors'-IR-MCL runner's plumbing (eval/reference/irmcl.py), without their code: our field goes out under
their layer names and computes the same occupancy in a network laid out as theirs (the paper's network:
Linear/BatchNorm/ReLU x 4, skip, x 4, Linear + sigmoid, named layer1 / layer2 / occ_out); a log window goes
out in their sequence format; their printed summary is read back."""

import json

import numpy as np
import torch
from omegaconf import OmegaConf
from torch import nn

import eval.reference.irmcl as ref
from irmcl_warp.config import SimConfig
from irmcl_warp.nof.model import NOF
from irmcl_warp.sim import simulate


class TheirLayout(nn.Module):
    """The NOF as their checkpoint names it (ours re-laid out; written here from the paper's description)."""

    def __init__(self, width=256, freqs=10):
        super().__init__()
        d = 2 + 4 * freqs
        block = lambda i, o: [nn.Linear(i, o), nn.BatchNorm1d(o), nn.ReLU()]  # noqa: E731
        self.layer1 = nn.Sequential(*sum([block(d if k == 0 else width, width) for k in range(4)], []))
        self.layer2 = nn.Sequential(*sum([block(d + width if k == 0 else width, width) for k in range(4)], []))
        self.occ_out = nn.Sequential(nn.Linear(width, 1), nn.Sigmoid())

    def forward(self, g):
        return self.occ_out(self.layer2(torch.cat([g, self.layer1(g)], -1))).squeeze(-1)


def test_our_field_computes_the_same_occupancy_under_their_names(tmp_path):
    torch.manual_seed(0)
    ours = NOF()
    for m in ours.modules():  # running statistics that differ from the defaults, so that they must travel too
        if isinstance(m, nn.BatchNorm1d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    ours.eval()
    pt = tmp_path / "nof.pt"
    torch.save({"model": ours.state_dict(), "model_config": ours.config_dict()}, pt)
    ckpt = ref.their_checkpoint(pt)
    assert all(k.startswith("nof.") for k in ckpt["state_dict"])
    theirs = TheirLayout()
    missing = theirs.load_state_dict({k[4:]: v for k, v in ckpt["state_dict"].items()}, strict=True)
    assert not missing.missing_keys and not missing.unexpected_keys
    theirs.eval()
    xy = torch.rand(500, 2) * 40 - 20
    with torch.no_grad():
        np.testing.assert_allclose(theirs(ours.encoding(xy)).numpy(), ours(xy).numpy(), rtol=1e-5, atol=1e-6)


def test_a_field_of_another_shape_is_refused(tmp_path):
    from irmcl_warp.config import ModelConfig

    small = NOF(ModelConfig(width=64))
    pt = tmp_path / "nof.pt"
    torch.save({"model": small.state_dict(), "model_config": small.config_dict()}, pt)
    try:
        ref.their_checkpoint(pt)
    except ValueError as e:
        assert "256 wide" in str(e) and str(pt) in str(e)
    else:
        raise AssertionError("a 64-wide field went out as theirs")


def test_a_window_goes_out_in_their_sequence_format(tmp_path):
    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=10.0, num_beams=24, width_m=12, height_m=8)), "cpu")
    log.T_base_laser = np.array([0.1, 0.0, 0.2])
    log.ground_truth[:3] = np.nan  # the window's first scans without ground truth: they start at the 4th
    log.ranges_m[5, 2] = np.nan  # a no-return beam
    log.ranges_m[6, 3] = 55.0  # beyond the far bound
    idx = np.arange(0, 20)
    first = ref.export_start(log, idx, 30.0, tmp_path)
    assert first == 3
    doc = json.loads((tmp_path / "seq.json").read_text())
    assert doc["num_beams"] == 24 and doc["max_range"] == 30.0 and len(doc["scans"]) == 20
    assert np.isclose(doc["angle_min"], log.info.angles_rad[0]) and np.isclose(
        doc["angle_res"], np.diff(log.info.angles_rad).mean()
    )
    s = doc["scans"]
    assert s[0]["timestamp"] == 0.0 and np.isclose(s[7]["timestamp"], log.stamps[7] - log.stamps[0])
    # no-return and too-far beams at max_range, which their loader drops (>= max_range -> 0)
    assert s[5]["range_reading"][2] == 30.0 and s[6]["range_reading"][3] == 30.0
    np.testing.assert_allclose(s[4]["range_reading"], np.round(log.ranges_m[4], 3), atol=1e-6)
    np.testing.assert_allclose(s[8]["pose_gt"], log.ground_truth[8])
    np.testing.assert_allclose(s[8]["odom_reading"], log.odom[8])
    T = np.loadtxt(tmp_path / "b2l.txt")
    np.testing.assert_allclose(T[:2, 3], [0.1, 0.0])
    np.testing.assert_allclose(np.arctan2(T[1, 0], T[0, 0]), 0.2)
    gt = np.loadtxt(tmp_path / "gt.tum")
    assert len(gt) == 17 and np.isclose(gt[0, 0], log.stamps[3] - log.stamps[0])


def test_their_printed_summary_and_step_times_are_read_back():
    text = (
        "finished frame 1 at timestamp 0.20s with time cost: 0.010s\nfinished frame 2 at timestamp 0.40s with time "
        "cost: 0.030s\nfinished frame 3 at timestamp 0.60s with time cost: 0.020s\n  location_rmse\t  location_ptc5\t"
        " ...\n           5.56\t 49.18\t 98.36\t 100.00\t 0.68\t 54.64\t 85.79\t 98.91\t\n"
    )
    out = ref.parse_their_log(text)
    assert np.isclose(out["their_ms_per_frame_median"], 20.0)
    assert out["their_summary"]["location_rmse_cm"] == 5.56 and out["their_summary"]["yaw_rmse_deg"] == 0.68
    # their evaluation failing after the header leaves no summary instead of a wrong one
    broken = ref.parse_their_log("  location_rmse\t location_ptc5\nTraceback (most recent call last):\n")
    assert "their_summary" not in broken


def test_a_split_goes_out_as_their_dataset_reads_it(tmp_path):
    """Their loader takes transform_matrix[:2, :3] as [R | t] and marks beams >= max_range invalid."""
    from irmcl_warp.nof.beams import BeamSet

    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-5, 5, 4), rng.uniform(-5, 5, 4), rng.uniform(-3, 3, 4)])
    ranges = rng.uniform(0.5, 9.0, (4, 7)).astype(np.float32)
    ranges[1, 2] = np.nan
    valid = np.isfinite(ranges)
    valid[2, 5] = False  # a beam ours does not score
    angles = np.linspace(-1.5, 1.5, 7)
    ref.export_split(BeamSet(np.arange(4.0), poses, ranges, angles, valid, "test"), 10.0, tmp_path / "test.json")
    doc = json.loads((tmp_path / "test.json").read_text())
    n = len(np.arange(doc["angle_min"], doc["angle_max"], doc["angle_res"]))  # their directions
    assert n == 7 and doc["max_range"] == 10.0
    for (x, y, yaw), scan, r, v in zip(poses, doc["scans"], ranges, valid):
        Rt = np.asarray(scan["transform_matrix"])[:2, :3]
        np.testing.assert_allclose(Rt, [[np.cos(yaw), -np.sin(yaw), x], [np.sin(yaw), np.cos(yaw), y]], atol=1e-12)
        got = np.asarray(scan["range_readings"])
        np.testing.assert_allclose(got[v], r[v], atol=1e-4)
        assert (got[~v] >= doc["max_range"]).all()  # invalid there
