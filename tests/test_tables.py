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


def _loc(dataset, weighting, mode, n, successes, rmse, **extra):
    summary = {"weighting": weighting, "mode": mode, "num_particles": n, "starts": 10, "successes": successes,
               "time_to_converge_s_mean": 2.0, "location_rmse_cm_mean": rmse, "yaw_rmse_deg_mean": 1.5,
               "within_10cm_pct_mean": 80.0, "within_1deg_pct_mean": 50.0, "divergences": 0, **extra}
    return {"dataset": dataset, "summary": summary, "settings": {"recovery_alpha_slow": 0.01, "recovery_alpha_fast": 0.2}}


def test_localization_table_pairs_global_and_tracking_and_keeps_the_largest_particle_count(tmp_path):
    from eval.tables import collect_localization, kidnap_table, localization_table

    kept, mine = tmp_path / "results", tmp_path / "outputs"
    _write(kept / "fr079/localize-nog_raymarch-global-100k-5cm/metrics.json", _loc("fr079", "nog_raymarch", "global", 100000, 10, 6.3))
    _write(kept / "fr079/localize-nog_raymarch-tracking-10k-5cm/metrics.json", _loc("fr079", "nog_raymarch", "tracking", 10000, 9, 6.1))
    _write(mine / "fr079/localize-nog_raymarch-global-2k-5cm/metrics.json", _loc("fr079", "nog_raymarch", "global", 2000, 0, None))
    _write(kept / "fr079/localize-likelihood_field-global-100k-10cm/metrics.json", _loc("fr079", "likelihood_field", "global", 100000, 5, 5.6))
    _write(kept / "fr079/localize-nog_raymarch-tracking-10k-5cm-kidnap30s-recovery/metrics.json",
           _loc("fr079", "nog_raymarch", "tracking", 10000, 0, None, recovered=8, recovery_time_s_mean=7.04, kidnap_at_s=30.0))
    _write(mine / "fr079/localize-nog_raymarch/metrics.json", {"an": "older layout"})  # left out by name
    runs = collect_localization((kept, mine))
    lines = localization_table(runs).splitlines()
    assert len(lines) == 4, lines  # header, rule, IR-MCL 5 cm (global + tracking in one row), likelihood field 10 cm
    assert lines[2].startswith("| fr079 | IR-MCL (NOG) | 5 cm | 100k | 10/10 | 2.0 | 6.3 / 1.50 | 80 / 50 | 10k | 9/10 | 6.1 / 1.50 | 0 |")
    assert lines[3].startswith("| fr079 | likelihood field | 10 cm | 100k | 5/10 |") and lines[3].endswith("| - | - | - | - |")
    kid = kidnap_table(runs).splitlines()
    assert len(kid) == 3 and "| 30 | 0.01 / 0.2 | 8/10 | 7.0 |" in kid[2]


def test_slam_table_counts_converged_seeds_and_lists_the_references(tmp_path):
    from eval.tables import collect_slam, slam_table

    def run(seed, err, std=0.05):
        return {"dataset": "intel", "proposal": "paper", "resample": "selective", "particles": 30, "seed": seed,
                "device": "cuda:0", "wall_time_s": 10.0 + seed,
                "relations": {"trans_abs_mean_m": err, "trans_abs_std_m": std, "rot_abs_mean_deg": 2.0}}

    for seed, err in enumerate([0.05, 0.07, 1.9]):
        _write(tmp_path / f"gmapping_intel/slam-paper-selective-30p-seed{seed}/metrics.json", run(seed, err))
    _write(tmp_path / "gmapping_intel/slam-paper-selective-30p-seed9/metrics.json",
           {**run(9, 0.0), "relations": "not scored: no relations file"})  # left out
    lines = slam_table(collect_slam((tmp_path,))).splitlines()
    ours = [l for l in lines if "paper + selective" in l]
    assert ours == ["| intel | paper + selective | 30 | 2/3 | 0.060 +- 0.050 | 2.00 | 0.673 | 10-12 s | H100 |"]
    assert any("*released C++, derived/intel.fileorder*" in l and "10/10" in l for l in lines)


def test_particles_vs_success_figure_only_for_datasets_with_scored_runs(tmp_path):
    from eval.plots import particles_vs_success

    runs = {("gmapping_intel", f"slam-paper-selective-{n}p-seed{s}"): {
        "dataset": "intel", "proposal": "paper", "resample": "selective", "particles": n, "device": "cuda:0",
        "relations": {"trans_abs_mean_m": 0.05 if s < n // 5 else 2.0}} for n in (5, 15) for s in range(3)}
    runs[("gmapping_fr079", "slam-x")] = {"dataset": "fr079", "proposal": "paper", "resample": "selective",
                                          "particles": 30, "relations": "not scored"}
    assert particles_vs_success(runs, "fr079", tmp_path / "fr079.png") is None
    out = particles_vs_success(runs, "intel", tmp_path / "intel.png")
    assert out.is_file() and out.stat().st_size > 5000
