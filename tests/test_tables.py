"""eval.tables builds its tables from the runs (kept in results/<group>/<exp>.json by eval.keep, or in
outputs/), labels them from their configs, and rewrites only the marked README block."""

import dataclasses
import json

import pytest
import yaml

from eval.keep import keep
from eval.tables import collect_synthesis, replace_block, synthesis_table
from irmcl_warp.config import LocalizeConfig, MCLConfig, SlamConfig


def _write(path, obj):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj))


def _run(root, exp, folder, metrics, config):
    """A finished run folder: metrics.json and the resolved config.yaml."""
    _write(root / exp / folder / "metrics.json", metrics)
    (root / exp / folder / "config.yaml").write_text(yaml.safe_dump(config))
    return root / exp / folder


NOF_CONFIG = {"train": {"name": "fast"}, "render": {"name": "warp"}}


def _synthesis(mae_nof, mae_grid):
    metric = lambda mae: {"mae_m": mae, "median_error_m": mae / 2, "accuracy_pct": 90.0, "chamfer_m": 0.2,
                          "fscore_pct": 97.0}
    return {"dataset": "fr079", "split": "test", "methods": {
        "NOF (fast)": {"kind": "nof", **metric(mae_nof)}, "OGM 5 cm": {"kind": "grid", **metric(mae_grid)}}}


def test_table_rows_come_from_files_and_later_roots_win(tmp_path):
    gpu, kept, mine = tmp_path / "gpu", tmp_path / "results", tmp_path / "outputs"
    keep([_run(gpu, "fr079", "synthesis-fast", _synthesis(0.3, 0.33), NOF_CONFIG),
          _run(gpu, "fr079", "train-fast", {"train_time_s": 89.4, "epochs_done": 6, "gpu": "H100", "device": "cuda:0"},
               NOF_CONFIG)], kept)
    assert (kept / "nof" / "fr079.json").is_file()
    _run(mine, "fr079", "synthesis-fast", _synthesis(0.2777, 0.33), NOF_CONFIG)
    table = synthesis_table(collect_synthesis(results=kept, outputs=mine))
    lines = table.splitlines()
    assert len(lines) == 4  # header, rule, NOF, one grid
    assert "| fr079 | test | NOF (fast) | 0.278 |" in lines[2] and lines[2].endswith("| ? |")  # no train file in outputs
    assert lines[3].startswith("| fr079 | test | OGM 5 cm | 0.330 |")



def test_an_experiment_past_the_file_size_goes_on_in_numbered_files(tmp_path):
    """write_kept splits an experiment's runs over <exp>.json, <exp>.2.json, ... under the size bound, in folder
    order; load_kept and the tables read them as one; a shorter set removes the files no longer needed."""
    from eval.collect import collect
    from eval.keep import kept_files, load_kept, write_kept

    group = tmp_path / "results" / "nof"
    group.mkdir(parents=True)
    runs = {f"synthesis-s{i:02d}": {"config": NOF_CONFIG, "metrics": _synthesis(0.3 + i / 1000, 0.33)} for i in range(12)}
    doc = {"group": "nof", "exp": "fr079", "runs": runs}
    one = len(json.dumps(runs["synthesis-s00"], sort_keys=True, separators=(",", ":")))
    write_kept(group / "fr079.json", doc, max_bytes=4 * one)
    files = kept_files(group, "fr079")
    assert [f.name for f in files[:3]] == ["fr079.json", "fr079.2.json", "fr079.3.json"] and len(files) >= 4
    assert all(f.stat().st_size <= 4 * one for f in files)
    assert load_kept(group, "fr079") == doc
    assert list(json.loads(files[1].read_text())["runs"])[0] > list(json.loads(files[0].read_text())["runs"])[-1]
    assert len(collect("nof", ("synthesis",), results=tmp_path / "results", outputs=None)) == 12
    write_kept(group / "fr079.json", {**doc, "runs": dict(list(runs.items())[:2])}, max_bytes=4 * one)
    assert kept_files(group, "fr079") == [group / "fr079.json"] and not (group / "fr079.2.json").exists()

