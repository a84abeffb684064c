"""The layers (docs/architecture.md): import-linter keeps them, and breaks on an upward import;
the installed package has one import name, a small top level and no long function; the old
module names still import, with a warning; no layer probes a task or a controller for what it
offers."""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "README.md", "peg_ctrl", "controllers", "planners", "experiments")
LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"
CONTRACTS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A non-editable install (``pip install .``, without dependencies) of a copy of the sources,
    built outside the repository so that it leaves nothing there."""
    tmp = tmp_path_factory.mktemp("wheel")
    (tmp / "src").mkdir()
    for name in SOURCES:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, tmp / "src" / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, tmp / "src" / name)
    cmd = [sys.executable, "-m", "pip", "install", "--quiet", "--no-index", "--no-deps"]
    cmd += ["--no-build-isolation", "--target", str(tmp / "site"), str(tmp / "src")]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return tmp / "site"


def _lint(site: Path) -> subprocess.CompletedProcess[str]:
    cmd = [str(LINT_IMPORTS), str(ROOT / "pyproject.toml"), "--no-cache", "--no-logo"]
    return subprocess.run(cmd, cwd=site, capture_output=True, text=True, env={"PYTHONPATH": str(site)})


def test_the_contracts_hold_at_least_four_layers_and_independence() -> None:
    layers = next(c for c in CONTRACTS if c["type"] == "layers")["layers"]
    assert len(layers) >= 4
    assert {c["type"] for c in CONTRACTS} >= {"layers", "independence", "acyclic_siblings"}


def test_the_package_keeps_its_import_contracts(site: Path) -> None:
    proc = _lint(site)
    assert proc.returncode == 0, proc.stdout[-3000:]
    assert f"Contracts: {len(CONTRACTS)} kept, 0 broken." in proc.stdout


@pytest.mark.parametrize(
    "module, line, broken",
    [
        (
            "sim/state.py",
            "from peg_ctrl.run.episode import run_episode",
            "peg_ctrl.sim.state -> peg_ctrl.run",
        ),
        ("controllers/pd.py", "import peg_ctrl.tasks.base", "peg_ctrl.controllers.pd -> peg_ctrl.tasks"),
        (
            "sim/physics.py",
            "from peg_ctrl.sim.scene import SceneConfig",
            "No cycles are allowed in peg_ctrl.sim",
        ),
    ],
    ids=["upward", "controllers-import-tasks", "cycle"],
)
def test_a_deliberate_bad_import_breaks_a_contract(
    site: Path, tmp_path: Path, module: str, line: str, broken: str
) -> None:
    bad = tmp_path / "site"
    shutil.copytree(site, bad)
    path = bad / "peg_ctrl" / module
    path.write_text(path.read_text() + f"\n{line}  # deliberately against the architecture\n")
    proc = _lint(bad)
    assert proc.returncode == 1
    assert broken in proc.stdout, proc.stdout[-3000:]


def test_one_import_name_and_a_small_top_level(site: Path) -> None:
    names = {p.name for p in site.iterdir() if not p.name.endswith(".dist-info") and p.name != "bin"}
    assert names == {"peg_ctrl"}
    modules = sorted(p.name for p in (site / "peg_ctrl").glob("*.py"))
    assert len(modules) <= 9, modules  # the foundation modules, __init__ and __main__
    packages = {p.name for p in (site / "peg_ctrl").iterdir() if (p / "__init__.py").is_file()}
    assert {
        "sim",
        "tasks",
        "controllers",
        "planners",
        "run",
        "gym",
        "teleop",
        "experiments",
        "tools",
        "cli",
    } <= packages


def test_no_function_is_longer_than_60_lines(site: Path) -> None:
    long = []
    for path in (site / "peg_ctrl").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1  # type: ignore[operator]
                if n > 60:
                    long.append(f"{path.relative_to(site)}:{node.lineno} {node.name} ({n} lines)")
    assert long == []


@pytest.mark.parametrize(
    "old, new",
    [
        ("peg_ctrl.episode", "peg_ctrl.run.episode"),
        ("peg_ctrl.scene", "peg_ctrl.sim.scene"),
        ("peg_ctrl.gym_env", "peg_ctrl.gym.env"),
    ],
)
def test_an_old_module_name_imports_the_same_module_with_a_warning(
    old: str, new: str, tmp_path: Path
) -> None:
    code = (
        "import warnings\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        f"    import {old} as moved\n"
        f"import {new} as home\n"
        "assert moved is home, (moved, home)\n"
        f"assert home.__spec__.name == {new!r}, home.__spec__\n"
        "print([str(w.message) for w in caught if w.category is DeprecationWarning])\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert f"{old} moved to {new}" in proc.stdout


def test_the_architecture_page_draws_the_contract_s_layers_in_order() -> None:
    """docs/architecture.md's picture has a node per package of the layers contract, top down."""
    page = (ROOT / "docs" / "architecture.md").read_text()
    chart = page.split("```mermaid", 1)[1].split("```", 1)[0]
    nodes = [line.split("[", 1)[0].strip() for line in chart.splitlines() if '["<b>' in line]
    layers = next(c for c in CONTRACTS if c["type"] == "layers")["layers"]
    drawn = []
    for layer in layers:
        names = [name.strip().removeprefix("peg_ctrl.") for name in layer.replace(":", "|").split("|")]
        foundation = all((ROOT / "peg_ctrl" / f"{name}.py").is_file() for name in names)
        drawn += ["foundation"] if foundation else names
    assert list(dict.fromkeys(drawn)) == nodes


#: Calls that look an attribute up by name, and what must not be their first argument: a task or
#: a controller (or a composite's inner one), by the name of the expression that holds it.
_PROBES = ("getattr", "hasattr", "getattr_static")
_COMPONENT = re.compile(r"task|controller|inner", re.IGNORECASE)


def _probes(path: Path) -> list[tuple[int, str]]:
    """The calls in ``path`` that look up a task's or a controller's attribute by name, outside
    ``check_capabilities`` (the one place that compares a task's members with its declaration)."""
    tree = ast.parse(path.read_text())
    allowed: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == "check_capabilities":
            allowed.update(range(node.lineno, node.end_lineno + 1))  # type: ignore[operator]
    found = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and node.args) or node.lineno in allowed:
            continue
        func = node.func
        name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
        if name in _PROBES and _COMPONENT.search(ast.unparse(node.args[0])):
            found.append((node.lineno, ast.unparse(node)))
    return found


def test_the_probe_finder_finds_a_probe_of_a_task_and_not_of_a_config(tmp_path: Path) -> None:
    source = tmp_path / "probe.py"
    source.write_text(
        "def f(loop, inner, config):\n"
        "    a = getattr(loop.task, 'belief', None)\n"
        "    b = hasattr(inner, 'insertion')\n"
        "    c = inspect.getattr_static(self.controller, 'timings')\n"
        "    return getattr(config, 'name')\n"
    )
    assert [line for line, _ in _probes(source)] == [2, 3, 4]


def test_no_layer_probes_a_task_or_a_controller_for_what_it_offers() -> None:
    """What a task offers is declared (``Capabilities`` in peg_ctrl/tasks/base.py) and what a
    controller offers is in its protocol (controllers/base.py): nothing looks either up by name."""
    found = [
        f"{path.relative_to(ROOT)}:{line}: {call}"
        for package in ("peg_ctrl", "controllers", "planners", "experiments")
        for path in sorted((ROOT / package).rglob("*.py"))
        for line, call in _probes(path)
    ]
    assert found == []
