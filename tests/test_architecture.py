"""The floors of docs/ARCHITECTURE.md as checks: the import contracts of pyproject.toml (import-linter) hold,
a forbidden import breaks them, and no module imports itself through others (no cycles between files)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import grimp
import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("irmcl_warp", "eval")  # the top-level kernels/ is irmcl_warp.kernels (irmcl_warp/kernels links to it)
FOLDERS = ("irmcl_warp", "kernels", "conf", "eval")


def _lint(root: Path) -> subprocess.CompletedProcess:
    """lint-imports on the packages under ``root`` (its pyproject.toml), as CI would run it."""
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    env = {"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"}
    return subprocess.run(
        [sys.executable, "-c", code, "--config", str(root / "pyproject.toml")],
        cwd=root,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


def test_import_contracts_hold():
    run = _lint(REPO)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "0 broken" in run.stdout


@pytest.mark.parametrize(
    "importer, forbidden, contract",
    [
        ("kernels/grid.py", "from irmcl_warp.nof.model import NOF", "kernels is a leaf"),
        ("irmcl_warp/slam/stage.py", "from irmcl_warp.mcl.stage import run_localize", "no stage imports another stage"),
        ("irmcl_warp/services/data.py", "from eval.tables import main", "(and the runs module) import no stage"),
    ],
)
def test_a_forbidden_import_breaks_a_contract(tmp_path, importer, forbidden, contract):
    for name in FOLDERS:  # the links in irmcl_warp/ stay links, to the copies
        shutil.copytree(REPO / name, tmp_path / name, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    with open(tmp_path / importer, "a") as f:
        f.write(f"\n{forbidden}  # noqa\n")
    run = _lint(tmp_path)
    assert run.returncode != 0 and f"{contract}" in run.stdout and "BROKEN" in run.stdout, run.stdout[-3000:]


def test_the_kernels_leaf_contract_names_every_other_part_of_the_package():
    """ "kernels is a leaf" lists the package's other modules one by one (a contract cannot forbid the package
    that holds its source): a new module must join the list, or kernels could import it unseen."""
    import tomllib

    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    (leaf,) = [c for c in contracts if c["name"].startswith("kernels is a leaf")]
    parts = {
        f"irmcl_warp.{p.stem}"
        for p in (REPO / "irmcl_warp").iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()
    }
    assert parts - {"irmcl_warp.kernels", "irmcl_warp.conf"} == set(leaf["forbidden_modules"]) - {"eval"}


def test_no_module_imports_itself_through_others():
    graph = grimp.build_graph(*PACKAGES, include_external_packages=False)
    cycles = sorted(
        {
            tuple(sorted((a, b)))
            for a in graph.modules
            for b in graph.find_modules_directly_imported_by(a)
            if graph.chain_exists(importer=b, imported=a)
        }
    )
    assert cycles == [], cycles


FOLDER_LITERAL = re.compile(
    r"""["'](?:localize|slam|train|synthesis|globloc|pipeline|inspect|relations)-|"""
    r"reference-(?:gmapping|irmcl)|stage_dir|run_tag|train_folder"
)
FOLDER_BUILT = re.compile(r"\s/\s*(?:cfg\.)?exp\s*/|\{(?:cfg\.)?exp\}/")


def test_run_folders_are_named_in_one_place():
    """No run-folder string literal in eval or the package, and no module but irmcl_warp/runs.py joins an
    experiment and a stage into a run's path: runs are found by their settings (irmcl_warp.runs.find)."""
    found = []
    for path in sorted(p for pkg in ("irmcl_warp", "eval") for p in (REPO / pkg).rglob("*.py")):
        if path == REPO / "irmcl_warp" / "runs.py":
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if FOLDER_LITERAL.search(line) or FOLDER_BUILT.search(line):
                found.append(f"{path.relative_to(REPO)}:{n}: {line.strip()}")
    assert found == []


def test_the_linter_finds_nothing():
    """ruff's default rules (pyflakes and pycodestyle's errors: unused or undefined names, ambiguous names, ...)
    over the repository, as pyproject.toml configures it."""
    run = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--output-format", "concise", str(REPO)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-1000:]


