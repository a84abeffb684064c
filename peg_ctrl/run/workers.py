"""Worker processes bound to their parent: they die with it, and a Ctrl-C starts nothing new.

Sweeps and batches run episodes on a :class:`concurrent.futures.ProcessPoolExecutor` with the
``spawn`` start method. :func:`worker_pool` adds what the executor does not do by itself:

- **A worker dies with its parent.** A worker whose parent is killed (``SIGKILL``, a crash, the
  out-of-memory killer) would run on and keep writing into the output directory, beside the
  sweep that resumes it. On Linux each worker asks the kernel for ``SIGTERM`` when its parent
  dies (``prctl(PR_SET_PDEATHSIG)``: the signal comes when the *thread* that started the worker
  ends, here the one that submitted the work, which outlives the pool). Everywhere, a daemon
  thread in the worker checks every :data:`WATCH_PERIOD_S` that its parent is still the process
  that started it, and ends the worker if not.
- **Ctrl-C belongs to the parent.** A terminal sends ``SIGINT`` to its whole foreground process
  group; a worker interrupted in an episode would take the next queued one (the executor hands
  a worker its next call in advance) or break the pool, and one interrupted while it starts
  prints a traceback. Workers ignore ``SIGINT`` from their first instruction: they are started
  with it ignored (a disposition, unlike a handler or the signal mask, survives ``exec``). The
  parent, on any exception leaving the pool's block (a ``KeyboardInterrupt`` included), cancels
  the work not started and terminates the workers: an episode cut off this way has no
  ``summary.json`` and runs again when the sweep is resumed.
"""

from __future__ import annotations

import concurrent.futures as futures
import contextlib
import ctypes
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator

from peg_ctrl.errors import ConfigError

__all__ = ["worker_pool", "WATCH_PERIOD_S"]

#: How often a worker checks that its parent is alive [s] (where the kernel does not tell it).
WATCH_PERIOD_S = 0.25
#: How long terminated workers get to exit before they are killed [s].
_TERMINATE_GRACE_S = 5.0
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_EXIT_ORPHANED = 128 + signal.SIGTERM  # as if the parent-death signal had ended the worker


def _set_parent_death_signal(signum: int) -> bool:
    """Linux: ask for ``signum`` when the parent dies; False where that is not available."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(_PR_SET_PDEATHSIG, ctypes.c_ulong(signum), 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent_pid: int) -> None:
    """Worker thread: end the worker once it is orphaned (its parent pid changes)."""
    while os.getppid() == parent_pid:
        time.sleep(WATCH_PERIOD_S)
    os._exit(_EXIT_ORPHANED)


def _bind_to_parent(parent_pid: int) -> None:
    """Pool initializer, in each worker: ignore SIGINT and die with ``parent_pid``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        _set_parent_death_signal(signal.SIGTERM)
    if os.getppid() != parent_pid:  # the parent died before the line above: no signal will come
        os._exit(_EXIT_ORPHANED)
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="watch-parent", daemon=True).start()


@contextlib.contextmanager
def _children_ignore_sigint() -> Iterator[None]:
    """Processes started in the block begin with SIGINT ignored; the block lasts as long as it
    takes to start them (about 5 ms for two workers).

    Only in the main thread of a POSIX process (elsewhere the workers ignore SIGINT from their
    initializer on). The main thread blocks SIGINT meanwhile, and receives one sent in the block
    when it ends; but if another thread (a native library's) takes it first, it is ignored, and
    that Ctrl-C is lost: the price of workers that never print a traceback for a Ctrl-C during
    their second of imports."""
    if (
        threading.current_thread() is not threading.main_thread()
        or not hasattr(signal, "pthread_sigmask")
        or signal.getsignal(signal.SIGINT) is None  # a handler installed from C: not restorable
    ):
        yield
        return
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _terminate(pool: futures.ProcessPoolExecutor) -> None:
    """Cancel the work not started and end the workers (running work is lost)."""
    terminate_workers = getattr(pool, "terminate_workers", None)  # Python >= 3.14: also cancels
    if terminate_workers is not None:
        terminate_workers()
        return
    # Before 3.14 the executor has no public way to end its workers: take them before shutdown()
    # forgets them. Wait on their sentinels, not join(): the executor's thread reaps them.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    sentinels = {process.sentinel: process for process in processes}
    deadline = time.monotonic() + _TERMINATE_GRACE_S
    while sentinels and time.monotonic() < deadline:
        for ready in multiprocessing.connection.wait(list(sentinels), deadline - time.monotonic()):
            sentinels.pop(ready)
    for process in sentinels.values():
        process.kill()


@contextlib.contextmanager
def worker_pool(max_workers: int) -> Iterator[futures.ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``max_workers`` workers bound to this process (see the module
    docstring).

    The workers are started on entry. Leaving the block normally waits for the submitted work.
    Leaving it with an exception (a ``KeyboardInterrupt``, a failed result, a generator closed
    by its consumer) cancels the work not started and terminates the workers before the
    exception goes on.

    Raises:
        ConfigError: ``max_workers`` is below 1.
    """
    if max_workers < 1:
        raise ConfigError(f"workers must be >= 1, got {max_workers}")
    pool = futures.ProcessPoolExecutor(
        max_workers=max_workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_bind_to_parent,
        initargs=(os.getpid(),),
    )
    try:
        with _children_ignore_sigint():
            for _ in range(max_workers):  # the executor starts a worker per submission
                pool.submit(os.getpid)
        yield pool
    except BaseException:
        _terminate(pool)
        raise
    pool.shutdown(wait=True)
