"""The hole search of the held-insertion ``align`` strategy: hops over a hexagonal lattice.

A peg whose end lies flat (the ``align`` strategy has just made it so on the block's top face)
drops onto the chamfer only when its axis comes within ``chamfer + clearance`` of the hole's:
the chamfer is the capture range. Sliding across the face to find it drags the peg's end
through friction — at μ = 0.9 the drag turns the peg in the pads by tenths of a degree a
second, more than the few tenths of a degree a 0.05 mm clearance tolerates at that friction.
So the search *hops*: it lifts the peg a fraction of a millimetre, moves it to the next point of
a hexagonal lattice whose pitch keeps every point of the plane within the capture range of one
lattice point, lowers it to just above the face, and presses lightly. The height at which the
press meets resistance tells face from chamfer:

- on the face (no drop below the face's height, measured during the alignment): the next point;
- on the chamfer (a drop ``d``): the contact is a single point on the chamfer's far side, so the
  moment about the peg's tip points away from the hole, and a 45° chamfer puts the axes
  ``chamfer + clearance - d`` apart. The search moves the peg there, then presses with the
  lateral axes force-controlled at zero so the chamfer guides it the rest of the way.

Lattice points are visited ring by ring outwards from the observed hole, so a small error is
found first. The task's phase guard (the lower end sensed in the bore) ends the search; a search
that has pressed every lattice point without finding the bore is ``exhausted``, and the task
ends the episode as missed.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import MotionLimits, Planner, Waypoint
from peg_ctrl.tasks.phases import TrajectorySequence

__all__ = ["HexLattice", "HopSearch", "HopSettings", "PRESS_AXES", "GUIDE_AXES"]

_Vec = NDArray[np.float64]
PRESS_AXES = (False, False, True, False, False, False)  # force along z only
_CONFIRM = 0.01  # a contact must last this long [s]
GUIDE_AXES = (True, True, True, False, False, False)  # and free laterally


@dataclasses.dataclass(frozen=True)
class HexLattice:
    """Points of a hexagonal lattice of ``pitch`` [m], ring by ring out to ``radius`` [m].

    Every point of the plane lies within ``pitch / sqrt(3)`` of a lattice point, so a pitch of
    ``sqrt(3)`` times the capture range leaves no gap.
    """

    pitch: float
    radius: float

    def points(self) -> list[_Vec]:
        out = [np.zeros(2)]
        ring = 1
        while ring * self.pitch * math.sqrt(3.0) / 2.0 <= self.radius + 1e-12:
            corners = [
                ring * self.pitch * np.array([math.cos(a), math.sin(a)]) for a in np.arange(6) * math.pi / 3.0
            ]
            for i in range(6):
                c0, c1 = corners[i], corners[(i + 1) % 6]
                out.extend(c0 + (c1 - c0) * j / ring for j in range(ring))
            ring += 1
        return out


@dataclasses.dataclass(frozen=True)
class HopSettings:
    """The search's numbers: forces [N], distances [m], speeds [m/s], times [s]."""

    press_force: float  # light press that tells face from chamfer
    hover: float  # the peg's end stops this far above the face before pressing
    lift: float  # and rises this far to move to the next point
    hop_speed: float  # lateral hop speed
    lower_speed: float  # the last descent to the hover height
    drop_min: float  # a press this far below the face has met the chamfer
    capture: float  # chamfer + clearance: the axes are this far apart when the drop is 0
    settle_time: float  # press this long on the chamfer before reading the moment
    guide_time: float  # then let the chamfer guide the peg this long


