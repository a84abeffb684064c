"""``handover``: approach, then hand over to a controller that plans the insertion itself.

Phases:

- ``approach`` (Ruckig, in free space): over the observed hole, the lower end ``hover`` above
  the face;
- ``handover``: the task hands over (its belief's ``plan_depth``: the end to be seated
  ``seat_margin`` below the success depth) and holds the approach's end as the target; the
  controller plans towards the goal on its own (``sampling_mpc``: controllers/belief_planner.py).
  No touch, landing, search or centring is scripted: the phase ends when the task's own seated
  detection fires (``seated``) or after ``plan_time``;
- ``hold``: still, for the success check; the controller goes on planning to the same goal.

A controller that does not plan only holds the target: this strategy is for ``sampling_mpc``
(until issue 49 it was named ``plan``; ``plan`` is now the planner over skills).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies.base import HeldInsertion, Strategy, StrategyConfig, never
from peg_ctrl.tasks.strategies.motions import Hold

__all__ = ["HandoverConfig", "HandoverStrategy"]


@dataclasses.dataclass(frozen=True)
class HandoverConfig(StrategyConfig):
    """Where the hand-over starts [m], the planning phase's budget [s], the goal's margin [m]."""

    name: ClassVar[str] = "handover"
    phases: ClassVar[tuple[str, ...]] = ("approach", "handover", "hold")
    hover: float = 0.001  # the lower end this far above the face when the planner takes over
    plan_time: float = 15.0  # budget of the planning phase
    seat_margin: float = 0.0005  # the goal: this far below the success depth
    hold_time: float = 1.0

    def build(self, task: HeldInsertion) -> HandoverStrategy:
        return HandoverStrategy(task, self)


class HandoverStrategy(Strategy):
    cfg: HandoverConfig

    def phase_table(self) -> dict[str, PhaseSpec]:
        t, c = self.task, self.cfg
        return {
            "approach": PhaseSpec(
                self._enter_approach, self._motion_done, "handover", Timeout(2.0, True), tick=t.feel_free
            ),
            "handover": PhaseSpec(self._enter_plan, self._seated, "hold", Timeout(c.plan_time), tick=t.feel),
            "hold": PhaseSpec(self._hold, never, DONE, Timeout(c.hold_time), tick=t.feel),
        }

    def _enter_approach(self, obs: Observation) -> Motion:
        t = self.task
        q = np.asarray(t.goal.quat_world)
        target = np.array([*t.observed_hole, t.z_face + self.cfg.hover])
        return t.move(Waypoint.of(t.pinch_for(target, q), q, 0.0))

    def _enter_plan(self, obs: Observation) -> Motion:
        t = self.task
        t.plan_depth = t.min_depth + self.cfg.seat_margin
        return self._hold(obs)

    def _seated(self, obs: Observation) -> str | None:
        return "seated" if self.task.seated_detected(obs) else None

    def _hold(self, obs: Observation) -> Motion:
        """Still where the approach ended (a planning controller does not track it)."""
        g = self.task.goal
        return Hold(GripperTarget.trusted(g.p_world, g.quat_world, np.zeros(3), np.zeros(3), 0.0))
