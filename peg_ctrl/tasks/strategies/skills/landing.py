"""A landing: a force-controlled descent that stops on whatever it meets, read from the pose;
and :class:`ProbeHost`, what a skill asks of the strategy that plays it."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import MotionLimits
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.strategies.base import HeldInsertion
from peg_ctrl.tasks.strategies.motions import down
from peg_ctrl.tasks.strategies.skills.common import LAND_AXES

if TYPE_CHECKING:
    from peg_ctrl.tasks.strategies.probe import ProbeConfig

__all__ = ["Landing", "ProbeHost"]

_Vec = np.ndarray


class Landing:
    """A force-controlled descent at ``force`` [N] (``axes``: what else is free) from where the
    hand is; it has landed once the hand descends slower than ``stop_speed`` for ``stop_time``
    (or the noise of the speed sensing's k sigma, where that is more), after it has moved or
    after 50 ms. ``z`` and ``xy`` are then the believed lower end's mean height and position
    over that window [m]."""

    def __init__(
        self, task: HeldInsertion, cfg: ProbeConfig, obs: Observation, force: float, axes: tuple[bool, ...]
    ) -> None:
        self.task, self.cfg = task, cfg
        s = obs.gripper
        self.target = GripperTarget.trusted(
            s.p_world, s.quat_world, np.zeros(3), np.zeros(3), 0.0, down(force), wrench_axes=axes
        )
        self._t0 = obs.t
        self._moved = False
        self._still: list[tuple[float, _Vec]] = []
        self.landed = False
        self.t_landed = 0.0
        self.z = 0.0
        self.xy = np.zeros(2)
        self.p_world = np.zeros(3)  # the hand's pose when it landed (mean position)
        self.quat_world = np.array([1.0, 0.0, 0.0, 0.0])

    def update(self, obs: Observation) -> bool:
        """Whether it has landed (true from then on)."""
        if self.landed:
            return True
        task, c = self.task, self.cfg
        limit = max(c.stop_speed, task.contact.k_on * task.speed_noise)
        speed = abs(float(task.hand_velocity[2]))
        self._moved = self._moved or speed > 2.0 * limit
        if speed >= limit or not (self._moved or obs.t - self._t0 > 0.05):
            self._still = []
            return False
        self._still.append((obs.t, task.believed_bottom(obs)))
        if self._still[-1][0] - self._still[0][0] < c.stop_time:
            return False
        tips = np.array([tip for _, tip in self._still])
        self.z, self.xy = float(tips[:, 2].mean()), tips[:, :2].mean(axis=0)
        self.p_world = obs.gripper.p_world + (tips.mean(axis=0) - tips[-1])
        self.quat_world = obs.gripper.quat_world.copy()
        self.landed = True
        self.t_landed = obs.t
        return True


class ProbeHost(Protocol):
    """The strategy a skill is played by (``probe``, ``locate``): its task and config, and the
    motions and readings the skills share."""

    @property
    def task(self) -> HeldInsertion: ...

    @property
    def cfg(self) -> ProbeConfig: ...  # read-only: a strategy may narrow it (locate's LocateConfig)

    @property
    def end_known(self) -> bool: ...

    @property
    def quat_upright(self) -> np.ndarray: ...

    def tip_offset(self) -> np.ndarray: ...

    def felt(self, force: float) -> float: ...

    def land(self, obs: Observation, axes: tuple[bool, ...] = LAND_AXES) -> Landing: ...

    def quick(self, v_lin: float | None = None) -> MotionLimits: ...

    def landing_limits(self) -> MotionLimits: ...