def test_the_code_is_formatted():
    """``ruff format --check``: the formatter's style, at the ruff version pyproject.toml pins (formatters change
    their style between releases; `ruff format .` with that version fixes what this finds)."""
    run = subprocess.run(
        [sys.executable, "-m", "ruff", "format", "--check", str(REPO)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-1000:]


# the far bound's former names; the sensor's largest reading (LaserInfo.range_max_m, sim.range_max_m, a
# CARMEN header's range_max) is another quantity and keeps its own name
FAR_BOUND_ALIASES = {"far", "usable", "usable_range_m", "max_range", "max_range_m"}


def far_bound_aliases(source: str) -> list[tuple[int, str]]:
    """(line, name) of every identifier or f-string field in ``source`` spelled as a former name of the far
    bound; prose in comments and strings is not code and is left alone."""
    import io
    import tokenize

    found = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NAME and tok.string in FAR_BOUND_ALIASES:
            found.append((tok.start[0], tok.string))
        elif tok.type == tokenize.STRING and tok.string.lstrip("rRbB").lower().startswith(("f", "rf")):
            for name in re.findall(r"\{([A-Za-z_]\w*)", tok.string):
                if name in FAR_BOUND_ALIASES:
                    found.append((tok.start[0], name))
    return found


def test_the_far_bound_has_one_name():
    """Issue 34: the sensor's far bound is ``far_m`` in every file of the package, the kernels, eval and the
    configs (it had five names and two fallbacks); the checker itself sees a planted alias."""
    assert far_bound_aliases("def f(usable_range_m):\n    return f'{far}'  # far is prose\n") == [
        (1, "usable_range_m"),
        (2, "far"),
    ]
    bad = []
    for folder in ("irmcl_warp", "kernels", "eval", "tests"):
        for path in sorted((REPO / folder).rglob("*.py")):
            if "kernels" in path.parts[len(REPO.parts) :] and folder == "irmcl_warp":
                continue  # irmcl_warp/kernels is a link to kernels/
            bad += [f"{path.relative_to(REPO)}:{line}: {name}" for line, name in far_bound_aliases(path.read_text())]
    for path in sorted((REPO / "conf").rglob("*.yaml")):
        text = path.read_text()
        bad += [
            f"{path.relative_to(REPO)}: {m}" for m in re.findall(r"^\s*(\w+):", text, re.M) if m in FAR_BOUND_ALIASES
        ]
    assert not bad, "the far bound is far_m everywhere:\n" + "\n".join(bad)


def step_shape(path: Path, cls: str, method: str) -> tuple[int, list[str], list[int]]:
    """(statements in ``cls.method`` without its docstring, the names it calls, the lines of its top-level calls
    that carry no comment)."""
    import ast

    source = path.read_text()
    tree = ast.parse(source)
    node = next(
        f
        for c in ast.walk(tree)
        if isinstance(c, ast.ClassDef) and c.name == cls
        for f in c.body
        if isinstance(f, ast.FunctionDef) and f.name == method
    )
    body = node.body[1:] if ast.get_docstring(node) else node.body
    statements = sum(isinstance(n, ast.stmt) for s in body for n in ast.walk(s))
    called = sorted(
        {
            n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", "")
            for s in body
            for n in ast.walk(s)
            if isinstance(n, ast.Call)
        }
    )
    lines = source.splitlines()
    uncommented = []
    for s in body:
        for n in ast.walk(s):  # the calls of the step's own parts: self._part(...)
            if (
                isinstance(n, ast.Call)
                and isinstance(n.func, ast.Attribute)
                and isinstance(n.func.value, ast.Name)
                and n.func.value.id == "self"
                and n.func.attr.startswith("_")
                and "#" not in lines[n.lineno - 1]
            ):
                uncommented.append(n.lineno)
    return statements, called, uncommented


@pytest.mark.parametrize(
    "path, cls, method",
    [("irmcl_warp/mcl/filter.py", "ParticleFilter", "step"), ("irmcl_warp/slam/rbpf.py", "RBPF", "step")],
)
def test_the_filter_steps_read_like_the_papers(path, cls, method):
    """Issue 34: ParticleFilter.step (motion -> weighting -> resampling -> estimate) and RBPF.step (GMapping's
    odometry -> decide -> propose -> weigh -> resample -> integrate) are short sequences of commented calls of
    their parts, with no timing inside (RBPF's parts are timed by a decorator around them)."""
    statements, called, uncommented = step_shape(REPO / path, cls, method)
    assert statements <= 25, f"{cls}.{method}: {statements} statements"
    timing = {"perf_counter", "time", "monotonic", "_tick", "_synced_clock", "synchronize"}
    assert not timing & set(called), f"{cls}.{method} times itself: {sorted(timing & set(called))}"
    assert not uncommented, f"{cls}.{method}: the parts called on lines {uncommented} carry no comment"
    assert len([c for c in called if c.startswith("_")]) >= 4  # the paper's steps are calls, not inline code
