"""eval.same_bits: the hashes of what runs wrote, and the comparison of two trees' records."""

from __future__ import annotations

import json

import pytest

from eval.same_bits import compare, digest_outputs


def _run(folder, tum: str, metrics: dict, run_id: str = "abc123"):
    out = folder / "outputs" / "sim" / "localize" / f"likelihood_field-global-{run_id}"
    out.mkdir(parents=True)
    (out / "start0.tum").write_text(tum)
    (out / "metrics.json").write_text(json.dumps(metrics))
    (out / "last.pt").write_bytes(b"resume state with a wall time")
    stream = folder / "outputs" / "sim" / "stream"
    stream.mkdir(parents=True)
    (stream / "stream-1.npz").write_bytes(b"a cache, an input")
    return {"tree": str(folder), "device": "cpu", "runs": {"sim": digest_outputs(folder)}}


def test_the_same_outputs_with_other_timings_and_run_ids_are_the_same_bits(tmp_path):
    metrics = {"runs": [{"rmse_cm": 3.25, "ms_per_step": 1.0, "time_s": 9.0}], "manifest": {"git": "a"}}
    a = _run(tmp_path / "a", "1 2 3\n", metrics)
    slower = {"runs": [{"rmse_cm": 3.25, "ms_per_step": 7.0, "time_s": 1.0}], "manifest": {"git": "b"}}
    b = _run(tmp_path / "b", "1 2 3\n", slower, run_id="def456")  # another id: the settings' names changed
    assert set(a["runs"]["sim"]) == {
        "outputs/sim/localize/likelihood_field-global-abc123/start0.tum",
        "outputs/sim/localize/likelihood_field-global-abc123/metrics.json",
    }  # the cache and the resume state are not outputs
    assert compare(a, b) == []


def test_a_changed_trajectory_or_metric_is_found(tmp_path):
    metrics = {"runs": [{"rmse_cm": 3.25}]}
    a = _run(tmp_path / "a", "1 2 3\n", metrics)
    b = _run(tmp_path / "b", "1 2 3.0000001\n", metrics)
    c = _run(tmp_path / "c", "1 2 3\n", {"runs": [{"rmse_cm": 3.2500001}]})
    assert compare(a, b) == ["sim: outputs/sim/localize/likelihood_field-global/start0.tum differs"]
    assert compare(a, c) == ["sim: outputs/sim/localize/likelihood_field-global/metrics.json differs"]
    assert compare(a, {"runs": {}}) == ["sim: only in the first record"]


@pytest.mark.parametrize(
    "name", ["same_bits_issue34", "same_bits_session20", "same_bits_session21", "same_bits_session22"]
)
def test_kept_same_bits_records_show_every_output_unchanged_on_the_cpu_and_the_gpu(name):
    """The records closing notes cite (issue 34's refactor; the twentieth session's CPU step, the twenty-first's GPU step,
    the twenty-second's one top-share kernel): the same runs before
    and after, on the CPU and on cuda:0, hashed file by file; every run wrote files, and none differs."""
    from pathlib import Path

    record = json.loads((Path(__file__).parents[1] / f"results/checks/{name}.json").read_text())
    assert set(record["devices"]) == {"cpu", "cuda:0"}
    for device, runs in record["devices"].items():
        assert set(runs["before"]) == set(runs["after"]) and len(runs["after"]) >= 8, device
        assert all(runs["after"].values()), f"{device}: a run hashed no file"
        assert compare({"runs": runs["before"]}, {"runs": runs["after"]}) == [], device
