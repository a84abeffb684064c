"""``spiral``: a guarded descent, then an Archimedean spiral pressed onto the face until the peg drops in.

Phases: ``approach`` → ``descend`` (as ``force``) → ``search``: a spiral about the point of
contact (pitch ``spiral_pitch``, below the chamfer's capture range, at ``spiral_speed``, out to
``search_radius``) pressing down with ``search_force``, until the lower end is believed inside
the bore → ``insert`` (as ``force``). A search that runs out of time (the spiral's length at its
speed) ends the episode.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies.base import HeldInsertion
from peg_ctrl.tasks.strategies.force import ForceConfig, ForceStrategy
from peg_ctrl.tasks.strategies.motions import Spiral

__all__ = ["SpiralConfig", "SpiralStrategy"]


@dataclasses.dataclass(frozen=True)
class SpiralConfig(ForceConfig):
    """The spiral: pitch and radius [m], speed [m/s], pressing force [N] (and ``force``'s fields)."""

    name: ClassVar[str] = "spiral"
    phases: ClassVar[tuple[str, ...]] = ("approach", "descend", "search", "insert")
    search_force: float = 3.0  # pressing force while searching [N]
    spiral_pitch: float = 0.0012  # radial step per turn of the spiral [m]
    spiral_speed: float = 0.005  # along the spiral [m/s]
    search_radius: float = 0.0045  # the spiral gives up beyond this radius [m]

    def build(self, task: HeldInsertion) -> SpiralStrategy:
        return SpiralStrategy(task, self)


class SpiralStrategy(ForceStrategy):
    cfg: SpiralConfig
    after_contact: ClassVar[str] = "search"

    def phase_table(self) -> dict[str, PhaseSpec]:
        c = self.cfg
        turns = c.search_radius / c.spiral_pitch
        length = math.pi * c.search_radius * turns  # of the spiral out to the search radius
        table = super().phase_table()
        table["search"] = PhaseSpec(
            self._enter_search,
            self.task.in_bore,
            self._after_search,
            Timeout(length / c.spiral_speed),
            tick=self.task.feel,
        )
        return table

    def _enter_search(self, obs: Observation) -> Motion:
        t, c = self.task, self.cfg
        t.hold_here(obs)
        return Spiral(t.goal, c.spiral_pitch, c.spiral_speed, c.search_force)
