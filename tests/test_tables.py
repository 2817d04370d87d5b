"""The results library and what is generated from it: run records kept in results/ (eval.keep) and found by
their settings, tables that take only the records whose settings they declare, the claims registry's verdicts
with their statistical tests, and README / REPRODUCTION / fidelity exactly as the kept records make them."""

import json
import re

import pytest

from eval.report.tables import kidnap_table, localization_table, slam_table, synthesis_table
from eval.results import claims as C
from eval.results.queries import synthesis_pairs
from eval.results.records import kept_files, keep, load, load_doc, write_doc
from eval.tables import replace_block
from runfakes import composed, fake_run


def _synthesis(mae_nof, mae_grid):
    def metric(mae):
        return {"mae_m": mae, "median_error_m": mae / 2, "accuracy_pct": 90.0, "chamfer_m": 0.2, "fscore_pct": 97.0}

    return {
        "dataset": "fr079",
        "split": "test",
        "methods": {"NOF (fast)": {"kind": "nof", **metric(mae_nof)}, "OGM 5 cm": {"kind": "grid", **metric(mae_grid)}},
    }


FR079_FAST = ("+exp=fr079", "train=fast")


def test_table_rows_come_from_records_and_yours_replace_kept_ones(tmp_path):
    gpu, results, mine = tmp_path / "gpu", tmp_path / "results", tmp_path / "outputs"
    cfg = composed(*FR079_FAST)
    train = fake_run(gpu, "train", cfg, {"train_time_s": 89.4, "epochs_done": 6, "gpu": "H100", "device": "cuda:0"})
    up = {"train": {"id": json.loads((train / "manifest.json").read_text())["id"], "run": "x"}}
    keep([fake_run(gpu, "synthesis", cfg, _synthesis(0.3, 0.33), upstream=up), train], results)
    assert (results / "nof" / "fr079.json").is_file()
    fake_run(mine, "synthesis", cfg, _synthesis(0.2777, 0.33))  # yours, the same settings: it replaces the kept one
    lines = synthesis_table(synthesis_pairs(load(("train", "synthesis"), results, mine))).splitlines()
    assert len(lines) == 4  # header, rule, NOF, one grid
    assert "| fr079 | test | NOF (fast) | 0.278 |" in lines[2]
    assert lines[3].startswith("| fr079 | test | OGM 5 cm | 0.330 |")
    kept_only = synthesis_table(synthesis_pairs(load(("train", "synthesis"), results, None))).splitlines()
    assert "| NOF (fast) | 0.300 |" in kept_only[2] and kept_only[2].endswith("89 s, 6 ep, H100 |")  # paired by id


def test_an_experiment_past_the_file_size_goes_on_in_numbered_files(tmp_path):
    """write_doc splits an experiment's records over <exp>.json, <exp>.2.json, ... under the size bound, in key
    order; load_doc reads them back as one; a shorter set removes the files no longer needed."""
    group = tmp_path / "results" / "nof"
    group.mkdir(parents=True)
    cfg = composed(*FR079_FAST)
    recs = {
        f"synthesis/s{i:02d}-{i:010d}": {
            "stage": "synthesis",
            "id": f"{i:064d}",
            "label": f"s{i:02d}",
            "config": {**cfg, "train": {**cfg["train"], "seed": i}},
            "metrics": _synthesis(0.3 + i / 1000, 0.33),
        }
        for i in range(12)
    }
    doc = {"group": "nof", "exp": "fr079", "records": recs}
    one = len(json.dumps(recs["synthesis/s00-0000000000"], sort_keys=True, separators=(",", ":"))) + 8
    write_doc(group / "fr079.json", doc, max_bytes=4 * one)
    files = kept_files(group, "fr079")
    assert [f.name for f in files[:3]] == ["fr079.json", "fr079.2.json", "fr079.3.json"] and len(files) >= 4
    assert all(f.stat().st_size <= 4 * one for f in files)
    assert load_doc(group, "fr079") == doc
    assert len(load(("synthesis",), tmp_path / "results", None)) == 12
    write_doc(group / "fr079.json", {**doc, "records": dict(list(recs.items())[:2])}, max_bytes=4 * one)
    assert kept_files(group, "fr079") == [group / "fr079.json"] and not (group / "fr079.2.json").exists()


