"""Entry points as a user meets them: an expected error is one line on stderr and exit status 2, never a
traceback (IRMCL_TRACEBACK=1 shows it); and the README's test command works without the shared data."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from irmcl_warp.config import ConfigError, SimConfig, validate
from irmcl_warp.io import write_bag
from irmcl_warp.sim import simulate

REPO = Path(__file__).resolve().parents[1]


def _run(args, cwd, **env):
    e = {**os.environ, **env}
    e.pop("IRMCL_TRACEBACK", None) if "IRMCL_TRACEBACK" not in env else None
    if args[0].startswith("eval."):  # the repository's tools, not installed with the package: run from the checkout
        e["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), e.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, env=e, timeout=300)


def _one_clean_line(run, *needles):
    assert run.returncode == 2, (run.returncode, run.stderr[-2000:])
    assert "Traceback" not in run.stderr and "Traceback" not in run.stdout, run.stderr[-2000:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and all(n in errors[0] for n in needles), run.stderr[-2000:]


def test_expected_errors_are_one_line_and_exit_2(tmp_path):
    log, _ = simulate(OmegaConf.structured(SimConfig(duration_s=3.0, num_beams=20, width_m=12, height_m=8)), "cpu")
    bag = write_bag(log, tmp_path / "sim.bag")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    _one_clean_line(_run(["irmcl_warp.inspect", "data=bag", f"data.path={cut}"], tmp_path), str(cut))
    _one_clean_line(
        _run(["irmcl_warp.inspect", "data=bag", f"data.path={tmp_path / 'none.bag'}"], tmp_path), "none.bag"
    )
    _one_clean_line(_run(["irmcl_warp.slam", "slam.num_particles=0"], tmp_path), "slam.num_particles=0", ">= 1")
    _one_clean_line(_run(["irmcl_warp.localize", "+mcl.foo=1"], tmp_path), "mcl.foo", "no such setting")
    shown = _run(["irmcl_warp.slam", "slam.num_particles=0"], tmp_path, IRMCL_TRACEBACK="1")
    assert shown.returncode != 0 and "Traceback" in shown.stderr and "ConfigError" in shown.stderr


def test_settings_are_checked_by_key_and_range():
    from hydra import compose, initialize_config_dir

    from irmcl_warp.config import register

    register()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        validate(compose("config"))  # the defaults pass
        for override, message in [
            ("mcl.num_particles=-5", "mcl.num_particles=-5: expected a number >= 1"),
            ("mapping.resolution_m=0", "mapping.resolution_m=0.0: expected a number > 0"),
            ("localize.run_s=-5", "localize.run_s=-5.0"),
            ("data.max_step_m=-1", "data.max_step_m"),
            ("data.beam_policy=resampel", "expected one of error, reject, resample"),
            ("+foo=1", "foo: no such setting"),
            ("+mcl.foo=1", "mcl.foo: no such setting"),
        ]:
            with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
                validate(compose("config", overrides=[override]))


def test_every_test_reading_the_shared_data_is_marked_data():
    """Without the marker, a clone with no ../shared fails instead of skipping (issue 19)."""
    unmarked = []
    for f in sorted((REPO / "tests").glob("test_*.py")):
        if "pytestmark = pytest.mark.data" in f.read_text():
            continue  # the whole module is marked
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.FunctionDef) and any(a.arg == "data_dir" for a in node.args.args):
                marks = [ast.unparse(d) for d in node.decorator_list]
                if "pytest.mark.data" not in marks:
                    unmarked.append(f"{f.name}::{node.name}")
    assert unmarked == []


@pytest.mark.slow
def test_data_tests_skip_without_the_data_and_fail_when_ci_requires_it(tmp_path):
    """The README's test command in a clone with nothing beside it: the data tests are skipped and listed;
    with IRMCL_REQUIRE_DATA=1 (CI) their absence fails."""
    missing = str(tmp_path / "no-shared-data")
    args = ["pytest", "-q", "-m", "data", "-p", "no:cacheprovider", str(REPO / "tests")]
    free = _run(args, REPO, IRMCL_DATA=missing, IRMCL_REQUIRE_DATA="0")
    assert free.returncode == 0 and " skipped" in free.stdout and "failed" not in free.stdout, free.stdout[-2000:]
    required = _run(args, REPO, IRMCL_DATA=missing, IRMCL_REQUIRE_DATA="1")
    assert required.returncode == 1 and "shared data is missing" in required.stdout, required.stdout[-2000:]


@pytest.mark.parametrize(
    "entry",
    [
        "irmcl_warp.slam",
        "irmcl_warp.train",
        "irmcl_warp.localize",
        "irmcl_warp.globloc",
        "irmcl_warp.inspect",
        "irmcl_warp.pipeline",
        "irmcl_warp.synthesis",
        "irmcl_warp.relations",
    ],
)
def test_every_hydra_entry_point_starts_and_checks_its_settings(tmp_path, entry):
    _one_clean_line(_run([entry, "mcl.num_particles=0"], tmp_path), "mcl.num_particles=0", ">= 1")


def test_argparse_entry_points_report_bad_input_without_a_traceback(tmp_path):
    _one_clean_line(
        _run(["eval.bench", "mcl", "--nog", str(tmp_path / "none.npz"), "--out", str(tmp_path)], tmp_path), "none.npz"
    )
    kept = _run(["eval.keep", str(tmp_path / "not-a-run"), "--results", str(tmp_path / "results")], tmp_path)
    assert kept.returncode == 2 and "not a finished run" in kept.stderr and "Traceback" not in kept.stderr


@pytest.mark.parametrize(
    "mistake, said", [("mcl.no_such_key=1", "no_such_key"), ("+exp=no_such_experiment", "no_such_experiment")]
)
def test_hydra_s_own_mistakes_exit_2_as_ours_do(tmp_path, mistake, said):
    run = _run(["irmcl_warp.inspect", mistake], tmp_path)
    assert run.returncode == 2 and said in run.stderr, (run.returncode, run.stderr[-2000:])
    assert "Traceback" not in run.stderr


def test_hydra_s_log_file_holds_what_the_run_said(tmp_path):
    run = _run(["irmcl_warp.inspect", "sim.duration_s=4", "sim.num_beams=30", "device=cpu"], tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    text = (tmp_path / "outputs" / "sim_office" / "inspect.log").read_text()
    assert "[INFO] - sim_office: 20 scans of 30 beams" in text and "map from ground truth" in text
    failed = _run(["irmcl_warp.inspect", "data=bag", f"data.path={tmp_path / 'none.bag'}"], tmp_path)
    assert failed.returncode == 2
    assert "[WARNING] - error: " in (tmp_path / "outputs" / "bag" / "inspect.log").read_text()
