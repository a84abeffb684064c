"""Autonomous episodes end to end: success, failure reasons, logs, determinism, interruption."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from peg_ctrl.config import ConfigError
from peg_ctrl.controllers import PDConfig
from peg_ctrl.run.episode import (
    FAILURE_REASONS,
    WALL_CLOCK_FIELDS,
    DomainConfig,
    EpisodeConfig,
    RandomizationConfig,
    contact_to_seat,
    episode_config_from_mapping,
    run_episode,
)
from peg_ctrl.run.episode_log import STEP_FIELDS, TRACE_COLUMNS, read_log, read_trace
from peg_ctrl.sim.ft_model import FT_PRESETS, FTSensorModel
from peg_ctrl.tasks.pick_and_place import SuccessConfig, TaskConfig, initial_qpos

from ..conftest import sigint_default

RANDOM = RandomizationConfig(enabled=True)
SUMMARY_KEYS = {
    "status": str,
    "reason": str,
    "phase": str,
    "controller": str,
    "planner": str,
    "seed": int,
    "total_timesteps": int,
    "sim_time_s": float,
    "wall_time_s": float,
    "peak_contact_force_n": float,
    "insertion_depth_m": float,
    "lateral_error_m": float,
    "tilt_rad": float,
    "max_penetration_m": float,
    "peg_slip_m": float,
    "log_path": str,
}


def _get(record: dict, dotted: str):
    for key in dotted.split("."):
        record = record[key]
    return record


@pytest.fixture(scope="module")
def episode(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("episode")
    return run_episode(EpisodeConfig(seed=3, randomization=RANDOM), out), out


def test_default_episode_inserts_the_peg(episode) -> None:
    result, out = episode
    assert result.status == "success", result.detail
    assert result.insertion_depth_m >= 0.04
    assert result.lateral_error_m <= 0.0025 and result.tilt_rad <= 0.1
    assert result.max_penetration_m <= 3e-3
    assert result.resting_penetration_m <= 0.5e-3
    assert result.peg_slip_m <= 0.5e-3
    assert result.total_timesteps <= 20_000
    phases = [p["phase"] for p in result.phases]
    assert (
        phases == ["start", "approach", "descend", "grasp", "lift", "rotate", "align", "release"]
        or phases[-1] == "settle"
    )


def test_summary_has_the_documented_fields(episode) -> None:
    _, out = episode
    summary = json.loads((out / "summary.json").read_text())
    for key, kind in SUMMARY_KEYS.items():
        assert isinstance(summary[key], kind), key
    assert Path(summary["log_path"]).is_file()
    assert (out / "force_profile.png").stat().st_size > 10_000
    config = json.loads((out / "config.json").read_text())
    assert config["seed"] == 3 and config["randomization"]["enabled"] is True


def test_log_records_have_every_spec_field(episode) -> None:
    _, out = episode
    records = read_log(out / "log.jsonl")
    steps = [r for r in records if r["event"] == "step"]
    assert len(steps) >= 100
    for r in steps:
        for field in STEP_FIELDS:
            _get(r, field)
        assert len(r["command"]["position"]) == 3 and len(r["gripper"]["quat"]) == 4
        assert len(r["gripper"]["euler"]) == 3 and len(r["peg"]["quat"]) == 4
        for c in r["contacts"]:
            assert set(c) >= {"pair", "force", "magnitude", "position"}
            assert c["magnitude"] >= 0.01
    assert np.all(np.diff([r["step"] for r in steps]) == 50)
    assert records[-1]["event"] == "end" and records[-1]["status"] == "success"
    assert [r["phase"] for r in records if r["event"] == "phase"][1] == "approach"
    # Held: the gripper-peg contact is in the log.
    assert any(c["pair"] == "gripper-peg" for r in steps if r["phase"] == "rotate" for c in r["contacts"])


def test_force_trace_is_full_rate(episode) -> None:
    result, out = episode
    trace = read_trace(out / "forces.npz")
    assert trace.shape == (result.total_timesteps, len(TRACE_COLUMNS))
    np.testing.assert_allclose(np.diff(trace[:, 0]), 0.001, atol=1e-9)
    with np.load(out / "forces.npz") as npz:
        np.testing.assert_array_equal(npz["data"], trace)


def test_same_seed_same_episode(tmp_path: Path) -> None:
    cfg = EpisodeConfig(seed=7, randomization=RANDOM, max_steps=4000)
    a = run_episode(cfg, tmp_path / "a", plot=False)
    b = run_episode(cfg, tmp_path / "b", plot=False)
    np.testing.assert_array_equal(read_trace(tmp_path / "a"), read_trace(tmp_path / "b"))
    skip = {*WALL_CLOCK_FIELDS, "log_path", "trace_path", "plot_path", "video_path"}
    assert {k: v for k, v in a.to_dict().items() if k not in skip} == {
        k: v for k, v in b.to_dict().items() if k not in skip
    }


def test_different_seeds_start_differently(tmp_path: Path) -> None:
    from peg_ctrl.sim.scene import build_model

    model = build_model()

    def start(seed: int) -> np.ndarray:
        cfg = EpisodeConfig(seed=seed, randomization=RANDOM)
        return initial_qpos(model, cfg.scene, cfg.randomization, np.random.default_rng(seed))

    a = start(1)
    b = start(2)
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(a, start(1))


@pytest.mark.parametrize(
    "cfg, reason, phase",
    [
        (EpisodeConfig(task=TaskConfig(grasp_height=0.06)), "grasp_lost", "grasp"),
        (EpisodeConfig(success=SuccessConfig(force_spike=0.05)), "force_spike", None),
        (EpisodeConfig(max_steps=2500), "timeout", None),
    ],
    ids=["closes-on-air", "tiny-force-limit", "step-limit"],
)
def test_failures_are_named(tmp_path: Path, cfg: EpisodeConfig, reason: str, phase: str | None) -> None:
    result = run_episode(cfg, tmp_path, plot=False)
    assert result.status == "failure"
    assert result.reason == reason and reason in FAILURE_REASONS
    if phase is not None:
        assert result.phase == phase
    assert read_log(tmp_path / "log.jsonl")[-1]["reason"] == reason


def test_fixed_speed_planner_with_a_guarded_insert(tmp_path: Path) -> None:
    """Both in one episode; each alone in the next test."""
    result = run_episode(
        EpisodeConfig(
            seed=5, planner="fixed_speed", randomization=RANDOM, task=TaskConfig(force_guarded_insert=True)
        ),
        tmp_path,
        plot=False,
    )
    assert result.status == "success", result.detail
    assert result.planner == "fixed_speed"
    assert "insert" in [p["phase"] for p in result.phases]  # the guarded insert's phase


@pytest.mark.slow  # two whole episodes (~7 s); the test above runs both features in one
def test_fixed_speed_planner_and_guarded_insert(tmp_path: Path) -> None:
    fixed = run_episode(
        EpisodeConfig(seed=5, planner="fixed_speed", randomization=RANDOM), tmp_path / "f", plot=False
    )
    assert fixed.status == "success", fixed.detail
    guarded = run_episode(
        EpisodeConfig(seed=5, randomization=RANDOM, task=TaskConfig(force_guarded_insert=True)),
        tmp_path / "g",
        plot=False,
    )
    assert guarded.status == "success", guarded.detail
    assert "insert" in [p["phase"] for p in guarded.phases]


def _start_run(out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "peg_ctrl", "run", "--randomize", "--seed", "1", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=sigint_default,  # the test interrupts it
    )


def _wait_for_steps(path: Path, n: int, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.is_file() and sum(1 for r in read_log(path) if r["event"] == "step") >= n:
            return
        time.sleep(0.1)
    raise AssertionError(f"{path} did not reach {n} step records")


def test_killed_episode_leaves_a_readable_log(tmp_path: Path) -> None:
    proc = _start_run(tmp_path)
    try:
        _wait_for_steps(tmp_path / "log.jsonl", 12)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    records = read_log(tmp_path / "log.jsonl")
    assert sum(r["event"] == "step" for r in records) >= 12
    # the trace goes out in chunks of 500 physics steps: the first is on disk by step 600
    trace = read_trace(tmp_path / "forces.partial")
    assert trace.shape[0] >= 500 and trace.shape[1] == len(TRACE_COLUMNS)
    np.testing.assert_allclose(np.diff(trace[:, 0]), 0.001, atol=1e-9)
    assert not (tmp_path / "summary.json").exists()


def test_interrupted_episode_writes_its_record(tmp_path: Path) -> None:
    proc = _start_run(tmp_path)
    _wait_for_steps(tmp_path / "log.jsonl", 5)
    os.kill(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "peg-sim: interrupted"
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert read_log(tmp_path / "log.jsonl")[-1]["event"] == "end"


def test_config_mapping_errors_name_the_field() -> None:
    with pytest.raises(ConfigError, match=r"^task.lift_heigth: unknown field"):
        episode_config_from_mapping({"task": {"lift_heigth": 0.2}})
    with pytest.raises(ConfigError, match=r"^seed: expected an integer"):
        episode_config_from_mapping({"seed": "three"})
    with pytest.raises(ConfigError, match=r"kp_pos"):
        episode_config_from_mapping({"controller": {"name": "pd", "kp_pos": -5.0}})
    with pytest.raises(ConfigError, match=r"^task.lift_timeout must be finite and >= 0"):
        episode_config_from_mapping({"task": {"lift_timeout": -1.0}})
    cfg = episode_config_from_mapping({"controller": {"name": "pd", "kp_pos": 2500.0}, "seed": 4})
    assert cfg.controller == PDConfig(kp_pos=2500.0) and cfg.seed == 4


def test_cli_config_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("planner: ruckig\ntask:\n  grasp_time: fast\n")
    proc = subprocess.run(
        [sys.executable, "-m", "peg_ctrl", "run", "--config", str(bad), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "peg-sim: error: task.grasp_time: expected a number, got 'fast'"


def test_divergence_is_detected(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A non-finite state ends the episode as `diverged`, not with a traceback."""
    import mujoco

    from peg_ctrl.run import episode as episode_module

    real_step = mujoco.mj_step
    calls = {"n": 0}

    def exploding_step(model, data, nstep=1):  # type: ignore[no-untyped-def]
        real_step(model, data, nstep=nstep)
        calls["n"] += 1
        if calls["n"] == 500:
            data.qvel[0] = np.inf

    monkeypatch.setattr(episode_module.mujoco, "mj_step", exploding_step)
    result = run_episode(EpisodeConfig(), tmp_path, plot=False)
    assert result.reason == "diverged"
    assert result.total_timesteps <= 510


