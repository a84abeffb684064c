"""Teleop sessions on the loop: resets, attempts, a scripted insertion."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.run.episode import EpisodeResult
from peg_ctrl.run.episode_log import TRACE_COLUMNS, read_log, read_trace
from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.monitors import FIRST_CONTACT_N
from peg_ctrl.teleop import SCRIPTED_INSERTION, ScriptedOperator, TeleopConfig, TeleopSession

CFG = TeleopConfig()
FAST = TeleopConfig(lin_speed=0.12, rot_speed=1.0, jaw_speed=0.08, lin_accel=1.2, jaw_accel=0.8)
DT = 0.001
HOME = np.array([-0.2, 0.0, 0.2])


def test_reset_restores_the_initial_state_exactly(tmp_path: Path) -> None:
    s = TeleopSession(tmp_path)
    qpos0 = s.data.qpos.copy()
    s.mapper.press("9")
    s.mapper.press("Q")
    s.advance(0.4)
    assert not np.array_equal(s.data.qpos, qpos0)
    s.mapper.press("Z")
    s.advance(0.001)  # the reset happens between steps, then one step runs
    s.mapper.press("Z")
    s._reset()  # and directly, to compare right after the reset
    np.testing.assert_array_equal(s.data.qpos, qpos0)
    np.testing.assert_array_equal(s.data.qvel, 0.0)
    np.testing.assert_array_equal(s.mapper.p_world, HOME)
    assert s.attempt == 3 and not s.mapper.held
    s.finish("quit")
    events = [r["event"] for r in read_log(tmp_path / "log.jsonl")]
    assert events.count("reset") == 2 and events[-1] == "end"


def test_attempts_are_limited(tmp_path: Path) -> None:
    s = TeleopSession(tmp_path)
    for _ in range(5):
        s.mapper.press("Z")
        s.advance(0.002)
    assert s.finished and s.end_reason == "attempts_exhausted"
    assert s.summary["attempts"] == 5


@pytest.mark.slow  # ~8 s; the scripted fixture below inserts the peg too, with the CLI's script
def test_scripted_session_inserts_the_peg(tmp_path: Path) -> None:
    s = TeleopSession(tmp_path, config=FAST)
    goals = [
        ("z", 0.020),
        ("jaw", 0.0),
        ("wait", 0.6),
        ("z", 0.15),
        ("roll", math.pi / 2),
        ("wait", 0.4),
        ("align", None),
        ("wait", 0.4),
        ("align", None),
        ("z", 0.09),
        ("jaw", 0.085),
        ("wait", 1.5),
    ]
    ScriptedOperator(s, goals).run(max_sim_s=60.0)
    summary = s.finish("script_done")
    assert summary["status"] == "success", summary
    assert summary["peg_radial_m"] < 0.002
    assert any(r["event"] == "inserted" for r in read_log(tmp_path / "log.jsonl"))


# 0.3 mm radial clearance: with the default 1 mm the scripted peg drops in without touching the
# bore, and the peg-block column of the trace stays at zero (as in ``peg-sim run``).
TIGHT = SceneConfig(assets=dataclasses.replace(AssetParams(), clearance=3e-4))


@pytest.fixture(scope="module")
def scripted(tmp_path_factory: pytest.TempPathFactory) -> tuple[TeleopSession, dict[str, Any], Path]:
    """The scripted insertion of ``peg-sim teleop --scripted``, in a bore tight enough to touch,
    at the faster key rates (30 s of simulated time instead of 40)."""
    out = tmp_path_factory.mktemp("teleop")
    session = TeleopSession(out, scene=TIGHT, config=FAST)
    ScriptedOperator(session, SCRIPTED_INSERTION).run(max_sim_s=120.0)
    return session, session.finish("script_done"), out


def test_scripted_session_writes_a_full_rate_force_trace(scripted) -> None:
    session, summary, out = scripted
    assert summary["status"] == "success", summary
    trace = read_trace(out / "forces.npz")
    assert not (out / "forces.partial").exists()
    assert trace.shape == (session.step_count, len(TRACE_COLUMNS))
    assert summary["total_timesteps"] == session.step_count > 10_000
    dt = float(session.model.opt.timestep)
    np.testing.assert_allclose(np.diff(trace[:, 0]), dt, atol=1e-9)  # one row per physics step
    block_peg = trace[:, TRACE_COLUMNS.index("block-peg")]
    assert block_peg.max() > FIRST_CONTACT_N  # the peg touched the bore on its way in
    assert summary["peak_contact_force_n"] == pytest.approx(block_peg.max(), rel=1e-9)
    assert summary["first_contact_s"] is not None and summary["contact_impulse_ns"] > 0


def test_scripted_session_summary_has_every_field_of_an_autonomous_run(scripted) -> None:
    _, summary, out = scripted
    autonomous = {f.name for f in dataclasses.fields(EpisodeResult)}
    assert autonomous <= set(summary), autonomous - set(summary)
    assert {"attempts", "end", "peg_radial_m", "peg_bottom_z_m"} <= set(summary)
    assert json.loads((out / "summary.json").read_text()) == summary
    assert (summary["task"], summary["physics"], summary["end_state"]) == ("teleop", "seed", "seated")
    assert summary["sim_time_s"] == pytest.approx(summary["total_timesteps"] * 0.001)
    tti, first = summary["time_to_insert_s"], summary["first_contact_s"]
    assert 0 < tti <= summary["sim_time_s"]
    # None when the peg first touched the bore after it was detected inside (on release).
    to_seat = summary["contact_to_seat_s"]
    assert to_seat is None if first > tti else to_seat == pytest.approx(tti - first)
    assert summary["insertion_depth_m"] > 0.04 and summary["peg_slip_m"] is None
    assert [p["phase"] for p in summary["phases"]] == ["teleop"]
    assert read_log(out / "log.jsonl")[-1]["event"] == "end"


def test_a_failure_in_the_loop_ends_the_session_with_its_records(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = TeleopSession(tmp_path)
    s.advance(0.05)
    steps = s.step_count

    def diverge() -> None:
        raise EpisodeFailure("diverged", "non-finite qacc")

    monkeypatch.setattr(s.loop, "step", diverge)
    s.advance(0.05)
    assert s.finished
    assert (s.summary["status"], s.summary["reason"], s.summary["detail"]) == (
        "failure",
        "diverged",
        "non-finite qacc",
    )
    assert read_trace(tmp_path / "forces.npz").shape[0] == steps


def test_scripted_session_can_be_replayed(scripted) -> None:
    from peg_ctrl.run.episode import episode_config_from_mapping
    from peg_ctrl.run.recorders import read_states
    from peg_ctrl.tools.replay import load_run

    session, summary, out = scripted
    cfg = episode_config_from_mapping(json.loads((out / "config.json").read_text()))
    assert (cfg.controller.name, cfg.seed, cfg.scene) == ("pd", 0, TIGHT)
    t, qpos = read_states(out / "states.npz")
    assert len(t) == 1 + summary["total_timesteps"] // session.loop.decimation  # the start, every step
    assert np.all(np.diff(t) > 0)
    np.testing.assert_array_equal(qpos[-1], session.data.qpos)
    model, t_run, _ = load_run(out)  # what peg-sim replay reads
    assert model.nq == session.model.nq and len(t_run) == len(t)


def test_a_reset_keeps_the_clock_running(tmp_path: Path) -> None:
    from peg_ctrl.run.recorders import read_states

    s = TeleopSession(tmp_path)
    s.advance(0.1)
    s.mapper.press("Z")
    s.advance(0.1)
    summary = s.finish("quit")
    assert summary["sim_time_s"] == pytest.approx(summary["total_timesteps"] * 0.001)
    assert [p["t_start"] for p in summary["phases"]] == [0.0, pytest.approx(0.1)]
    t, _ = read_states(tmp_path / "states.npz")
    assert np.all(np.diff(t) >= 0)  # the reset state shares its time with the last one before
    trace = read_trace(tmp_path)
    assert np.all(np.diff(trace[:, 0]) > 0) and len(trace) == summary["total_timesteps"]
