"""Episode logging that never stalls the simulation loop.

The loop hands records to a :class:`EpisodeLogger`, which queues them for a background writer
thread. The writer serialises what is queued and appends it, one write per file, whenever the
queue runs dry, so the files grow by whole records: a write that fails (disk full) is cut back
to the last whole record and reported to the loop's thread, and a process killed in a write
leaves at most a torn last line or row, which :func:`read_log` and :func:`read_trace` skip:

- ``log.jsonl`` — one JSON object per line: ``{"event": "step", ...}`` every ``interval`` steps
  with the SPEC §7 fields, ``{"event": "phase", ...}`` when a phase ends, ``{"event": "end", ...}``
  with the episode record;
- ``forces.npz`` — the full-rate force trace (:data:`TRACE_COLUMNS`): time, phase, the net
  contact force of every body-group pair, the peg's deepest penetration and its depth, and the
  grip (the finger pads' squeeze on the peg, ``grip_force_n``), at every physics step. While
  the episode runs the rows are appended, in chunks, to ``forces.partial``
  (raw little-endian float64, :data:`TRACE_COLUMNS` per row), which :func:`read_trace` reads
  too; it is replaced by ``forces.npz`` when the episode ends.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import threading
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.errors import OutputError
from peg_ctrl.io import atomic_path, to_json, write_error
from peg_ctrl.sim.state import PAIRS

__all__ = ["EpisodeLogger", "TRACE_COLUMNS", "read_log", "read_trace", "STEP_FIELDS"]

TRACE_COLUMNS = (
    "t",
    "phase",
    *("-".join(p) for p in PAIRS),
    "peg_penetration_m",
    "peg_depth_m",
    "grip_force_n",
)

# Required fields of a step record (dotted paths), SPEC §7.
STEP_FIELDS = (
    "step",
    "t",
    "phase",
    "command.position",
    "command.omega_body",
    "command.jaw_sep_m",
    "gripper.position",
    "gripper.euler",
    "gripper.quat",
    "gripper.jaw_sep_m",
    "peg.position",
    "peg.quat",
    "contacts",
)

_STOP = object()


class EpisodeLogger:
    """Queue-fed writer of ``log.jsonl`` and the force trace in ``out_dir``.

    Both files only ever grow by whole records: the writer appends each batch of JSON lines
    (or trace rows) with one write and, if the write fails part-way (no space left), cuts the
    file back to the last whole record. A write error stops the writer; the next :meth:`record`,
    :meth:`trace` or :meth:`close` on the producer's thread raises it as
    :class:`~peg_ctrl.errors.OutputError`.

    Raises:
        OutputError: ``log.jsonl`` or ``forces.partial`` cannot be created.
    """

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.out_dir / "log.jsonl"
        self.trace_path = self.out_dir / "forces.partial"
        self.npz_path = self.out_dir / "forces.npz"
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._trace_chunks: list[np.ndarray] = []
        self._error: BaseException | None = None
        self._log = _RecordFile(self.log_path)
        try:
            self._trace = _RecordFile(self.trace_path)
        except OutputError:
            self._log.close()
            raise
        self._thread = threading.Thread(target=self._run, name="episode-log-writer", daemon=True)
        self._thread.start()
        self._closed = False

    # -- producer side (the simulation loop) -----------------------------------------------
    def record(self, entry: dict[str, Any]) -> None:
        """Queue one JSON record (serialised on the writer thread).

        Raises:
            OutputError: the writer failed (no space left, read-only, ...).
        """
        self._check()
        self._queue.put(("json", entry))

    def trace(self, rows: np.ndarray) -> None:
        """Append rows (n, len(TRACE_COLUMNS)) to the force trace; the logger keeps ``rows``.

        Raises:
            OutputError: the writer failed (no space left, read-only, ...).
        """
        self._check()
        self._trace_chunks.append(rows)
        self._queue.put(("trace", rows))

    def sync(self) -> None:
        """Wait until everything queued so far is on disk (the writer works on its own thread:
        a file written after this sees every record and row before it).

        Raises:
            OutputError: a write failed.
        """
        if self._closed:
            return
        written = threading.Event()
        self._queue.put(("sync", written))
        while not written.wait(0.05):
            if not self._thread.is_alive():  # the writer stopped on an error: raised below
                break
        self._check()

    def close(self, end_record: dict[str, Any] | None = None) -> None:
        """Flush everything, write the end record and ``forces.npz`` (atomically), stop the
        writer and remove ``forces.partial``.

        Raises:
            OutputError: a write failed; ``log.jsonl`` keeps its whole records and
                ``forces.partial`` its whole rows.
        """
        if self._closed:
            return
        self._closed = True
        if end_record is not None:
            self._queue.put(("json", end_record))
        self._stop()
        self._check()
        chunks = self._trace_chunks or [np.zeros((0, len(TRACE_COLUMNS)))]
        trace = np.concatenate(chunks)
        with atomic_path(self.npz_path) as tmp:
            np.savez_compressed(tmp, columns=np.array(TRACE_COLUMNS), data=trace)
        self.trace_path.unlink(missing_ok=True)

    def abort(self) -> None:
        """Stop the writer after what is queued, without the end record or ``forces.npz`` (an
        episode that ended in an exception); ``forces.partial`` stays. Never raises."""
        if not self._closed:
            self._closed = True
            self._stop()

    def _stop(self) -> None:
        self._queue.put(_STOP)
        self._thread.join()

    def _check(self) -> None:
        error = self._error
        if error is None:
            return
        if isinstance(error, OutputError):
            raise error
        raise RuntimeError(f"log writer failed: {error!r}") from error

    # -- consumer side (writer thread) ------------------------------------------------------
    def _run(self) -> None:
        try:
            stop = False
            while not stop:
                lines: list[str] = []
                rows: list[bytes] = []
                synced: list[threading.Event] = []
                item = self._queue.get()
                while True:  # take everything queued: one write per file per batch
                    if item is _STOP:
                        stop = True
                        break
                    kind, payload = item
                    if kind == "json":
                        lines.append(to_json(payload, separators=(",", ":")) + "\n")
                    elif kind == "sync":
                        synced.append(payload)
                    else:
                        rows.append(np.ascontiguousarray(payload, dtype="<f8").tobytes())
                    try:
                        item = self._queue.get_nowait()
                    except queue.Empty:
                        break
                self._log.append("".join(lines).encode("utf-8"))
                self._trace.append(b"".join(rows))
                for event in synced:
                    event.set()
        except BaseException as exc:  # raised on the producer's thread by _check()
            self._error = exc
        finally:
            self._log.close()
            self._trace.close()


class _RecordFile:
    """An append-only file that grows by whole records: :meth:`append` writes a batch of whole
    records and, if that fails part-way, truncates the file back to where the batch began."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.size = 0
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
        except OSError as exc:
            raise write_error(path, exc) from None

    def append(self, data: bytes) -> None:
        """Write ``data`` (whole records) at the end of the file.

        Raises:
            OutputError: the write failed; the file ends at its last whole record.
        """
        view = memoryview(data)
        written = 0
        try:
            while written < len(view):
                written += os.write(self._fd, view[written:])
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self.size)
            raise write_error(self.path, exc) from None
        self.size += written

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


def read_log(path: Path) -> list[dict[str, Any]]:
    """All complete records of a ``log.jsonl``. A torn last line (the process was killed in a
    write) is skipped; a damaged line before it raises :class:`json.JSONDecodeError`."""
    lines = Path(path).read_bytes().split(b"\n")
    # After the last newline: b"" for a whole file, else the start of a record cut short.
    return [json.loads(line) for line in lines[:-1]]


def read_trace(path: Path) -> np.ndarray:
    """The force trace (n, len(TRACE_COLUMNS)) of ``forces.npz``, or of an episode's
    ``forces.partial`` if it did not finish (a torn last row, from a kill, is skipped). ``path``
    is either file or the episode directory."""
    path = Path(path)
    if path.is_dir():
        path = path / "forces.npz" if (path / "forces.npz").exists() else path / "forces.partial"
    if path.suffix == ".npz":
        with np.load(path) as npz:
            return np.asarray(npz["data"], dtype=float)
    raw = np.fromfile(path, dtype="<f8")
    n = len(raw) // len(TRACE_COLUMNS)
    return raw[: n * len(TRACE_COLUMNS)].reshape(n, len(TRACE_COLUMNS)).astype(float)
