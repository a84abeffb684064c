"""``straight``: the stiff baseline. Over the observed hole, then a position-controlled descent to
below the seated depth, whatever the contact.

Phases: ``approach`` (Ruckig, over the observed hole, the lower end ``start_height`` above the
mouth) → ``push``: a descent at ``descent_speed`` to ``seat_margin`` below the seated depth; the
phase ends when its motion and 1 s more are over.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from peg_ctrl.planners.base import MotionLimits, Waypoint
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies.base import HeldInsertion, Strategy, StrategyConfig, never

__all__ = ["StraightConfig", "StraightStrategy", "approach_over_hole", "seated_goal", "slow"]


@dataclasses.dataclass(frozen=True)
class StraightConfig(StrategyConfig):
    """The descent's speed [m/s] and how far below the seated depth it aims [m]."""

    name: ClassVar[str] = "straight"
    phases: ClassVar[tuple[str, ...]] = ("approach", "push")
    descent_speed: float = 0.005  # guarded descent, and the straight push [m/s]
    seat_margin: float = 0.002  # the push aims this far below the seated depth [m]

    def build(self, task: HeldInsertion) -> StraightStrategy:
        return StraightStrategy(task, self)


def approach_over_hole(task: HeldInsertion) -> Motion:
    """Over the observed hole, the lower end ``start_height`` above the mouth, orientation kept."""
    q = np.asarray(task.goal.quat_world)
    target = np.array([*task.observed_hole, task.block_top + task.start_height])
    return task.move(Waypoint.of(task.pinch_for(target, q), q, 0.0))


def seated_goal(task: HeldInsertion, seat_margin: float) -> Waypoint:
    """The last goal moved down until the believed lower end is ``seat_margin`` below the seated depth."""
    g = task.goal
    q = np.asarray(g.quat_world)
    bottom = task.believed_bottom_of(g)
    bottom[2] = task.block_top - task.min_depth - seat_margin
    return Waypoint.of(task.pinch_for(bottom, q), q, 0.0)


def slow(task: HeldInsertion, speed: float) -> MotionLimits:
    """The task's motion limits with every speed scaled so that the linear one is ``speed`` [m/s]."""
    return task.limits.scaled(speed / task.limits.v_lin)


class StraightStrategy(Strategy):
    cfg: StraightConfig

    def phase_table(self) -> dict[str, PhaseSpec]:
        return {
            "approach": PhaseSpec(self._enter_approach, self._motion_done, "push", Timeout(1.0, True)),
            "push": PhaseSpec(self._enter_push, never, DONE, Timeout(1.0, True)),
        }

    def _enter_approach(self, obs: Observation) -> Motion:
        return approach_over_hole(self.task)

    def _enter_push(self, obs: Observation) -> Motion:
        t = self.task
        return t.move(seated_goal(t, self.cfg.seat_margin), slow(t, self.cfg.descent_speed))
