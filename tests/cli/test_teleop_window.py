"""The real teleop window under Xvfb, driven by xdotool."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from peg_ctrl.run.episode_log import read_log

# -- a real window ---------------------------------------------------------------------------

ARTIFACTS = os.environ.get("PEG_TEST_ARTIFACTS")  # a directory to keep the screenshot in, if set


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


def _steps(records: list[dict], attempt: int | None = None) -> list[dict]:
    return [r for r in records if r["event"] == "step" and attempt in (None, r["attempt"])]


def _released_and_ran_on(records: list[dict]) -> bool:
    """Step records of the first attempt more than 600 steps after the last one with 8 held."""
    held = [r["step"] for r in _steps(records, 1) if "8" in r["keys"]]
    return bool(held) and _steps(records, 1)[-1]["step"] > held[-1] + 600


def _wait_for_log(proc: subprocess.Popen, log: Path, done: Callable[[list[dict]], bool], what: str) -> None:
    """Until the session's log shows ``done``. The window paces the session to the clock, but
    no faster than it can draw: on a loaded machine its simulated time falls behind the clock,
    so the test waits on the session's own records rather than on the clock."""
    deadline = time.monotonic() + 120.0
    while not (log.is_file() and done(read_log(log))):
        assert proc.poll() is None, f"teleop exited ({proc.returncode}) before it did {what}"
        assert time.monotonic() < deadline, f"the session did not {what} within 120 s"
        time.sleep(0.1)


def test_window_keys_move_reset_and_quit(xserver: str, tmp_path: Path) -> None:
    env = {**os.environ, "DISPLAY": xserver}
    env.pop("MUJOCO_GL", None)
    shot, log = tmp_path / "teleop_window.png", tmp_path / "log.jsonl"
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
        _wait_for_log(proc, log, lambda records: len(_steps(records)) >= 3, "start")
        _xdotool(xserver, "keydown", "8")
        _wait_for_log(
            proc,
            log,
            lambda records: any(r["gripper"]["position"][2] > 0.21 for r in _steps(records, 1)),
            "move the gripper up 1 cm with 8 held",
        )
        _xdotool(xserver, "keyup", "8")
        _wait_for_log(proc, log, _released_and_ran_on, "run on after 8 was released")
        _xdotool(xserver, "key", "z")
        _wait_for_log(proc, log, lambda records: len(_steps(records, 2)) >= 3, "reset")
        _xdotool(xserver, "key", "Escape")
        # Esc ends the session at the next control step (the end record below says "quit");
        # the process then writes its files and exits by itself, in a time that grows with the
        # machine's load: a bound here only catches a hang.
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1, err  # quit with the peg not inserted, as a failed 'peg-sim run'
    records = read_log(log)
    assert records[-1]["event"] == "end" and records[-1]["end"] == "quit"
    steps = _steps(records)
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
    if ARTIFACTS:
        Path(ARTIFACTS).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot, Path(ARTIFACTS) / "teleop_window.png")
