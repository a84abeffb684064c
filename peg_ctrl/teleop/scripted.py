"""A headless operator that drives a teleop session through its key mapping."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

from peg_ctrl.commands import quat_to_euler
from peg_ctrl.teleop.session import TeleopSession

__all__ = ["ScriptedOperator", "SCRIPTED_INSERTION"]

# The scripted insertion of ``peg-sim teleop --scripted``: grasp, lift, turn, align, lower, open.
SCRIPTED_INSERTION: tuple[tuple[str, Any], ...] = (
    ("z", 0.020),
    ("jaw", 0.0),
    ("wait", 0.8),
    ("z", 0.15),
    ("roll", math.pi / 2),
    ("wait", 0.5),
    ("align", None),
    ("wait", 0.5),
    ("align", None),
    ("z", 0.09),
    ("jaw", 0.085),
    ("wait", 2.0),
)


class ScriptedOperator:
    """A headless operator: holds keys until the commanded pose reaches each goal.

    Goals are ``(kind, value)`` pairs: ``("x"|"y"|"z", metres)``, ``("roll", radians)``,
    ``("jaw", metres)``, ``("wait", seconds)``, or ``("align", None)`` which moves the gripper so
    the peg's bottom is over the hole (it looks at the peg, as a person would).
    """

    _AXIS_KEYS = {"x": ("6", "7"), "y": ("4", "5"), "z": ("8", "9"), "jaw": ("[", "]")}

    def __init__(
        self, session: TeleopSession, goals: Iterable[tuple[str, Any]], *, tol: float = 2e-4
    ) -> None:
        self.session = session
        self.goals = list(goals)
        self.tol = tol

    def run(
        self, *, max_sim_s: float = 60.0, dt: float = 0.01, on_tick: Callable[[], None] | None = None
    ) -> None:
        s = self.session
        m = s.mapper
        t_end = s.data.time + max_sim_s
        queue: list[tuple[str, Any]] = []
        for kind, value in self.goals:
            if kind == "align":
                queue.append(("align", None))
            else:
                queue.append((kind, value))
        while queue and not s.finished and s.data.time < t_end:
            kind, value = queue[0]
            if kind == "wait":
                s.advance(value)
                queue.pop(0)
                continue
            if kind == "align":
                hx, hy = s.scene.hole_xy
                bottom = s.peg().bottom_world
                pinch = s.state().p_world
                queue[0:1] = [("x", hx - (bottom[0] - pinch[0])), ("y", hy - (bottom[1] - pinch[1]))]
                continue
            current = {"x": m.p_world[0], "y": m.p_world[1], "z": m.p_world[2], "jaw": m.jaw_sep_m}.get(kind)
            if kind == "roll":
                current = quat_to_euler(m.quat_world)[0]
            assert current is not None, kind
            error = value - current
            tol = self.tol if kind != "roll" else 2e-3
            if abs(error) <= tol:
                m.release_all()
                s.advance(0.2)  # let the rate limit bring the motion to rest
                queue.pop(0)
                continue
            if kind == "roll":
                plus, minus = "Q", "E"
            else:
                plus, minus = self._AXIS_KEYS[kind]
            m.release_all()
            speed = {"roll": s.cfg.rot_speed, "jaw": s.cfg.jaw_speed}.get(kind, s.cfg.lin_speed)
            fine = abs(error) < 0.5 * speed  # within half a second at full speed: slow down
            m.press(plus if error > 0 else minus, shift=fine)
            s.advance(dt)
            if on_tick is not None:
                on_tick()
        m.release_all()
