"""The command line: help, exports, benchmarks, and one-line errors with exit code 2."""

from __future__ import annotations

import json
import os
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
    assert main(["bench", "--controller", "pd", "--out", str(out), "--steps", "200", "--repeats", "1"]) == 0
    result = json.loads(out.read_text())
    (entry,) = result["controllers"]
    assert entry["controller"] == "pd"
    assert entry["physics_steps"] == 200
    for key in ("raw_step_us_median", "loop_step_us_median", "overhead_ratio", "solve_time_us_p99"):
        assert isinstance(entry[key], float)
    (episode,) = result["episodes"]
    assert episode["status"] == "success"
    for key in (
        "raw_step_us_median",
        "episode_step_us_median",
        "overhead_ratio",
        "logging_share_of_overhead",
    ):
        assert isinstance(episode[key], float)


def test_run_writes_a_video(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", "run", "--max-steps", "600", "--video", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    assert proc.returncode == 1, proc.stderr  # 600 steps is too short to insert: a timeout failure
    assert "FAILURE (timeout" in proc.stdout
    import imageio.v2 as imageio

    reader = imageio.get_reader(str(tmp_path / "episode.mp4"))
    frames = [frame for frame in reader]
    assert len(frames) == 19  # 0 .. 0.6 s at 30 fps, both ends
    assert frames[0].shape == (480, 640, 3)
    assert frames[-1].std() > 10  # a rendered scene, not a blank frame


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["bench", "--controller", "nope"],
            "unknown controller 'nope'; known: admittance, diffik, impedance, mpc, pd",
        ),
        (["bench", "--steps", "many"], "argument --steps: invalid int value: 'many'"),
        (["bench", "--steps", "5"], "--steps must be >= 100"),
        (["bench", "--control-dt", "0.0015", "--steps", "200"], "not a whole multiple"),
        (["calibrate", "--samples", "2"], "--samples must be >= 4"),
        (["sweep"], "the following arguments are required: config"),
        (["teleop", "--speed", "9"], "--speed must be in [0.1, 5.0]"),
        (
            ["run", "--controller", "nope"],
            "unknown controller 'nope'; known: admittance, diffik, impedance, mpc, pd",
        ),
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
