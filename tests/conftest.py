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


def peg_sim(argv: list[str], *, cwd: Path, timeout: float = 600.0) -> subprocess.CompletedProcess[str]:
    """``peg-sim ARGV`` in a fresh interpreter, run in ``cwd``; a command that runs longer than
    ``timeout`` [s] fails the test (subprocess.TimeoutExpired) instead of hanging the suite."""
    return subprocess.run(
        [sys.executable, "-m", "peg_ctrl", *argv], capture_output=True, text=True, cwd=cwd, timeout=timeout
    )


def peg_sim_here(argv: list[str], *, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``peg-sim ARGV`` run in ``cwd`` by this interpreter (:func:`peg_ctrl.cli.main`, which the
    console script calls), as :func:`peg_sim` reports it: without a fresh interpreter's second of
    start-up, for the many argument and config errors. Each kind of error is also checked once
    through :func:`peg_sim`."""
    import contextlib
    import io

    from peg_ctrl.cli import main

    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse: --help, or an argument error
                code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["peg-sim", *argv], code, out.getvalue(), err.getvalue())


# Imports each snippet in a fork of a process that has loaded the heavy libraries the package
# uses but no module of the package: its first import there, in a tenth of the time a fresh
# interpreter takes. Protocol: a JSON line [code, cwd, log] in, the exit code out; the child's
# stdout and stderr go to the file ``log``.
_FORK_SERVER = """
import json, os, sys, traceback
for name in sys.argv[1:]:
    __import__(name)
assert not [m for m in sys.modules if m.split(".")[0] == "peg_ctrl"], "preloaded the package"
print("ready", flush=True)
for line in sys.stdin:
    code, cwd, log = json.loads(line)
    pid = os.fork()
    if pid == 0:
        status = 0
        try:
            fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            os.chdir(cwd)
            exec(compile(code, "<first import>", "exec"), {"__name__": "__main__"})
        except BaseException:
            traceback.print_exc()
            status = 1
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), flush=True)
"""
#: The libraries the package's modules import at their top (a library missing here only costs time).
PRELOADED = ("numpy", "scipy.linalg", "scipy.sparse", "mujoco", "gymnasium", "qpsolvers", "ruckig")


class FirstImports:
    """Runs code in a fresh fork of a process that has imported :data:`PRELOADED` and nothing of
    peg_ctrl, so that an import in it is the package's first: an import cycle shows, as in a
    fresh interpreter. (A module that uses a submodule of those libraries without importing it
    would pass here: ``tests/test_packaging.py`` imports every module in a fresh interpreter too,
    among the slow tests.)"""

    def __init__(self, logs: Path) -> None:
        self._logs = logs
        self._count = 0
        self._proc = subprocess.Popen(
            [sys.executable, "-c", _FORK_SERVER, *PRELOADED],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self._proc.stdout is not None and self._proc.stdout.readline() == "ready\n"

    def run(self, code: str, *, cwd: Path) -> subprocess.CompletedProcess[str]:
        """``python -c CODE`` in ``cwd``, forked: its exit code, and its stdout and stderr as stderr."""
        import json

        assert self._proc.stdin is not None and self._proc.stdout is not None
        self._count += 1
        log = self._logs / f"{self._count}.txt"
        self._proc.stdin.write(json.dumps([code, str(cwd), str(log)]) + "\n")
        self._proc.stdin.flush()
        code_out = int(self._proc.stdout.readline())
        return subprocess.CompletedProcess(["-c", code], code_out, "", log.read_text())

    def close(self) -> None:
        assert self._proc.stdin is not None
        self._proc.stdin.close()
        self._proc.wait(timeout=60)


@pytest.fixture(scope="session")
def first_imports(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FirstImports]:
    """A :class:`FirstImports` for the session (one per test worker)."""
    server = FirstImports(tmp_path_factory.mktemp("first-imports"))
    yield server
    server.close()


def assert_one_line_error(proc: subprocess.CompletedProcess[str], message: str) -> None:
    """A user or OS mistake: exit 2 and one ``peg-sim: error: ...`` line containing ``message``."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("peg-sim: error: ") and message in lines[0], lines[0]


@pytest.fixture()
def fake_triton(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """An importable stand-in ``triton`` package (its ``__init__.py`` is returned, empty), not
    imported yet; afterwards whatever ``triton`` was imported before is back (PyTorch looks for
    the real one in ``sys.modules``)."""
    package = tmp_path / "fake_triton" / "triton"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(package.parent))
    saved = sys.modules.pop("triton", None)
    yield package / "__init__.py"
    sys.modules.pop("triton", None)
    if saved is not None:
        sys.modules["triton"] = saved
