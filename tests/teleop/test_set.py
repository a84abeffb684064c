"""``peg-sim teleop --set``: a session runs the controller, physics and scene it is given and
records them; anything else is refused in one line, as ``run --set`` refuses a bad field."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from peg_ctrl.cli import main
from peg_ctrl.run.episode_log import read_log
from peg_ctrl.sim.physics import PRECISION
from peg_ctrl.teleop import ScriptedOperator

from ..conftest import assert_one_line_error, peg_sim_here


def _written(out: Path) -> tuple[dict, dict, dict]:
    """The session's config.json, summary.json and teleop_start log record."""
    config = json.loads((out / "config.json").read_text())
    summary = json.loads((out / "summary.json").read_text())
    (start,) = [r for r in read_log(out / "log.jsonl") if r["event"] == "teleop_start"]
    return config, summary, start


@pytest.mark.slow  # ~9 s: the whole scripted insertion; the next test runs 0.1 s of it
def test_scripted_teleop_runs_in_the_precision_profile(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "session"
    assert main(["teleop", "--scripted", "--set", "physics.profile=precision", "--out", str(out)]) == 0
    assert capsys.readouterr().out.startswith("teleop ended (")
    config, summary, start = _written(out)
    assert config["physics"] == {"profile": "precision", "friction_time": None}
    assert summary["physics"] == start["physics"] == "precision"
    # Every physics step is one of the precision profile's, and the session's limit is simulated
    # time (SPEC §5's 50,000 steps of the seed profile: 50 s), so the script has time to insert.
    assert summary["total_timesteps"] == round(summary["sim_time_s"] / PRECISION.timestep)
    assert summary["status"] == "success" and summary["end"] == "script_done"


def test_the_precision_profile_reaches_the_session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ScriptedOperator, "run", lambda self, **kwargs: self.session.advance(0.1))
    out = tmp_path / "session"
    # 0.1 s of the script: the peg is not inserted, exit code 1
    assert main(["teleop", "--scripted", "--set", "physics.profile=precision", "--out", str(out)]) == 1
    config, summary, start = _written(out)
    assert config["physics"] == {"profile": "precision", "friction_time": None}
    assert summary["physics"] == start["physics"] == "precision"
    assert (
        summary["total_timesteps"] == round(0.1 / PRECISION.timestep) == round(summary["sim_time_s"] / 0.0005)
    )


def test_controller_and_scene_settings_reach_the_session(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def short(self, **kwargs):  # type: ignore[no-untyped-def]
        self.session.advance(0.1)

    monkeypatch.setattr(ScriptedOperator, "run", short)
    out = tmp_path / "session"
    argv = ["teleop", "--scripted", "--controller", "pd", "--out", str(out)]
    argv += ["--set", "scene.assets.clearance=0.0005", "--set", "controller.kp_pos=2000"]
    assert main(argv) == 1  # 0.1 s of the script: not inserted
    config, summary, start = _written(out)
    assert config["scene"]["assets"]["clearance"] == 0.0005
    assert (config["controller"]["name"], config["controller"]["kp_pos"]) == ("pd", 2000.0)
    assert config["physics"] == {"profile": "seed", "friction_time": None}  # the default
    assert summary["physics"] == start["physics"] == "seed"
    assert summary["total_timesteps"] == 100


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--set", "seed=3"],
            "--set seed: not a teleop setting; teleop takes controller.*, physics.*, scene.* "
            "(the start pose: --seed and --randomize)",
        ),
        (["--set", "task.name=held_insertion"], "--set task.name: not a teleop setting"),
        (["--set", "domain.force_noise=0.1"], "--set domain.force_noise: not a teleop setting"),
        (["--set", "physics.profile=nope"], "physics.profile: unknown physics profile 'nope'"),
        (["--set", "scene.assets.clearance=abc"], "scene.assets.clearance: expected a number, got 'abc'"),
        (["--set", "foo"], "expected KEY=VALUE"),
        (
            ["--set", "physics.profile=precision", "--set", "scene.contact_override=true"],
            "scene.contact_override: would replace physics.profile=precision's contact parameters",
        ),
        (
            ["--controller", "admittance", "--set", "physics.profile=fast"],
            "control_dt 0.001 s is not a whole multiple of the physics timestep 0.0025 s",
        ),
        (
            ["--set", "controller.name=impedance", "--controller", "pd"],
            "--controller pd and --set controller.name=impedance name different controllers",
        ),
    ],
)
def test_bad_settings_are_one_line_with_exit_2_and_write_nothing(
    options: list[str], message: str, tmp_path: Path
) -> None:
    proc = peg_sim_here(["teleop", "--scripted", *options, "--out", "X"], cwd=tmp_path)
    assert_one_line_error(proc, message)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("item", ["physics.profile=nope", "scene.assets.clearance=abc"])
def test_a_bad_field_is_the_error_run_gives(item: str, tmp_path: Path) -> None:
    teleop = peg_sim_here(["teleop", "--scripted", "--set", item, "--out", "X"], cwd=tmp_path)
    run = peg_sim_here(["run", "--set", item, "--out", "X"], cwd=tmp_path)
    assert teleop.returncode == run.returncode == 2 and teleop.stderr == run.stderr, teleop.stderr
    assert list(tmp_path.iterdir()) == []