def test_replace_block_keeps_the_rest_and_needs_markers():
    text = "intro\n<!-- table:nof -->\nold\n<!-- /table:nof -->\noutro\n"
    assert replace_block(text, "nof", "new") == "intro\n<!-- table:nof -->\nnew\n<!-- /table:nof -->\noutro\n"
    with pytest.raises(SystemExit, match="no <!-- table:mcl -->"):
        replace_block(text, "mcl", "x")


def test_a_damaged_record_or_results_file_is_reported(tmp_path):
    run = fake_run(tmp_path / "outputs", "synthesis", composed(*FR079_FAST), _synthesis(0.3, 0.33))
    (run / "config.yaml").write_text("data: [")
    with pytest.raises(ValueError, match="unreadable run record"):
        load(("synthesis",), None, tmp_path / "outputs")
    (tmp_path / "results" / "nof").mkdir(parents=True)
    (tmp_path / "results" / "nof" / "fr079.json").write_text('{"records": {"synth')
    with pytest.raises(ValueError, match="fr079.json: unreadable results file"):
        load(("synthesis",), tmp_path / "results", None)


def _loc(weighting, mode, n, successes, rmse, **summary):
    return {
        "dataset": "fr079",
        "runs": [{"ms_per_scan": 1.0}],
        "summary": {
            "weighting": weighting,
            "mode": mode,
            "num_particles": n,
            "starts": 10,
            "successes": successes,
            "time_to_converge_s_mean": 2.0,
            "location_rmse_cm_mean": rmse,
            "yaw_rmse_deg_mean": 1.5,
            "within_10cm_pct_mean": 80.0,
            "within_1deg_pct_mean": 50.0,
            "divergences": 0,
            **summary,
        },
        "settings": {"recovery_alpha_slow": 0.01, "recovery_alpha_fast": 0.2},
    }


def test_localization_table_takes_the_cells_from_the_settings_and_leaves_other_settings_out(tmp_path):
    """Cells come from the records' settings (weighting, mode, particles, resolution); a record whose other
    settings differ from the experiment's (an ablation, a kidnapping, a changed motion noise) is not a cell."""
    out = tmp_path / "outputs"
    cell = lambda *ov: composed("+exp=fr079", *ov)  # noqa: E731
    fake_run(out, "localize", cell("mcl.weighting=likelihood_field"), _loc("nog_raymarch", "global", 100000, 10, 6.3))
    fake_run(
        out,
        "localize",
        cell("mcl.weighting=likelihood_field", "localize.mode=tracking", "mcl.num_particles=10000"),
        _loc("nog_raymarch", "tracking", 10000, 9, 6.1),
    )
    fake_run(
        out,
        "localize",
        cell("mcl.weighting=likelihood_field", "mcl.map_resolution_m=0.1"),
        _loc("likelihood_field", "global", 100000, 5, 5.6),
    )
    fake_run(
        out,
        "localize",
        cell("mcl.weighting=likelihood_field", "mcl.alphas=[0.2,0.02,0.2,0.02]"),
        _loc("likelihood_field", "global", 100000, 1, 99.0),
    )  # other motion noise: no cell of the table
    fake_run(
        out,
        "localize",
        cell(
            "mcl.weighting=likelihood_field",
            "localize.mode=tracking",
            "mcl.num_particles=10000",
            "localize.kidnap_at_s=30",
            "mcl.recovery_alpha_slow=0.01",
            "mcl.recovery_alpha_fast=0.2",
        ),
        _loc("nog_raymarch", "tracking", 10000, 0, None, recovered=8, recovery_time_s_mean=7.04, kidnap_at_s=30.0),
    )
    runs = load(("localize",), None, out)
    lines = localization_table(runs).splitlines()
    assert len(lines) == 4, lines  # header, rule, the 5 cm row (global + tracking), the 10 cm row
    assert lines[2].startswith(
        "| fr079 | likelihood field | 5 cm | 100k | 10/10 | 2.0 | 6.3 / 1.50 | 80 / 50 | 10k | 9/10 |"
    )
    assert lines[3].startswith("| fr079 | likelihood field | 10 cm | 100k | 5/10 |") and lines[3].endswith(
        "| - | - | - | - |"
    )
    kid = kidnap_table(runs).splitlines()
    assert len(kid) == 3 and "| 30 | 0.01 / 0.2 | 8/10 | 7.0 |" in kid[2]