@pytest.mark.parametrize(
    ("first", "seated", "expected"),
    [(1.0, 3.5, 2.5), (3.5, 3.5, 0.0), (9.235, 9.155, None), (None, 3.0, None), (1.0, None, None)],
)
def test_contact_to_seat_is_none_unless_contact_came_first(
    first: float | None, seated: float | None, expected: float | None
) -> None:
    """A peg seated before it first touched the block (dropped into a wide hole, it meets the
    bore only afterwards) has no contact-to-seat time, not a negative one."""
    assert contact_to_seat(first, seated) == expected


# -- the sensors' noise (domain) ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("domain", "message"),
    [
        ({"torque_noise": -0.1}, "domain.torque_noise must be finite and >= 0, got -0.1"),
        ({"ft_latency": float("nan")}, "domain.ft_latency must be finite and >= 0, got nan"),
        ({"ft_bias_drift": float("inf")}, "domain.ft_bias_drift must be finite and >= 0, got inf"),
        (
            {"ft_sensor": "nope"},
            "domain.ft_sensor: unknown F/T sensor preset 'nope'; known: forge, ideal, mini45, wrist",
        ),
        (
            {"ft_sensor": "wrist", "force_noise": 0.1},
            "domain.force_noise: set either domain.ft_sensor (a preset) or the sensor's noise fields, "
            "not both",
        ),
        (
            {"ft_sensor": "ideal", "ft_latency": 0.01},
            "domain.ft_latency: set either domain.ft_sensor (a preset) or the sensor's noise fields, "
            "not both",
        ),
    ],
)
def test_sensor_noise_errors_name_the_field(domain: dict, message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        episode_config_from_mapping({"domain": domain})
    assert str(exc.value) == message


def test_the_ft_model_is_the_preset_or_the_five_fields() -> None:
    assert DomainConfig().ft_model == FTSensorModel()
    for name, preset in FT_PRESETS.items():
        assert DomainConfig(ft_sensor=name).ft_model == preset
    fields = DomainConfig(
        force_noise=0.2, torque_noise=0.003, ft_latency=0.02, ft_bias_drift=0.05, ft_rate=100.0
    )
    assert fields.ft_model == FTSensorModel(
        force_noise=0.2, torque_noise=0.003, latency=0.02, bias_drift=0.05, rate=100.0
    )
    with pytest.raises(ConfigError, match=r"^domain\.ft_rate must be finite and >= 0, got -1\.0$"):
        DomainConfig(ft_rate=-1.0)
    with pytest.raises(ConfigError, match=r"^domain\.orientation_noise must be finite and >= 0, got nan$"):
        DomainConfig(orientation_noise=float("nan"))
    with pytest.raises(ConfigError, match=r"^domain\.ft_rate: set either domain\.ft_sensor"):
        DomainConfig(ft_sensor="wrist", ft_rate=100.0)


@pytest.mark.parametrize(
    ("domain", "noisy"),
    [
        ({}, False),
        ({"ft_sensor": "ideal"}, False),
        ({"ft_sensor": "wrist"}, True),
        ({"force_noise": 0.1}, True),
        ({"torque_noise": 0.01}, True),
        ({"ft_latency": 0.01}, True),
        ({"ft_bias_drift": 0.01}, True),
        ({"velocity_noise": 0.01}, True),
        ({"orientation_noise": 1e-4}, True),
    ],
)
def test_any_sensor_noise_makes_the_seed_matter(domain: dict, noisy: bool) -> None:
    cfg = episode_config_from_mapping({"domain": domain})
    assert cfg.domain.noisy is noisy and cfg.domain.random is noisy and cfg.seeded is noisy


def test_an_ideal_ft_sensor_is_the_episode_without_domain_settings(tmp_path: Path) -> None:
    base = {"seed": 4, "randomization": {"enabled": True}, "max_steps": 3000}
    plain = run_episode(episode_config_from_mapping(base), tmp_path / "plain", plot=False)
    ideal = episode_config_from_mapping({**base, "domain": {"ft_sensor": "ideal"}})
    same = run_episode(ideal, tmp_path / "ideal", plot=False)
    np.testing.assert_array_equal(read_trace(tmp_path / "plain"), read_trace(tmp_path / "ideal"))
    skip = {*WALL_CLOCK_FIELDS, "log_path", "trace_path", "plot_path", "video_path"}
    assert {k: v for k, v in plain.to_dict().items() if k not in skip} == {
        k: v for k, v in same.to_dict().items() if k not in skip
    }


def test_the_result_records_the_peg_s_friction_time(tmp_path: Path) -> None:
    """A run with ``physics.friction_time`` says so in its result, its summary and its line; one
    without records None (the profile's)."""
    base = {"physics": {"profile": "precision"}, "max_steps": 40, "log": {"trace": False}}
    plain = run_episode(episode_config_from_mapping(base), tmp_path / "plain", plot=False)
    assert plain.friction_time_s is None and "friction time" not in plain.one_line()
    slow = {**base, "physics": {"profile": "precision", "friction_time": 0.005}}
    result = run_episode(episode_config_from_mapping(slow), tmp_path / "slow", plot=False)
    assert result.friction_time_s == 0.005
    assert json.loads((tmp_path / "slow" / "summary.json").read_text())["friction_time_s"] == 0.005
    assert "(pick_and_place, precision physics, the peg's friction time 5 ms)" in result.one_line()
