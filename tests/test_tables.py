"""eval.tables builds its table from metrics.json files and rewrites only the marked README block."""

import json

import pytest

from eval.tables import collect_synthesis, replace_block, synthesis_table


def _write(path, obj):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj))


def _synthesis(mae_nof, mae_grid):
    metric = lambda mae: {"mae_m": mae, "median_error_m": mae / 2, "accuracy_pct": 90.0, "chamfer_m": 0.2,
                          "fscore_pct": 97.0}
    return {"dataset": "fr079", "split": "test", "methods": {
        "NOF (fast)": {"kind": "nof", **metric(mae_nof)}, "OGM 5 cm": {"kind": "grid", **metric(mae_grid)}}}


def test_table_rows_come_from_files_and_later_roots_win(tmp_path):
    kept, mine = tmp_path / "results", tmp_path / "outputs"
    _write(kept / "fr079/synthesis-fast/metrics.json", _synthesis(0.3, 0.33))
    _write(kept / "fr079/train-fast/metrics.json", {"train_time_s": 89.4, "epochs_done": 6, "gpu": "H100", "device": "cuda:0"})
    _write(mine / "fr079/synthesis-fast/metrics.json", _synthesis(0.2777, 0.33))
    table = synthesis_table(collect_synthesis((kept, mine)))
    lines = table.splitlines()
    assert len(lines) == 4  # header, rule, NOF, one grid
    assert "| fr079 | test | NOF (fast) | 0.278 |" in lines[2] and lines[2].endswith("| ? |")  # no train file in outputs
    assert lines[3].startswith("| fr079 | test | OGM 5 cm | 0.330 |")


def test_replace_block_keeps_the_rest_and_needs_markers():
    text = "intro\n<!-- table:nof -->\nold\n<!-- /table:nof -->\noutro\n"
    assert replace_block(text, "nof", "new") == "intro\n<!-- table:nof -->\nnew\n<!-- /table:nof -->\noutro\n"
    with pytest.raises(SystemExit, match="no <!-- table:mcl -->"):
        replace_block(text, "mcl", "x")


def test_a_half_written_metrics_file_is_reported(tmp_path):
    f = tmp_path / "fr079/synthesis-fast/metrics.json"
    f.parent.mkdir(parents=True)
    f.write_text('{"dataset": "fr0')
    with pytest.raises(SystemExit, match="unreadable metrics file"):
        collect_synthesis((tmp_path,))
