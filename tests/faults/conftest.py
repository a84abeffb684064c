"""Checks shared by the output fault tests: strict JSON, and "every file is complete or absent".

Fixtures, so that ``test_outputs.py`` and ``test_disk_full.py`` use the same definition of a
complete file.
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from peg_ctrl.run.episode_log import TRACE_COLUMNS


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"non-standard JSON constant {name}")


def strict_loads(text: str | bytes) -> Any:
    """``json.loads`` that refuses ``NaN``, ``Infinity`` and ``-Infinity`` (RFC 8259)."""
    return json.loads(text, parse_constant=_refuse_constant)


def _check_json(path: Path) -> None:
    strict_loads(path.read_bytes())


def _check_jsonl(path: Path) -> None:
    data = path.read_bytes()
    assert data == b"" or data.endswith(b"\n"), f"{path}: torn last line"
    for line in data.splitlines():
        strict_loads(line)


def _check_npz(path: Path) -> None:
    with np.load(path) as npz:
        assert npz.files, f"{path}: no arrays"
        for name in npz.files:
            np.asarray(npz[name])


def _check_partial(path: Path) -> None:
    row = 8 * len(TRACE_COLUMNS)  # little-endian float64, one row per physics step
    assert path.stat().st_size % row == 0, f"{path}: {path.stat().st_size} bytes is not whole rows"


def _check_png(path: Path) -> None:
    from PIL import Image

    with Image.open(path) as image:
        image.verify()
    with Image.open(path) as image:
        image.load()


def _check_csv(path: Path) -> None:
    rows = list(csv.reader(io.StringIO(path.read_text(), newline="")))
    for row in rows[1:]:
        assert len(row) == len(rows[0]), f"{path}: a row of {len(row)} cells under {len(rows[0])} columns"


def _check_parquet(path: Path) -> None:
    import pyarrow.parquet as pq

    pq.read_table(path)


def _check_text(path: Path) -> None:
    assert path.read_text(encoding="utf-8"), f"{path}: empty"


def _check_mp4(path: Path) -> None:
    import imageio.v2 as imageio

    reader = imageio.get_reader(str(path))
    try:
        assert reader.count_frames() > 0, f"{path}: no frames"
    finally:
        reader.close()


def _check_lock(path: Path) -> None:
    assert re.fullmatch(rb"(\d+\n)?", path.read_bytes()), f"{path}: not a pid"


CHECKS: dict[str, Callable[[Path], None]] = {
    ".json": _check_json,
    ".jsonl": _check_jsonl,
    ".npz": _check_npz,
    ".partial": _check_partial,
    ".png": _check_png,
    ".csv": _check_csv,
    ".parquet": _check_parquet,
    ".md": _check_text,
    ".mp4": _check_mp4,
    ".lock": _check_lock,
}


def check_tree(root: Path) -> int:
    """Check that every file under ``root`` is complete: JSON parses strictly, every line of a
    ``.jsonl`` too and it ends with a newline, npz archives load, ``forces.partial`` is whole
    rows, PNGs decode, CSV rows have the header's width, parquet reads, videos have frames; no
    temporary file is left. A file of another kind fails (a new writer must be added here).
    Returns the number of files checked."""
    checked = 0
    for path in sorted(p for p in Path(root).rglob("*") if p.is_file()):
        assert ".tmp" not in path.name, f"temporary file left behind: {path}"
        check = CHECKS.get(path.suffix)
        assert check is not None, f"no completeness check for {path}"
        try:
            check(path)
        except AssertionError:
            raise
        except Exception as exc:
            raise AssertionError(f"{path} is not complete: {exc!r}") from exc
        checked += 1
    return checked


@pytest.fixture
def strict_json() -> Callable[[str | bytes], Any]:
    """:func:`strict_loads`."""
    return strict_loads


@pytest.fixture
def complete_tree() -> Callable[[Path], int]:
    """:func:`check_tree`."""
    return check_tree
