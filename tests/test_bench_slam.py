"""``python -m eval.bench slam --match-at N``: the hill climb of one processed scan timed in each way RBPF.match
has on the device, whose poses must agree bit for bit."""

from __future__ import annotations

import argparse
import json

import pytest

from eval.bench.slam import run_slam_bench


def _args(tmp_path, match_at):
    return argparse.Namespace(
        exp="gmapping_sim",
        particles=[6],
        device="cpu",
        scans=None,
        override=["sim.duration_s=40"],
        repeats=1,
        released=False,
        match_at=match_at,
        match_repeats=2,
        out=str(tmp_path / "bench"),
    )


def test_the_match_benchmark_times_each_way_and_the_ways_agree(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the simulator's stream cache goes to outputs/ here
    res = run_slam_bench(_args(tmp_path, 60))[0]
    assert res["scan"] >= 60
    assert set(res["md5"]) == {"threads", "rounds"} and len(set(res["md5"].values())) == 1, res["md5"]
    assert all(len(t) == 2 and min(t) > 0 for t in res["ms"].values())
    assert res["rounds"]["rounds"] >= res["rounds"]["threads"] > 0  # launched rounds come in blocks of 8
    saved = json.loads((tmp_path / "bench" / "slam-match-gmapping_sim-cpu.json").read_text())
    assert saved["md5"] == res["md5"]


def test_the_match_benchmark_says_when_no_scan_is_processed_after_the_one_asked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="no scan is processed after it"):
        run_slam_bench(_args(tmp_path, 10**6))
