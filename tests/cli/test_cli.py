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

from peg_ctrl.cli import app as cli
from peg_ctrl.cli import main, model, sweep
from peg_ctrl.cli.teleop_window import WindowUnavailable
from peg_ctrl.errors import DivergenceError
from peg_ctrl.progress import ENV_VAR

from ..conftest import assert_one_line_error, peg_sim, peg_sim_here

SUBCOMMANDS = [
    "model",
    "calibrate",
    "bench",
    "run",
    "teleop",
    "sweep",
    "validity",
    "crosscheck",
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


@pytest.mark.parametrize(
    ("profile", "per_control_step", "min_steps"),
    [
        pytest.param("seed", 5, 5000, marks=pytest.mark.slow),  # ~11 s; the fast profile's in 3 s
        ("fast", 2, 2000),
    ],
)
def test_bench_writes_json(profile: str, per_control_step: int, min_steps: int, tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    argv = ["bench", "--controller", "pd", "--task", "default", "--profile", profile, "--repeats", "1"]
    argv += ["--throughput-episodes", "0"]
    assert main([*argv, "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    (entry,) = result["episodes"]
    assert (entry["controller"], entry["task"], entry["profile"], entry["status"]) == (
        "pd",
        "default",
        profile,
        "success",
    )
    assert entry["control_hz"] == pytest.approx(200.0)
    assert entry["physics_steps_per_control_step"] == per_control_step
    assert entry["physics_steps"] > min_steps  # a whole episode: grasp, transport and insertion contacts
    for key in ("raw_us_per_step", "loop_us_per_step"):
        assert 0 < entry[key]["min"] <= entry[key]["median"]
    assert entry["loop_us_per_step"]["median"] > entry["raw_us_per_step"]["min"]
    assert set(entry["components_us_per_step"]) == {"task", "controller", "physics", "monitors", "recording"}
    assert all(v > 0 for v in entry["components_us_per_step"].values())
    assert 0 < entry["efficiency"] <= 1 and entry["loop_own_us_per_control_step"] > 0
    assert "CPU time" in result["clock"] and result["throughput"] == []


def test_run_writes_a_video(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != ENV_VAR}
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", "run", "--max-steps", "100", "--video", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        env={**env, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    assert proc.returncode == 1, proc.stderr  # 100 steps is too short to insert: a timeout failure
    assert "FAILURE (timeout" in proc.stdout
    assert "video:" not in proc.stderr  # no progress bar into a pipe
    import imageio.v2 as imageio

    reader = imageio.get_reader(str(tmp_path / "episode.mp4"))
    frames = [frame for frame in reader]
    assert len(frames) == 4  # 0 .. 0.1 s at 30 fps, both ends
    assert frames[0].shape == (480, 1280, 3)  # the follow view and the hole close-up, side by side
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
        (["bench", "--task", "nope"], "--task: unknown task 'nope'; known: contact, default"),
        (
            ["bench", "--profile", "nope"],
            "--profile: unknown physics profile 'nope'; known: fast, precision, seed",
        ),
        (["bench", "--control-dt", "0.0015"], "not a whole multiple"),
        (["validate-profile", "nope"], "PROFILE: unknown physics profile 'nope'"),
        (["validity", "--profile", "nope"], "--profile: unknown physics profile 'nope'"),
        (["validate-profile", "fast", "--reference", "fast"], "--reference must differ"),
        (["validate-profile", "fast", "--seeds", "1"], "--seeds must be >= 2"),
        (["calibrate", "--out", "jaw.json", "--samples", "2"], "--samples must be >= 4"),
        (["calibrate"], "one of the arguments --out --replace-packaged is required"),
        (["calibrate", "--out", "jaw.json", "--replace-packaged"], "not allowed with argument --out"),
        (["sweep"], "one of the arguments config --list is required"),
        (
            ["sweep", "nope"],
            "no shipped experiment has that name; shipped: clearance, contact, contact_hard, "
            "contact_hard_offgrid, contact_real, contact_real_descent, contact_real_friction5, "
            "contact_real_offgrid, contact_real_offgrid_friction5, contact_real_offgrid_orientation, "
            "contact_real_orientation, contact_real_plan, contact_real_plan_fixed, "
            "contact_real_plan_offgrid, guarded, plan, quick",
        ),
        (["sweep", "quick", "--workers", "0"], "--workers must be >= 1, got 0"),
        (["sweep", "quick", "--dry-run", "--workers", "-1"], "--workers must be >= 1, got -1"),
        (["sweep", "quick", "--workers", "two"], "argument --workers: invalid int value: 'two'"),
        (["sweep", "nope", "--dry-run"], "no shipped experiment has that name"),
        (["sweep", "quick", "--dry-run", "--set", "seeds=0"], "seeds: must be >= 1, got 0"),
        (["sweep", "quick", "--set", "seeds=20001"], "sweep quick: 100,005 episodes, estimated "),
        (
            ["sweep", "quick", "--set", "seeds=20001"],
            "more than 20,000 episodes or 24 h; pass --yes to run it anyway (or --dry-run to see the "
            "breakdown)",
        ),
        (["teleop", "--speed", "9"], "--speed must be in [0.1, 5.0]"),
        (
            ["teleop", "--scripted", "--controller", "nope"],
            "--controller: unknown controller 'nope'; known: admittance, diffik, impedance, mpc, pd",
        ),
        (
            ["teleop", "--scripted", "--seed", "3"],
            "--seed only changes the peg's start pose with --randomize",
        ),
        (
            ["run", "--controller", "nope"],
            "--controller: unknown controller 'nope'; known: admittance, diffik, impedance, mpc, pd",
        ),
        (["run", "--seed", "3"], "--seed has no effect here: the start pose is drawn only with --randomize"),
        (["run", "--seed", "0", "--set", "randomization.enabled=false"], "add --randomize"),
        (["run", "--planner", "warp"], "unknown planner 'warp'; known: fixed_speed, ruckig"),
        (["run", "--seed", "-3"], "seed must be >= 0"),
        (["run", "--config", "missing.yaml"], "does not exist"),
        (
            ["run", "--set", "domain.ft_sensor=nope"],
            "domain.ft_sensor: unknown F/T sensor preset 'nope'; known: forge, ideal, mini45, wrist",
        ),
        (
            ["run", "--set", "domain.ft_sensor=wrist", "--set", "domain.torque_noise=0.01"],
            "domain.torque_noise: set either domain.ft_sensor (a preset) or the sensor's noise fields",
        ),
        (["run", "--seed", "3", "--set", "domain.ft_sensor=ideal"], "--seed has no effect here"),
    ],
)
def test_user_errors_are_one_line_with_exit_2(argv, message, tmp_path: Path) -> None:
    assert_one_line_error(peg_sim_here(argv, cwd=tmp_path), message)
    assert list(tmp_path.iterdir()) == [], "bad input must be rejected before any output is created"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["bench", "--repeats", "many"], "argument --repeats: invalid int value: 'many'"),  # argparse's
        (["run", "--planner", "warp"], "unknown planner 'warp'; known: fixed_speed, ruckig"),  # a config's
        (["sweep", "quick", "--out", "{file}"], "is not a directory"),  # the system's
    ],
)
def test_errors_are_one_line_with_exit_2_from_a_fresh_interpreter(argv, message, tmp_path: Path) -> None:
    """The tests above call ``main`` in this interpreter; here ``python -m peg_ctrl`` itself."""
    (tmp_path / "file").write_text("")
    proc = peg_sim([a.format(file=tmp_path / "file") for a in argv], cwd=tmp_path)
    assert_one_line_error(proc, message)
    assert [p.name for p in tmp_path.iterdir()] == ["file"]