def test_slam_table_counts_converged_seeds_and_lists_the_references(tmp_path):
    def run(seed, err, std=0.05, n=30):
        return {
            "dataset": "intel",
            "proposal": "paper",
            "resample": "selective",
            "particles": n,
            "seed": seed,
            "device": "cuda:0",
            "wall_time_s": 10.0 + seed,
            "relations": {
                "trans_abs_mean_m": err,
                "trans_abs_std_m": std,
                "rot_abs_mean_deg": 2.0,
                "relations_used": 100,
                "relations_unmatched": 0,
            },
        }

    out = tmp_path / "outputs"
    cfg = lambda seed, *ov: composed("+exp=gmapping_intel", f"slam.seed={seed}", *ov)  # noqa: E731
    for seed, err in enumerate([0.05, 0.07, 1.9]):
        fake_run(out, "slam", cfg(seed), run(seed, err))
    fake_run(out, "slam", cfg(9), {**run(9, 0.0), "relations": "not scored: no relations file"})  # left out
    fake_run(out, "slam", cfg(4, "slam.line=dda"), run(4, 0.05))
    partial = run(5, 0.04, n=60)  # scored on a fifth of the relations: the table says so
    partial["relations"] = {**partial["relations"], "relations_used": 20, "relations_unmatched": 80}
    fake_run(out, "slam", cfg(5, "slam.num_particles=60"), partial)
    released = {
        ("gmapping_intel", f"30p-seed{k}"): {**run(k, err), "settings": {"maxRange": 79.99}}
        for k, err in enumerate([0.05, 0.5])
    }
    released[("gmapping_intel", "40")] = {**run(0, 0.06), "settings": {"maxRange": 79.99, "maxUrange": 40.0}}
    lines = slam_table(load(("slam",), None, out), released).splitlines()
    ours = [line for line in lines if "paper + selective" in line]
    assert ours == [
        "| intel | paper + selective | 30 | 2/3 | 0.060 +- 0.050 | 2.00 | 0.673 | 10-12 s | H100 |",
        "| intel | paper + selective [scored on 20 of 100 relations] | 60 | 1/1 | 0.040 +- 0.050 | 2.00 | "
        "0.040 | 15-15 s | H100 |",
        "| intel | paper + selective (line=dda) | 30 | 1/1 | 0.050 +- 0.050 | 2.00 | 0.050 | 14-14 s | H100 |",
    ]
    # the released code's rows come from its runs (eval.reference.gmapping), one per setting that differs from
    # the ROS wrapper's defaults (maxRange is taken from the log, not chosen)
    assert (
        "| intel | *released C++ (python -m eval.reference.gmapping)* | 30 | 1/2 | 0.050 +- 0.050 | 2.00 | 0.275 | "
        "10-11 s | 2-core CPU |" in lines
    )
    assert any("eval.reference.gmapping; maxUrange=40)*" in line and "| 1/1 |" in line for line in lines)
    assert any("published GMapping (Kümmerle et al. 2009)" in line for line in lines)


