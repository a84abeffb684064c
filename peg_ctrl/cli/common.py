"""What every ``peg-sim`` command shares: exit codes, the one-line-error parser, the registries'
names for option choices, the shared options (``--out``, ``--config``, ``--set``,
``--controller``, ``--profile``) and the episode-config plumbing of ``run``, ``model`` and
``teleop`` (the config file, then ``--set``, then ``--controller``: :func:`episode_mapping`)."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

from peg_ctrl.errors import ConfigError, UnknownComponent

EXIT_FAILED = 1
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130


class Parser(argparse.ArgumentParser):
    """Argument errors in one line (``peg-sim: error: ...``), exit code 2; ``--help`` for usage."""

    def error(self, message: str) -> NoReturn:
        """Print ``message`` as one ``peg-sim: error:`` line and exit with code 2."""
        self.exit(2, f"peg-sim: error: {message} (see '{self.prog} --help')\n")


class Known:
    """The names in one of the package's registries, for an option's ``choices`` (listed in its
    help as ``%(choices)s``) and ``type`` (an unknown name is refused with the known ones).

    The registry is imported on first use, not when the parser is built: ``peg-sim --help``
    stays fast, and :func:`~peg_ctrl.cli.app.main` picks the GL backend before anything imports
    mujoco.
    """

    def __init__(self, kind: str, module: str, attr: str) -> None:
        self.kind = kind
        self.module = module
        self.attr = attr

    def names(self) -> list[str]:
        """The registered names, sorted."""
        from importlib import import_module

        return sorted(getattr(import_module(self.module), self.attr))

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __contains__(self, name: object) -> bool:
        return name in self.names()

    def __call__(self, value: str) -> str:
        if value not in self:
            raise argparse.ArgumentTypeError(str(UnknownComponent(self.kind, value, self.names())))
        return value


CONTROLLERS = Known("controller", "peg_ctrl.controllers", "REGISTRY")
PLANNERS = Known("planner", "peg_ctrl.planners", "PLANNERS")
PROFILES = Known("physics profile", "peg_ctrl.sim.physics", "PROFILES")
BENCH_TASKS = Known("task", "peg_ctrl.tools.bench", "BENCH_TASKS")


def add_out(
    p: argparse.ArgumentParser,
    default: str | None = None,
    *,
    file: bool = False,
    required: bool = False,
    help: str = "",
) -> None:
    """``--out DIR`` (or ``FILE``), where a command writes."""
    kind = "file" if file else "directory"
    p.add_argument(
        "--out",
        default=default,
        required=required,
        metavar="FILE" if file else "DIR",
        help=help or f"output {kind}" + ("" if default is None else " (default %(default)s)"),
    )


def add_config(p: argparse.ArgumentParser, help: str = "episode config file (.yaml, .toml or .json)") -> None:
    """``--config FILE``: an episode config file."""
    p.add_argument("--config", metavar="FILE", help=help)


def add_set(p: argparse.ArgumentParser, what: str = "config", help: str = "") -> None:
    """``--set KEY=VALUE`` (repeatable): a field of the ``what`` by dotted path."""
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help=help
        or f"set {'an' if what[0] in 'aeiou' else 'a'} {what} field by dotted path, value parsed as YAML "
        "(repeatable), "
        "e.g. --set physics.profile=precision --set scene.assets.clearance=5e-5",
    )


def add_known(p: argparse.ArgumentParser, flag: str, known: Known, help: str, **kwargs: Any) -> None:
    """An option whose value is one of ``known``'s names (``%(choices)s`` in ``help``)."""
    metavar = kwargs.pop("metavar", "NAME")
    p.add_argument(flag, type=known, choices=known, metavar=metavar, help=help, **kwargs)


def episode_mapping(args: argparse.Namespace) -> dict[str, Any]:
    """The episode config's plain data: the ``--config`` file, every ``--set KEY=VALUE``, then
    ``--controller`` (the controller section merged by :func:`merge_controller`). ``args`` may
    lack ``config`` or ``controller`` (a command without the option)."""
    from peg_ctrl.config import apply_overrides, read_mapping

    config = getattr(args, "config", None)
    data = read_mapping(Path(config)) if config else {}
    sets = args.set or []
    merged = apply_overrides(data, sets)
    controller_sets = [item for item in sets if item.partition("=")[0].strip().split(".")[0] == "controller"]
    section = merge_controller(data.get("controller"), controller_sets, getattr(args, "controller", None))
    if section is not None:
        merged["controller"] = section
    return merged


def merge_controller(file: object, sets: list[str], flag: str | None) -> dict[str, Any] | None:
    """The episode's controller section from the config file's (``file``: a name, a mapping or
    None), the ``--set controller...`` assignments (``sets``) and ``--controller`` (``flag``).

    The controller is the flag's, else the last ``--set controller.name``'s (or ``--set
    controller=NAME``'s), else the file's. The file's fields are kept when they are that
    controller's (the same name, or none) and dropped when the file names another controller;
    the ``--set controller.*`` fields are always kept, on top of them (an unknown field is then
    refused by name). A flag and a ``--set controller.name`` that name different controllers
    are refused in one line. None: nothing on the command line touches the controller.
    """
    from peg_ctrl.config import apply_overrides

    if not sets and flag is None:
        return None
    set_section = apply_overrides({}, sets).get("controller")
    set_name = set_section if isinstance(set_section, str) else None
    if isinstance(set_section, dict):
        set_name = set_section.get("name")
    if flag is not None and set_name is not None and set_name != flag:
        raise ConfigError(
            f"--controller {flag} and --set controller.name={set_name} name different controllers; "
            "give one of them"
        )
    base = {"name": file} if isinstance(file, str) else dict(file) if isinstance(file, dict) else {}
    name = flag or set_name or base.get("name")
    if name is not None and base.get("name", name) != name:
        base = {}  # the file's fields are another controller's
    section = apply_overrides({"controller": base}, sets)["controller"]
    if isinstance(section, str):
        section = {"name": section}
    if not isinstance(section, dict):
        return None  # not a controller section at all: loading refuses it by name
    return section if name is None else {**section, "name": name}


def require_display(what: str, instead: str) -> None:
    """A window needs a display: without one, one line naming the alternative (exit 2)."""
    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if sys.platform.startswith("linux") and not display:
        raise ConfigError(f"{what} needs a display (DISPLAY is not set); {instead}")