class HopSearch:
    """The hop search as a motion the task plays and steps (see the module docstring).

    ``tip_to_pinch(tip, q)`` converts a position of the peg's lower end to the pinch point (the
    task's belief of the grasp); ``z_face`` is the face's height as sensed by that belief.
    """

    def __init__(
        self,
        *,
        centre: _Vec,
        z_face: float,
        quat: _Vec,
        lattice: HexLattice,
        settings: HopSettings,
        planner: Planner,
        limits: MotionLimits,
        tip_to_pinch: object,
        t0: float,
    ) -> None:
        self.centre = np.asarray(centre, dtype=float)
        self.z_face = z_face
        self.quat = np.asarray(quat, dtype=float)
        self.points = lattice.points()
        self.s = settings
        self.planner = planner
        self._fast = dataclasses.replace(limits, v_lin=settings.hop_speed, a_lin=3.0, j_lin=100.0)
        self._slow = dataclasses.replace(limits, v_lin=settings.lower_speed, a_lin=0.5, j_lin=20.0)
        self._pinch = tip_to_pinch
        self.index = 0  # lattice point being pressed
        self.hops = 0
        self.chamfer_hits = 0
        self.exhausted = False
        self._xy = self.centre + self.points[0]
        self._state = "press"
        self._t0 = t0
        self._contact_t: float | None = None
        self._confirmed = False
        self._trajectory: TrajectorySequence | None = None
        self._target = self._press(PRESS_AXES)
        self.duration = 0.0

    def sample(self, t: float) -> GripperTarget:
        return self._target

    def _tip_target(self, xy: _Vec, z: float) -> _Vec:
        return self._pinch(np.array([xy[0], xy[1], z]), self.quat)  # type: ignore[operator]

    def _press(self, axes: tuple[bool, ...]) -> GripperTarget:
        p = self._tip_target(self._xy, self.z_face + self.s.hover)
        return GripperTarget.trusted(
            p, self.quat, np.zeros(3), np.zeros(3), 0.0, (0.0, 0.0, -self.s.press_force), wrench_axes=axes
        )

    def _hop_to(self, t: float, tip: _Vec, xy: _Vec) -> None:
        """Lift, move over ``xy``, lower to the hover height."""
        q = self.quat
        up = self.z_face + self.s.lift
        a0 = Waypoint.of(self._tip_target(tip[:2], float(tip[2])), q, 0.0)
        a1 = Waypoint.of(self._tip_target(tip[:2], up), q, 0.0)
        a2 = Waypoint.of(self._tip_target(xy, up), q, 0.0)
        a3 = Waypoint.of(self._tip_target(xy, self.z_face + self.s.hover), q, 0.0)
        self._trajectory = TrajectorySequence(
            [
                self.planner.plan(a0, a1, self._fast),
                self.planner.plan(a1, a2, self._fast),
                self.planner.plan(a2, a3, self._slow),
            ]
        )
        self._xy = np.asarray(xy, dtype=float)
        self._t0 = t
        self.hops += 1

    def step(self, t: float, tip: _Vec, force: _Vec, moment_tip: _Vec, touching: bool) -> None:
        """Advance with the believed lower end ``tip`` [m], the estimated contact force on the
        hand [N] and its moment about the lower end [N m] (world), and whether the estimate
        says the hand is pushed (``touching``: the task's contact detection)."""
        s = self.s
        elapsed = t - self._t0
        if self._state in ("move", "to_chamfer"):
            assert self._trajectory is not None
            self._target = self._trajectory.sample(elapsed)
            if elapsed >= self._trajectory.duration:
                self._state = "press" if self._state == "move" else "guide"
                self._t0, self._contact_t, self._confirmed = t, None, False
                self._target = self._press(PRESS_AXES if self._state == "press" else GUIDE_AXES)
            return
        if self._state == "guide":
            if elapsed > s.guide_time:  # not in yet: press where it is and look again
                self._state, self._t0, self._contact_t, self._confirmed = "press", t, None, False
                self._xy = np.asarray(tip[:2], dtype=float)
                self._target = self._press(PRESS_AXES)
            return
        # press: contact is a detected push, with the peg's end down at the face or below
        # (the sensor also reads the hand's own deceleration at the end of a hop)
        drop = self.z_face - float(tip[2])
        pressed = touching and drop > -0.5 * s.hover
        if self._contact_t is None or not self._confirmed:
            if not pressed:
                self._contact_t = None
                return
            if self._contact_t is None:
                self._contact_t = t
            if t - self._contact_t < _CONFIRM:
                return
            self._confirmed = True
            if drop < s.drop_min:  # on the face: the next lattice point
                self._next_point(t, tip)
            return
        if t - self._contact_t < _CONFIRM + s.settle_time:
            return
        # On the chamfer: the contact is on its far side, away from the hole.
        drop = self.z_face - float(tip[2])
        fz = max(float(force[2]), 1e-6)
        cop = np.array([-moment_tip[1] / fz, moment_tip[0] / fz])  # centre of pressure from the tip
        norm = float(np.linalg.norm(cop))
        direction = -cop / norm if norm > 1e-9 else np.zeros(2)
        gap = max(0.0, s.capture - drop)
        self.chamfer_hits += 1
        self._hop_to(t, tip, tip[:2] + direction * gap)
        self._state = "to_chamfer"

    def _next_point(self, t: float, tip: _Vec) -> None:
        if self.index + 1 >= len(self.points):  # every point pressed: the task ends the search
            self.exhausted = True
            return
        self.index += 1
        self._hop_to(t, tip, self.centre + self.points[self.index])
        self._state = "move"
