"""The command line: help, exports, benchmarks, and one-line errors with exit code 2."""

from __future__ import annotations

import errno
import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import mujoco
import pytest

from peg_ctrl import cli
from peg_ctrl.cli import main
from peg_ctrl.errors import DivergenceError
from peg_ctrl.teleop_window import WindowUnavailable

from .conftest import assert_one_line_error, peg_sim

SUBCOMMANDS = [
    "model",
    "calibrate",
    "bench",
    "run",
    "teleop",
    "sweep",
    "validity",
    "validate-profile",
    "plot",
]


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
    argv = ["bench", "--controller", "pd", "--task", "default", "--repeats", "1"]
    argv += ["--throughput-episodes", "0"]
    assert main([*argv, "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    (entry,) = result["episodes"]
    assert (entry["controller"], entry["task"], entry["profile"], entry["status"]) == (
        "pd",
        "default",
        "seed",
        "success",
    )
    assert entry["control_hz"] == pytest.approx(200.0) and entry["physics_steps_per_control_step"] == 5
    assert entry["physics_steps"] > 5000  # a whole episode: grasp, transport and insertion contacts
    for key in ("raw_us_per_step", "loop_us_per_step"):
        assert 0 < entry[key]["min"] <= entry[key]["median"]
    assert entry["loop_us_per_step"]["median"] > entry["raw_us_per_step"]["min"]
    assert set(entry["components_us_per_step"]) == {"task", "controller", "physics", "monitors", "recording"}
    assert all(v > 0 for v in entry["components_us_per_step"].values())
    assert "CPU time" in result["clock"] and result["throughput"] == []


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
        (["bench", "--repeats", "many"], "argument --repeats: invalid int value: 'many'"),
        (["bench", "--repeats", "0"], "--repeats must be >= 1"),
        (["bench", "--task", "nope"], "--task must be one of default, contact, got 'nope'"),
        (["bench", "--profile", "nope"], "--profile: unknown physics profile 'nope'"),
        (["bench", "--control-dt", "0.0015"], "not a whole multiple"),
        (["validate-profile", "nope"], "profile: unknown physics profile 'nope'"),
        (["validate-profile", "fast", "--reference", "fast"], "--reference must differ"),
        (["validate-profile", "fast", "--seeds", "1"], "--seeds must be >= 2"),
        (["calibrate", "--samples", "2"], "--samples must be >= 4"),
        (["sweep"], "one of the arguments config --list is required"),
        (
            ["sweep", "nope"],
            "no shipped experiment has that name; shipped: clearance, contact, guarded, quick",
        ),
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
    assert_one_line_error(peg_sim(argv, cwd=tmp_path), message)
    assert list(tmp_path.iterdir()) == [], "bad input must be rejected before any output is created"


@pytest.mark.parametrize("command", ["run", "model", "teleop --scripted", "sweep quick"])
def test_out_that_is_a_regular_file_is_one_line_with_exit_2(command: str, tmp_path: Path) -> None:
    target = tmp_path / "results"
    target.write_text("not a directory")
    proc = peg_sim([*command.split(), "--out", str(target)], cwd=tmp_path)
    assert_one_line_error(proc, f"output directory {str(target)!r} is not a directory")
    assert target.read_text() == "not a directory"


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--out", "{file}/sub"],
        ["model", "--out", "{file}/sub/deeper"],
        ["bench", "--controller", "pd", "--out", "{file}/bench.json"],
        ["calibrate", "--out", "{file}/jaw.json"],
    ],
)
def test_out_under_a_file_is_one_line_with_exit_2(argv: list[str], tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    argv = [a.format(file=tmp_path / "file") for a in argv]
    assert_one_line_error(peg_sim(argv, cwd=tmp_path), f"its parent {str(tmp_path / 'file')!r} is a file")


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write to read-only directories")
@pytest.mark.parametrize("command", ["run", "model"])
def test_read_only_out_is_one_line_with_exit_2(command: str, tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        assert_one_line_error(peg_sim([command, "--out", str(ro)], cwd=tmp_path), "is not writable")
    finally:
        ro.chmod(stat.S_IRWXU)


def test_bench_out_that_is_a_directory_is_rejected(tmp_path: Path) -> None:
    assert_one_line_error(
        peg_sim(["bench", "--controller", "pd", "--out", str(tmp_path)], cwd=tmp_path), "is a directory"
    )


def _fake_command(monkeypatch: pytest.MonkeyPatch, exc: BaseException) -> None:
    def command(args):  # type: ignore[no-untyped-def]
        raise exc

    monkeypatch.setattr(cli, "_cmd_model", command)


@pytest.mark.parametrize(
    "exc, message",
    [
        (
            OSError(errno.ENOSPC, "No space left on device", "out/log.jsonl"),
            "'out/log.jsonl': No space left on device",
        ),
        (PermissionError(errno.EACCES, "Permission denied", "/x"), "'/x': Permission denied"),
        (WindowUnavailable("GLFW could not open a window"), "GLFW could not open a window"),
    ],
)
def test_os_and_environment_errors_exit_2(
    exc: BaseException, message: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _fake_command(monkeypatch, exc)
    assert main(["model", "--out", "x"]) == 2
    assert capsys.readouterr().err == f"peg-sim: error: {message}\n"


def test_ctrl_c_exits_130(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _fake_command(monkeypatch, KeyboardInterrupt())
    assert main(["model", "--out", "x"]) == 130
    assert capsys.readouterr().err == "peg-sim: interrupted\n"


@pytest.mark.parametrize(
    "exc", [ZeroDivisionError("a bug"), ValueError("a bug"), RuntimeError("a bug"), DivergenceError("nan")]
)
def test_bugs_keep_their_traceback(exc: BaseException, monkeypatch: pytest.MonkeyPatch) -> None:
    _fake_command(monkeypatch, exc)
    with pytest.raises(type(exc)):
        main(["model", "--out", "x"])


def test_bench_writes_exactly_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import peg_ctrl.bench

    def fake(out: Path, **kwargs):  # type: ignore[no-untyped-def]
        out.write_text("{}")
        return {"clock": "CPU", "episodes": [], "throughput": []}

    monkeypatch.setattr(peg_ctrl.bench, "run_benchmarks", fake)
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--controller", "pd", "--out", "sub/b.json"]) == 0
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == ["sub", "sub/b.json"]
    assert main(["bench", "--controller", "pd"]) == 0
    assert (tmp_path / "bench.json").is_file()


def test_bench_sweep_writes_exactly_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import peg_ctrl.experiments.runner

    result = {"episodes": 2, "wall_s": {"1": 2.0, "2": 1.0}, "speedup_2_vs_1": 2.0}
    monkeypatch.setattr(peg_ctrl.experiments.runner, "bench_sweep", lambda n: result)
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--sweep", "--sweep-episodes", "2", "--out", "s/sweep.json"]) == 0
    assert json.loads((tmp_path / "s" / "sweep.json").read_text()) == result
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["s", "sweep.json"]


def test_bench_physics_writes_exactly_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import peg_ctrl.bench

    row = {
        "profile": "precision",
        "situation": "on top face",
        "step_us_median": 60.0,
        "timestep_ms": 0.5,
        "contacts": 44,
        "us_per_simulated_ms": 120.0,
        "cost_vs_seed": 0.5,
    }
    monkeypatch.setattr(peg_ctrl.bench, "bench_profiles", lambda repeats: {"rows": [row], "repeats": repeats})
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--physics", "--repeats", "2", "--out", "p/phys.json"]) == 0
    assert json.loads((tmp_path / "p" / "phys.json").read_text()) == {"rows": [row], "repeats": 2}
    assert "precision on top face :    60.0 us/step (dt 0.5 ms, 44 contacts)" in capsys.readouterr().out


def test_sweep_lists_the_shipped_experiments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in lines]
    assert names == ["clearance", "contact", "guarded", "quick"]
    assert lines[3].split(None, 1)[1] == "Every controller on the default task, 20 randomized seeds each."


def test_sweep_resolves_a_shipped_name_unless_a_file_exists(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    shipped = cli.shipped_experiments()
    assert cli._resolve_experiment("quick") == shipped["quick"]
    assert shipped["quick"].is_file()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "quick").write_text("name: mine\n")
    assert cli._resolve_experiment("quick") == Path("quick")
