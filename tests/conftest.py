"""Shared fixtures: the default scene compiled once per test session; tests run outside the tree."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

# Offscreen rendering in the tests (videos, replays) without a window system, as peg-sim does:
# mujoco reads MUJOCO_GL when it first renders, from the value set before it was imported.
if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

# peg_ctrl first: it sets one BLAS thread, read when numpy's BLAS loads; the tests then run
# with the threads a user's `peg-sim` has (two threads change qpOASES's rounding in the mpc).
import peg_ctrl  # noqa: E402, F401, I001

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers import make_controller
from peg_ctrl.sim.scene import build_model
from peg_ctrl.run.tracker import Tracker

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
HOME = np.array([-0.2, 0.0, 0.2])


@pytest.fixture(autouse=True, scope="session")
def _run_outside_the_repository(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """MuJoCo writes MUJOCO_LOG.TXT into the working directory on warnings, and generated meshes
    go to a cache: keep both out of the repository and out of the user's cache."""
    cwd = os.getcwd()
    cache = os.environ.get("PEG_CTRL_CACHE")
    os.environ["PEG_CTRL_CACHE"] = str(tmp_path_factory.mktemp("cache"))
    os.chdir(tmp_path_factory.mktemp("cwd"))
    try:
        yield
    finally:
        os.chdir(cwd)
        if cache is None:
            os.environ.pop("PEG_CTRL_CACHE", None)
        else:
            os.environ["PEG_CTRL_CACHE"] = cache


@pytest.fixture(scope="session")
def model() -> mujoco.MjModel:
    return build_model()


@pytest.fixture()
def sim(model: mujoco.MjModel) -> Tracker:
    return Tracker(model, make_controller("pd", model))


def target(p, quat=IDENTITY, *, jaw: float = 0.085, v=(0.0, 0.0, 0.0), w=(0.0, 0.0, 0.0)) -> GripperTarget:
    return GripperTarget(
        p_world=np.asarray(p, dtype=float),
        quat_world=np.asarray(quat, dtype=float),
        jaw_sep_m=jaw,
        v_world=np.asarray(v, dtype=float),
        omega_body=np.asarray(w, dtype=float),
    )


def sigint_default() -> None:
    """``preexec_fn`` for a child that a test interrupts: Ctrl-C's default action, even when this
    process was started with SIGINT ignored (a background shell, nohup, some CI), which a child
    would otherwise inherit and which Python then keeps (no KeyboardInterrupt)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def peg_sim(argv: list[str], *, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``peg-sim ARGV`` in a fresh interpreter, run in ``cwd``."""
    return subprocess.run([sys.executable, "-m", "peg_ctrl", *argv], capture_output=True, text=True, cwd=cwd)


def assert_one_line_error(proc: subprocess.CompletedProcess[str], message: str) -> None:
    """A user or OS mistake: exit 2 and one ``peg-sim: error: ...`` line containing ``message``."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("peg-sim: error: ") and message in lines[0], lines[0]
