"""Teleoperation: the pure key mapping, resets, a scripted insertion, and a real window under Xvfb."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

from peg_ctrl.episode_log import read_log
from peg_ctrl.teleop import KEYMAP, ScriptedOperator, TeleopConfig, TeleopMapper, TeleopSession

CFG = TeleopConfig()
DT = 0.001
HOME = np.array([-0.2, 0.0, 0.2])


def _mapper() -> TeleopMapper:
    return TeleopMapper(CFG, p_world=HOME, quat_world=[1.0, 0.0, 0.0, 0.0], jaw_sep_m=0.04)


def _hold(m: TeleopMapper, key: str, seconds: float, *, shift: bool = False) -> None:
    m.press(key, shift=shift)
    for _ in range(int(round(seconds / DT))):
        m.step(DT)
    m.release(key)


def _rates(m: TeleopMapper) -> np.ndarray:
    """Body angular displacement of the command since home [rad]."""
    rotvec = np.zeros(3)
    mujoco.mju_subQuat(rotvec, m.quat_world, np.array([1.0, 0.0, 0.0, 0.0]))
    return rotvec


@pytest.mark.parametrize("key, index, sign", [(k, i, s) for k, (i, s) in KEYMAP.items()])
def test_each_key_moves_its_axis_in_its_direction(key: str, index: int, sign: float) -> None:
    m = _mapper()
    _hold(m, key, 0.5)
    moved = np.concatenate([m.p_world - HOME, _rates(m), [m.jaw_sep_m - 0.04]])
    assert np.sign(moved[index]) == sign
    others = np.delete(moved, index)
    assert np.abs(others).max() < 1e-12, f"{key} moved other axes: {moved}"


def test_release_stops_the_motion() -> None:
    m = _mapper()
    _hold(m, "Q", 0.5)  # a rotation, the case that used to stick
    for _ in range(1000):
        m.step(DT)
    assert np.all(m.velocity == 0.0)
    frozen = m.quat_world.copy()
    for _ in range(500):
        m.step(DT)
    np.testing.assert_array_equal(m.quat_world, frozen)


def test_rate_limit_and_full_speed() -> None:
    m = _mapper()
    m.press("6")
    previous = 0.0
    for _ in range(300):
        m.step(DT)
        assert m.velocity[0] - previous <= CFG.lin_accel * DT + 1e-15
        previous = m.velocity[0]
    assert m.velocity[0] == pytest.approx(CFG.lin_speed)  # reached after lin_speed / lin_accel = 0.1 s


def test_deadzone_zeroes_small_velocities() -> None:
    m = _mapper()
    m.press("8")
    m.step(DT)  # one step of ramp: 0.6 mm/s, inside the 2 % deadzone of 60 mm/s
    m.release("8")
    m.step(DT)
    assert m.velocity[2] == 0.0


def test_fine_motion_and_speed_keys() -> None:
    m = _mapper()
    _hold(m, "6", 1.0, shift=True)
    assert m.velocity.max() <= CFG.lin_speed * CFG.fine_scale + 1e-12
    for key, speed in (("J", 0.5), ("K", 1.0), ("L", 2.0)):
        m.press(key)
        assert m.speed == speed
    for _ in range(20):
        m.press("=")
    assert m.speed == 5.0
    for _ in range(40):
        m.press("-")
    assert m.speed == 0.1
    with pytest.raises(ValueError, match="speed multiplier"):
        m.set_speed(7.0)


def test_jaw_command_stays_in_range() -> None:
    m = _mapper()
    _hold(m, "]", 3.0)
    assert m.jaw_sep_m == 0.0
    _hold(m, "[", 5.0)
    assert m.jaw_sep_m == 0.085


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


# -- a real window ---------------------------------------------------------------------------

ARTIFACTS = Path(os.environ.get("PEG_TEST_ARTIFACTS", Path(__file__).resolve().parent.parent / "artifacts"))


@pytest.fixture()
def xserver():
    missing = [tool for tool in ("Xvfb", "xdotool") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"no X server for the window test: {', '.join(missing)} not installed (make sysdeps)")
    read, write = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
        pass_fds=(write,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write)
    with os.fdopen(read) as fh:
        number = fh.readline().strip()
    if not number:
        proc.kill()
        pytest.skip("Xvfb could not start an X server")
    yield f":{number}"
    proc.terminate()
    proc.wait(timeout=10)


def _xdotool(display: str, *args: str) -> str:
    return subprocess.run(
        ["xdotool", *args], env={**os.environ, "DISPLAY": display}, capture_output=True, text=True, timeout=60
    ).stdout.strip()


def test_window_keys_move_reset_and_quit(xserver: str, tmp_path: Path) -> None:
    env = {**os.environ, "DISPLAY": xserver}
    env.pop("MUJOCO_GL", None)
    shot = tmp_path / "teleop_window.png"
    proc = subprocess.Popen(
        [sys.executable, "-m", "peg_ctrl", "teleop", "--out", str(tmp_path), "--screenshot", str(shot)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        window = _xdotool(xserver, "search", "--sync", "--name", "peg_ctrl teleop").splitlines()[0]
        _xdotool(xserver, "windowfocus", "--sync", window)
        _xdotool(xserver, "mousemove", "--window", window, "400", "400")
        time.sleep(1.5)
        _xdotool(xserver, "keydown", "8")
        time.sleep(2.0)
        _xdotool(xserver, "keyup", "8")
        time.sleep(1.5)
        _xdotool(xserver, "key", "z")
        time.sleep(1.0)
        t0 = time.monotonic()
        _xdotool(xserver, "key", "Escape")
        out, err = proc.communicate(timeout=10)
        quit_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert quit_s < 2.0
    records = read_log(tmp_path / "log.jsonl")
    assert records[-1]["event"] == "end" and records[-1]["end"] == "quit"
    steps = [r for r in records if r["event"] == "step"]
    held = [r for r in steps if "8" in r["keys"]]
    assert held, "the key press never reached the session"
    z = [r["gripper"]["position"][2] for r in steps if r["attempt"] == 1]
    assert max(z) > 0.21, "the gripper did not move up"
    after = [r for r in steps if r["attempt"] == 1 and r["step"] > held[-1]["step"] + 500]
    assert after and np.ptp([r["command"]["position"][2] for r in after]) < 1e-9, "motion did not stop"
    assert any(r["event"] == "reset" for r in records)
    assert [r["gripper"]["position"][2] for r in steps if r["attempt"] == 2][-1] == pytest.approx(
        0.2, abs=1e-3
    )
    assert shot.stat().st_size > 20_000
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(shot, ARTIFACTS / "teleop_window.png")
