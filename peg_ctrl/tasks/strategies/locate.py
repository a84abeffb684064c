"""``locate``: find the peg's end against the block's sides, then land it in the hole.

A camera's estimate of the hole is off by a millimetre or so, and the peg sits some millimetres
off where the task believes it in the hand. The block's sides are datum surfaces of its drawing,
a known distance from the hole's axis (to a machining tolerance): touching two of them with the
peg's end locates that end against the hole, whatever the grasp's offset and the camera's error,
with the pose alone (a touch's stop is read from the hand, not from a force threshold).

Phases (``probe``'s, with ``sides`` before the transfer; :mod:`~peg_ctrl.tasks.strategies.probe`
has the others):

- ``approach``, ``touch``, ``rock``, ``reference``: the tilt in the hand from three landings on
  a datum of the top face, the peg turned upright, the face's height;
- ``sides``: the end lifted clear of the face, out beyond the -x side by ``side_gap`` more than
  the drawing puts it, down to ``side_depth`` below the face; a pose-tracked approach along +x at
  ``touch_speed`` until the hand stalls (its filtered speed along the approach below
  ``stall_fraction`` of the command's); a lateral push at ``wall_force`` until it is still; the
  end's position read. Back off, round the corner, the same along +y against the -y side. The
  hole, as the task's belief of the end sees it: ``side + radius + the drawing's distance`` on
  each axis;
- ``transfer``, ``probe``: over the located hole, landings from a tight prior about it
  (``located_sigma``, ``located_radius``); the first lands in the chamfer or the bore;
- ``centre``, ``insert``, ``hold``: as ``probe``.

A side the approach does not meet within ``side_gap`` beyond where the drawing puts it leaves the
hole where the camera saw it, searched with ``probe``'s prior.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import Motion, PhaseSpec, Timeout, TrajectorySequence
from peg_ctrl.tasks.strategies.base import HeldInsertion, TaskDisturbance
from peg_ctrl.tasks.strategies.probe import _WALL_SETTLE, ProbeConfig, ProbeStrategy

__all__ = ["LocateConfig", "LocateStrategy", "SideTouches"]

_Vec = np.ndarray
_X, _Y = np.array([1.0, 0.0]), np.array([0.0, 1.0])


@dataclasses.dataclass(frozen=True)
class LocateConfig(ProbeConfig):
    """``probe``'s parameters, and the side touches' [m, m/s, s]."""

    name: ClassVar[str] = "locate"
    phases: ClassVar[tuple[str, ...]] = (
        "approach",
        "touch",
        "rock",
        "reference",
        "sides",
        "transfer",
        "probe",
        "centre",
        "insert",
        "hold",
    )
    side_gap: float = 0.008  # a side approach starts this far beyond where the drawing puts the side
    side_depth: float = 0.002  # the end this far below the face while it touches a side
    side_lift: float = 0.001  # clear of the face, this far above it, crossing the edge
    side_backoff: float = 0.001  # back off a side by this before moving on
    touch_speed: float = 0.015  # the approach to a side
    stall_fraction: float = 0.3  # it has met the side once the hand moves slower than this x touch_speed
    side_time: float = 4.0  # budget of the two touches and the moves between them
    located_sigma: float = 0.0003  # the search's prior about the located hole
    located_radius: float = 0.0015  # ... and its extent

    def build(self, task: HeldInsertion) -> LocateStrategy:
        return LocateStrategy(task, self)

    def check(self, scene: SceneConfig, task: TaskDisturbance) -> None:
        super().check(scene, task)
        for name in ("side_gap", "side_depth", "touch_speed", "located_sigma", "located_radius"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"task.strategy.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 < self.stall_fraction < 1:
            raise ConfigError(f"task.strategy.stall_fraction must be in (0, 1), got {self.stall_fraction!r}")
        if self.side_depth >= 0.5 * scene.assets.block_size[2]:
            raise ConfigError(
                f"task.strategy.side_depth must be below half the block's height "
                f"({0.5 * scene.assets.block_size[2]:g} m), got {self.side_depth!r}"
            )


class LocateStrategy(ProbeStrategy):
    cfg: LocateConfig

    def __init__(self, task: HeldInsertion, config: LocateConfig) -> None:
        super().__init__(task, config)
        self.sides: SideTouches | None = None

    def phase_table(self) -> dict[str, PhaseSpec]:
        table = super().phase_table()
        reference = table["reference"]
        table["reference"] = dataclasses.replace(reference, next="sides")
        table["sides"] = PhaseSpec(
            self._enter_sides, self._sides_done, "transfer", Timeout(self.cfg.side_time, True), tick=self._side
        )
        return {name: table[name] for name in self.cfg.phases}

    def hole_prior(self) -> tuple[_Vec, float, float]:
        """The located hole with the tight prior; the observed one if a side was not found."""
        if self.sides is None or self.sides.hole is None:
            return super().hole_prior()
        return self.sides.hole, self.cfg.located_sigma, self.cfg.located_radius

    def _enter_sides(self, obs: Observation) -> Motion:
        self.sides = SideTouches(self, obs)
        return self.sides

    def _side(self, obs: Observation) -> None:
        self.task.feel(obs)
        assert self.sides is not None
        self.sides.step(obs)

    def _sides_done(self, obs: Observation) -> str | None:
        assert self.sides is not None
        return "located" if self.sides.done else None


class SideTouches:
    """The ``sides`` phase, as a motion the strategy plays and steps (module docstring).

    States per side: ``move`` (a planned path to the approach's start), ``approach`` (the
    guarded, pose-tracked approach), ``press`` (the lateral push until the hand is still), then
    the next side, or ``leave`` (back off, up clear of the face).

    Attributes:
        touched: the believed lower end's (x, y) [m] at each side found; ``hole``: the hole's
            axis, as the task's belief of the end sees it (None unless both sides were found);
            ``done``: the end is back above the face.
    """

    duration = 0.0

    def __init__(self, strategy: LocateStrategy, obs: Observation) -> None:
        self.strategy, self.task, self.cfg = strategy, strategy.task, strategy.cfg
        t, c = self.task, self.cfg
        self.quat = np.asarray(t.goal.quat_world, dtype=float)
        self.touched: list[_Vec] = []
        self.hole: _Vec | None = None
        self.done = False
        tip = t.believed_bottom(obs)
        self._datum = tip[:2].copy()
        self._z_low = t.z_face - c.side_depth
        self._z_high = t.z_face + c.side_lift
        # Where the drawing puts the -x and -y sides, seen from the camera's hole [m].
        sides = np.asarray(t.drawing_sides, dtype=float)
        self._side_at = (t.observed_hole[0] - sides[1], t.observed_hole[1] - sides[3])
        self._distance = (float(sides[1]), float(sides[3]))
        self._t0 = obs.t
        self._state = "move"
        self._still: list[_Vec] = []
        self._at_speed = False
        self._trajectory = self._path(
            [tip, tip + np.array([0.0, 0.0, c.side_lift]), *self._out_to(0, tip, from_datum=True)]
        )
        self._target = self._trajectory.sample(0.0)

    def sample(self, t: float) -> GripperTarget:
        return self._target  # set by step(), which keeps the episode's clock

    # -- paths ---------------------------------------------------------------------------------------
    def _start_of(self, n: int) -> _Vec:
        """Where the approach to side ``n`` (0: -x, 1: -y) starts: ``side_gap`` beyond the side
        the drawing gives, one radius out, at the datum's other coordinate, below the face."""
        c, t = self.cfg, self.task
        start = np.array([*self._datum, self._z_low])
        start[n] = self._side_at[n] - t.radius - c.side_gap
        return start

    def _out_to(self, n: int, tip: _Vec, *, from_datum: bool) -> list[_Vec]:
        """The waypoints from ``tip`` to side ``n``'s start: over the face and down beyond the
        edge from the datum; round the corner, below the face, from the first side."""
        start = self._start_of(n)
        if from_datum:
            return [np.array([*start[:2], self._z_high]), start]
        corner = np.array([tip[0], start[1], self._z_low])
        return [corner, start]

    def _path(self, tips: list[_Vec]) -> Motion:
        st = self.strategy
        parts = [
            self.task.planner.plan(st.tip_waypoint(a, self.quat), st.tip_waypoint(b, self.quat), st.quick())
            for a, b in zip(tips, tips[1:], strict=False)
        ]
        self.task.goal = st.tip_waypoint(tips[-1], self.quat)
        return TrajectorySequence(parts)

    # -- the states ------------------------------------------------------------------------------------
    def step(self, obs: Observation) -> None:
        if self.done:
            return
        t = obs.t
        if self._state in ("move", "approach", "leave"):
            assert self._trajectory is not None
            self._target = self._trajectory.sample(t - self._t0)
            over = t - self._t0 >= self._trajectory.duration
            if self._state == "approach" and self._stalled(obs):
                self._press(obs)
            elif over and self._state == "move":
                self._approach(obs)
            elif over and self._state == "approach":  # no side within the gap: the camera's hole
                self._leave(obs)
            elif over:
                self.done = True
        else:
            self._read(obs)

    def _direction(self) -> _Vec:
        return _X if len(self.touched) == 0 else _Y

    def _approach(self, obs: Observation) -> None:
        c, st = self.cfg, self.strategy
        tip = self.task.believed_bottom(obs)
        goal = tip.copy()
        goal[:2] += self._direction() * 2.0 * c.side_gap
        limits = dataclasses.replace(self.task.limits, v_lin=c.touch_speed, a_lin=c.move_accel)
        self._trajectory = self.task.planner.plan(
            st.tip_waypoint(tip, self.quat), st.tip_waypoint(goal, self.quat), limits
        )
        self._state, self._t0, self._at_speed = "approach", obs.t, False

    def _stalled(self, obs: Observation) -> bool:
        """Slower than ``stall_fraction`` of the approach's speed, once it has gone faster than
        twice that (the hand's filtered speed along the approach)."""
        c = self.cfg
        v = float(np.dot(self.task.hand_velocity[:2], self._direction()))
        if not self._at_speed:
            self._at_speed = v > 2.0 * c.stall_fraction * c.touch_speed
            return False
        return v < c.stall_fraction * c.touch_speed

    def _press(self, obs: Observation) -> None:
        """Hold here, pushing on into the side at the wall force (the lateral axis free)."""
        d = self._direction()
        axes = (bool(d[0]), bool(d[1]), False, False, False, False)
        force = np.array([*(self.strategy.felt(self.cfg.wall_force) * d), 0.0])
        self._target = GripperTarget.trusted(
            obs.gripper.p_world, self.quat, np.zeros(3), np.zeros(3), 0.0, force, wrench_axes=axes
        )
        self._state, self._t0, self._still = "press", obs.t, []

    def _read(self, obs: Observation) -> None:
        """Once the hand is still: where the end is."""
        c, task = self.cfg, self.task
        v = float(np.hypot(*task.hand_velocity[:2]))
        limit = max(0.5 * c.stop_speed, task.contact.k_on * task.speed_noise)
        if v >= limit or obs.t - self._t0 < _WALL_SETTLE:
            self._still = []
            return
        self._still.append(task.believed_bottom(obs)[:2])
        if len(self._still) * task.control_dt < 2.0 * c.stop_time:
            return
        self.touched.append(np.mean(self._still, axis=0))
        if len(self.touched) == 2:
            x, y = self.touched[0][0], self.touched[1][1]
            r = task.radius
            self.hole = np.array([x + r + self._distance[0], y + r + self._distance[1]])
            self._leave(obs)
            return
        tip = task.believed_bottom(obs)
        back = tip - np.array([*(_X * c.side_backoff), 0.0])
        self._trajectory = self._path([tip, back, *self._out_to(1, back, from_datum=False)])
        self._state, self._t0 = "move", obs.t

    def _leave(self, obs: Observation) -> None:
        """Back off the side, up clear of the face."""
        c = self.cfg
        tip = self.task.believed_bottom(obs)
        back = tip - np.array([*(self._direction() * c.side_backoff), 0.0])
        up = np.array([*back[:2], self._z_high])
        self._trajectory = self._path([tip, back, up])
        self._state, self._t0 = "leave", obs.t

