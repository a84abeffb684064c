"""Processes and their output directories: a directory is held by one run or sweep at a time,
workers die with their sweep, Ctrl-C starts nothing new, ``--workers 0`` is refused, ``plot``
never draws from a cut-off table, and a sweep killed at random moments resumes to the results
of an uninterrupted one.

Processes are found through ``/proc``: every process of a sweep started here carries a marker
in its environment (inherited by its workers), so the tests see exactly the processes they
started, whoever their parent is now.
"""

from __future__ import annotations

import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from peg_ctrl.cli import main
from peg_ctrl.errors import ConfigError, OutputError, OutputInUse
from peg_ctrl.experiments.config import experiment_from_mapping
from peg_ctrl.experiments.report import episodes_csv_problem
from peg_ctrl.experiments.runner import run_sweep
from peg_ctrl.io import LOCK_NAME, lock_output_dir
from peg_ctrl.run.batch import run_batch
from peg_ctrl.run.episode import WALL_CLOCK_FIELDS
from peg_ctrl.run.workers import WATCH_PERIOD_S, worker_pool

from ..conftest import assert_one_line_error, peg_sim_here, sigint_default

needs_proc = pytest.mark.skipif(
    not Path("/proc/self/environ").is_file(), reason="finds processes through /proc (Linux)"
)
MARKER = "PEG_CTRL_TEST_MARKER"

# Six episodes of about a second each (they time out: deterministic, and long enough to be
# caught running).
SWEEP = """\
name: faults
controllers: [{name: pd}, {name: impedance}]
clearances: [0.001]
seeds: [0, 1, 2]
max_steps: 6000
"""
N_EPISODES = 6
# Four episodes of a few hundredths of a second, for the plot tests.
SMALL = {"name": "small", "controllers": ["pd", "impedance"], "seeds": [0, 1], "max_steps": 300}
# Columns that differ from run to run.
WALL_CLOCK = WALL_CLOCK_FIELDS


# ---------------------------------------------------------------------------------------------
# helpers


def _marked(marker: str) -> list[int]:
    """The live (not zombie) processes whose environment holds ``marker``."""
    needle = f"{MARKER}={marker}".encode()
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            environ = Path(f"/proc/{entry}/environ").read_bytes()
            state = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue  # gone, or not ours
        if needle in environ.split(b"\0") and state != "Z":
            found.append(int(entry))
    return found


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""  # gone


def _wait_for(condition: Callable[[], bool], timeout: float, period: float = 0.01) -> float:
    """Seconds until ``condition()`` held; raises AssertionError after ``timeout`` [s]."""
    t0 = time.monotonic()
    while not condition():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"still not true after {timeout} s: {condition}")
        time.sleep(period)
    return time.monotonic() - t0


def _clean_up(procs: list[subprocess.Popen], markers: list[str]) -> None:
    """After a failed test: kill what it started (by pid, only processes still marked as ours)."""
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    for marker in markers:
        for pid in _marked(marker):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def _start_sweep(config: Path, out: Path, marker: str, log: Path) -> subprocess.Popen:
    """``peg-sim sweep CONFIG --out OUT --workers 2`` in its own session; stderr to ``log``."""
    with open(log, "w") as err:
        return subprocess.Popen(
            [sys.executable, "-m", "peg_ctrl", "sweep", str(config), "--out", str(out), "--workers", "2"],
            stdout=subprocess.DEVNULL,
            stderr=err,
            env={**os.environ, MARKER: marker},
            start_new_session=True,
            preexec_fn=sigint_default,  # the tests interrupt it
        )


def _assert_interrupted(log: Path) -> None:
    """The sweep's stderr: its progress lines (stderr is a file), the last one ``stopped``, then
    the one line of an interrupted command, and nothing else (no traceback)."""
    *progress, last = log.read_text().splitlines()
    assert last == "peg-sim: interrupted", log.read_text()
    assert all(line.startswith("sweep faults: ") for line in progress), log.read_text()
    assert not progress or progress[-1].endswith(", stopped"), log.read_text()


def _episode_dirs(out: Path) -> set[str]:
    return {p.name for p in (out / "episodes").glob("*")}