def test_particles_vs_success_figure_only_for_datasets_with_scored_runs(tmp_path):
    from eval.report.plots import particles_vs_success

    out = tmp_path / "outputs"
    for n in (5, 15):
        for s in range(3):
            fake_run(
                out,
                "slam",
                composed("+exp=gmapping_intel", f"slam.num_particles={n}", f"slam.seed={s}"),
                {
                    "dataset": "intel",
                    "proposal": "paper",
                    "resample": "selective",
                    "particles": n,
                    "device": "cuda:0",
                    "relations": {"trans_abs_mean_m": 0.05 if s < n // 5 else 2.0},
                },
            )
    fake_run(
        out,
        "slam",
        composed("+exp=gmapping_fr079"),
        {"dataset": "fr079", "proposal": "paper", "resample": "selective", "particles": 30, "relations": "not scored"},
    )
    recs = load(("slam",), None, out)
    assert particles_vs_success(recs, "fr079", tmp_path / "fr079.png") is None
    made = particles_vs_success(recs, "intel", tmp_path / "intel.png")
    assert made.is_file() and made.stat().st_size > 5000


def test_records_kept_before_a_setting_existed_read_at_its_default():
    """A record kept before mcl.motion (or any setting) existed reads with the value the setting was introduced
    with: its schema default, which every new setting takes so that the runs before it ran that way."""
    from eval.results.records import complete

    config = {
        "mcl": {"weighting": "nog_raymarch", "num_particles": 10000},
        "localize": {"mode": "tracking"},
        "exp": "x",
    }
    full = complete(config)
    assert full["mcl"]["motion"] == "odometry" and full["mcl"]["num_particles"] == 10000 and "slam" not in full
    assert "motion" not in config["mcl"]  # the kept record is left alone
    assert complete(full) == full
    old = complete({"sim": {"max_range_m": 8.0}, "mapping": {"max_range_m": 30.0, "l_occ": 0.9}})
    assert old["sim"]["range_max_m"] == 8.0 and "max_range_m" not in old["sim"]  # renamed, value kept
    assert "max_range_m" not in old["mapping"] and old["mapping"]["l_occ"] == 0.9  # removed; others kept
    # a setting whose default is a new behaviour: a record from before holds what it did, a newer one its own value
    assert complete({"worlds": {"split": "test"}})["worlds"]["map_drive"] == "random"
    assert complete({"worlds": {"map_drive": "cover"}})["worlds"]["map_drive"] == "cover"


# --- the claims registry ----------------------------------------------------------------------------------------


def test_success_counts_are_compared_with_a_test_not_by_eye():
    verdict, reason, test = C.more_successes("the pipeline", 9, 10, "lidar-only", 7, 10)
    assert verdict == C.PARTLY and "p = 0.58" in test  # 9/10 against 7/10: no difference shown
    assert C.more_successes("a", 10, 10, "b", 3, 10)[0] == C.REPRODUCED
    assert C.more_successes("a", 7, 10, "b", 9, 10)[0] == C.NOT_REPRODUCED
    lo, hi = C.wilson(7, 10)
    assert 0.39 < lo < 0.40 and 0.89 < hi < 0.90


def test_per_start_errors_are_compared_with_a_test(rng):
    low, high = list(rng.normal(5.0, 0.3, 10)), list(rng.normal(8.0, 0.3, 10))
    assert C.lower("a", low, "b", high, "cm", "RMSE")[0] == C.REPRODUCED, f"seed {rng.seed}"
    assert C.lower("a", high, "b", low, "cm", "RMSE")[0] == C.NOT_REPRODUCED, f"seed {rng.seed}"
    same = [v + rng.normal(0, 0.01) for v in low[::-1]]  # the same values, shuffled a little: no difference to
    # find (two fresh draws of one distribution differed at p < 0.05 in one run of twenty: a flaky test)
    verdict, reason, test = C.lower("a", low, "b", same, "cm", "RMSE")
    assert verdict in (C.PARTLY, C.NOT_REPRODUCED) and "p = " in test, f"seed {rng.seed}: {reason}"


def test_every_claim_the_audit_named_has_a_row():
    keys = {c.key for c in C.CLAIMS}
    audit = {
        "irmcl.synthesis.fr079",
        "irmcl.synthesis.intel",
        "irmcl.synthesis.mit_csail",
        "irmcl.convergence.fr079",
        "irmcl.tracking.fr079",
        "irmcl.online",
        "gmapping.particles.campus",
        "gmapping.particles.killian80",
        "gmapping.fewer_particles",
        "gmapping.selective",
        "lidar_camera.lighting",
        "lidar_camera.moved_objects",
        "lidar_camera.pnp",
        "lidar_camera.trigger",
        "lidar_camera.clustering",
    }
    assert audit <= keys and len(keys) == len(C.CLAIMS)
    assert all(c.tolerance and c.where and c.statement for c in C.CLAIMS)


def test_the_generated_documents_are_what_the_kept_records_make():
    """README's tables and quoted figures, docs/REPRODUCTION.md (every claim with its verdict) and
    docs/fidelity.md are exactly what ``python -m eval.tables --write`` makes from results/ now; an edited
    figure, or results that moved under the prose, fail here."""
    from eval.report.facts import readme_facts, write_facts
    from eval.tables import documents

    made = documents()
    for path, text in made.items():
        assert path.read_text() == text, f"{path.name} is stale: run python -m eval.tables --write"
    readme = next(t for p, t in made.items() if p.name == "README.md")
    quoted = readme_facts(readme)
    assert len(quoted) >= 8
    name = next(iter(quoted))
    edited = readme.replace(f"<!-- fact:{name} -->{quoted[name]}", f"<!-- fact:{name} -->99/10", 1)
    assert readme_facts(write_facts(edited, quoted))[name] == quoted[name]
    with pytest.raises(SystemExit, match="no_such_fact"):
        write_facts(readme + "<!-- fact:no_such_fact -->1<!-- /fact -->", quoted)
    reproduction = next(t for p, t in made.items() if p.name == "REPRODUCTION.md")
    assert all(c.statement in reproduction for c in C.CLAIMS)


FIGURE = re.compile(r"\b\d+(?:\.\d+)?\s?(?:%|cm|mm|m|s|ms|deg|rad|Hz|GB|MB|kB|min|x)(?![\w/])|\b\d+/\d+\b|\b\d+\.\d+\b")


def unchecked_figures(text: str) -> list[str]:
    """The figures a markdown text states outside code, generated tables and quoted facts: a number with a unit, a
    count k/n, a decimal."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = re.sub(r"<!-- table:(\w+) -->.*?<!-- /table:\1 -->", "", text, flags=re.S)
    text = re.sub(r"<!-- fact:\w+ -->.*?<!-- /fact -->", "", text, flags=re.S)
    text = re.sub(r"`[^`]*`", "", text)
    text = re.sub(r"\]\([^)]*\)", "]", text)
    return [m.group(0) for m in FIGURE.finditer(text)]


def test_the_readme_states_no_figure_the_results_do_not_give():
    """Every measured figure in README.md's prose is a generated table or a quoted fact (checked against the
    kept records above); the rule itself catches a typed figure."""
    from eval.results.records import REPO

    assert unchecked_figures((REPO / "README.md").read_text()) == []
    assert unchecked_figures("it converged after 2.2 s in 9/10 runs, `mcl.sigma_m=0.5`") == ["2.2 s", "9/10"]


def test_the_step_graph_runs_are_summarised_per_card_never_pooled():
    """eval.report.facts: the train=graph runs' medians are taken per GPU (an H100's and an H200's times are not one
    population), a run of another name is left out, and the card's short name makes the fact's key."""
    from eval.report.facts import _graph_spans, gpu_slug

    assert gpu_slug("NVIDIA H100 80GB HBM3") == "h100" and gpu_slug("NVIDIA H200") == "h200"
    assert gpu_slug("cpu") == "cpu"

    def run(mae, secs, gpu):
        return {"methods": {"NOF (x)": {"mae_m": mae, "chamfer_m": mae / 2}}}, {"train_time_s": secs, "gpu": gpu}

    nof = {
        ("fr079", "h_g_s1"): run(0.25, 16.0, "NVIDIA H100 80GB HBM3"),
        ("fr079", "h_g_s2"): run(0.24, 18.0, "NVIDIA H100 80GB HBM3"),
        ("fr079", "h_g_s3"): run(0.26, 17.0, "NVIDIA H100 80GB HBM3"),
        ("fr079", "sg64_e5"): run(0.30, 10.0, "NVIDIA H200"),
        ("fr079", "h_g4_s1"): run(0.99, 1.0, "NVIDIA H100 80GB HBM3"),  # another recipe's name
        ("intel", "h_g_s1"): run(0.99, 1.0, "NVIDIA H100 80GB HBM3"),  # not a graph run's name on intel
    }
    spans = _graph_spans(nof, "fr079")
    assert set(spans) == {"h100", "h200"}
    assert spans["h100"]["seeds"] == "3" and spans["h100"]["time"] == "17.0 [16.0-18.0]"
    assert spans["h100"]["mae"] == "0.250 [0.240-0.260]"
    assert spans["h200"]["seeds"] == "1" and spans["h200"]["gpu"] == "NVIDIA H200"
    assert _graph_spans(nof, "intel") == {}


def test_the_kidnap_evidence_facts_bound_what_the_scans_allow(tmp_path):
    """README's bound on re-convergence comes from results/checks/kidnaps_evidence_<name>.json (eval.analyses.kidnaps
    --evidence): of 10 kidnappings 6 met the windows and of the 4 misses read, 1 had scans that fit both places, so a
    localizer reading only the scans can be sure of at most 9/10."""
    import json

    from eval.report.facts import _kidnap_evidence

    (tmp_path / "checks").mkdir()
    doc = {"kidnaps": 10, "classes": {"met": 6, "look-alike": 3, "not detected": 1}}
    doc["evidence"] = {"tie": 0.02, "misses_read": 4, "scans_could_tell": 3}
    doc["drives"] = [{"drive": "twin-1-run2", "scans_tell": False}, {"drive": "loop-1-run1", "scans_tell": True}]
    doc["drives"] += [{"drive": "hall-1-run1", "class": "met"}]
    (tmp_path / "checks" / "kidnaps_evidence_test_x.json").write_text(json.dumps(doc))
    assert _kidnap_evidence(tmp_path) == {
        "kidnaps_evidence_test_x_met": "6/10",
        "kidnaps_evidence_test_x_alike": "1 of the 4",
        "kidnaps_evidence_test_x_alike_drives": "twin-1-run2",
        "kidnaps_evidence_test_x_bound": "9/10 (90 %)",
    }
    assert _kidnap_evidence(tmp_path / "nothing") == {}


def test_the_paired_worlds_facts_quote_both_counts_and_the_test(tmp_path):
    """README's KLD-sampling figures come from results/checks/paired_worlds_<name>.json (eval.analyses.paired_worlds):
    both counts over the drives with McNemar's p, the drives only one side got right, and each side's particles per
    update in thousands; a comparison not kept gives no fact (and README's marker then fails the generated-documents test)."""
    import json

    from eval.report.facts import PAIRED_WORLDS, _paired_worlds

    (tmp_path / "checks").mkdir()
    doc = {
        "drives": 80,
        "outcomes": {
            "right_at_end": {
                "a": 73,
                "b": 70,
                "p_mcnemar": 0.375,
                "only_a": ["hall-1-run2", "loop-1-run1"],
                "only_b": [],
            }
        },
        "particles_per_update_a": 12923.8,
        "particles_per_update_b": 20000.0,
    }
    (tmp_path / "checks" / f"paired_worlds_{PAIRED_WORLDS[0]}.json").write_text(json.dumps(doc))
    got = _paired_worlds(tmp_path)
    assert set(got) == {PAIRED_WORLDS[0]}
    assert got[PAIRED_WORLDS[0]] == {
        "right_at_end": "73/80 against 70/80 (McNemar exact p = 0.38)",
        "right_at_end_only_a": "hall-1-run2, loop-1-run1",  # the discordant drives by name
        "right_at_end_only_b": "none",
        "per_update_a": "12.9k",
        "per_update_b": "20.0k",
    }
    doc["auroc"] = {"a": 0.889, "b": 0.8584, "difference": 0.0306, "ci95": [-0.0371, 0.0904]}  # made from folders
    (tmp_path / "checks" / f"paired_worlds_{PAIRED_WORLDS[0]}.json").write_text(json.dumps(doc))
    assert _paired_worlds(tmp_path)[PAIRED_WORLDS[0]]["auroc"] == (
        "0.889 against 0.858 (difference +0.031, 95 % over drive resamples -0.037 to +0.090)"
    )
    assert "false_alarms" not in _paired_worlds(tmp_path)[PAIRED_WORLDS[0]]  # (comparisons kept before the rates)
    doc["false_alarms"] = {"a": 0, "b": 4, "hours_a": 1.2152, "hours_b": 1.1867, "p_rates": 0.1203}
    (tmp_path / "checks" / f"paired_worlds_{PAIRED_WORLDS[0]}.json").write_text(json.dumps(doc))
    assert _paired_worlds(tmp_path)[PAIRED_WORLDS[0]]["false_alarms"] == (
        "0 in 1.22 h against 4 in 1.19 h of right tracking (exact test of two Poisson rates p = 0.12)"
    )


def test_two_false_alarm_rates_are_compared_by_their_exposures():
    """eval.analyses.paired_worlds.rates_exact: equal counts over equal hours are no difference (p = 1); 0 against 4
    over equal hours is 2 / 2^4; over unequal hours the expected share moves; 0 against 0 says nothing."""
    from eval.analyses.paired_worlds import rates_exact

    assert rates_exact(3, 1.0, 3, 1.0) == pytest.approx(1.0)
    assert rates_exact(0, 1.0, 4, 1.0) == pytest.approx(2 / 16)
    assert rates_exact(0, 3.0, 4, 1.0) < rates_exact(0, 1.0, 4, 1.0) < rates_exact(0, 1.0, 4, 3.0)
    assert rates_exact(0, 1.0, 0, 2.0) == 1.0


def test_the_seeds_of_one_recipe_make_one_row_per_card_with_medians_and_spans():
    """synthesis_table: kept NOF runs named <recipe> and <recipe>_s<seed>, on one card and with as many epochs, make
    one row (medians [min-max], the seed count); a run of the recipe on another card is a row of its own; a lone
    <name>_s1 keeps its name; the grids appear once."""

    def pair(mae, secs, gpu, epochs=5):
        m = {"mae_m": mae, "median_error_m": mae / 4, "accuracy_pct": 90.0, "chamfer_m": mae / 2, "fscore_pct": 97.0}
        syn = {"dataset": "fr079", "split": "test", "methods": {"NOF (x)": {"kind": "nof", **m}}}
        syn["methods"]["OGM 5 cm"] = {"kind": "grid", **m}
        return syn, {"train_time_s": secs, "epochs_done": epochs, "gpu": gpu, "device": "cuda:0"}

    runs = {
        ("fr079", "x"): pair(0.25, 30.0, "H100"),
        ("fr079", "x_s1"): pair(0.24, 16.0, "H100"),
        ("fr079", "x_s2"): pair(0.26, 17.0, "H100"),
        ("fr079", "x_s3"): pair(0.30, 10.0, "H200"),
        ("fr079", "lone_s1"): pair(0.28, 12.0, "H100"),
    }
    lines = synthesis_table(runs).splitlines()[2:]
    assert len(lines) == 4, lines  # x on the H100, x on the H200, lone_s1, one grid
    grouped = next(line for line in lines if "(x, 3 seeds)" in line)
    assert "| 0.250 [0.240-0.260] |" in grouped and grouped.endswith("| 17 [16-30] s, 5 ep, H100 |")
    assert any("| NOF (x_s3) | 0.300 |" in line and line.endswith("10 s, 5 ep, H200 |") for line in lines)
    assert any("| NOF (lone_s1) | 0.280 |" in line for line in lines)
    assert sum("OGM 5 cm" in line for line in lines) == 1


def test_keep_check_files_runs_under_their_log_and_refuses_an_edited_one(tmp_path):
    """``python -m eval.keep --check STUDY``: each run goes into results/checks/STUDY.json under the log its manifest
    names; a run whose metrics are not what it wrote stops the call, naming the folder."""
    from eval.keep import keep_checks
    from eval.results.records import checks

    gpu, results = tmp_path / "gpu", tmp_path / "results"
    fr079 = fake_run(gpu, "synthesis", composed(*FR079_FAST), _synthesis(0.3, 0.33))
    intel = fake_run(gpu, "synthesis", composed("+exp=intel", "train=fast"), _synthesis(0.2, 0.25))
    keep_checks("demo", [fr079, intel], results)
    kept = checks("demo", results)
    assert sorted(r.exp for r in kept) == ["fr079", "intel"]
    assert {r.exp: r["methods"]["NOF (fast)"]["mae_m"] for r in kept} == {"fr079": 0.3, "intel": 0.2}
    (intel / "metrics.json").write_text(json.dumps(_synthesis(0.1, 0.25)))  # edited after the run
    with pytest.raises(SystemExit, match=re.escape(str(intel))):
        keep_checks("demo", [intel], results)
