"""A full or read-only disk: ``peg-sim`` exits 2 with one line naming the file and the reason, and
leaves every file complete or absent.

The disk is a small tmpfs (so the tests need to mount: they are skipped where they may not).
Its size is computed from a reference run into a large tmpfs, page by page, so that the disk
fills at a chosen moment: at ``config.json``, in the log or the force trace while the episode
runs, at ``summary.json``, at the packed trace ``forces.npz``, at ``states.npz``, at the plot;
and at several moments of a sweep. Each case checks every file left (see ``conftest.py``:
strict JSON, whole JSON lines and trace rows, loadable npz, decodable PNG, no temporary file).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from peg_ctrl.progress import ENV_VAR
from peg_ctrl.run.episode_log import TRACE_COLUMNS

PAGE = os.sysconf("SC_PAGE_SIZE")  # tmpfs counts whole pages
ENOSPC = "No space left on device"
EROFS = "Read-only file system"
# No force trace and no step records: the files are small and each one can be hit on its own.
# 2 s of the episode, which then times out: every file of a run, in a fifth of an episode's time.
LEAN = ["--set", "log.trace=false", "--set", "log.interval=100000", "--max-steps", "2000"]
# The full-rate force trace, no step records: a step record carries the controller's wall-clock
# solve time, whose printed length varies from run to run, so the log's size before its end
# record would move by some bytes against the reference's and, near a page's end, by a page.
TRACED = ["--set", "log.interval=100000"]
SWEEP = """\
name: tiny
controllers: [{name: pd}]
seeds: [0, 1]
max_steps: 600
"""


def _pages(n_bytes: int) -> int:
    return math.ceil(n_bytes / PAGE)


def _run(cmd: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


@contextlib.contextmanager
def _tmpfs(where: Path, pages: int) -> Iterator[Path]:
    """A tmpfs of ``pages`` pages mounted on ``where`` (skips the test where mounting is refused)."""
    if shutil.which("mount") is None:
        pytest.skip("no mount command")
    where.mkdir(parents=True, exist_ok=True)
    proc = _run(["mount", "-t", "tmpfs", "-o", f"size={pages * PAGE}", "tmpfs", str(where)])
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {proc.stderr.strip()}")
    try:
        yield where
    finally:
        _umount(where)


def _umount(where: Path) -> None:
    if _run(["umount", str(where)]).returncode != 0:
        _run(["umount", "-l", str(where)])


def _peg_sim(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, ENV_VAR: "0"}
    return subprocess.run(
        [sys.executable, "-m", "peg_ctrl", *args], capture_output=True, text=True, env=env, timeout=600
    )


def _one_error_line(proc: subprocess.CompletedProcess[str]) -> str:
    """The failed command's one stderr line; exit code 2 and no traceback."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("peg-sim: error: "), proc.stderr
    return lines[0]


def _sizes(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): p.stat().st_size for p in root.rglob("*") if p.is_file()}


# -- one episode ---------------------------------------------------------------------------------
def _reference(tmp_path_factory: pytest.TempPathFactory, args: list[str]) -> dict[str, int]:
    """The files of ``peg-sim run --out MNT/run ARGS`` (the same path as the cases: the log
    holds it) and ``log.jsonl`` before its end record (``log_before_end``)."""
    mnt = tmp_path_factory.mktemp("reference") / "mnt"
    with _tmpfs(mnt, 16384):
        proc = _peg_sim("run", "--out", str(mnt / "run"), *args)
        assert proc.returncode in (0, 1), proc.stderr
        sizes = _sizes(mnt / "run")
        log = (mnt / "run" / "log.jsonl").read_bytes()
        sizes["log_before_end"] = len(log) - len(log.splitlines(keepends=True)[-1])
        summary = json.loads((mnt / "run" / "summary.json").read_text())
        sizes["forces.partial"] = summary["total_timesteps"] * 8 * len(TRACE_COLUMNS)  # while running
    return sizes


@pytest.fixture(scope="module")
def lean(tmp_path_factory: pytest.TempPathFactory) -> dict[str, int]:
    return _reference(tmp_path_factory, LEAN)


@pytest.fixture(scope="module")
def traced(tmp_path_factory: pytest.TempPathFactory) -> dict[str, int]:
    return _reference(tmp_path_factory, TRACED)