def _snapshot(out: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``out``: size and modification time [ns]."""
    return {str(p.relative_to(out)): (p.stat().st_size, p.stat().st_mtime_ns) for p in out.rglob("*")}


def _table(path: Path) -> list[dict[str, str]]:
    """``episodes.csv`` sorted by key, without the wall-clock columns."""
    with open(path, newline="") as fh:
        rows = [{k: v for k, v in row.items() if k not in WALL_CLOCK} for row in csv.DictReader(fh)]
    return sorted(rows, key=lambda row: row["key"])


@pytest.fixture()
def sweep_file(tmp_path: Path) -> Path:
    path = tmp_path / "faults.yaml"
    path.write_text(SWEEP)
    return path


@pytest.fixture()
def held(tmp_path: Path) -> Iterator[tuple[Path, int]]:
    """A directory locked by another process: (the directory, that process's pid)."""
    out = tmp_path / "out"
    out.mkdir()
    code = (
        "import sys, time\n"
        "from peg_ctrl.io import lock_output_dir\n"
        "with lock_output_dir(sys.argv[1]):\n"
        "    print('locked', flush=True)\n"
        "    time.sleep(120)\n"
    )
    holder = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        yield out, holder.pid
    finally:
        holder.kill()
        holder.wait()


# ---------------------------------------------------------------------------------------------
# 1. one process per output directory


def test_a_locked_directory_is_refused_until_its_holder_dies(held: tuple[Path, int]) -> None:
    out, pid = held
    with pytest.raises(OutputInUse) as exc, lock_output_dir(out):
        pass
    assert str(exc.value) == f"output directory {str(out)!r} is in use by another peg-sim process (pid {pid})"
    assert exc.value.pid == pid and isinstance(exc.value, OutputError)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    with lock_output_dir(out) as locked:  # the kernel released it with the process: at once
        assert locked == out
        assert (out / LOCK_NAME).read_text() == f"{os.getpid()}\n"
    with lock_output_dir(out):  # and this process released it when the block ended
        pass
    assert os.listdir(out) == [LOCK_NAME]  # the lock file stays, and nothing else is made


def test_the_lock_is_not_reentrant_in_one_process(tmp_path: Path) -> None:
    with lock_output_dir(tmp_path), pytest.raises(OutputInUse, match=r"in use by this process \(pid \d+\)"):
        with lock_output_dir(tmp_path):
            pass


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--max-steps", "10", "--out", "{out}"],
        ["sweep", "{config}", "--workers", "1", "--out", "{out}"],
        ["teleop", "--scripted", "--out", "{out}"],
        ["validity", "--trials", "1", "--out", "{out}"],
        ["validate-profile", "fast", "--seeds", "2", "--workers", "1", "--out", "{out}"],
        ["plot", "{out}"],
    ],
    ids=lambda argv: argv[0],
)
def test_a_command_on_a_directory_in_use_is_refused_in_one_line(
    argv: list[str], held: tuple[Path, int], sweep_file: Path
) -> None:
    out, pid = held
    if argv[0] == "plot":
        (out / "episodes.csv").write_text("key\n")
    proc = peg_sim_here([a.format(out=out, config=sweep_file) for a in argv], cwd=out.parent)
    assert_one_line_error(
        proc, f"output directory {str(out)!r} is in use by another peg-sim process (pid {pid})"
    )
    assert set(os.listdir(out)) <= {LOCK_NAME, "episodes.csv"}, "nothing may be written into it"


def test_run_sweep_in_a_directory_in_use_raises(held: tuple[Path, int]) -> None:
    out, pid = held
    with pytest.raises(OutputInUse, match=f"pid {pid}"):
        run_sweep(experiment_from_mapping(SMALL), out, workers=1, progress=False)
    assert os.listdir(out) == [LOCK_NAME]


# ---------------------------------------------------------------------------------------------
# 2. workers die with their parent


