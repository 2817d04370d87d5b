"""The package as a user installs it: what the wheel holds (the configs and kernels inside irmcl_warp, nothing
under a top-level name another distribution uses), the ``irmcl-warp`` command, and a CPU machine's start.
CI also installs the wheel into a fresh venv and runs the command outside the checkout (.ci/wheel)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import warp as wp

import irmcl_warp
from irmcl_warp import cli

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> zipfile.ZipFile:
    """Built from a copy of the checkout's files (tracked, or new and not ignored; links kept as links), so that a
    stale build/ folder cannot slip old modules in and a file git does not carry cannot make it work here only."""
    src, out = tmp_path_factory.mktemp("src"), tmp_path_factory.mktemp("dist")
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split("\0")
    for name in filter(None, listed):
        path, to = REPO / name, src / name
        if not path.is_symlink() and not path.is_file():
            continue  # deleted in the working tree
        to.parent.mkdir(parents=True, exist_ok=True)
        to.symlink_to(path.readlink()) if path.is_symlink() else shutil.copy2(path, to)
    run = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(out), str(src)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    (built,) = out.glob("irmcl_warp-*.whl")
    return zipfile.ZipFile(built)


def test_the_wheel_holds_the_package_its_configs_and_kernels_and_no_foreign_top_level_name(wheel):
    names = wheel.namelist()
    info = f"irmcl_warp-{irmcl_warp.__version__}.dist-info"
    assert {n.split("/")[0] for n in names} == {"irmcl_warp", "hydra_plugins", info}
    configs = {f"irmcl_warp/conf/{p.relative_to(REPO / 'conf').as_posix()}" for p in (REPO / "conf").rglob("*.yaml")}
    kernels = {f"irmcl_warp/kernels/{p.name}" for p in (REPO / "kernels").glob("*.py")}
    assert configs <= set(names) and kernels <= set(names) and len(configs) > 40
    assert set(n for n in names if n.startswith("irmcl_warp/mcl/calibration/")) == {
        f"irmcl_warp/mcl/calibration/{p.name}" for p in (REPO / "irmcl_warp/mcl/calibration").glob("*.json")
    }
    entry = wheel.read(f"{info}/entry_points.txt").decode()
    assert "irmcl-warp = irmcl_warp.cli:main" in entry
    assert f"Version: {irmcl_warp.__version__}\n" in wheel.read(f"{info}/METADATA").decode()


def test_every_command_is_a_stage_with_a_hydra_main_and_examples():
    import importlib

    for name, (module, about, examples) in cli.COMMANDS.items():
        main = importlib.import_module(module).main
        assert callable(main) and about and examples
        assert all(e.startswith(f"irmcl-warp {name}") for e in examples)


def test_version_help_and_a_mistyped_command(capsys):
    cli.main(["--version"])
    assert capsys.readouterr().out.strip() == f"irmcl-warp {irmcl_warp.__version__}"
    cli.main([])
    listing = capsys.readouterr().out
    assert all(f"  {name} " in listing for name in cli.COMMANDS)
    cli.main(["localize", "--help"])
    text = capsys.readouterr().out
    assert text.startswith("irmcl-warp localize: ") and "examples:" in text and "--cfg job" in text
    with pytest.raises(SystemExit) as e:
        cli.main(["locallize"])
    assert e.value.code == 2 and "did you mean 'localize'" in capsys.readouterr().err


def test_the_command_finds_its_configs_as_package_data(tmp_path, monkeypatch, capsys):
    """Hydra reads the configs as pkg://irmcl_warp.conf, as it must once installed (no ../conf beside the module)."""
    monkeypatch.chdir(tmp_path)
    cli.main(["localize", "--cfg", "job", "+exp=worlds"])
    out = capsys.readouterr().out
    assert "weighting: likelihood_field" in out and "split:" in out  # conf/exp/worlds.yaml was composed
    assert not (tmp_path / "outputs").exists()  # --cfg prints and runs nothing


@pytest.mark.skipif(wp.is_cuda_available(), reason="the check is for a machine without a GPU")
def test_a_cpu_machine_starts_quietly_and_refuses_a_cuda_device():
    code = "from irmcl_warp.kernels import pick_device; print(pick_device()); pick_device('cuda:0')"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.stdout.strip() == "cpu"
    assert "Warp CUDA warning" not in run.stderr  # the driver line every CPU machine printed is held back
    assert "ValueError: device=cuda:0: Warp sees no CUDA device" in run.stderr
