"""The documentation's examples run: every ``python`` block of the pages below is executed in a
fresh namespace, in a temporary working directory."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGES = ("../README.md", "api.md", "rl.md", "sensing.md")
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _examples() -> list[tuple[str, str]]:
    found = []
    for page in PAGES:
        text = (DOCS / page).read_text(encoding="utf-8")
        for i, match in enumerate(_BLOCK.finditer(text)):
            line = text.count("\n", 0, match.start()) + 1
            found.append((f"{Path(page).name}:{line}", match.group(1)))
            assert i < 50
    return found


EXAMPLES = _examples()
# Examples that run for long, by what they call: a sweep of four whole episodes (the sweeps of
# tests/experiments run in the default suite) and PPO training (tests/experiments/test_rl.py).
SLOW_CALLS = ("run_sweep(", "PPO(")


def test_every_page_has_examples() -> None:
    assert len(EXAMPLES) >= 6


@pytest.mark.parametrize(
    ("where", "code"),
    [
        pytest.param(
            where, code, id=where, marks=pytest.mark.slow if any(c in code for c in SLOW_CALLS) else ()
        )
        for where, code in EXAMPLES
    ],
)
def test_example_runs(where: str, code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    # A real module, as a script's would be: dataclasses and type hints look their module up.
    module = types.ModuleType("docs_example")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    # What an example registers stays in its test: the registries are restored afterwards.
    from peg_ctrl.controllers import REGISTRY
    from peg_ctrl.tasks.strategies import STRATEGIES

    snapshots = [(r, dict(r)) for r in (REGISTRY, STRATEGIES)]
    try:
        exec(compile(code, where, "exec"), module.__dict__)  # noqa: S102 - our own documentation
    finally:
        for registry, saved in snapshots:
            registry.clear()
            registry.update(saved)


# -- the held-insertion episode the README and `make demo` run ----------------------------------

ROOT = DOCS.parent
HELD_INSERTION = DOCS / "demo" / "held_insertion.yaml"
# The row of the featured comparison it reproduces: mpc/align, friction 0.3, 1 mm, no tilt, seed 0.
HELD_INSERTION_KEY = "38d1b53e10f3e7e1"


def _contact_hard_row(key: str) -> dict[str, str]:
    import csv

    with open(DOCS / "contact_hard" / "episodes.csv", newline="") as fh:
        (row,) = [r for r in csv.DictReader(fh) if r["key"] == key]
    return row


def test_the_held_insertion_config_is_a_contact_hard_episode() -> None:
    from peg_ctrl.config import read_mapping
    from peg_ctrl.experiments.config import expand, load_experiment
    from peg_ctrl.run.episode import episode_config_from_mapping

    cfg = episode_config_from_mapping(read_mapping(HELD_INSERTION))
    (job,) = [
        j
        for j in expand(load_experiment(ROOT / "experiments" / "configs" / "contact_hard.yaml"))
        if j.config == cfg
    ]
    assert job.key == HELD_INSERTION_KEY
    row = _contact_hard_row(job.key)
    cell = {k: row[k] for k in ("arm", "seed", "scene.friction", "task.lateral_error", "task.tilt_error")}
    assert cell == {
        "arm": "mpc/align",
        "seed": "0",
        "scene.friction": "0.3",
        "task.lateral_error": "0.001",
        "task.tilt_error": "0.0",
    }


@pytest.mark.slow
def test_the_held_insertion_config_reproduces_its_sweep_episode(tmp_path: Path) -> None:
    import json

    from peg_ctrl.run.episode import WALL_CLOCK_FIELDS

    from .conftest import peg_sim

    # In a fresh interpreter, as the README runs it: this one imported numpy before peg_ctrl, so its
    # BLAS runs more than one thread, which changes the MPC's results in the 11th digit.
    proc = peg_sim(["run", "--config", str(HELD_INSERTION), "--out", str(tmp_path)], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    row = _contact_hard_row(HELD_INSERTION_KEY)
    compared = [k for k in row if k in summary and k not in {*WALL_CLOCK_FIELDS, "log_path"}]
    assert {"status", "peak_contact_force_n", "time_to_insert_s", "total_timesteps"} <= set(compared)
    for name in compared:
        value = summary[name]
        expected = row[name]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            assert value == float(expected), name
        else:
            assert ("" if value is None else str(value)) == expected, name


# -- links ----------------------------------------------------------------------------------------

_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _anchors(page: Path) -> set[str]:
    """GitHub's anchors of a Markdown page's headings."""
    found = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            found.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return found


@pytest.mark.parametrize("page", ["README.md", "docs/guide.md", "docs/api.md", "docs/contact_real.md"])
def test_every_relative_link_resolves(page: str) -> None:
    path = ROOT / page
    broken = []
    for target in _LINK.findall(path.read_text(encoding="utf-8")):
        if re.match(r"^(https?:|mailto:)", target):
            continue
        file, _, anchor = target.partition("#")
        resolved = (path.parent / file) if file else path
        if not resolved.exists():
            broken.append(target)
        elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
            broken.append(target)
    assert broken == []
