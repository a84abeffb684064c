"""The exceptions peg_ctrl raises, under one root.

``PegCtrlError`` is the root. Its subclasses say *whose* problem it is, so that a command-line
front end can map them to exit codes in one place (see :mod:`peg_ctrl.cli.app`):

- user input: :class:`ConfigError` (a bad configuration value or argument; the message names
  the field), :class:`UnknownComponent` (a name not in a registry; the message lists the known
  names), :class:`CommandError` (a command or target outside its bounds), :class:`OutputError`
  (an output location that cannot be written; :class:`OutputInUse`: another peg-sim process is
  using it), :class:`AssetError` (a required asset is missing);
- the simulation: :class:`DivergenceError` (non-finite state or control, or a MuJoCo warning),
  :class:`PlanningError` (no trajectory satisfies the limits).

The user-input classes also derive from :class:`ValueError` (and ``OutputError`` from
:class:`OSError`), so code that catches the built-in types keeps working.
"""

from __future__ import annotations

__all__ = [
    "PegCtrlError",
    "ConfigError",
    "UnknownComponent",
    "CommandError",
    "OutputError",
    "OutputInUse",
    "AssetError",
    "DivergenceError",
    "PlanningError",
    "EpisodeFailure",
    "OutputWarning",
    "FAILURE_REASONS",
    "USER_ERRORS",
]


class PegCtrlError(Exception):
    """Root of every exception raised on purpose by peg_ctrl."""


class ConfigError(PegCtrlError, ValueError):
    """A configuration value or argument is missing, unknown or invalid; the message names it."""


class UnknownComponent(ConfigError):
    """A component name (controller, planner, task, backend, ...) that is not registered."""

    def __init__(self, kind: str, name: object, known: object, *, where: str = "") -> None:
        names = ", ".join(sorted(str(k) for k in known))  # type: ignore[attr-defined]
        message = f"unknown {kind} {name!r}; known: {names}"
        super().__init__(f"{where}: {message}" if where else message)
        self.kind = kind
        self.name = name


class CommandError(PegCtrlError, ValueError):
    """A command or target is non-finite or outside its documented bounds."""


class OutputError(PegCtrlError, OSError):
    """An output path cannot be used (it is a file, read-only, or the disk is full)."""


class OutputInUse(OutputError):
    """An output directory is locked by another running peg-sim process (a run or a sweep);
    ``pid`` is that process's id, if known."""

    def __init__(self, message: str, *, pid: int | None = None) -> None:
        super().__init__(message)
        self.pid = pid


class OutputWarning(UserWarning):
    """An optional output (a plot, a video) could not be made; the run's results are intact and
    its record says which output is missing (e.g. ``plot_path: null``)."""


class AssetError(PegCtrlError, FileNotFoundError):
    """A required third-party asset (the Menagerie gripper model) cannot be found."""


class DivergenceError(PegCtrlError, ArithmeticError):
    """The simulation or a controller produced a non-finite value, or MuJoCo raised a warning."""


class PlanningError(PegCtrlError, RuntimeError):
    """A planner could not produce a trajectory within the limits."""


#: Why an episode can fail (``EpisodeResult.reason``).
FAILURE_REASONS = (
    "timeout",
    "force_spike",
    "excessive_tilt",
    "grasp_lost",
    "diverged",
    "missed",  # held insertion: the peg never entered the bore
    "jammed",  # ... stuck in the bore, held by friction
    "wedged",  # ... stuck in the bore in two-point contact
)


class EpisodeFailure(PegCtrlError):
    """An episode ended in failure: raised by a task or monitor, caught by the loop, which
    records ``reason`` (one of :data:`FAILURE_REASONS`) and ``detail`` in the result. It never
    reaches a user as an exception."""

    def __init__(self, reason: str, detail: str) -> None:
        if reason not in FAILURE_REASONS:
            raise ValueError(f"unknown failure reason {reason!r}; known: {', '.join(FAILURE_REASONS)}")
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


#: Exceptions that are the user's or the operating system's doing, never a bug.
USER_ERRORS: tuple[type[BaseException], ...] = (ConfigError, CommandError, OutputError, AssetError)
