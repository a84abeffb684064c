"""Episode logging that never stalls the simulation loop.

The loop hands records to a :class:`EpisodeLogger`, which queues them for a background writer
thread. The writer serialises and writes them and flushes whenever the queue runs dry, so a
crash or Ctrl-C leaves readable files up to the last flush:

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

import json
import os
import queue
import threading
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.state import PAIRS

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
    """Queue-fed writer of ``log.jsonl`` and the force trace in ``out_dir``."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.out_dir / "log.jsonl"
        self.trace_path = self.out_dir / "forces.partial"
        self.npz_path = self.out_dir / "forces.npz"
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._trace_chunks: list[np.ndarray] = []
        self._error: BaseException | None = None
        self._log_file = open(self.log_path, "w", encoding="utf-8")  # noqa: SIM115 (closed by the writer)
        self._trace_file = open(self.trace_path, "wb")  # noqa: SIM115
        self._thread = threading.Thread(target=self._run, name="episode-log-writer", daemon=True)
        self._thread.start()
        self._closed = False

    # -- producer side (the simulation loop) -----------------------------------------------
    def record(self, entry: dict[str, Any]) -> None:
        """Queue one JSON record (serialised on the writer thread)."""
        self._queue.put(("json", entry))

    def trace(self, rows: np.ndarray) -> None:
        """Append rows (n, len(TRACE_COLUMNS)) to the force trace; the logger keeps ``rows``."""
        self._trace_chunks.append(rows)
        self._queue.put(("trace", rows))

    def close(self, end_record: dict[str, Any] | None = None) -> None:
        """Flush everything, write the end record and ``forces.npz``, stop the writer."""
        if self._closed:
            return
        self._closed = True
        if end_record is not None:
            self._queue.put(("json", end_record))
        self._queue.put(_STOP)
        self._thread.join()
        if self._error is not None:
            raise RuntimeError(f"log writer failed: {self._error}") from self._error
        chunks = self._trace_chunks or [np.zeros((0, len(TRACE_COLUMNS)))]
        trace = np.concatenate(chunks)
        tmp = self.npz_path.with_name(self.npz_path.name + ".tmp.npz")
        np.savez_compressed(tmp, columns=np.array(TRACE_COLUMNS), data=trace)
        os.replace(tmp, self.npz_path)
        self.trace_path.unlink(missing_ok=True)

    # -- consumer side (writer thread) ------------------------------------------------------
    def _run(self) -> None:
        try:
            while True:
                item = self._queue.get()
                while True:
                    if item is _STOP:
                        self._flush()
                        return
                    kind, payload = item
                    if kind == "json":
                        self._log_file.write(json.dumps(payload, separators=(",", ":")) + "\n")
                    else:
                        self._trace_file.write(np.ascontiguousarray(payload, dtype="<f8").tobytes())
                    try:
                        item = self._queue.get_nowait()
                    except queue.Empty:
                        break
                self._flush()  # the queue ran dry: make what we have durable
        except BaseException as exc:  # reported by close()
            self._error = exc
        finally:
            self._log_file.close()
            self._trace_file.close()

    def _flush(self) -> None:
        self._log_file.flush()
        self._trace_file.flush()


def read_log(path: Path) -> list[dict[str, Any]]:
    """All complete records of a ``log.jsonl`` (a torn last line, from a kill, is skipped)."""
    records = []
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            if not line.endswith("\n"):
                break
            records.append(json.loads(line))
    return records


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
