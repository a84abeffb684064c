"""Progress for long commands on stderr: a tqdm bar on a terminal, plain lines in a log.

On a terminal a command shows a tqdm bar. When stderr is not a terminal (``nohup``, CI, a
cluster job, ``> log 2>&1``) a bar would be an unreadable run of carriage returns, so a command
that asks for them (``lines=``) prints instead a plain line when it starts, about every
:data:`LINE_PERIOD_S` seconds and when it ends, flushed at once (``tail -f`` shows it)::

    sweep contact_hard: 120/400 episodes (30%), 117 inserted, elapsed 10m05s, ETA 23m30s

The environment variable :data:`ENV_VAR` overrides the terminal check: ``PEG_SIM_PROGRESS=0``
hides bars and lines, ``PEG_SIM_PROGRESS=1`` draws bars even when stderr is redirected. tqdm is
imported only when a bar is made.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from types import TracebackType
from typing import Any, Literal, TextIO, TypeVar

__all__ = [
    "ENV_VAR",
    "LINE_PERIOD_S",
    "ProgressLines",
    "format_duration",
    "progress",
    "progress_bar",
    "progress_mode",
    "show_progress",
]

ENV_VAR = "PEG_SIM_PROGRESS"
#: Seconds between two progress lines (when stderr is not a terminal).
LINE_PERIOD_S = 10.0

_T = TypeVar("_T")


def _setting() -> bool | None:
    """:data:`ENV_VAR`: True (show), False (hide) or None (unset or not understood)."""
    setting = os.environ.get(ENV_VAR, "").strip().lower()
    if setting in ("0", "false", "no", "off"):
        return False
    if setting in ("1", "true", "yes", "on"):
        return True
    return None


def _stderr_is_a_terminal() -> bool:
    stream = sys.stderr
    return stream is not None and hasattr(stream, "isatty") and stream.isatty()


def show_progress(requested: bool = True) -> bool:
    """Whether to draw a bar: ``requested``, then :data:`ENV_VAR` if set, else stderr is a TTY."""
    if not requested:
        return False
    setting = _setting()
    return _stderr_is_a_terminal() if setting is None else setting


def progress_mode(requested: bool = True, *, lines: bool = False) -> Literal["bar", "lines", "off"]:
    """How to show progress: a ``bar`` (:func:`show_progress`); else, when the caller offers
    ``lines``, stderr is not a terminal and :data:`ENV_VAR` does not say ``0``, plain ``lines``;
    else ``off``."""
    if show_progress(requested):
        return "bar"
    if requested and lines and _setting() is None and sys.stderr is not None:
        return "lines"
    return "off"


def format_duration(seconds: float) -> str:
    """``45s``, ``10m05s``, ``2h03m`` or ``3d04h``: a duration to the second, minute or hour."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    m = round(seconds / 60)
    if m < 24 * 60:
        return f"{m // 60}h{m % 60:02d}m"
    h = round(seconds / 3600)
    return f"{h // 24}d{h % 24:02d}h"