def test_replace_block_keeps_the_rest_and_needs_markers():
    text = "intro\n<!-- table:nof -->\nold\n<!-- /table:nof -->\noutro\n"
    assert replace_block(text, "nof", "new") == "intro\n<!-- table:nof -->\nnew\n<!-- /table:nof -->\noutro\n"
    with pytest.raises(SystemExit, match="no <!-- table:mcl -->"):
        replace_block(text, "mcl", "x")


def test_a_half_written_metrics_or_results_file_is_reported(tmp_path):
    f = _run(tmp_path / "outputs", "fr079", "synthesis-fast", {}, NOF_CONFIG) / "metrics.json"
    f.write_text('{"dataset": "fr0')
    with pytest.raises(SystemExit, match="synthesis-fast: unreadable run"):
        collect_synthesis(results=tmp_path / "results", outputs=tmp_path / "outputs")
    (tmp_path / "results" / "nof").mkdir(parents=True)
    (tmp_path / "results" / "nof" / "fr079.json").write_text('{"runs": {"synth')
    with pytest.raises(SystemExit, match="fr079.json: unreadable results file"):
        collect_synthesis(results=tmp_path / "results", outputs=None)


def _loc(dataset, weighting, mode, n, successes, rmse, res=0.05, kidnap_at_s=0.0, **extra):
    summary = {"weighting": weighting, "mode": mode, "num_particles": n, "starts": 10, "successes": successes,
               "time_to_converge_s_mean": 2.0, "location_rmse_cm_mean": rmse, "yaw_rmse_deg_mean": 1.5,
               "within_10cm_pct_mean": 80.0, "within_1deg_pct_mean": 50.0, "divergences": 0, **extra}
    if kidnap_at_s:
        summary["kidnap_at_s"] = kidnap_at_s
    recovery = {"recovery_alpha_slow": 0.01, "recovery_alpha_fast": 0.2} if kidnap_at_s else {}
    settings = {**dataclasses.asdict(MCLConfig()), **dataclasses.asdict(LocalizeConfig()), "weighting": weighting,
                "mode": mode, "num_particles": n, "map_resolution_m": res, "kidnap_at_s": kidnap_at_s, **recovery}
    return {"dataset": dataset, "summary": summary, "settings": settings}


