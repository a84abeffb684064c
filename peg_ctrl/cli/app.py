"""``peg-sim``: the command-line entry point (also ``python -m peg_ctrl``).

Exit codes, decided in one place (:func:`main`):

- 0: done (an episode or a teleop session: inserted);
- 1: an episode ran but failed (timeout, force spike, ...), or a teleop session ended without the
  peg inserted;
- 2: the user's or the system's problem: a bad argument or config (every class in
  :data:`peg_ctrl.errors.USER_ERRORS`, and any other :class:`~peg_ctrl.errors.PegCtrlError` that
  is not a simulation error, such as no window system for teleop), or an :class:`OSError` (a
  read-only or full disk, an unusable ``--out``). One line ``peg-sim: error: ...`` on stderr;
- 130: interrupted with Ctrl-C.

Any other exception is a bug and keeps its traceback.

Every command that takes ``--out`` checks it (created, writable) after validating its arguments
and before any work starts. A command that writes a directory (``run``, ``teleop``, ``sweep``,
``validity``, ``validate-profile``, ``plot``) locks it while it works
(:func:`peg_ctrl.io.lock_output_dir`): a second one on the same directory is refused (exit 2).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any

from peg_ctrl.cli import (
    bench,
    calibrate,
    compare,
    crosscheck,
    model,
    plot,
    replay,
    run,
    sweep,
    teleop,
    validate_profile,
    validity,
)
from peg_ctrl.cli.common import EXIT_INTERRUPTED, EXIT_USER_ERROR, Parser
from peg_ctrl.errors import USER_ERRORS, DivergenceError, OutputWarning, PegCtrlError, PlanningError
from peg_ctrl.progress import ENV_VAR

__all__ = ["main"]

# One module per command, each with register(sub) and run(args), in the order of --help.
COMMANDS = (
    model,
    calibrate,
    bench,
    run,
    teleop,
    sweep,
    compare,
    validity,
    crosscheck,
    validate_profile,
    replay,
    plot,
)


def _is_user_error(exc: BaseException) -> bool:
    """The user's or the system's doing (exit 2, one line) rather than a bug (traceback)."""
    if isinstance(exc, (*USER_ERRORS, OSError)):
        return True
    return isinstance(exc, PegCtrlError) and not isinstance(exc, (DivergenceError, PlanningError))


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and not isinstance(exc, PegCtrlError) and exc.strerror:
        # "[Errno 28] No space left on device: 'x'" -> "'x': No space left on device"
        where = f"{str(exc.filename)!r}: " if exc.filename is not None else ""
        text = f"{where}{exc.strerror}"
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


def _version() -> str:
    """The installed distribution's version, or ``unknown`` when it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("peg-ctrl")
    except PackageNotFoundError:
        return "unknown (not installed)"


def _parser() -> argparse.ArgumentParser:
    """The ``peg-sim`` parser: one subcommand per command, each with a help line and a description."""
    parser = Parser(
        prog="peg-sim",
        description="Peg-in-hole simulation and controller research in MuJoCo. "
        "'peg-sim COMMAND --help' describes a command.",
        epilog="Progress goes to stderr: a bar on a terminal; otherwise long commands (sweep, validity, "
        f"validate-profile, bench) print a plain line about every 10 s. {ENV_VAR}=0 hides both, "
        f"{ENV_VAR}=1 draws the bars anyway.",
    )
    parser.add_argument("--version", action="version", version=f"peg-sim {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.register(sub)
    return parser


def _one_line_warning(default: Callable[..., None]) -> Callable[..., None]:
    """A ``warnings.showwarning`` that prints an :class:`~peg_ctrl.errors.OutputWarning` (a plot
    or video not written) as one ``peg-sim: warning: ...`` line, and others as ``default`` does."""

    def show(message: Warning | str, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        if issubclass(category, OutputWarning):
            print(f"peg-sim: warning: {' '.join(str(message).split())}", file=sys.stderr)
        else:
            default(message, category, *args, **kwargs)

    return show


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``peg-sim`` with ``argv`` (default: the process's arguments); returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(warnings.showwarning)
            return int(args.func(args))
    except KeyboardInterrupt:
        print("peg-sim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader of our output went away (`peg-sim sweep --list | head`): not an error.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except Exception as exc:
        if not _is_user_error(exc):
            raise  # a bug: keep the traceback
        print(f"peg-sim: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USER_ERROR


if __name__ == "__main__":
    sys.exit(main())
