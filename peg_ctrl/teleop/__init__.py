"""Teleoperation: keys → rate-limited command deltas → the same command API, controller and loop.

- :mod:`~peg_ctrl.teleop.mapper` — the pure key → command mapping (SPEC §5 keymap);
- :mod:`~peg_ctrl.teleop.task` — teleoperation as a task on the one loop;
- :mod:`~peg_ctrl.teleop.session` — the session: loop, resets, logs, summary;
- :mod:`~peg_ctrl.teleop.scripted` — a headless operator for tests and demos.
The window lives in :mod:`peg_ctrl.cli.teleop_window`.
"""

from peg_ctrl.teleop.mapper import (
    HELP_TITLES,
    HELP_VALUES,
    KEYMAP,
    SPEED_KEYS,
    SPEED_RANGE,
    TeleopConfig,
    TeleopMapper,
)
from peg_ctrl.teleop.scripted import SCRIPTED_INSERTION, ScriptedOperator
from peg_ctrl.teleop.session import TeleopSession
from peg_ctrl.teleop.task import TeleopTask

__all__ = [
    "HELP_TITLES",
    "HELP_VALUES",
    "KEYMAP",
    "SPEED_KEYS",
    "SPEED_RANGE",
    "TeleopConfig",
    "TeleopMapper",
    "TeleopTask",
    "TeleopSession",
    "ScriptedOperator",
    "SCRIPTED_INSERTION",
]
