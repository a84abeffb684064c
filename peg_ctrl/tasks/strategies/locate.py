"""``locate``: find the peg's end against the block's sides, then calibrate and insert.

A camera's estimate of the hole is off by a millimetre or so, and the peg sits some millimetres
off where the task believes it in the hand. The block's sides are datum surfaces of its drawing,
a known distance from the hole's axis (to a machining tolerance). Touching a side with the peg's
end tells where the end is against the hole; touching it again with the hand turned about the
vertical through the believed end by ``yaw`` tells where the end is against the *hand* (the true
end swings about the believed one by the offset between them). Two sides, two touches each: the
end is located in the hand and against the hole, whatever the grasp's offset and the camera's
error, from the pose alone (a touch's stop is read from the hand, not from a force threshold).

Knowing the end matters for the tilt calibration: ``probe``'s landings turn the hand about the
pads' normal, and an end off the believed one by ``e`` across the pads rises or falls by
``e sin(angle)`` as it turns, as a tilt would: 3 mm puts the fit more than half a degree off
(``tests/tasks/strategies/test_probe.py``), and half a degree wedges a peg in a 0.05 mm bore.

Phases:

- ``approach``: the end out beyond the -x side by ``side_gap`` more than the drawing puts it
  (seen from the camera's hole), ``side_depth`` below the face;
- ``sides``: a pose-tracked approach along +x at ``touch_speed`` until the hand stalls (its
  filtered speed along the approach below ``stall_fraction`` of the command's); a lateral push at
  ``wall_force`` until it is still; the end's position read. Back off, turn by ``yaw`` about the
  believed end, touch again; turn back, round the corner, the same along +y against the -y side.
  The task's belief of the grasp moves to the located end (:meth:`HeldInsertion.revise_axis`);
  the hole is ``side + radius + the drawing's distance`` on each axis;
- ``datum``, ``touch``, ``rock``, ``reference``: ``probe``'s tilt calibration on a datum of the
  top face, about the located end;
- ``transfer``, ``probe``: over the located hole, landings from a tight prior about it
  (``located_sigma``, ``located_radius``); the first lands in the chamfer or the bore;
- ``centre``, ``insert``, ``hold``: as ``probe``.

A side the approach does not meet within twice ``side_gap`` leaves the grasp as believed and the
hole where the camera saw it, searched with ``probe``'s prior.

``side_touches: 3``: between two pads the end can sit off the believed one only across them
(the pads centre it along their closing direction; the tilt in the grasp turns it about that
direction), so the offset is one length along a known direction. The side on which a turn moves
the end most along the approach is touched twice (yaw 0, then turned), the other once
(:func:`pair_offset`, :func:`locate_across`); ``quick_datum`` then moves to the datum at
``move_accel``, turning back on the way (docs/contact_real.md, "Three touches and a quiet hand").
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.rotations import rotate_inv
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies.base import HeldInsertion, TaskDisturbance
from peg_ctrl.tasks.strategies.probe import ProbeConfig, ProbeStrategy
from peg_ctrl.tasks.strategies.skills.models import SkillNoise
from peg_ctrl.tasks.strategies.skills.side_touch import (
    SideTouches,
    locate_across,
    locate_end,
    pair_offset,
)

__all__ = ["LocateConfig", "LocateStrategy", "SideTouches", "locate_across", "locate_end", "pair_offset"]

_Vec = np.ndarray


@dataclasses.dataclass(frozen=True)
class LocateConfig(ProbeConfig):
    """``probe``'s parameters, and the side touches' [m, m/s, rad, s]."""

    name: ClassVar[str] = "locate"
    # probe's, the side touches first: its approach to the datum is ``datum`` here.
    phases: ClassVar[tuple[str, ...]] = ("approach", "sides", "datum", *ProbeConfig.phases[1:])
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (*ProbeConfig.NON_NEGATIVE, "turn_speed")
    datum_offset: float = 0.032  # probe's, clear of the mouth at 3 mm in the hand, 1 mm of camera
    insert_speed: float = 0.03  # probe's descent, slower: 0.08 m/s taps the bore at ~50 N
    side_gap: float = 0.008  # the first approach starts this far beyond where the drawing puts the side
    camera_gap: float = 0.004  # ... the second side's, this far beyond it, the end's offset across known
    side_depth: float = 0.002  # the end this far below the face while it touches a side
    side_lift: float = 0.001  # clear of the face, this far above it, crossing the edge
    side_backoff: float = 0.003  # back off a side by this before turning or moving on
    yaw: float = 0.25  # the second touch of a side, the hand turned this far about the vertical
    touch_speed: float = 0.005  # the approach to a side: its impact is ~8 N at this, ~10 N at 0.01
    stall_fraction: float = 0.3  # it has met the side once the hand moves slower than this x touch_speed
    side_time: float = 8.0  # budget of the side touches and the moves between them
    turn_speed: float = 0.0  # [rad/s] the hand's turns about the end between touches; 0: the task's limit
    side_touches: int = 4  # 3: the end's offset in the pads' plane is one length, one side touched once
    quick_datum: bool = False  # the move from the sides to the datum at move_accel, turning back on it
    located_sigma: float = 0.0003  # the search's prior about the located hole
    located_radius: float = 0.0015  # ... and its extent

    def build(self, task: HeldInsertion) -> LocateStrategy:
        return LocateStrategy(task, self)

    def check(self, scene: SceneConfig, task: TaskDisturbance) -> None:
        super().check(scene, task)
        positive = (
            "side_gap",
            "camera_gap",
            "side_depth",
            "side_backoff",
            "yaw",
            "touch_speed",
            "located_sigma",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ConfigError(f"task.strategy.{name} must be > 0, got {getattr(self, name)!r}")
        if self.side_touches not in (3, 4):
            raise ConfigError(f"task.strategy.side_touches must be 3 or 4, got {self.side_touches!r}")
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
        t, c = self.task, self.cfg
        table = super().phase_table()
        table["datum"] = table["approach"]
        table["approach"] = PhaseSpec(
            self._enter_side, self._motion_done, "sides", Timeout(2.0, True), tick=t.feel_free
        )
        budget = Timeout(c.side_time, True)
        table["sides"] = PhaseSpec(self._enter_sides, self._sides_done, "datum", budget, tick=self._side)
        return {name: table[name] for name in LocateConfig.phases}

    def noise(self) -> SkillNoise:
        return SkillNoise.of(self.task, self.cfg.rock_angle, self.cfg.yaw)

    def hole_prior(self) -> tuple[_Vec, float, float]:
        """The located hole with the tight prior; the observed one if a side was not found."""
        if self.sides is None or self.sides.hole is None:
            return super().hole_prior()
        return self.sides.hole, self.cfg.located_sigma, self.cfg.located_radius

    def _enter_datum(self, obs: Observation) -> Motion:
        """probe's approach to the datum; after the sides with ``quick_datum``, briskly, at the
        orientation the touches started from."""
        if not self.cfg.quick_datum or self.sides is None:
            return super()._enter_datum(obs)
        return self.task.move(self.datum_waypoint(self.sides.quat), self.quick())

    def _enter_side(self, obs: Observation) -> Motion:
        """Up, out beyond the -x side, down below the face."""
        self.sides = SideTouches(self, obs)
        return self.sides.path_to_first(obs)

    def _enter_sides(self, obs: Observation) -> Motion:
        assert self.sides is not None
        self.sides.begin(obs)
        return self.sides

    def _side(self, obs: Observation) -> None:
        self.task.feel(obs)
        assert self.sides is not None
        self.sides.step(obs)

    def _sides_done(self, obs: Observation) -> str | None:
        assert self.sides is not None
        if not self.sides.done:
            return None
        if self.sides.delta is not None:
            t = self.task
            assert self.sides.hole is not None
            across = float(np.dot(self.sides.delta, t.knowledge_across))
            self.observe("sides", [*self.sides.hole, across], obs)
            shift = rotate_inv(self.sides.quat, np.array([*self.sides.delta, 0.0]))
            t.revise_axis(t.up_body, obs.gripper, grasp_shift=shift)
            self.end_known = True
        return "located"