def _lean_pages(stage: str, s: dict[str, int]) -> int:
    """Pages of a tmpfs that fills when the lean run writes ``stage``. Before it: the lock file
    and ``config.json`` (a page each), the log, the summary, the trace, the states, the plot."""
    log, log_early, summary = _pages(s["log.jsonl"]), _pages(s["log_before_end"]), _pages(s["summary.json"])
    npz, states, plot = _pages(s["forces.npz"]), _pages(s["states.npz"]), _pages(s["force_profile.png"])
    return {
        "config.json": 1,
        "log.jsonl": 2,
        "summary.json": 2 + log_early,
        "forces.npz": 2 + log + summary,
        "states.npz": 2 + log + summary + npz + states // 2,
        "force_profile.png": 2 + log + summary + npz + states + plot // 2,
    }[stage]


FAST = ("config.json", "summary.json", "force_profile.png")


@pytest.mark.parametrize(
    "stage",
    [
        pytest.param(s, marks=() if s in FAST else pytest.mark.slow)
        for s in ("config.json", "log.jsonl", "summary.json", "forces.npz", "states.npz", "force_profile.png")
    ],
)
def test_a_run_on_a_full_disk_exits_2_and_leaves_nothing_torn(
    stage: str,
    lean: dict[str, int],
    tmp_path: Path,
    strict_json: Callable[[str], Any],
    complete_tree: Callable[[Path], int],
) -> None:
    mnt = tmp_path / "mnt"
    with _tmpfs(mnt, _lean_pages(stage, lean)):
        proc = _peg_sim("run", "--out", str(mnt / "run"), *LEAN)
        line = _one_error_line(proc)
        assert line == f"peg-sim: error: cannot write '{mnt / 'run' / stage}': {ENOSPC}"
        checked = complete_tree(mnt)
        left = {p.name for p in (mnt / "run").iterdir()}
        if stage != "log.jsonl":  # written atomically: absent; the log: whole lines (checked)
            assert stage not in left
        if "summary.json" in left:  # the record survived the failure
            summary = strict_json((mnt / "run" / "summary.json").read_text())
            assert summary["status"] in ("success", "failure") and summary["plot_path"] is None
        print(f"{stage}: {proc.stderr.strip()} ({checked} files checked)")


@pytest.mark.slow
@pytest.mark.parametrize("stage", ["while running", "summary.json", "forces.npz"])
def test_a_traced_run_on_a_full_disk_keeps_whole_trace_rows(
    stage: str,
    traced: dict[str, int],
    tmp_path: Path,
    complete_tree: Callable[[Path], int],
) -> None:
    """With the full-rate force trace: the disk fills in the trace or the log while the episode
    runs (both are cut back to whole records), at the summary, or at the packed trace
    (``forces.partial`` stays, whole)."""
    mnt = tmp_path / "mnt"
    s = traced
    log, log_early, summary = _pages(s["log.jsonl"]), _pages(s["log_before_end"]), _pages(s["summary.json"])
    partial = _pages(s["forces.partial"])
    pages = {
        "while running": 2 + (log + partial) // 2,
        "summary.json": 2 + log_early + partial,
        "forces.npz": 2 + log + partial + summary + _pages(s["forces.npz"]) // 2,
    }[stage]
    with _tmpfs(mnt, pages):
        line = _one_error_line(_peg_sim("run", "--out", str(mnt / "run"), *TRACED))
        named = line.removeprefix(f"peg-sim: error: cannot write '{mnt / 'run'}/").removesuffix(
            f"': {ENOSPC}"
        )
        assert named in (("log.jsonl", "forces.partial") if stage == "while running" else (stage,)), line
        checked = complete_tree(mnt)
        if stage != "while running":  # the episode ended: its whole trace is there, unpacked
            assert (mnt / "run" / "forces.partial").stat().st_size == s["forces.partial"]
        print(f"traced, {stage}: {line} ({checked} files checked)")


VIDEO = [*LEAN, "--video", "--max-steps", "3000"]  # the last --max-steps counts