@needs_proc
def test_killing_a_sweep_ends_its_workers_and_their_writes(tmp_path: Path, sweep_file: Path) -> None:
    out, marker = tmp_path / "out", uuid.uuid4().hex
    proc = _start_sweep(sweep_file, out, marker, tmp_path / "stderr.txt")
    try:
        _wait_for(lambda: len(_episode_dirs(out)) >= 2, timeout=120)  # both workers in an episode
        workers = [pid for pid in _marked(marker) if pid != proc.pid]
        assert len(workers) >= 2, "the workers (and the resource tracker) should be running"
        proc.send_signal(signal.SIGKILL)
        t_kill = time.monotonic()
        proc.wait()
        _wait_for(lambda: not _marked(marker), timeout=5.0)
        died_s = time.monotonic() - t_kill
        print(f"workers gone {died_s:.3f} s after the sweep was killed")
        assert len(list(out.glob("episodes/*/summary.json"))) < N_EPISODES, "killed too late"
        before = _snapshot(out)
        time.sleep(1.0)
        assert _snapshot(out) == before, "something still writes into --out"
    finally:
        _clean_up([proc], [marker])


@needs_proc
def test_an_orphaned_worker_ends_itself_without_the_kernel_signal(tmp_path: Path) -> None:
    """The portable fallback alone: a thread that watches the parent's pid."""
    marker, ready = uuid.uuid4().hex, tmp_path / "watching"
    child = (
        "import os, sys, threading, time\n"
        "from peg_ctrl.run import workers\n"
        "threading.Thread(target=workers._watch_parent, args=(int(sys.argv[1]),), daemon=True).start()\n"
        "open(sys.argv[2], 'w').close()\n"
        "time.sleep(120)\n"
    )
    parent = (
        "import os, subprocess, sys, time\n"
        f"subprocess.Popen([sys.executable, '-c', {child!r}, str(os.getpid()), sys.argv[1]])\n"
        "time.sleep(120)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", parent, str(ready)], env={**os.environ, MARKER: marker})
    try:
        _wait_for(ready.exists, timeout=60)
        assert len(_marked(marker)) == 2
        proc.kill()
        proc.wait()
        gone_s = _wait_for(lambda: not _marked(marker), timeout=10 * WATCH_PERIOD_S + 2.0)
        assert gone_s < 4 * WATCH_PERIOD_S + 1.0
    finally:
        _clean_up([proc], [marker])


# ---------------------------------------------------------------------------------------------
# 3. Ctrl-C


@needs_proc
@pytest.mark.parametrize("to", ["parent", "process group"])
def test_ctrl_c_ends_a_sweep_and_starts_no_queued_episode(to: str, tmp_path: Path, sweep_file: Path) -> None:
    """A terminal's Ctrl-C reaches the whole process group; ``kill -INT`` only the parent."""
    out, marker = tmp_path / "out", uuid.uuid4().hex
    proc = _start_sweep(sweep_file, out, marker, tmp_path / "stderr.txt")
    try:
        _wait_for(lambda: len(_episode_dirs(out)) >= 1, timeout=120)
        started = _episode_dirs(out)
        (os.killpg if to == "process group" else os.kill)(proc.pid, signal.SIGINT)
        t0 = time.monotonic()
        assert proc.wait(timeout=30) == 130
        exit_s = time.monotonic() - t0
        _assert_interrupted(tmp_path / "stderr.txt")
        _wait_for(lambda: not _marked(marker), timeout=5.0)
        after = _episode_dirs(out)
        time.sleep(1.0)
        assert _episode_dirs(out) == after, "episodes still start after the sweep ended"
        # The two running episodes were ended; of the queued ones, none started (a worker may
        # have taken one in the instant between the listing above and the signal).
        assert len(after - started) <= 1, (started, after)
        assert len(after) < N_EPISODES
        print(f"Ctrl-C to the {to}: exit 130 after {exit_s:.2f} s, {len(after)} episodes begun")
    finally:
        _clean_up([proc], [marker])


