"""The command line: help, exports, benchmarks, and one-line errors with exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mujoco
import pytest

from peg_ctrl.cli import main

SUBCOMMANDS = ["model", "calibrate", "bench", "run", "teleop", "sweep"]


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_subcommand_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "usage: peg-sim " + command in capsys.readouterr().out


def test_model_export(tmp_path: Path) -> None:
    assert main(["model", "--out", str(tmp_path)]) == 0
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "scene.xml"))
    assert model.nu == 7


def test_bench_writes_json(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    assert main(["bench", "--out", str(out), "--steps", "200", "--repeats", "1"]) == 0
    result = json.loads(out.read_text())
    (entry,) = result["controllers"]
    assert entry["controller"] == "pd"
    assert entry["physics_steps"] == 200
    for key in ("raw_step_us_median", "loop_step_us_median", "overhead_ratio", "solve_time_us_p99"):
        assert isinstance(entry[key], float)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["bench", "--controller", "nope"], "unknown controller 'nope'; known: pd"),
        (["bench", "--steps", "5"], "--steps must be >= 100"),
        (["bench", "--control-dt", "0.0015", "--steps", "200"], "not a whole multiple"),
        (["calibrate", "--samples", "2"], "--samples must be >= 4"),
        (["teleop"], "'teleop' is not available"),
        (["run", "--controller", "nope"], "unknown controller 'nope'; known: pd"),
        (["run", "--planner", "warp"], "unknown planner 'warp'; known: fixed_speed, ruckig"),
        (["run", "--seed", "-3"], "seed must be >= 0"),
        (["run", "--config", "missing.yaml"], "does not exist"),
    ],
)
def test_user_errors_are_one_line_with_exit_2(argv, message, tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", *argv], capture_output=True, text=True, cwd=tmp_path
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("peg-sim: error: ") and message in lines[0]
