"""Packaging: every module imports first in a fresh interpreter, and nothing is left out of the wheel."""

from __future__ import annotations

import importlib.util
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import FirstImports

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parent.parent
SETUPTOOLS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
PACKAGES: list[str] = SETUPTOOLS["packages"]
DATA_PACKAGES = {"peg_ctrl.data", "peg_ctrl.experiments.configs"}  # folders of data, no code


def _package_dir(package: str) -> Path:
    """Where ``package`` lives, found without importing it (its parents are imported)."""
    spec = importlib.util.find_spec(package)
    assert spec is not None and spec.submodule_search_locations, package
    return Path(next(iter(spec.submodule_search_locations)))


def _all_modules() -> list[str]:
    """Every module of the installed packages (walking each package listed in pyproject, since
    the editable install maps peg_ctrl.controllers etc. from other folders)."""
    names = set(PACKAGES)
    for package in PACKAGES:
        for info in pkgutil.walk_packages([str(_package_dir(package))], prefix=f"{package}."):
            names.add(info.name)
    return sorted(names)


MODULES = _all_modules()


@pytest.mark.parametrize("module", MODULES)
def test_module_imports_first(module: str, tmp_path: Path, first_imports: FirstImports) -> None:
    proc = first_imports.run(f"import {module}", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr.strip().splitlines()[-1:]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # ~1 s each; the test above imports each module first in a fork, in 0.1 s
@pytest.mark.parametrize("module", MODULES)
def test_module_imports_first_in_a_fresh_interpreter(module: str, tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-c", f"import {module}"], capture_output=True, text=True, cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stderr.strip().splitlines()[-1:]
    assert list(tmp_path.iterdir()) == []


def test_every_package_is_listed_for_the_wheel() -> None:
    """A subpackage missing from ``[tool.setuptools] packages`` would be absent when installed."""
    mapped = {v: k for k, v in SETUPTOOLS.get("package-dir", {}).items()}
    found = set()
    for top in ("peg_ctrl", *mapped):
        for init in (ROOT / top).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT).parts
            name = ".".join((mapped[rel[0]], *rel[1:])) if rel[0] in mapped else ".".join(rel)
            found.add(name)
    assert found == set(PACKAGES) - DATA_PACKAGES
    for package in DATA_PACKAGES:  # listed with their files as package data
        assert package in PACKAGES and SETUPTOOLS["package-data"][package]


def test_shipped_experiments_are_package_data() -> None:
    configs = sorted(p.name for p in (ROOT / "experiments" / "configs").glob("*"))
    assert configs and all(name.endswith(".yaml") for name in configs)
    assert SETUPTOOLS["package-data"]["peg_ctrl.experiments.configs"] == ["*.yaml"]


def test_python_dash_m_runs_the_cli(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", "--help"], capture_output=True, text=True, cwd=tmp_path
    )
    assert proc.returncode == 0 and proc.stdout.startswith("usage: peg-sim")
