"""``peg-sim compare``: a new arm against a committed study, the study's rows taken from its
committed run after a rerun sample reproduces them; a user's controller file loaded in the
sweep's (spawned) workers."""

from __future__ import annotations

import csv
import json
import shutil
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from peg_ctrl.cli.app import main
from peg_ctrl.errors import ConfigError
from peg_ctrl.experiments.compare import BaselineMismatch, plan_comparison, run_comparison
from peg_ctrl.experiments.config import experiment_from_mapping
from peg_ctrl.experiments.runner import run_sweep
from peg_ctrl.run.plugins import load_plugin

TINY = {"name": "tiny", "controllers": ["pd", "impedance"], "seeds": [0, 1], "max_steps": 300}

USER_FILE = '''
import dataclasses
from typing import ClassVar

from peg_ctrl.controllers import PDConfig


@dataclasses.dataclass(frozen=True, kw_only=True)
class MyConfig(PDConfig):
    """The reference PD, a third softer."""

    name: ClassVar[str] = "my_pd_{tag}"
    kp_pos: float = {kp}


NOT_A_CONFIG = 3
'''


@pytest.fixture(autouse=True)
def _registries_restored() -> Iterator[None]:
    """What a test's plugins register stays in it (the registries live as long as the process,
    and other modules' tests list them)."""
    from peg_ctrl.controllers import REGISTRY
    from peg_ctrl.tasks.strategies import STRATEGIES

    saved = [(registry, dict(registry)) for registry in (REGISTRY, STRATEGIES)]
    yield
    for registry, before in saved:
        registry.clear()
        registry.update(before)


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A committed run as docs/ keeps one: the tables without the episodes' directories."""
    out = tmp_path_factory.mktemp("study") / "tiny"
    run_sweep(experiment_from_mapping(TINY), out, workers=1, progress=False, report=False)
    shutil.rmtree(out / "episodes")
    return out


def user_file(folder: Path, tag: str) -> str:
    """A controller in a file outside the package: ``PATH.py:MyConfig``, its name unique per test
    (the registry lives as long as the test process)."""
    path = folder / "my_ctrl.py"
    path.write_text(textwrap.dedent(USER_FILE.format(tag=tag, kp=2000.0)))
    return f"{path}:MyConfig"


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_only_the_new_arm_and_a_sample_run_the_rest_is_the_committed_run(study: Path, tmp_path: Path) -> None:
    comp = plan_comparison(str(study), user_file(tmp_path, "a"), assignments=["controller.kd_pos=90"])
    assert comp.arm == "my_pd_a" and comp.plugins and comp.controller["kd_pos"] == 90.0
    assert {a: len(s) for a, s in comp.sample.items()} == {"pd": 1, "impedance": 1}
    out = tmp_path / "out"
    rows = run_comparison(comp, out, workers=1, progress=False)  # a spawned worker loads the file

    ran = sorted(p.name for p in (out / "episodes").iterdir())
    sample = sorted(j.key for s in comp.sample.values() for j in s)
    assert ran == sorted([*sample, *(j.key for j in comp.new_jobs)])  # 2 new + 1 per study arm
    assert [r["arm"] for r in rows] == ["pd", "pd", "impedance", "impedance", "my_pd_a", "my_pd_a"]
    committed = {r["key"]: r for r in read_csv(study / "episodes.csv")}
    table = read_csv(out / "episodes.csv")
    for row in table[:4]:  # the study's rows are its committed rows, cell for cell
        assert row == committed[row["key"]]
    assert all(isinstance(r["peak_contact_force_n"], float) for r in rows)

    record = json.loads((out / "compare.json").read_text())
    for arm in ("pd", "impedance"):
        assert record["verified"][arm]["episodes"] == [comp.sample[arm][0].key]
        assert record["verified"][arm]["class"] == "reproduced" and record["verified"][arm]["reproduced"]
    assert record["environment"]["here"] and record["environment"]["differences"] == []  # one machine
    assert record["rerun"] == []
    report = (out / "report.md").read_text()
    assert "## my_pd_a against tiny's arms" in report
    assert "![Force profiles](force_profiles.png)" in report  # the new arm's alone
    section = report.split("## my_pd_a against tiny's arms")[1].split("\n## ")[0]
    table_rows = [line for line in section.splitlines() if line.startswith("| 1 |")]
    assert [r.split("|")[2].strip() for r in table_rows] == [
        "**my_pd_a**",
        "pd",
        "impedance",
    ]

    # The same command resumes: nothing runs again.
    again = run_comparison(
        plan_comparison(str(study), comp.plugins[0], assignments=["controller.kd_pos=90"]),
        out,
        workers=1,
        progress=False,
    )
    assert [r["key"] for r in again] == [r["key"] for r in rows]
    assert json.loads((out / "run_time.json").read_text())["invocations"] == 1  # nothing ran again
    other = plan_comparison(str(study), "pd", assignments=["controller.kp_pos=1500"])
    with pytest.raises(ConfigError, match="holds another comparison"):
        run_comparison(other, out, workers=1, progress=False)


