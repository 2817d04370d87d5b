"""``python -m eval.bench mcl``'s table check: how far the range table's ranges lie from the march's on the
benchmark's particles, also when none of them sees a wall."""

from __future__ import annotations

import numpy as np
import warp as wp

from eval.bench.mcl import VARIANTS, table_error
from irmcl_warp.mcl import MCLConfig
from irmcl_warp.nog import NOG
from irmcl_warp.services.filters import WeightingMaps, build_filter
from tests.devices import DEVICE


def test_the_table_check_measures_the_ranges_and_says_when_no_ray_sees_a_wall(tmp_path, monkeypatch):
    """On a box the table's ranges lie within centimetres of the march's from its middle; with every particle far off the
    map (a long bench run's odometry drives the cloud 5 cm a step) no ray hits a wall and the check says so (rays 0)
    instead of failing on an empty quantile, as it did after 2000 steps on an H200 (thirty-fifth session)."""
    monkeypatch.setenv("IRMCL_CACHE_DIR", str(tmp_path))  # (the table's disk cache: this test's own)
    occ = np.zeros((40, 40), np.float32)
    occ[[0, -1], :] = occ[:, [0, -1]] = 1.0
    nog = NOG(occ, (0.0, 0.0), 0.1)
    cfg = MCLConfig(num_particles=64, num_samples=64, **{**VARIANTS["table"], "table_angles": 36, "step_graph": "off"})
    maps = WeightingMaps(nog=nog, occupancy=occ, origin_xy=(-0.05, -0.05), resolution_m=0.1)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 32).astype(np.float32)
    pf = build_filter(cfg, nog, (0.0, 0.0, 0.0), angles, 10.0, DEVICE, maps)
    rng = np.random.default_rng(1)
    centre = np.column_stack([rng.uniform(1.5, 2.4, 64), rng.uniform(1.5, 2.4, 64), rng.uniform(-3, 3, 64)])
    pf.set_particles(centre)
    near = table_error(pf, nog, cfg, 10.0, DEVICE)
    assert near["rays"] > 1000 and 0.0 < near["median"] < 0.15 and near["p90"] >= near["median"]  # (36 headings)
    pf.particles.assign(wp.array((centre + [500.0, 500.0, 0.0]).astype(np.float32), dtype=wp.vec3, device=DEVICE))
    assert table_error(pf, nog, cfg, 10.0, DEVICE) == {"median": None, "p90": None, "max": None, "rays": 0}


def test_the_host_split_times_each_part_of_a_captured_step():
    """``--host-split``: a captured step's parts timed apart (the step, its graph replayed and waited for, back to back,
    the upload, the read-back, a bare wait), each a positive median within its repeats' range; a filter launched one by
    one has no graph to replay and gets no split."""
    from eval.bench.mcl import bench_filter, measured_scan, simulator_nog

    nog = simulator_nog(0.1, DEVICE)
    angles, measured = measured_scan(nog, 20.0, DEVICE)
    row = bench_filter(nog, "likelihood_field", 200, DEVICE, 3, 20.0, angles, measured, repeats=2, split=True)
    split = row["host_split_ms"]
    assert list(split) == ["step", "replay and wait", "replay back to back", "upload", "read back", "wait alone"]
    assert all(0 < v["min"] <= v["ms"] <= v["max"] for v in split.values()), split
    eager = bench_filter(
        nog, "likelihood_field", 200, DEVICE, 2, 20.0, angles, measured, repeats=1, graph="off", split=True
    )
    assert "host_split_ms" not in eager
