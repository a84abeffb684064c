"""Teleop sessions on the loop: resets, attempts, a scripted insertion."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from peg_ctrl.episode_log import read_log
from peg_ctrl.teleop import ScriptedOperator, TeleopConfig, TeleopSession

CFG = TeleopConfig()
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


def test_scripted_session_inserts_the_peg(tmp_path: Path) -> None:
    fast = TeleopConfig(lin_speed=0.12, rot_speed=1.0, jaw_speed=0.08, lin_accel=1.2, jaw_accel=0.8)
    s = TeleopSession(tmp_path, config=fast)
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