def test_a_committed_episode_that_no_longer_reproduces_stops_it_in_one_line(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    changed = tmp_path / "tiny"
    shutil.copytree(study, changed)
    comp = plan_comparison(str(changed), "pd", assignments=["controller.kp_pos=1500"])
    victim = comp.sample["impedance"][0].key
    rows = read_csv(changed / "episodes.csv")
    for row in rows:
        if row["key"] == victim:  # an outcome no last-bit perturbation changes for this arm
            was = row["end_state"]
            row["end_state"] = "wedged" if was != "wedged" else "seated"
    with open(changed / "episodes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)

    argv = [
        "compare",
        str(changed),
        "--controller",
        "pd",
        "--set",
        "controller.kp_pos=1500",
        "--workers",
        "1",
    ]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    err = lines[-1]  # after the verification's progress lines
    assert all(line.startswith("verify tiny:") for line in lines[:-1])
    assert "committed impedance differs" in err and f"episode {victim}" in err
    assert f"end_state was {'wedged' if was != 'wedged' else 'seated'}, is {was}" in err
    assert "--rerun-baselines" in err

    comp = plan_comparison(str(changed), "pd", assignments=["controller.kp_pos=1500"])
    with pytest.raises(BaselineMismatch):
        run_comparison(comp, tmp_path / "again", workers=1, progress=False, report=False)
    # ... and the same directory takes the rerun (the failed verification's episode is reused).
    rows = run_comparison(
        comp, tmp_path / "again", workers=1, progress=False, rerun_baselines=True, report=False
    )
    record = json.loads((tmp_path / "again" / "compare.json").read_text())
    assert record["rerun"] == ["impedance"] and record["verified"]["pd"]["reproduced"]
    fresh = {r["key"]: r for r in rows}
    tampered = {r["key"]: r for r in read_csv(changed / "episodes.csv")}
    assert fresh[victim]["end_state"] != tampered[victim]["end_state"]
    assert len(list((tmp_path / "again" / "episodes").iterdir())) == 1 + 2 + 2  # pd's sample, impedance, new


def test_a_set_that_changes_what_the_study_ran_needs_rerun_baselines(study: Path, tmp_path: Path) -> None:
    fewer = plan_comparison(str(study), "pd", assignments=["controller.kp_pos=1500", "seeds=[1]"])
    assert [len(j) for j in fewer.study_jobs.values()] == [1, 1] and len(fewer.new_jobs) == 1
    assert not fewer.missing
    longer = plan_comparison(str(study), "pd", assignments=["controller.kp_pos=1500", "max_steps=200"])
    assert longer.missing == {"pd": 2, "impedance": 2}
    with pytest.raises(ConfigError, match=r"lacks 2 of pd's episodes .*--rerun-baselines"):
        run_comparison(longer, tmp_path / "out", workers=1, progress=False)
    assert not (tmp_path / "out").exists()


def test_bad_input_is_one_line_naming_it(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = user_file(tmp_path, "b")
    path = spec.rpartition(":")[0]
    cases = {
        "no_such_study": "no such directory or committed study; committed:",
        str(tmp_path): "holds no committed run (no experiment.json, episodes.csv)",
    }
    for what, message in cases.items():
        assert main(["compare", what, "--controller", "pd", "--out", str(tmp_path / "o")]) == 2
        assert message in capsys.readouterr().err
    plugins = {
        f"{tmp_path}/none.py:MyConfig": "there is no file",
        f"{path}:Missing": "defines no Missing",
        f"{path}:NOT_A_CONFIG": "is not a ControllerConfig or StrategyConfig subclass",
    }
    for value, message in plugins.items():
        assert main(["compare", str(study), "--controller", value, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
    assert main(["compare", str(study), "--controller", "pd", "--out", str(tmp_path / "o")]) == 2
    assert "runs the same episodes as tiny's arm pd" in capsys.readouterr().err
    broken = tmp_path / "broken.py"
    broken.write_text("raise RuntimeError('oops')\n")
    with pytest.raises(ConfigError, match="importing .*broken.py failed: RuntimeError: oops"):
        load_plugin(f"{broken}:X")
    with pytest.raises(ConfigError, match="is a controller config; a strategy config is needed"):
        load_plugin(spec, "strategy")
    assert not (tmp_path / "o").exists()


def test_dry_run_counts_what_it_would_run(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["compare", str(study), "--controller", "pd", "--set", "controller.kp_pos=1500", "--dry-run"]
    assert main([*argv, "--verify", "2", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "compare pd*/" not in out and "compare pd* against tiny" in out
    assert "6 episodes to run" in out and "the new arm: 2 episodes" in out
    assert "verification: 4 committed episodes rerun (2 study arms: pd, impedance)" in out
    assert "estimated wall time" in out and out.rstrip().endswith("dry run: nothing written")
    assert not (tmp_path / "o").exists()


def test_committed_rows_are_matched_by_what_the_episode_is_not_by_its_key(
    study: Path, tmp_path: Path
) -> None:
    """A key leaves out the fields at their defaults, so a default changed since the study ran
    changes its episodes' keys; the committed experiment.json pins every field, so the rows still
    are those episodes."""
    changed = tmp_path / "tiny"
    shutil.copytree(study, changed)
    rows = read_csv(changed / "episodes.csv")
    for i, row in enumerate(rows):
        row["key"] = f"{i:016x}"  # keys computed under other defaults
    with open(changed / "episodes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    comp = plan_comparison(str(changed), "pd", assignments=["controller.kp_pos=1500"])
    assert not comp.missing and len(comp.committed) == 4
    assert {r["seed"] for r in comp.committed.values()} == {"0", "1"}
    pd_row = comp.committed[comp.study_jobs["pd"][1].key]
    assert (pd_row["arm"], pd_row["seed"]) == ("pd", "1")
    # ... and an episode under another physics than the study's is not one of its episodes.
    other = plan_comparison(
        str(changed), "pd", assignments=["controller.kp_pos=1500", "physics.profile=precision"]
    )
    assert other.missing == {"pd": 2, "impedance": 2}


STRATEGY_FILE = """
import dataclasses
from typing import ClassVar

from peg_ctrl.tasks.strategies import StraightConfig


@dataclasses.dataclass(frozen=True, kw_only=True)
class MyStraight(StraightConfig):
    name: ClassVar[str] = "my_straight"
"""


def test_a_strategy_from_a_users_file_runs_in_the_workers(tmp_path: Path) -> None:
    held = tmp_path / "held"
    exp = {
        "name": "held",
        "controllers": [{"name": "pd", "kp_pos": 2500.0}],
        "strategies": ["straight"],
        "task": {"name": "held_insertion"},
        "seeds": [0],
        "max_steps": 200,
    }
    run_sweep(experiment_from_mapping(exp), held, workers=1, progress=False, report=False)
    (tmp_path / "mine.py").write_text(STRATEGY_FILE)
    # A study controller of the name brings its fields; --set changes them.
    mine = plan_comparison(str(held), "pd", "straight", ["controller.kd_pos=50"])
    assert (mine.arm, mine.controller["kp_pos"], mine.controller["kd_pos"]) == ("pd*/straight", 2500.0, 50.0)
    with pytest.raises(ConfigError, match="runs the same episodes as held's arm pd/straight"):
        plan_comparison(str(held), "pd", "straight")
    with pytest.raises(ConfigError, match="--strategy is needed: study held crosses strategies"):
        plan_comparison(str(held), "impedance")
    comp = plan_comparison(str(held), "impedance", f"{tmp_path / 'mine.py'}:MyStraight")
    assert comp.arm == "impedance/my_straight" and comp.strategy == {"name": "my_straight", **comp.strategy}
    rows = run_comparison(comp, tmp_path / "out", workers=1, progress=False, report=False)
    assert [r["arm"] for r in rows] == ["pd/straight", "impedance/my_straight"]
    assert rows[1]["strategy"] == "my_straight" and rows[1]["total_timesteps"] == 200


def test_a_set_that_fixes_a_grid_axis_keeps_the_match_and_writes_the_tables(tmp_path: Path) -> None:
    """The committed rows keep the fixed axis's column (the new arm's do not), and a level the
    file wrote as an integer (1) is the config's float (1.0)."""
    grid = tmp_path / "grid"
    exp = {
        "name": "grid",
        "controllers": ["pd"],
        "seeds": [0],
        "max_steps": 100,
        "grid": {"scene.friction": [1, 0.5]},
    }
    run_sweep(experiment_from_mapping(exp), grid, workers=1, progress=False, report=False)
    comp = plan_comparison(str(grid), "pd", assignments=["controller.kp_pos=1500", "scene.friction=1"])
    assert not comp.missing and [len(j) for j in comp.study_jobs.values()] == [1]
    rows = run_comparison(comp, tmp_path / "out", workers=1, progress=False)
    assert [r["arm"] for r in rows] == ["pd", "pd*"]
    assert "scene.friction" not in read_csv(tmp_path / "out" / "episodes.csv")[0]  # fixed: not a column
    assert "## pd* against grid's arms" in (tmp_path / "out" / "report.md").read_text()


def test_the_new_arm_meets_each_study_arm_with_the_same_planner() -> None:
    from peg_ctrl.experiments.report.sections import against_section

    rows = [
        {
            "arm": arm,
            "controller": arm,
            "planner": planner,
            "clearance_m": "0.001",
            "status": "success" if i % 2 else "failure",
            "reason": "",
            "peak_contact_force_n": str(1.0 + i),
            "time_to_insert_s": str(2.0 + i),
            "strategy": "",
        }
        for arm in ("new", "base")
        for planner in ("ruckig", "toppra")
        for i in range(4)
    ]
    lines = against_section(rows, "new", "study", rerun=["base"])
    table = [line.split("|")[2].strip() for line in lines if line.startswith("| 1 |")]
    assert table == ["**new+ruckig**", "base+ruckig", "**new+toppra**", "base+toppra"]
    assert "except base: rerun here in full" in lines[2]