class ProgressLines:
    """Plain progress lines: ``DESC: N/TOTAL NOUN (P%), POSTFIX, elapsed T, ETA T``.

    Use it as a context manager: entering prints the first line (a resumed job's ``initial``
    counts as done), :meth:`update` counts work and prints a line when ``period_s`` has passed
    since the last one, and leaving prints the last line (``done``, or ``stopped`` when it ends
    short of ``total``). The ETA extrapolates only this run's rate (``initial`` is not work
    done now), and is left out until there is one.

    ``background`` starts a thread that prints the due lines while no work finishes (a job of
    long items still shows it is alive); without it lines are printed only by :meth:`update`
    and :meth:`tick`. ``clock`` (seconds, monotonic) and ``stream`` can be replaced in tests.
    The interface is the part of tqdm's that the package's commands use.
    """

    def __init__(
        self,
        *,
        total: int | None,
        desc: str,
        noun: str,
        initial: int = 0,
        postfix: str = "",
        period_s: float = LINE_PERIOD_S,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
        background: bool = True,
    ) -> None:
        if period_s <= 0:
            raise ValueError(f"period_s must be > 0, got {period_s}")
        self.total = total
        self.n = initial
        self.desc = desc
        self.noun = noun
        self.initial = initial
        self.postfix = postfix
        self.period_s = period_s
        self._stream = stream
        self._clock = clock
        self._background = background
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started = clock()
        self._last_line = self._started
        self._open = False

    # -- tqdm's interface ------------------------------------------------------------------

    def update(self, n: int = 1) -> None:
        """Count ``n`` more items done; print a line if one is due."""
        with self._lock:
            self.n += n
        self.tick()

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        """What follows the count in the next lines (``117 inserted``)."""
        self.postfix = s

    def set_postfix(
        self, ordered_dict: dict[str, Any] | None = None, refresh: bool = True, **kwargs: Any
    ) -> None:
        """``key=value, ...`` after the count, as tqdm shows it."""
        items = {**(ordered_dict or {}), **kwargs}
        self.postfix = ", ".join(f"{k}={v}" for k, v in items.items())

    def close(self, *, stopped: bool = False) -> None:
        """Print the last line (once) and stop the background thread."""
        if not self._open:
            return
        self._open = False
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        short = self.total is not None and self.n < self.total
        self._print(self.line(end="stopped" if stopped or short else "done"))

    def __enter__(self) -> ProgressLines:
        self._started = self._last_line = self._clock()
        self._open = True
        self._print(self.line())
        if self._background:
            self._thread = threading.Thread(target=self._run, name="progress-lines", daemon=True)
            self._thread.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(stopped=exc_type is not None)

    # -- the lines ---------------------------------------------------------------------------

    def tick(self) -> bool:
        """Print a line if ``period_s`` has passed since the last one; whether it did."""
        with self._lock:
            now = self._clock()
            if not self._open or now - self._last_line < self.period_s:
                return False
            self._last_line = now
        self._print(self.line())
        return True

    def line(self, *, end: str = "") -> str:
        """The current line; ``end`` (``done``, ``stopped``) replaces the ETA."""
        elapsed = self._clock() - self._started
        count = f"{self.n}/{self.total} {self.noun}" if self.total is not None else f"{self.n} {self.noun}"
        if self.total:
            count += f" ({100 * self.n // self.total}%)"
        parts = [count]
        if self.postfix:
            parts.append(self.postfix)
        parts.append(f"elapsed {format_duration(elapsed)}")
        if end:
            parts.append(end)
        else:
            eta = self.eta_s(elapsed)
            if eta is not None:
                parts.append(f"ETA {format_duration(eta)}")
        return f"{self.desc}: {', '.join(parts)}"

    def eta_s(self, elapsed: float) -> float | None:
        """Seconds left at this run's rate; None before this run has done anything (or with no
        total)."""
        done_now = self.n - self.initial
        if self.total is None or done_now <= 0 or elapsed <= 0:
            return None
        return max(0, self.total - self.n) * elapsed / done_now

    def _print(self, text: str) -> None:
        stream = self._stream if self._stream is not None else sys.stderr
        if stream is None:
            return
        try:
            stream.write(text + "\n")
            stream.flush()
        except (OSError, ValueError):  # a closed or broken log: progress is not worth an error
            pass

    def _run(self) -> None:
        while not self._stop.wait(min(1.0, self.period_s)):
            self.tick()


def progress_bar(
    *,
    total: int | None,
    desc: str,
    unit: str = "it",
    initial: int = 0,
    enabled: bool = True,
    lines: str | None = None,
    postfix: str = "",
) -> Any:
    """A tqdm bar on stderr, used as a context manager with ``update(n)``, ``n`` and
    ``set_postfix_str``; a no-op bar when :func:`show_progress` says no.

    ``lines`` (a plural noun, ``"episodes"``): when stderr is not a terminal, plain progress
    lines counting these instead (:class:`ProgressLines`, see :func:`progress_mode`).
    ``postfix``: the text after the count from the start (changed with ``set_postfix_str``).
    """
    mode = progress_mode(enabled, lines=lines is not None)
    if mode == "lines" and lines is not None:
        return ProgressLines(total=total, desc=desc, noun=lines, initial=initial, postfix=postfix)
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc=desc,
        unit=unit,
        postfix=postfix or None,
        file=sys.stderr,
        dynamic_ncols=True,
        disable=mode != "bar",
    )


def progress(
    iterable: Iterable[_T],
    *,
    total: int | None = None,
    desc: str,
    unit: str = "it",
    enabled: bool = True,
    lines: str | None = None,
) -> Iterator[_T]:
    """``iterable`` with a bar that advances per item (``total`` defaults to its ``len``);
    ``lines`` as in :func:`progress_bar`."""
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    with progress_bar(total=total, desc=desc, unit=unit, enabled=enabled, lines=lines) as bar:
        for item in iterable:
            yield item
            bar.update(1)