def test_localization_table_pairs_global_and_tracking_and_keeps_the_largest_particle_count(tmp_path):
    from eval.tables import collect_localization, kidnap_table, localization_table

    gpu, kept, mine = tmp_path / "gpu", tmp_path / "results", tmp_path / "outputs"
    # folder names say nothing to the tables: the cells come from the settings
    keep([_run(gpu, "fr079", "localize-a", _loc("fr079", "nog_raymarch", "global", 100000, 10, 6.3), {}),
          _run(gpu, "fr079", "localize-b", _loc("fr079", "nog_raymarch", "tracking", 10000, 9, 6.1), {}),
          _run(gpu, "fr079", "localize-c", _loc("fr079", "likelihood_field", "global", 100000, 5, 5.6, res=0.1), {}),
          _run(gpu, "fr079", "localize-d", _loc("fr079", "nog_raymarch", "tracking", 10000, 0, None, recovered=8,
                                                 recovery_time_s_mean=7.04, kidnap_at_s=30.0), {})], kept)
    _run(mine, "fr079", "localize-e", _loc("fr079", "nog_raymarch", "global", 2000, 0, None), {})
    runs = collect_localization(results=kept, outputs=mine)
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
                "relations": {"trans_abs_mean_m": err, "trans_abs_std_m": std, "rot_abs_mean_deg": 2.0,
                              "relations_used": 100, "relations_unmatched": 0}}

    def config(seed):
        return {"slam": {**dataclasses.asdict(SlamConfig()), "seed": seed}, "data": {"name": "intel"}}

    for seed, err in enumerate([0.05, 0.07, 1.9]):
        _run(tmp_path, "gmapping_intel", f"slam-{seed}", run(seed, err), config(seed))
    _run(tmp_path, "gmapping_intel", "slam-9", {**run(9, 0.0), "relations": "not scored: no relations file"},
         config(9))  # left out
    _run(tmp_path, "gmapping_intel", "slam-dda", run(4, 0.05), {**config(4), "slam": {**config(4)["slam"], "line": "dda"}})
    partial = {**run(5, 0.04), "particles": 60}  # scored on a fifth of the relations: the table says so
    partial["relations"] = {**partial["relations"], "relations_used": 20, "relations_unmatched": 80}
    _run(tmp_path, "gmapping_intel", "slam-partial", partial, {**config(5), "slam": {**config(5)["slam"], "num_particles": 60}})
    released = {("gmapping_intel", f"30p-seed{k}"): {**run(k, err), "settings": {"maxRange": 79.99}}
                for k, err in enumerate([0.05, 0.5])}
    released[("gmapping_intel", "40")] = {**run(0, 0.06), "settings": {"maxRange": 79.99, "maxUrange": 40.0}}
    lines = slam_table(collect_slam(results=tmp_path / "none", outputs=tmp_path), released).splitlines()
    ours = [l for l in lines if "paper + selective" in l]
    assert ours == ["| intel | paper + selective | 30 | 2/3 | 0.060 +- 0.050 | 2.00 | 0.673 | 10-12 s | H100 |",
                    "| intel | paper + selective [scored on 20 of 100 relations] | 60 | 1/1 | 0.040 +- 0.050 | 2.00 | "
                    "0.040 | 15-15 s | H100 |",
                    "| intel | paper + selective (dda) | 30 | 1/1 | 0.050 +- 0.050 | 2.00 | 0.050 | 14-14 s | H100 |"]
    # the released code's rows come from its runs (eval.reference.gmapping), one per setting that differs from
    # the ROS wrapper's defaults (maxRange is taken from the log, not chosen)
    assert "| intel | *released C++ (python -m eval.reference.gmapping)* | 30 | 1/2 | 0.050 +- 0.050 | 2.00 | 0.275 | " \
           "10-11 s | 2-core CPU |" in lines
    assert any("eval.reference.gmapping; maxUrange=40)*" in l and "| 1/1 |" in l for l in lines)
    assert any("published GMapping (Kümmerle et al. 2009)" in l for l in lines)


