"""Trajectory planners that any controller can track, selected by name from one registry."""

from __future__ import annotations

from collections.abc import Callable

from peg_ctrl.planners.base import MotionLimits, Planner, RotationPath, Trajectory, Waypoint
from peg_ctrl.planners.fixed_speed import FixedSpeedPlanner
from peg_ctrl.planners.ruckig_planner import PlanningError, RuckigPlanner

__all__ = [
    "MotionLimits",
    "Planner",
    "PlanningError",
    "RotationPath",
    "Trajectory",
    "Waypoint",
    "FixedSpeedPlanner",
    "RuckigPlanner",
    "PLANNERS",
    "UnknownPlanner",
    "make_planner",
]

PLANNERS: dict[str, Callable[[], Planner]] = {
    "ruckig": RuckigPlanner,
    "fixed_speed": FixedSpeedPlanner,
}


class UnknownPlanner(ValueError):
    """A planner name that is not registered; the message lists the known names."""

    def __init__(self, name: str) -> None:
        super().__init__(f"unknown planner {name!r}; known: {', '.join(sorted(PLANNERS))}")


def make_planner(name: str) -> Planner:
    if name not in PLANNERS:
        raise UnknownPlanner(name)
    return PLANNERS[name]()
