"""A sweep's run time, summed over the invocations that ran its episodes (``run_time.json``):
the sweep adds each invocation's time, the report reads the total."""

from __future__ import annotations

import json
from pathlib import Path

from peg_ctrl.io import atomic_write_text, to_json

__all__ = ["RUN_TIME_FILE", "run_time", "add_run_time"]

RUN_TIME_FILE = "run_time.json"


def run_time(out_dir: Path) -> tuple[float, int] | None:
    """The sweep's run time in ``out_dir`` [s], summed over the invocations that ran episodes,
    and their number; None when it was not recorded (or the record is unreadable)."""
    try:
        saved = json.loads((Path(out_dir) / RUN_TIME_FILE).read_text())
        return float(saved["run_time_s"]), int(saved["invocations"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def add_run_time(out_dir: Path, seconds: float) -> tuple[float, int]:
    """Add one invocation's ``seconds`` to ``out_dir``'s :data:`RUN_TIME_FILE`; returns the new
    total [s] and number of invocations."""
    total, invocations = run_time(out_dir) or (0.0, 0)
    total, invocations = total + seconds, invocations + 1
    record = {"run_time_s": total, "invocations": invocations}
    atomic_write_text(Path(out_dir) / RUN_TIME_FILE, to_json(record, indent=2) + "\n")
    return total, invocations
