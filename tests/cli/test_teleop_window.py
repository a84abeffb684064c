"""The real teleop window under Xvfb, driven by xdotool."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
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
        _xdotool(xserver, "key", "Escape")
        # Esc ends the session at the next control step (the end record below says "quit");
        # the process then writes its files and exits by itself, in a time that grows with the
        # machine's load: a bound here only catches a hang.
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
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
    if ARTIFACTS:
        Path(ARTIFACTS).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot, Path(ARTIFACTS) / "teleop_window.png")
