"""The centring: the end, in the bore's mouth, pushed against its walls; the wall push and the
pressed circle it is made of."""

from __future__ import annotations

import math

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.strategies.base import HeldInsertion
from peg_ctrl.tasks.strategies.motions import down
from peg_ctrl.tasks.strategies.skills.landing import ProbeHost

_Vec = np.ndarray


__all__ = ["Centring", "WallPush", "PressedCircle"]

_WALL_SETTLE = 0.04  # a push for a wall is watched for a stop only after this long [s]


class Centring:
    """The lower end, in the bore's mouth, to the bore's axis: pushed laterally (``wall_force``)
    against the wall along +x, -x, +y, -y in turn, the height held; each push has found its wall
    once the hand stops moving (the pose, not the force, tells). The centre is midway between the
    walls; a push that finds no wall within ``centre_time`` leaves the centre where the end was.

    Attributes:
        walls: the lower end's position (x, y) [m] at each wall found; ``centre``: the bore's axis
            at the mouth, None until all four are found.
    """

    duration = 0.0
    _DIRECTIONS = (np.array([1.0, 0.0]), np.array([-1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.0, -1.0]))

    def __init__(self, strategy: ProbeHost, obs: Observation) -> None:
        self.strategy, self.task, self.cfg = strategy, strategy.task, strategy.cfg
        self.walls: list[_Vec] = []
        self.centre: _Vec | None = None
        self._start = obs.gripper.p_world.copy()
        self._p: _Vec = self._start.copy()  # the pushes' held position
        self._reanchored = False  # the pose held for a tick before a reversed push
        self._push(obs)

    def sample(self, t: float) -> GripperTarget:
        return self._target

    def _push(self, obs: Observation) -> None:
        """Along the next direction, the other lateral axis held (at the middle of the x walls,
        once found: a chord through the axis). With ``centre_reanchor``, a push that reverses
        the last one is preceded by one tick of the pose held where the hand is: the axis stays
        force-controlled across a reversal, so the contact loop would go on from its command,
        pressed into the wall just found, and the hand would stand still there (a wall read on
        the wrong side) while the command backs out."""
        n = len(self.walls)
        p = obs.gripper.p_world.copy()
        p[2] = self._start[2]
        if n == 2:  # the x walls found: over to the middle between them
            p[0] += 0.5 * (self.walls[0][0] + self.walls[1][0]) - self.task.believed_bottom(obs)[0]
        self._p = p if n != 3 else self._p
        anchor = self._p
        if n % 2 and self.cfg.centre_reanchor:
            anchor = self._p.copy()
            anchor[n // 2] = obs.gripper.p_world[n // 2]  # along the push: where the hand is
            if not self._reanchored:
                quat = self.strategy.quat_upright
                self._target = GripperTarget.trusted(anchor, quat, np.zeros(3), np.zeros(3), 0.0)
                self._reanchored = True
                return
        self._reanchored = False
        self._wall = WallPush(self.strategy, obs, anchor, self.strategy.quat_upright, self._DIRECTIONS[n])
        self._target = self._wall.target

    def step(self, obs: Observation) -> None:
        if self.centre is not None:
            return
        if self._reanchored:  # the tick with the pose held is over: push
            self._push(obs)
            return
        wall = self._wall.update(obs)
        if wall is None:
            return
        self.walls.append(wall)
        if len(self.walls) < len(self._DIRECTIONS):
            self._push(obs)
            return
        w = self.walls
        self.centre = np.array([0.5 * (w[0][0] + w[1][0]), 0.5 * (w[2][1] + w[3][1])])


class WallPush:
    """The hand at ``p_world`` and ``quat``, pushing along the horizontal unit ``direction``
    (x or y) at the wall force (that lateral axis free, the rest held): a wall is found once the
    hand has been still (its filtered speed within the stop speed's half, or k sigma of the speed
    sensing's noise) for twice the landings' stop time, after ``_WALL_SETTLE``. :meth:`update`
    then gives the believed lower end's mean (x, y) [m] over that stillness."""

    def __init__(
        self, strategy: ProbeHost, obs: Observation, p_world: _Vec, quat: _Vec, direction: _Vec
    ) -> None:
        self.task, self.cfg = strategy.task, strategy.cfg
        axes = (bool(direction[0]), bool(direction[1]), False, False, False, False)
        force = np.array([*(strategy.felt(self.cfg.wall_force) * direction), 0.0])
        self.target = GripperTarget.trusted(
            p_world, quat, np.zeros(3), np.zeros(3), 0.0, force, wrench_axes=axes
        )
        self._t0 = obs.t
        self._still: list[_Vec] = []

    def update(self, obs: Observation) -> _Vec | None:
        c, task = self.cfg, self.task
        v = float(np.hypot(*task.hand_velocity[:2]))
        limit = max(0.5 * c.stop_speed, task.contact.k_on * task.speed_noise)
        if v >= limit or obs.t - self._t0 < _WALL_SETTLE:
            self._still = []
            return None
        self._still.append(task.believed_bottom(obs)[:2])
        if len(self._still) * task.control_dt < 2.0 * c.stop_time:
            return None
        return np.mean(self._still, axis=0)


class PressedCircle:
    """A circle of ``radius`` [m] about the lower end's position ``tip`` in the horizontal plane,
    at ``speed`` [m/s], once round, pressing down with ``force`` [N] (the height free)."""

    def __init__(
        self, task: HeldInsertion, tip: _Vec, radius: float, quat: _Vec, speed: float, force: float
    ) -> None:
        self.task, self.tip, self.radius, self.quat = task, np.asarray(tip, dtype=float), radius, quat
        self.rate = speed / radius  # [rad/s]
        self.duration = 2.0 * math.pi / self.rate + 0.5 * radius / speed
        self._force = down(force)

    def sample(self, t: float) -> GripperTarget:
        # out to the circle along x first (a quarter of the duration's lead-in), then round it
        lead = 0.5 * self.radius / (self.rate * self.radius)
        if t < lead:
            r, a, w = self.radius * t / lead, 0.0, 0.0
        else:
            r, a, w = self.radius, self.rate * (t - lead), self.rate
        p_tip = self.tip + np.array([r * math.cos(a), r * math.sin(a), 0.0])
        v = np.array([-r * w * math.sin(a), r * w * math.cos(a), 0.0])
        p = self.task.pinch_for(p_tip, self.quat)
        return GripperTarget.trusted(p, self.quat, v, np.zeros(3), 0.0, self._force)
