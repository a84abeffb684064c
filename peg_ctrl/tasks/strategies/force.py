"""``force``: a guarded descent, then a force-regulated push.

Phases: ``approach`` (over the observed hole) → ``descend`` (Ruckig, at ``descent_speed``, until
the task's contact detection fires — a push on the hand k sigma above the sensor's noise — or the
lower end is believed in the bore: the chamfer guided it in) → ``insert``: a push at
``insert_force`` with the lateral position held, easing off above ``insert_speed`` of descent,
for at most ``insert_time``. A descent that meets nothing by the end of its motion (and 1 s) goes
on to ``insert`` as well.

:class:`ForceStrategy` is also the base of ``spiral`` and ``tilt``: they share the approach,
the guarded descent and the push, and search between the last two.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies.base import HeldInsertion, PushIn, Strategy, StrategyConfig, never
from peg_ctrl.tasks.strategies.straight import approach_over_hole, seated_goal, slow

__all__ = ["ForceConfig", "ForceStrategy"]


@dataclasses.dataclass(frozen=True)
class ForceConfig(StrategyConfig):
    """Descent and push: speeds [m/s], forces [N], distances [m], time [s]."""

    name: ClassVar[str] = "force"
    phases: ClassVar[tuple[str, ...]] = ("approach", "descend", "insert")
    descent_speed: float = 0.005  # guarded descent [m/s]
    insert_force: float = 3.0  # force-regulated push [N]
    insert_speed: float = 0.01  # above this descent speed the push eases off, to 0 N at twice it [m/s]
    seat_margin: float = 0.002  # the descent aims this far below the seated depth [m]
    insert_time: float = 8.0  # budget of the force-regulated push [s]

    def build(self, task: HeldInsertion) -> ForceStrategy:
        return ForceStrategy(task, self)


class ForceStrategy(Strategy):
    cfg: ForceConfig
    #: The phase a contact on the face leads to, and the one a peg already in the bore leads to.
    after_contact: ClassVar[str] = "insert"
    in_bore_next: ClassVar[str] = "insert"

    def __init__(self, task: HeldInsertion, config: ForceConfig) -> None:
        super().__init__(task, config)
        self.push_in = PushIn(task, config.insert_force, config.insert_speed)

    def phase_table(self) -> dict[str, PhaseSpec]:
        t = self.task
        return {
            "approach": PhaseSpec(
                self._enter_approach, self._motion_done, "descend", Timeout(1.0, True), tick=t.feel_free
            ),
            "descend": PhaseSpec(
                self._enter_descend, self._touched, self._after_descend, Timeout(1.0, True), tick=t.feel
            ),
            "insert": PhaseSpec(
                self.push_in.enter, never, DONE, Timeout(self.cfg.insert_time), tick=self.push_in.govern
            ),
        }

    def _enter_approach(self, obs: Observation) -> Motion:
        return approach_over_hole(self.task)

    def _enter_descend(self, obs: Observation) -> Motion:
        t = self.task
        return t.move(seated_goal(t, self.cfg.seat_margin), slow(t, self.cfg.descent_speed))

    def _touched(self, obs: Observation) -> str | None:
        t = self.task
        if t.in_bore(obs):
            return "entered"  # the chamfer guided the peg in: push
        if t.contact.on:
            return "contact"
        return "no_contact" if t.machine.motion_over(obs.t) else None

    def _after_descend(self, obs: Observation) -> str:
        return self.in_bore_next if self.task.in_bore(obs) else self.after_contact

    def _after_search(self, obs: Observation) -> str:
        """Push if the search found the bore; a search that ran out of time has missed."""
        return self.in_bore_next if self.task.in_bore(obs) else DONE
