"""Progress bars for long commands: tqdm on stderr, shown only when someone is watching.

A bar is shown when the caller asks for one and stderr is a terminal, so pipes, log files and
test runs stay clean. The environment variable :data:`ENV_VAR` overrides the terminal check:
``PEG_SIM_PROGRESS=0`` hides every bar, ``PEG_SIM_PROGRESS=1`` shows them even when stderr is
redirected. tqdm is imported only when a bar is made.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Iterator
from typing import Any, TypeVar

__all__ = ["ENV_VAR", "progress", "progress_bar", "show_progress"]

ENV_VAR = "PEG_SIM_PROGRESS"

_T = TypeVar("_T")


def show_progress(requested: bool = True) -> bool:
    """Whether to draw a bar: ``requested``, then :data:`ENV_VAR` if set, else stderr is a TTY."""
    if not requested:
        return False
    setting = os.environ.get(ENV_VAR, "").strip().lower()
    if setting in ("0", "false", "no", "off"):
        return False
    if setting in ("1", "true", "yes", "on"):
        return True
    stream = sys.stderr
    return stream is not None and hasattr(stream, "isatty") and stream.isatty()


def progress_bar(
    *, total: int | None, desc: str, unit: str = "it", initial: int = 0, enabled: bool = True
) -> Any:
    """A tqdm bar on stderr (a no-op bar when :func:`show_progress` says no); use it as a context
    manager and call ``update(n)``."""
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        dynamic_ncols=True,
        disable=not show_progress(enabled),
    )


def progress(
    iterable: Iterable[_T], *, total: int | None = None, desc: str, unit: str = "it", enabled: bool = True
) -> Iterator[_T]:
    """``iterable`` with a bar that advances per item (``total`` defaults to its ``len``)."""
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    with progress_bar(total=total, desc=desc, unit=unit, enabled=enabled) as bar:
        for item in iterable:
            yield item
            bar.update(1)