@pytest.mark.parametrize(
    "command", ["run", "model", "teleop --scripted", "sweep quick", "sweep quick --dry-run"]
)
def test_out_that_is_a_regular_file_is_one_line_with_exit_2(command: str, tmp_path: Path) -> None:
    target = tmp_path / "results"
    target.write_text("not a directory")
    proc = peg_sim_here([*command.split(), "--out", str(target)], cwd=tmp_path)
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
    proc = peg_sim_here(argv, cwd=tmp_path)
    assert_one_line_error(proc, f"its parent {str(tmp_path / 'file')!r} is a file")


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write to read-only directories")
@pytest.mark.parametrize("command", ["run", "model"])
def test_read_only_out_is_one_line_with_exit_2(command: str, tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        assert_one_line_error(peg_sim_here([command, "--out", str(ro)], cwd=tmp_path), "is not writable")
    finally:
        ro.chmod(stat.S_IRWXU)


def test_bench_out_that_is_a_directory_is_rejected(tmp_path: Path) -> None:
    assert_one_line_error(
        peg_sim_here(["bench", "--controller", "pd", "--out", str(tmp_path)], cwd=tmp_path), "is a directory"
    )


def _fake_command(monkeypatch: pytest.MonkeyPatch, exc: BaseException) -> None:
    def command(args):  # type: ignore[no-untyped-def]
        raise exc

    monkeypatch.setattr(model, "run", command)


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


def test_run_video_shows_its_progress(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", "run", "--max-steps", "100", "--video", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), ENV_VAR: "1"},
    )
    assert proc.returncode == 1, proc.stderr  # a timeout: 0.1 s of the episode
    # The bar counts the frames (0 .. 0.1 s at 30 fps); its total, the step limit's 4 frames,
    # is the video's length when the episode ends.
    last = proc.stderr.replace("\r", "\n").strip().splitlines()[-1]
    assert last.startswith("video: 100%") and "4/4 " in last, proc.stderr
    assert "FAILURE (timeout" in proc.stdout and "frame/s" not in proc.stdout  # the bar: stderr


def _bench_entry(overhead: float) -> dict:
    return {
        "controller": "pd",
        "task": "default",
        "profile": "seed",
        "status": "success",
        "control_hz": 200.0,
        "physics_steps": 9630,
        "physics_steps_per_control_step": 5,
        "raw_us_per_step": {"min": 100.0, "median": 110.0},
        "loop_us_per_step": {"min": 120.0, "median": 140.0},
        "overhead": {"median": overhead, "min": overhead - 0.02, "of_minimums": overhead},
        "components_us_per_step": dict.fromkeys(
            ("task", "controller", "physics", "monitors", "recording"), 1.0
        ),
        "within_target": overhead <= 0.10,
        "efficiency": 1.0 / (1.0 + overhead),
        "loop_own_us_per_control_step": 50.0,
    }


@pytest.mark.parametrize("overhead, flagged", [(0.27, True), (0.05, False)])
def test_bench_says_what_its_overhead_and_target_are(
    overhead: float,
    flagged: bool,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    import peg_ctrl.tools.bench

    def fake(out: Path, **kwargs):  # type: ignore[no-untyped-def]
        out.write_text("{}")
        return {"clock": "CPU", "episodes": [_bench_entry(overhead)], "throughput": []}

    monkeypatch.setattr(peg_ctrl.tools.bench, "run_benchmarks", fake)
    assert main(["bench", "--controller", "pd", "--out", str(tmp_path / "b.json")]) == 0
    out = capsys.readouterr().out
    assert f"overhead {100 * overhead:+5.1f} %" in out
    assert ("> 10 % target" in out) is flagged
    assert f"efficiency {1.0 / (1.0 + overhead):.2f} (raw physics / loop)" in out
    assert "the loop's own work  50.0 us per control step" in out
    # What the overhead is measured against, what the target is, and why a shared machine misses it.
    assert "bare mj_step replay of the same controls" in out
    assert "target: median <= 10 % (b.json: within_target)" in out
    assert "loaded or shared 2-core machine" in out


def test_bench_writes_exactly_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import peg_ctrl.tools.bench

    def fake(out: Path, **kwargs):  # type: ignore[no-untyped-def]
        out.write_text("{}")
        return {"clock": "CPU", "episodes": [], "throughput": []}

    monkeypatch.setattr(peg_ctrl.tools.bench, "run_benchmarks", fake)
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
    import peg_ctrl.tools.bench

    row = {
        "profile": "precision",
        "situation": "on top face",
        "step_us_median": 60.0,
        "timestep_ms": 0.5,
        "contacts": 44,
        "us_per_simulated_ms": 120.0,
        "cost_vs_seed": 0.5,
    }
    monkeypatch.setattr(
        peg_ctrl.tools.bench, "bench_profiles", lambda repeats: {"rows": [row], "repeats": repeats}
    )
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--physics", "--repeats", "2", "--out", "p/phys.json"]) == 0
    assert json.loads((tmp_path / "p" / "phys.json").read_text()) == {"rows": [row], "repeats": 2}
    assert "precision on top face :    60.0 us/step (dt 0.5 ms, 44 contacts)" in capsys.readouterr().out


def test_sweep_lists_the_shipped_experiments(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in lines]
    assert names == [
        "clearance",
        "contact",
        "contact_hard",
        "contact_hard_offgrid",
        "contact_real",
        "contact_real_descent",
        "contact_real_friction5",
        "contact_real_offgrid",
        "contact_real_offgrid_friction5",
        "contact_real_offgrid_orientation",
        "contact_real_orientation",
        "contact_real_plan",
        "contact_real_plan_fixed",
        "contact_real_plan_offgrid",
        "guarded",
        "plan",
        "quick",
    ]
    assert (
        lines[names.index("quick")].split(None, 1)[1]
        == "Every controller on the default task, 20 randomized seeds each."
    )


def test_sweep_resolves_a_shipped_name_unless_a_file_exists(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    shipped = sweep.shipped_experiments()
    assert sweep.resolve_experiment("quick") == shipped["quick"]
    assert shipped["quick"].is_file()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "quick").write_text("name: mine\n")
    assert sweep.resolve_experiment("quick") == Path("quick")


def test_version_prints_the_installed_version(capsys: pytest.CaptureFixture[str]) -> None:
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"peg-sim {version('peg-ctrl')}\n"


def test_version_falls_back_when_not_installed(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.metadata

    def missing(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert cli._version() == "unknown (not installed)"


def _command_lines(help_text: str) -> dict[str, list[str]]:
    """``peg-sim --help``'s command list: each command's help, line by line."""
    section = help_text.split("\n  COMMAND\n", 1)[1].split("\n\n", 1)[0]
    commands: dict[str, list[str]] = {}
    name = ""
    for line in section.splitlines():
        if line.startswith("    ") and not line.startswith("     "):  # "    name   help"
            name, _, text = line.strip().partition(" ")
            commands[name] = [text.strip()] if text.strip() else []
        else:  # a continuation: the help of a long name, or a wrapped help
            commands[name].append(line.strip())
    return commands


def test_every_subcommand_has_a_one_line_help_and_a_description(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit):
        main(["--help"])
    commands = _command_lines(capsys.readouterr().out)
    assert set(SUBCOMMANDS) <= set(commands)
    for name, lines in commands.items():
        assert len(lines) == 1 and lines[0], f"{name}: help must be one line at 80 columns, got {lines}"
        with pytest.raises(SystemExit):
            main([name, "--help"])
        paragraphs = capsys.readouterr().out.split("\n\n")
        assert not paragraphs[1].startswith(("positional arguments:", "options:")), f"{name}: no description"


def test_help_lists_the_registered_names(capsys: pytest.CaptureFixture[str]) -> None:
    from peg_ctrl.controllers import REGISTRY
    from peg_ctrl.planners import PLANNERS
    from peg_ctrl.sim.physics import PROFILES

    for argv, names in [
        (["run", "--help"], [*REGISTRY, *PLANNERS]),
        (["teleop", "--help"], REGISTRY),
        (["bench", "--help"], [*REGISTRY, *PROFILES, "default", "contact"]),
        (["validity", "--help"], PROFILES),
    ]:
        with pytest.raises(SystemExit):
            main(argv)
        text = " ".join(capsys.readouterr().out.split())
        assert all(name in text for name in names), (argv, names)


def test_top_level_help_imports_no_registry() -> None:
    """``peg-sim --help`` stays fast: the registries (and mujoco) load only when a command needs
    them."""
    code = "\n".join(
        [
            "import sys",
            "from peg_ctrl.cli import main",
            "try:",
            "    main(['--help'])",
            "except SystemExit:",
            "    pass",
            "heavy = ('mujoco', 'peg_ctrl.controllers', 'peg_ctrl.sim.physics')",
            "print(sorted(m for m in heavy if m in sys.modules))",
        ]
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.splitlines()[-1] == "[]"


@pytest.mark.parametrize(
    "extra",
    [
        ["--randomize"],
        ["--set", "randomization.enabled=true"],
        ["--set", "task.name=held_insertion"],  # draws its lateral error direction from the seed
        ["--set", "domain.friction_scale=[0.8,1.2]"],
        ["--set", "domain.force_noise=0.1"],
        ["--set", "domain.ft_sensor=wrist"],
        ["--set", "domain.ft_latency=0.01"],
    ],
)
def test_seed_is_accepted_when_the_episode_depends_on_it(
    extra: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import peg_ctrl.run.episode

    seen = []

    class Result:
        status = "success"

        def one_line(self) -> str:
            return "ok"

    def fake_run(cfg, out, **kwargs):  # type: ignore[no-untyped-def]
        seen.append(cfg)
        return Result()

    monkeypatch.setattr(peg_ctrl.run.episode, "run_episode", fake_run)
    assert main(["run", "--seed", "3", *extra, "--out", str(tmp_path)]) == 0
    assert seen[0].seed == 3 and seen[0].seeded


def _packaged_calibration() -> tuple[bytes, int]:
    from peg_ctrl.sim.jaw import DEFAULT_PATH

    return DEFAULT_PATH.read_bytes(), DEFAULT_PATH.stat().st_mtime_ns


def test_calibrate_without_out_is_refused_and_leaves_the_packaged_table(tmp_path: Path) -> None:
    before = _packaged_calibration()
    proc = peg_sim_here(["calibrate", "--samples", "4"], cwd=tmp_path)
    assert_one_line_error(proc, "one of the arguments --out --replace-packaged is required")
    assert _packaged_calibration() == before
    assert list(tmp_path.iterdir()) == []


def test_calibrate_writes_out_and_only_out(tmp_path: Path) -> None:
    from peg_ctrl.sim.jaw import JawCalibration

    before = _packaged_calibration()
    proc = peg_sim(["calibrate", "--samples", "4", "--out", "cal/jaw.json"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no progress bar when stderr is not a terminal
    cal = JawCalibration.from_file(tmp_path / "cal" / "jaw.json")
    assert cal.sep_open_m > cal.sep_closed_m
    assert _packaged_calibration() == before
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["cal", "jaw.json"]


def test_calibrate_replace_packaged_is_refused_in_an_installed_copy(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import peg_ctrl.sim.jaw

    before = _packaged_calibration()
    monkeypatch.setattr(peg_ctrl.sim.jaw, "source_tree_path", lambda: None)
    assert main(["calibrate", "--replace-packaged"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("peg-sim: error: --replace-packaged works only in a source checkout")
    assert len(err.splitlines()) == 1
    assert _packaged_calibration() == before


@pytest.mark.parametrize("window", [False, True], ids=["scripted", "window"])
def test_teleop_ended_without_the_peg_inserted_exits_1(
    window: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """As ``run`` does for a failed episode: a session (scripted, or in the window, here cut to
    0.1 s) that ends with the peg not inserted exits with 1, its records written."""
    import peg_ctrl.cli.teleop_window
    from peg_ctrl.teleop import ScriptedOperator

    if window:
        monkeypatch.setenv("DISPLAY", ":0")

        def quit_early(session, screenshot):  # type: ignore[no-untyped-def]
            session.advance(0.1)
            return session.finish("quit")

        monkeypatch.setattr(peg_ctrl.cli.teleop_window, "run_window", quit_early)
    else:
        monkeypatch.setattr(ScriptedOperator, "run", lambda self, **kwargs: self.session.advance(0.1))
    argv = ["teleop", *([] if window else ["--scripted"]), "--out", str(tmp_path)]
    assert main(argv) == 1
    assert "not inserted" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (summary["status"], summary["end"]) == ("failure", "quit" if window else "script_done")


@pytest.mark.parametrize(("status", "code"), [("success", 0), ("failure", 1)])
def test_teleop_exit_code_follows_the_sessions_status(
    status: str, code: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import peg_ctrl.cli.teleop

    summary = {"status": status, "end": "script_done", "total_timesteps": 10, "attempts": 1}
    monkeypatch.setattr(peg_ctrl.cli.teleop, "_session", lambda args, cfg, out: summary)
    assert main(["teleop", "--scripted", "--out", str(tmp_path)]) == code


def test_teleop_interrupted_keeps_its_records(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from peg_ctrl.run.episode_log import read_trace
    from peg_ctrl.teleop import ScriptedOperator

    def interrupted(self, **kwargs):  # type: ignore[no-untyped-def]
        self.session.advance(0.1)
        raise KeyboardInterrupt

    monkeypatch.setattr(ScriptedOperator, "run", interrupted)
    assert main(["teleop", "--scripted", "--out", str(tmp_path)]) == 130
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (summary["status"], summary["end"]) == ("interrupted", "interrupted")
    assert read_trace(tmp_path / "forces.npz").shape[0] == summary["total_timesteps"] == 100


def test_run_viewer_without_a_display_is_one_line_and_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["run", "--viewer", "--out", str(tmp_path / "run")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        "peg-sim: error: --viewer needs a display (DISPLAY is not set); run without it, or with --video"
    ]
    assert not (tmp_path / "run").exists()


def test_run_with_a_control_period_the_physics_step_does_not_divide_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "run",
        "--controller",
        "admittance",
        "--set",
        "physics.profile=fast",
        "--out",
        str(tmp_path / "run"),
    ]
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        "peg-sim: error: control_dt 0.001 s is not a whole multiple of the physics timestep 0.0025 s"
    ]
    assert not (tmp_path / "run").exists()
