"""``tilt``: tilt the peg, slide its lowest rim across the face into the bore, straighten, push.

Phases: ``approach`` with the peg tilted by ``tilt_angle`` (its lowest rim towards +x) and that
rim ``slide_start`` beyond the observed chamfer's edge → ``descend`` onto the top face (as
``force``) → ``slide`` towards -x pressing with ``search_force`` until the rim drops into the
bore → ``straighten`` (Ruckig, still pressing: the pinch point moves on the chord of the arc
about the lower end, which drifts by about 0.1 mm) → ``insert`` (as ``force``). A slide that runs
out of time ends the episode.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.sim.rotations import quat_mul
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies.base import HeldInsertion
from peg_ctrl.tasks.strategies.force import ForceConfig, ForceStrategy
from peg_ctrl.tasks.strategies.motions import Pressed, Slide, about

__all__ = ["TiltConfig", "TiltStrategy"]


@dataclasses.dataclass(frozen=True)
class TiltConfig(ForceConfig):
    """The tilt [rad], the slide [m, m/s], the straightening rate [rad/s] (and ``force``'s fields)."""

    name: ClassVar[str] = "tilt"
    phases: ClassVar[tuple[str, ...]] = ("approach", "descend", "slide", "straighten", "insert")
    search_force: float = 3.0  # pressing force while sliding [N]
    tilt_angle: float = 0.12  # tilt of the tilt-and-slide strategy [rad]
    turn_speed: float = 0.1  # straightening, about the peg's lower end [rad/s]
    slide_start: float = 0.0045  # lowest rim this far beyond the observed chamfer edge [m]
    slide_speed: float = 0.005  # [m/s]

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 < self.tilt_angle < 0.5:
            raise ConfigError(f"task.strategy.tilt_angle must be in (0, 0.5) rad, got {self.tilt_angle!r}")

    def build(self, task: HeldInsertion) -> TiltStrategy:
        return TiltStrategy(task, self)


class TiltStrategy(ForceStrategy):
    cfg: TiltConfig
    after_contact: ClassVar[str] = "slide"
    in_bore_next: ClassVar[str] = "straighten"

    def phase_table(self) -> dict[str, PhaseSpec]:
        t, c = self.task, self.cfg
        span = c.slide_start + 2.0 * (t.chamfer + 0.002)
        table = super().phase_table()
        table["slide"] = PhaseSpec(
            self._enter_slide, t.in_bore, self._after_search, Timeout(span / c.slide_speed), tick=t.feel
        )
        table["straighten"] = PhaseSpec(
            self._enter_straighten, self._motion_done, "insert", Timeout(0.3, True), tick=t.feel
        )
        return table

    def _tilted(self) -> np.ndarray:
        """The gripper orientation that tilts the peg by ``tilt_angle`` with its lowest rim towards +x."""
        q0 = np.asarray(self.task.goal.quat_world)
        return quat_mul(about(np.array([0.0, 1.0, 0.0]), self.cfg.tilt_angle), q0)

    def _enter_approach(self, obs: Observation) -> Motion:
        """Tilted over the observed hole, the lowest rim ``slide_start`` beyond the chamfer's
        edge along +x and the lower end ``start_height`` above the mouth."""
        t, c = self.task, self.cfg
        target = np.array([*t.observed_hole, t.block_top + t.start_height])
        q = self._tilted()
        a = c.tilt_angle
        rim = t.hole_radius + t.chamfer + c.slide_start  # of the lowest rim from the axis
        target[0] += rim - t.radius * math.cos(a)
        target[2] += t.radius * math.sin(a)
        return t.move(Waypoint.of(t.pinch_for(target, q), q, 0.0))

    def _enter_slide(self, obs: Observation) -> Motion:
        t, c = self.task, self.cfg
        t.hold_here(obs)
        return Slide(t.goal, np.array([-1.0, 0.0, 0.0]), c.slide_speed, c.search_force)

    def _enter_straighten(self, obs: Observation) -> Motion:
        """Upright again, turning about the peg's lower end, pressing down."""
        t, c = self.task, self.cfg
        t.hold_here(obs)
        g = t.goal
        bottom = t.believed_bottom_of(g)
        q_up = quat_mul(about(np.array([0.0, 1.0, 0.0]), -c.tilt_angle), np.asarray(g.quat_world))
        goal = Waypoint.of(t.pinch_for(bottom, q_up), q_up, 0.0)
        trajectory = t.planner.plan(g, goal, t.limits.scaled(c.turn_speed / t.limits.v_rot))
        t.goal = goal
        return Pressed(trajectory, c.search_force)
