"""``python -m eval.bench estimate``: the top-share estimate by the sort and by the radix select's widths, timed
side by side; every way must give the sort's estimate (the same particles, summed in another order)."""

from __future__ import annotations

import argparse
import json

import pytest

from eval.bench.estimate import method_settings, run_estimate_bench
from irmcl_warp.kernels.estimate import TopShareMean


def test_the_estimate_benchmark_times_each_way_and_the_ways_agree(tmp_path):
    a = argparse.Namespace(
        device="cpu",
        particles=[3000],
        weights=["spread", "ties"],
        methods=["sort", "select", "select4"],
        steps=2,
        repeats=2,
        out=str(tmp_path / "bench"),
    )
    rows = run_estimate_bench(a)
    assert [(r["weights"], r["method"]) for r in rows] == [(w, m) for w in a.weights for m in a.methods]
    for r in rows:
        assert r["repeats"] == 2 and r["step_ms_min"] > 0
        assert max(r["pose_diff_vs_first"]) < 1e-3, r  # the same top share as the sort's
    assert TopShareMean.SELECT is None and TopShareMean.SELECT_PER_THREAD is None  # the class settings restored
    saved = json.loads((tmp_path / "bench" / "estimate-cpu.json").read_text())
    assert [r["pose"] for r in saved["rows"]] == [r["pose"] for r in rows]
    with pytest.raises(ValueError, match="unknown method"):
        method_settings("select-four")