def test_particles_vs_success_figure_only_for_datasets_with_scored_runs(tmp_path):
    from eval.collect import Run
    from eval.plots import particles_vs_success

    def config(n, s):
        return {"slam": {**dataclasses.asdict(SlamConfig()), "num_particles": n, "seed": s}, "data": {}}

    runs = {("gmapping_intel", f"slam-paper-selective-{n}p-seed{s}"): Run({
        "dataset": "intel", "proposal": "paper", "resample": "selective", "particles": n, "device": "cuda:0",
        "relations": {"trans_abs_mean_m": 0.05 if s < n // 5 else 2.0}}, config(n, s)) for n in (5, 15) for s in range(3)}
    runs[("gmapping_fr079", "slam-x")] = Run({"dataset": "fr079", "proposal": "paper", "resample": "selective",
                                              "particles": 30, "relations": "not scored"}, config(30, 0))
    assert particles_vs_success(runs, "fr079", tmp_path / "fr079.png") is None
    out = particles_vs_success(runs, "intel", tmp_path / "intel.png")
    assert out.is_file() and out.stat().st_size > 5000


def test_readme_prose_agrees_with_the_kept_results():
    """Every figure the README's prose quotes as a fact is what the kept runs give (eval.tables --write sets
    them); an edited figure, or results that moved under the prose, fail here."""
    from eval.claims import facts, readme_facts, write_facts
    from eval.collect import REPO, collect_slam, collect_slam_reference, collect_synthesis

    text = (REPO / "README.md").read_text()
    quoted = readme_facts(text)
    assert len(quoted) >= 8
    values = facts(collect_slam(outputs=None), collect_slam_reference(outputs=None), collect_synthesis(outputs=None))
    assert {k: v for k, v in quoted.items() if values.get(k) != v} == {}
    name = next(iter(quoted))
    edited = text.replace(f"<!-- fact:{name} -->{quoted[name]}", f"<!-- fact:{name} -->99/10", 1)
    assert readme_facts(edited)[name] != values[name]  # what the check above would catch
    assert readme_facts(write_facts(edited, values))[name] == values[name]
    with pytest.raises(SystemExit, match="no_such_fact"):
        write_facts(text + "<!-- fact:no_such_fact -->1<!-- /fact -->", values)


def test_fidelity_document_agrees_with_the_kept_results():
    """docs/fidelity.md is what eval.fidelity makes from results/ now (rerun --write after keeping runs)."""
    from eval.fidelity import REPO as ROOT
    from eval.fidelity import document

    assert (ROOT / "docs" / "fidelity.md").read_text() == document(), "run python -m eval.fidelity --write"


def test_verdicts_follow_the_figures(rng):
    from eval.claims import _against_released, _fails_verdict, _slam_verdict

    ok, bad = list(rng.uniform(0.04, 0.07, 10)), list(rng.uniform(0.2, 0.5, 10))
    assert _slam_verdict(ok[:9] + bad[:1], 0.07) == "reproduced"
    assert _slam_verdict(ok[:9] + bad[:1], 0.03).startswith("partly")  # converged, but far above the paper's error
    assert _slam_verdict(ok[:6] + bad[:4]) == "partly: 6/10 seeds converge"
    assert _slam_verdict(ok[:2] + bad[:8]).startswith("not reproduced: 2/10")
    assert _slam_verdict([]) == "not run"
    assert _against_released(ok[:3] + bad[:7], ok[:1] + bad[:9]).startswith("reproduced")
    # fewer successes than the released code, but not shown to differ at these counts (Fisher p = 0.58)
    assert _against_released(ok[:1] + bad[:9], ok[:3] + bad[:7]).startswith("partly: ours 1/10")
    assert _against_released(bad, ok).startswith("not reproduced: ours 0/10")
    # rates, not counts, where the two sides ran different numbers of seeds: 4/20 = 20 % >= 2/10
    assert _against_released(ok[:4] + bad + bad[:6], ok[:2] + bad[:8]).startswith("reproduced: ours 4/20")
    assert not _against_released(ok[:3] + bad + bad[:7], ok[:2] + bad[:8]).startswith("reproduced")  # 3/20 < 2/10
    assert _fails_verdict(bad) == "reproduced" and _fails_verdict(ok).startswith("partly")


def test_kept_runs_read_in_todays_names():
    """A localize run kept before mcl.motion existed reads with the model it ran with, in its config and its
    settings, however often it is migrated (eval.collect migrates every kept run it reads)."""
    from eval.keep import migrate

    config = {"mcl": {"weighting": "nog_raymarch", "num_particles": 10000}, "localize": {"mode": "tracking"}}
    metrics = {"settings": {"weighting": "nog_raymarch", "mode": "tracking"}, "summary": {}}
    c1, m1 = migrate(config, metrics, "localize")
    assert c1["mcl"]["motion"] == "odometry" and m1["settings"]["motion"] == "odometry"
    assert "motion" not in config["mcl"] and "motion" not in metrics["settings"]  # the inputs are left alone
    assert migrate(c1, m1, "localize") == (c1, m1)
    c2, m2 = migrate({**config, "mcl": {**config["mcl"], "motion": "irmcl"}},
                     {**metrics, "settings": {**metrics["settings"], "motion": "irmcl"}}, "localize")
    assert c2["mcl"]["motion"] == m2["settings"]["motion"] == "irmcl"