@needs_proc
def test_ctrl_c_while_the_workers_start_prints_no_traceback(tmp_path: Path, sweep_file: Path) -> None:
    """Workers start with SIGINT ignored: a Ctrl-C in their first second (imports) is the parent's.
    (Not in the few milliseconds in which they are started: there the parent ignores it too, see
    ``peg_ctrl.run.workers._children_ignore_sigint``.)"""
    out, marker = tmp_path / "out", uuid.uuid4().hex
    proc = _start_sweep(sweep_file, out, marker, tmp_path / "stderr.txt")

    def started_workers() -> bool:
        return sum(b"spawn_main" in _cmdline(pid) for pid in _marked(marker)) >= 2

    try:
        _wait_for(started_workers, timeout=120, period=0.001)
        time.sleep(0.1)  # past the start of the workers, in their imports
        os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(timeout=30) == 130
        _assert_interrupted(tmp_path / "stderr.txt")
        _wait_for(lambda: not _marked(marker), timeout=5.0)
    finally:
        _clean_up([proc], [marker])


# ---------------------------------------------------------------------------------------------
# 4. --workers 0


def test_zero_workers_are_refused_in_one_line(tmp_path: Path, sweep_file: Path) -> None:
    proc = peg_sim_here(["sweep", str(sweep_file), "--workers", "0"], cwd=tmp_path)
    assert_one_line_error(proc, "--workers must be >= 1, got 0")
    proc = peg_sim_here(["validate-profile", "fast", "--workers", "0"], cwd=tmp_path)
    assert_one_line_error(proc, "--workers must be >= 1, got 0")
    assert sorted(os.listdir(tmp_path)) == [sweep_file.name], "refused before any output"


def test_zero_workers_are_refused_in_python(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="workers must be >= 1, got 0"):
        run_batch([], workers=0)
    with pytest.raises(ConfigError, match="workers must be >= 1, got 0"):
        run_sweep(experiment_from_mapping(SMALL), tmp_path, workers=0, progress=False)
    with pytest.raises(ConfigError, match="workers must be >= 1, got -1"), worker_pool(-1):
        pass


