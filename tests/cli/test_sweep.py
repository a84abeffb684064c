"""``peg-sim sweep``: progress lines in a log, ``--dry-run``, and the guard against huge sweeps."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from peg_ctrl.cli import main, sweep
from peg_ctrl.cli.sweep import _about
from peg_ctrl.experiments.config import expand, load_experiment
from peg_ctrl.experiments.estimate import EPISODE_OVERHEAD_S
from peg_ctrl.experiments.runner import experiment_text
from peg_ctrl.progress import ENV_VAR

from ..conftest import assert_one_line_error, peg_sim

ROOT = Path(__file__).resolve().parents[2]

# Three 10-step episodes: a sweep of them is over in seconds.
TINY = """\
name: tiny
controllers: [{name: pd}]
seeds: 3
max_steps: 10
"""
LINE = re.compile(r"^sweep tiny: (\d+)/3 episodes \(\d+%\), (\d+) inserted, elapsed \d+s(, ETA \S+|, done)?$")


def _tree(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


def test_a_sweep_into_a_log_file_prints_progress_lines(tmp_path: Path) -> None:
    config = tmp_path / "tiny.yaml"
    config.write_text(TINY)
    log = tmp_path / "log.txt"
    env = {k: v for k, v in os.environ.items() if k != ENV_VAR}
    with open(log, "w") as err:  # `peg-sim sweep ... 2> log`: stderr is not a terminal
        proc = subprocess.run(
            [sys.executable, "-m", "peg_ctrl", "sweep", str(config), "--workers", "1", "--out", "out"],
            stdout=subprocess.PIPE,
            stderr=err,
            text=True,
            cwd=tmp_path,
            env=env,
        )
    text = log.read_text()
    assert proc.returncode == 0, text
    lines = text.splitlines()
    assert all(LINE.match(line) for line in lines), text
    assert lines[0] == "sweep tiny: 0/3 episodes (0%), 0 inserted, elapsed 0s"
    assert lines[-1].startswith("sweep tiny: 3/3 episodes (100%), 0 inserted, elapsed ")  # 10 steps: timeouts
    assert lines[-1].endswith(", done") and "\r" not in text
    assert "tiny: 0/3 episodes inserted" in proc.stdout


def test_a_resumed_sweep_counts_the_finished_episodes_as_done(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "tiny.yaml"
    config.write_text(TINY)
    out = tmp_path / "out"
    assert main(["sweep", str(config), "--workers", "1", "--out", str(out)]) == 0
    first_s = json.loads((out / "run_time.json").read_text())["run_time_s"]
    assert f"Run time {first_s:.0f} s." in (out / "report.md").read_text()
    (first, *_) = sorted((out / "episodes").iterdir())
    (first / "summary.json").unlink()  # one episode to run again
    capsys.readouterr()
    monkeypatch.delenv(ENV_VAR, raising=False)  # capsys's stderr is not a terminal: lines
    assert main(["sweep", str(config), "--workers", "1", "--out", str(out)]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "sweep tiny: 2/3 episodes (66%), 0 inserted, elapsed 0s"
    assert lines[-1].startswith("sweep tiny: 3/3 episodes (100%), 0 inserted, elapsed ")
    # The report's run time is the sum over both invocations, not the last one's.
    saved = json.loads((out / "run_time.json").read_text())
    assert saved["invocations"] == 2 and saved["run_time_s"] > first_s
    total = f"Run time {saved['run_time_s']:.0f} s over 2 invocations."
    assert total in (out / "report.md").read_text()


def test_progress_can_be_switched_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "tiny.yaml"
    config.write_text(TINY.replace("seeds: 3", "seeds: 1"))
    monkeypatch.setenv(ENV_VAR, "0")
    assert main(["sweep", str(config), "--workers", "1", "--out", str(tmp_path / "out")]) == 0
    assert capsys.readouterr().err == ""


def test_dry_run_prints_the_breakdown_and_an_estimate_and_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "contact_hard", "--dry-run", "--workers", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("contact_hard: 400 episodes = 10 arms x 8 cells x 5 seeds\n")
    assert "  arms (10): pd/straight, pd/spiral, pd/align, impedance/spiral," in out
    assert "  cells (8) = scene.friction x task.lateral_error x task.tilt_error\n" in out
    assert "    scene.friction (2): 0.3, 0.9\n" in out
    assert "    task.tilt_error (2): 0, 0.0349066\n" in out
    assert "  seeds (5): 0..4\n" in out
    assert "runs/contact_hard does not exist yet; 400 to run" in out
    # The estimate is the committed run's own time: its episodes' wall time over 2 workers.
    with open(ROOT / "docs" / "contact_hard" / "episodes.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    measured = (sum(float(r["wall_time_s"]) for r in rows) + EPISODE_OVERHEAD_S * len(rows)) / 2
    total = re.search(
        r"^estimated wall time with 2 workers: (\S+ \S+) \(at most (\S+ \S+) if every", out, re.M
    )
    assert total is not None and total[1] == _about(measured) and total[1] != total[2]
    pd = re.search(
        r"^    pd +held_insertion/precision: 120 x ([\d.]+) x ([\d.]+) s \(20 s\) = (\S+ \S+); contact_hard$",
        out,
        re.M,
    )
    assert pd is not None
    pd_rows = [r for r in rows if r["controller"] == "pd"]
    sim_s = sum(float(r["sim_time_s"]) for r in pd_rows) / len(pd_rows)
    assert float(pd[2]) == pytest.approx(sim_s, rel=0.01)
    assert "contact_hard: the committed contact_hard sweep (docs/contact_hard/episodes.csv" in out
    assert out.endswith("dry run: nothing written\n")
    assert list(tmp_path.iterdir()) == []


def test_dry_run_counts_what_a_resumed_sweep_would_skip(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two finished episodes in --out (their summaries written here): not work, and measured here."""
    config = tmp_path / "tiny.yaml"
    config.write_text(TINY.replace("max_steps: 10", "max_steps: 5000"))
    exp = load_experiment(config)
    out = tmp_path / "out"
    out.mkdir()
    (out / "experiment.json").write_text(experiment_text(exp))
    for job in expand(exp)[:2]:
        (out / "episodes" / job.key).mkdir(parents=True)
        summary = {"status": "success", "trace_path": "forces.npz", "task": "pick_and_place"}
        summary |= {"physics": "seed", "controller": "pd", "wall_time_s": 3.0, "sim_time_s": 4.0}
        (out / "episodes" / job.key / "summary.json").write_text(json.dumps(summary))
    before = _tree(tmp_path)
    assert main(["sweep", str(config), "--dry-run", "--workers", "2", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"{out} holds 2 finished episodes: the sweep resumes; 1 to run" in text
    assert "estimated wall time with 2 workers (1 at once): " in text
    assert "    pd pick_and_place/seed: 1 x 0.75 x 4 s (5 s) = " in text
    assert f"measured here: the finished episodes in {out} (this machine)" in text
    assert _tree(tmp_path) == before


def test_dry_run_refuses_what_the_sweep_would_refuse(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "tiny.yaml"
    config.write_text(TINY)
    out = tmp_path / "out"
    out.mkdir()
    (out / "experiment.json").write_text("{}\n")
    assert main(["sweep", str(config), "--dry-run", "--out", str(out)]) == 2
    assert "holds results of a different experiment" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        # 5 controllers x 20,001 seeds
        (["sweep", "quick", "--set", "seeds=20001"], "sweep quick: 100,005 episodes, estimated "),
    ],
)
def test_a_huge_sweep_needs_yes(argv: list[str], message: str, tmp_path: Path) -> None:
    proc = peg_sim(argv, cwd=tmp_path, timeout=60.0)
    assert_one_line_error(proc, message)
    hours = re.search(r"estimated ([\d.]+) (h|days) with", proc.stderr)
    assert hours is not None and float(hours[1]) * (24 if hours[2] == "days" else 1) > 24, proc.stderr
    assert (
        "more than 20,000 episodes or 24 h; pass --yes to run it anyway (or --dry-run to see the breakdown)"
        in proc.stderr
    )
    assert list(tmp_path.iterdir()) == [], "refused before anything is written"


def test_a_sweep_of_allowed_size_estimated_too_long_needs_yes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Up to 20,000 episodes are allowed, but not more than MAX_WALL_S of them: here 1 h, which
    1,200 contact_hard episodes on one worker exceed (3 times the committed run's 400 on two)."""
    monkeypatch.setattr(sweep, "MAX_WALL_S", 3600.0)
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "contact_hard", "--set", "seeds=15", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "sweep contact_hard: 1,200 episodes, estimated " in err
    assert "more than 20,000 episodes or 1 h" in err
    assert list(tmp_path.iterdir()) == [], "refused before anything is written"


def test_yes_runs_a_huge_sweep(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import peg_ctrl.experiments.runner

    ran = []

    def fake_run_sweep(exp, out, **kwargs):  # type: ignore[no-untyped-def]
        ran.append((len(exp.seeds), Path(out)))
        return []

    monkeypatch.setattr(peg_ctrl.experiments.runner, "run_sweep", fake_run_sweep)
    argv = ["sweep", "quick", "--set", "seeds=20001", "--out", str(tmp_path / "out")]
    assert main(argv) == 2 and ran == []
    assert main([*argv, "--yes"]) == 0
    assert ran == [(20001, tmp_path / "out")]


def test_the_guard_uses_its_thresholds(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(sweep, "MAX_EPISODES", 99)
    assert main(["sweep", "quick", "--out", "unused"]) == 2  # 100 episodes
    assert "100 episodes" in capsys.readouterr().err
    monkeypatch.setattr(sweep, "MAX_EPISODES", 20_000)
    monkeypatch.setattr(sweep, "MAX_WALL_S", 60.0)
    assert main(["sweep", "quick", "--out", "unused", "--workers", "2"]) == 2  # about 2 min
    assert "more than 20,000 episodes or 0.0166667 h" in capsys.readouterr().err
