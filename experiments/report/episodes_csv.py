"""A sweep's ``episodes.csv``: its rows, and whether a report can be drawn from it."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from peg_ctrl.experiments.stats import number_columns

__all__ = ["REQUIRED_COLUMNS", "read_rows", "episodes_csv_problem"]

# Columns the report cannot be drawn without (the columns read as numbers:
# peg_ctrl.experiments.stats.number_columns, from the episode record's declarations).
REQUIRED_COLUMNS = (
    "key",
    "controller",
    "planner",
    "clearance_m",
    "status",
    "reason",
    "peak_contact_force_n",
    "time_to_insert_s",
)
_STATUSES = ("success", "failure")


def read_rows(out_dir: Path) -> list[dict[str, Any]]:
    """The rows of ``out_dir/episodes.csv`` (values as strings)."""
    with open(Path(out_dir) / "episodes.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def episodes_csv_problem(path: Path) -> str | None:
    """What makes ``path`` (an ``episodes.csv``) unusable for a report, in a few words, or None.

    Found: a missing, unreadable, empty or non-text file; NUL bytes (a torn write); a file cut
    off (its last line has no line end, or a row has fewer fields than the header); a row with
    more fields; a column the report needs missing; a status other than success or failure; a
    metric that is not a number.
    """
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except FileNotFoundError:
        return "does not exist"
    except OSError as exc:
        return f"cannot be read: {exc.strerror or exc}"
    except UnicodeDecodeError as exc:
        return f"is not text (byte {exc.start} is not UTF-8)"
    if not text:
        return "is empty"
    if "\0" in text:  # a torn write after a crash leaves zero-filled blocks
        line = text.count("\n", 0, text.index("\0")) + 1
        return f"is damaged: line {line} holds NUL bytes"
    if not text.endswith("\n"):
        last = text.count("\n") + 1
        return f"is cut off: its last line ({last}) has no line end"
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader)
        missing = [name for name in REQUIRED_COLUMNS if name not in header]
        if missing:
            return f"has no column {', '.join(missing)} (line 1)"
        numbers = [(header.index(name), name) for name in number_columns() if name in header]
        status = header.index("status")
        for fields in reader:
            line = reader.line_num
            if len(fields) < len(header):
                return f"is cut off or damaged: line {line} has {len(fields)} of {len(header)} fields"
            if len(fields) > len(header):
                return f"is damaged: line {line} has {len(fields)} fields, the header {len(header)}"
            if fields[status] not in _STATUSES:
                return f"is damaged: line {line} has status {fields[status]!r} (not success or failure)"
            for i, name in numbers:
                try:
                    float(fields[i] or 0.0)
                except ValueError:
                    return f"is damaged: line {line} has {name} {fields[i]!r} (not a number)"
    except csv.Error as exc:
        return f"is damaged: line {reader.line_num}: {exc}"
    return None