# ---------------------------------------------------------------------------------------------
# 5. plot on a cut-off or damaged episodes.csv


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished four-episode sweep without its report (copy it before changing it)."""
    out = tmp_path_factory.mktemp("small") / "out"
    run_sweep(experiment_from_mapping(SMALL), out, workers=1, progress=False, report=False)
    return out


def _damage(text: str, how: str) -> str:
    lines = text.splitlines(keepends=True)
    return {
        "cut mid-row": text[: len(text) * 2 // 3],
        "cut after a row": "".join(lines[:-1]),
        "cut after the header": lines[0],
        "empty": "",
        "zeroed tail": text[: len(text) // 2] + "\0" * (len(text) - len(text) // 2),
        "garbled value": text.replace(",failure,", ",f@ilure,", 1),
    }[how]


DAMAGES = ["cut mid-row", "cut after a row", "cut after the header", "empty", "zeroed tail", "garbled value"]


@pytest.mark.parametrize("how", DAMAGES)
def test_plot_rebuilds_a_damaged_table_from_the_episode_summaries(
    how: str, small_sweep: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    shutil.copytree(small_sweep, out)
    table = out / "episodes.csv"
    whole = table.read_bytes()
    table.write_text(_damage(whole.decode(), how), newline="")
    assert main(["plot", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith(f"{table} ") and printed[0].endswith(
        ": rebuilt the tables from 4 episode summaries"
    ), printed
    assert printed[1:] == [f"wrote {out / 'report.md'}"]
    assert table.read_bytes() == whole
    assert "4 episodes" in (out / "report.md").read_text()


def test_plot_uses_a_sound_table_as_it_is(small_sweep: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    shutil.copytree(small_sweep, out)
    before = (out / "episodes.csv").stat().st_mtime_ns
    assert main(["plot", str(out)]) == 0
    assert capsys.readouterr().out == f"wrote {out / 'report.md'}\n"
    assert (out / "episodes.csv").stat().st_mtime_ns == before
    # Episode directories pruned to save space: the table still has every episode.
    shutil.rmtree(next((out / "episodes").iterdir()))
    assert main(["plot", str(out)]) == 0
    assert capsys.readouterr().out == f"wrote {out / 'report.md'}\n"


def test_plot_of_an_unfinished_sweep_says_what_it_covers(small_sweep: Path, tmp_path: Path, capsys) -> None:
    """A sweep killed before it wrote its table: no episodes.csv, one episode not finished."""
    out = tmp_path / "out"
    shutil.copytree(small_sweep, out)
    for name in ("episodes.csv", "episodes.parquet", "summary.csv"):
        (out / name).unlink()
    (next((out / "episodes").iterdir()) / "summary.json").unlink()
    assert main(["plot", str(out)]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"{out / 'episodes.csv'} does not exist: rebuilt the tables from 3 episode summaries",
        "3 of 4 episodes have finished: the report covers those",
        f"wrote {out / 'report.md'}",
    ]
    assert len(_table(out / "episodes.csv")) == 3


@pytest.mark.parametrize("how", ["cut mid-row", "empty", "zeroed tail", "garbled value"])
def test_plot_refuses_a_damaged_table_it_cannot_rebuild(how: str, small_sweep: Path, tmp_path: Path) -> None:
    table = tmp_path / "episodes.csv"
    table.write_text(_damage((small_sweep / "episodes.csv").read_text(), how), newline="")
    proc = peg_sim_here(["plot", str(tmp_path)], cwd=tmp_path)
    assert_one_line_error(proc, f"{table} {episodes_csv_problem(table)}, ")
    assert f"and it cannot be rebuilt: there is no {tmp_path / 'experiment.json'}" in proc.stderr
    assert not (tmp_path / "report.md").exists()


def test_plot_without_a_table_or_an_experiment_is_refused(tmp_path: Path) -> None:
    assert_one_line_error(peg_sim_here(["plot", str(tmp_path)], cwd=tmp_path), "has no episodes.csv")


@pytest.mark.parametrize(
    "how, problem",
    [
        ("cut mid-row", "is cut off: its last line (4) has no line end"),
        ("cut after the header", None),  # a header alone is a table of no episodes
        ("empty", "is empty"),
        ("zeroed tail", "is damaged: line 3 holds NUL bytes"),
        ("garbled value", "is damaged: line 2 has status 'f@ilure' (not success or failure)"),
    ],
)
def test_the_table_check_names_the_problem_and_the_line(
    how: str, problem: str | None, small_sweep: Path, tmp_path: Path
) -> None:
    path = tmp_path / "episodes.csv"
    path.write_text(_damage((small_sweep / "episodes.csv").read_text(), how), newline="")
    assert episodes_csv_problem(path) == problem


def test_the_table_check_finds_missing_columns_and_bad_numbers(small_sweep: Path, tmp_path: Path) -> None:
    path = tmp_path / "episodes.csv"
    text = (small_sweep / "episodes.csv").read_text()
    path.write_text(text.replace("peak_contact_force_n,", "peak_force,", 1), newline="")
    assert episodes_csv_problem(path) == "has no column peak_contact_force_n (line 1)"
    rows = list(csv.DictReader(text.splitlines()))
    rows[2]["clearance_m"] = "1mm"
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert episodes_csv_problem(path) == "is damaged: line 4 has clearance_m '1mm' (not a number)"
    assert episodes_csv_problem(tmp_path / "none.csv") == "does not exist"
    path.write_bytes(b"key,\xff\n")
    assert episodes_csv_problem(path) == "is not text (byte 4 is not UTF-8)"


# ---------------------------------------------------------------------------------------------
# 6. kill and resume, again and again


def _kill_resume_battery(tmp_path: Path, *, seeds: int, kills: int, seed: int) -> None:
    """``kills`` times: start a sweep of ``2 * seeds`` episodes (a resume, after the first),
    SIGKILL it at a random moment of its start-up and its next four episodes (or, with none
    left, of its tables and report), and start the next at once. Then resume to the end and
    compare with a clean run. A run that ends before its kill is not counted as one."""
    config, clean = tmp_path / "battery.yaml", tmp_path / "clean"
    config.write_text(SWEEP.replace("seeds: [0, 1, 2]", f"seeds: {seeds}"))
    n_episodes = 2 * seeds

    def sweep(out: Path) -> float:
        t0 = time.monotonic()
        done = subprocess.run(
            [sys.executable, "-m", "peg_ctrl", "sweep", str(config), "--out", str(out), "--workers", "2"],
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        return time.monotonic() - t0

    # How long a run takes on this machine now: the clean run, and a resume with nothing left
    # to run (start-up, tables, report).
    whole_s = sweep(clean)
    fixed_s = sweep(clean)
    episode_s = max(whole_s - fixed_s, 0.0) / n_episodes  # of wall time, on the two workers
    out, rng, log = tmp_path / "killed", random.Random(seed), tmp_path / "stderr.txt"
    finished_at_kill: list[int] = []  # episodes finished when each kill came
    finished_first, death_s, procs, markers = 0, [], [], []
    killed: tuple[str, float] | None = None  # the last killed run's marker, and when
    try:
        while True:
            markers.append(uuid.uuid4().hex)
            proc = _start_sweep(config, out, markers[-1], log)
            procs.append(proc)
            if killed is not None:  # the killed run's workers must be gone while this one starts
                _wait_for(lambda m=killed[0]: not _marked(m), timeout=5.0)
                death_s.append(time.monotonic() - killed[1])
                killed = None
            if len(finished_at_kill) == kills:
                break  # the final resume, to the end
            assert len(finished_at_kill) + finished_first < 3 * kills, "sweeps keep ending before their kill"
            left = n_episodes - len(list(out.glob("episodes/*/summary.json")))
            try:
                proc.wait(timeout=rng.uniform(0.05, 1.0) * (fixed_s + min(left, 4) * episode_s))
            except subprocess.TimeoutExpired:
                finished_at_kill.append(len(list(out.glob("episodes/*/summary.json"))))
                proc.send_signal(signal.SIGKILL)
                killed = (markers[-1], time.monotonic())
                proc.wait()
            else:
                assert proc.returncode == 0, log.read_text()
                finished_first += 1
        assert proc.wait(timeout=300) == 0, log.read_text()
    finally:
        _clean_up(procs, markers)
    rows = _table(out / "episodes.csv")
    assert len(rows) == n_episodes and rows == _table(clean / "episodes.csv")
    summaries = sorted(out.glob("episodes/*/summary.json"))
    named = 0  # the files the summaries name (log, trace, ...): all there
    for path in summaries:
        summary = json.loads(path.read_text())
        assert summary["status"] in ("success", "failure"), path
        assert summary["trace_path"].endswith("forces.npz"), path  # the final summary, not the first
        assert (path.parent / "states.npz").is_file(), path
        for key in ("log_path", "trace_path", "plot_path", "video_path"):
            if summary.get(key) is not None:
                assert Path(summary[key]).is_file(), (path, key)
                named += 1
    assert len(summaries) == n_episodes
    leftovers = [p.name for p in out.rglob(".*") if p.name != LOCK_NAME]  # temporaries of killed writes
    assert leftovers == []  # each resume removes them, where it runs again
    print(
        f"\nkill/resume battery: {len(finished_at_kill)} SIGKILLs survived (episodes finished at each: "
        f"{finished_at_kill}; {finished_first} runs ended before their kill), {len(rows)} episodes.csv "
        f"rows x {len(rows[0])} columns identical to a clean run, {len(summaries)} summary.json files "
        f"parsed and the {named} files they name present; workers gone {min(death_s):.3f}-"
        f"{max(death_s):.3f} s after their sweep was killed; hidden leftovers: {leftovers or 'none'}"
    )


@pytest.mark.slow  # ~50 s; the default suite resumes an interrupted sweep in test_experiments
@needs_proc
def test_a_sweep_killed_twice_resumes_to_the_results_of_a_clean_run(tmp_path: Path) -> None:
    _kill_resume_battery(tmp_path, seeds=4, kills=2, seed=1)


@needs_proc
@pytest.mark.slow
def test_a_sweep_killed_ten_times_resumes_to_the_results_of_a_clean_run(tmp_path: Path) -> None:
    _kill_resume_battery(tmp_path, seeds=8, kills=10, seed=0)