@pytest.mark.slow
def test_a_video_on_a_full_disk_is_absent_not_torn(
    tmp_path_factory: pytest.TempPathFactory,
    tmp_path: Path,
    strict_json: Callable[[str], Any],
    complete_tree: Callable[[Path], int],
) -> None:
    """The encoder writes the video while the episode runs and its index at the end; ffmpeg
    does not report a failure at the end, so the recorder checks the file's structure. Where
    the disk fills depends on when ffmpeg writes: any file may be the one named, but the video
    is whole or absent, and the summary says which."""
    s = _reference(tmp_path_factory, VIDEO)
    before = 2 + sum(_pages(s[k]) for k in ("log.jsonl", "summary.json", "forces.npz", "states.npz"))
    mnt = tmp_path / "mnt"
    with _tmpfs(mnt, before + _pages(s["episode.mp4"]) // 2):
        line = _one_error_line(_peg_sim("run", "--out", str(mnt / "run"), *VIDEO))
        assert line.startswith(f"peg-sim: error: cannot write '{mnt / 'run'}/") and line.endswith(ENOSPC)
        checked = complete_tree(mnt)
        if (mnt / "run" / "summary.json").exists():
            summary = strict_json((mnt / "run" / "summary.json").read_text())
            assert (summary["video_path"] is None) == (not (mnt / "run" / "episode.mp4").exists())
        print(f"video: {line} ({checked} files checked)")


# -- a sweep ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sweep_sizes(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int]]:
    base = tmp_path_factory.mktemp("sweep")
    (base / "tiny.yaml").write_text(SWEEP)
    mnt = base / "mnt"
    with _tmpfs(mnt, 16384):
        proc = _peg_sim("sweep", str(base / "tiny.yaml"), "--workers", "1", "--out", str(mnt / "s"))
        assert proc.returncode == 0, proc.stderr
        sizes = _sizes(mnt / "s")
    return base / "tiny.yaml", sizes


@pytest.mark.parametrize(
    "fraction",
    [
        pytest.param(0.0, marks=pytest.mark.slow, id="experiment.json"),
        pytest.param(0.3, id="first-episode"),
        pytest.param(0.7, marks=pytest.mark.slow, id="second-episode"),
        pytest.param(0.97, marks=pytest.mark.slow, id="tables-and-report"),
    ],
)
def test_a_sweep_on_a_full_disk_exits_2_and_leaves_nothing_torn(
    fraction: float,
    sweep_sizes: tuple[Path, dict[str, int]],
    tmp_path: Path,
    complete_tree: Callable[[Path], int],
) -> None:
    experiment, sizes = sweep_sizes
    total = sum(_pages(n) for n in sizes.values())
    mnt = tmp_path / "mnt"
    with _tmpfs(mnt, max(1, round(fraction * total))):
        proc = _peg_sim("sweep", str(experiment), "--workers", "1", "--out", str(mnt / "s"))
        line = _one_error_line(proc)
        assert line.endswith(f": {ENOSPC}") and f"'{mnt / 's'}/" in line, line
        checked = complete_tree(mnt)
        print(f"sweep at {fraction:.0%} of {total} pages: {line} ({checked} files checked)")


# -- read-only -------------------------------------------------------------------------------------
def test_a_run_into_a_read_only_directory_exits_2(tmp_path: Path) -> None:
    mnt = tmp_path / "mnt"
    with _tmpfs(mnt, 256):
        (mnt / "existing").mkdir()
        assert _run(["mount", "-o", "remount,ro", str(mnt)]).returncode == 0
        line = _one_error_line(_peg_sim("run", "--max-steps", "10", "--out", str(mnt / "run")))
        assert line == f"peg-sim: error: cannot create output directory '{mnt / 'run'}': {EROFS}"
        line = _one_error_line(_peg_sim("run", "--max-steps", "10", "--out", str(mnt / "existing")))
        assert line == f"peg-sim: error: output directory '{mnt / 'existing'}' is not writable: {EROFS}"
        assert list(mnt.rglob("*")) == [mnt / "existing"]


@pytest.mark.slow
def test_a_sweep_whose_episodes_are_read_only_exits_2(
    sweep_sizes: tuple[Path, dict[str, int]], tmp_path: Path, complete_tree: Callable[[Path], int]
) -> None:
    """The sweep's directory is writable, its ``episodes/`` is a read-only bind mount: every
    episode fails in its worker; the tables are written, and the error is the episodes'."""
    experiment, _ = sweep_sizes
    mnt = tmp_path / "mnt"
    with _tmpfs(mnt, 4096):
        episodes = mnt / "s" / "episodes"
        episodes.mkdir(parents=True)
        assert _run(["mount", "--bind", str(episodes), str(episodes)]).returncode == 0
        try:
            assert _run(["mount", "-o", "remount,ro,bind", str(episodes)]).returncode == 0
            proc = _peg_sim("sweep", str(experiment), "--workers", "1", "--out", str(mnt / "s"))
            line = _one_error_line(proc)
            assert line.startswith(f"peg-sim: error: cannot create output directory '{episodes}/"), line
            assert line.endswith(EROFS)
            assert complete_tree(mnt) >= 2  # experiment.json, the lock, empty tables
        finally:
            _umount(episodes)
