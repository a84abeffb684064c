"""The rock: the peg's tilt in the hand from the heights at which it lands on the face."""

from __future__ import annotations

import math

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.sim.rotations import quat_mul, rotate, rotate_inv
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import TrajectorySequence
from peg_ctrl.tasks.strategies.motions import about
from peg_ctrl.tasks.strategies.skills.common import (
    PRESS_AXES,
)
from peg_ctrl.tasks.strategies.skills.landing import Landing, ProbeHost

_Vec = np.ndarray


__all__ = ["RockCalibration", "PAD_NORMAL", "upright"]


class RockCalibration:
    """The peg's tilt in the hand from the heights at which it lands (module docstring).

    The pads let the peg turn only about their normal (the gripper's x): its axis is the
    nominal one turned by ``theta`` about it. A peg tilted in total by ``a`` lands with its end's
    centre ``R sin a`` above the face, and the hand's pose says where that centre is for a given
    ``theta``; three landings (the touch, and the hand turned by +/- ``rock_angle`` about the
    pads' normal through the believed lower end) fix ``theta`` and the face's height. Each
    landing starts from just above the highest height the touch allows for it.

    With ``free_end`` (a unit direction, world x, y, at the orientation ``frame``) the end's
    offset along it from the believed one is fitted too (up to ``end_range`` [m] either way): an
    end off by ``e`` rises or falls by ``e sin(angle)`` as the hand turns, which a fit that
    takes the end as known reads as a tilt (``α/R`` of it: 5 mrad a millimetre here). The rim
    drops on the side the tilt leans to and the offset lifts one side and lowers the other, so
    the landings tell the two apart; ``angles`` (default ``+/- rock_angle``) gives the turned
    landings. With the strategy's ``end_known`` (``plan``) the offset holds the tilt's swing of the
    end across the pads as well; the swing's rise, ``grip_length (1 - cos tilt)`` (37 µm at 2°),
    is not modelled and goes into the fitted face's height.

    Attributes:
        tilt: the fitted ``theta`` [rad], None until the last landing; ``axis_body``: the
            peg's axis in the gripper frame; ``z_face``: the face's height the fit gives [m];
            ``end``: the end's fitted offset along ``free_end`` [m] (0 without it); ``q0``: the
            hand's orientation at the touch.
    """

    duration = 0.0
    #: The believed lower end is the true one (found by touch): the fit turns the axis about it.
    end_known = False

    def __init__(
        self,
        strategy: ProbeHost,
        touch: Landing,
        obs: Observation,
        *,
        angles: list[float] | None = None,
        free_end: _Vec | None = None,
        frame: _Vec | None = None,
        end_range: float = 0.0,
    ) -> None:
        self.strategy, self.task, self.cfg = strategy, strategy.task, strategy.cfg
        self.end_known = strategy.end_known
        self.q0 = touch.quat_world.copy()
        self.landings = [touch]
        self.tilt: float | None = None
        self.end = 0.0
        self.axis_body = self.task.up_body
        self.z_face = self.task.block_top
        self._angles = list(angles) if angles else [self.cfg.rock_angle, -self.cfg.rock_angle]
        self._thetas = np.linspace(-self.cfg.max_tilt, self.cfg.max_tilt, 321)
        # The end's offsets the fit weighs (gripper frame, one per grid value), none without free_end.
        self._ends = np.linspace(-end_range, end_range, 61) if free_end is not None else np.zeros(1)
        if free_end is not None:
            q = np.asarray(frame if frame is not None else self.q0, dtype=float)
            self._end_body = rotate_inv(q, np.array([free_end[0], free_end[1], 0.0]))
        else:
            self._end_body = np.zeros(3)
        self._next(obs)

    def sample(self, t: float) -> GripperTarget:
        return self._target

    def _model(self, q: _Vec, theta: float) -> tuple[_Vec, float]:
        """For a tilt ``theta`` in the hand at orientation ``q``: the true lower end's offset
        from the believed one (world) [m], and how far the end's lowest point is below its
        centre [m]."""
        t = self.task
        up = _turned(t.up_body, PAD_NORMAL, theta)
        # An end located by touch is where the task believes it, whatever the tilt.
        offset = np.zeros(3) if self.end_known else rotate(q, t.grip_length * (t.up_body - up))
        a = rotate(q, up)
        return offset, t.radius * math.sqrt(max(0.0, 1.0 - a[2] * a[2]))

    def _faces(self, landing: Landing) -> _Vec:
        """The face's height each (tilt, end offset) of the grid implies for ``landing`` [m],
        flattened tilt-major."""
        q = landing.quat_world
        tip = landing.p_world + rotate(q, self.task.grasp_body - self.task.grip_length * self.task.up_body)
        out = np.empty(len(self._thetas))
        for k, theta in enumerate(self._thetas):
            offset, rim = self._model(q, float(theta))
            out[k] = tip[2] + offset[2] - rim
        lift = rotate(q, self._end_body)[2] * self._ends  # the end's offset, turned with the hand
        return (out[:, None] + lift[None, :]).ravel()

    def _next(self, obs: Observation) -> None:
        """Lift, turn to the next angle about the believed lower end, down to just above the
        highest contact the landings so far allow, then land."""
        t, c, st = self.task, self.cfg, self.strategy
        angle = self._angles[len(self.landings) - 1]
        q = quat_mul(about(rotate(self.q0, PAD_NORMAL), angle), self.q0)
        # The tilts the landings so far allow, given the face's height on the drawing (to within
        # how far a landing presses into it) and that it is one face: the next landing starts
        # just above the highest of them.
        faces = np.array([self._faces(landing) for landing in self.landings])
        allowed = np.all(np.abs(faces - (t.block_top - 0.5 * _FACE_TOLERANCE)) <= _FACE_TOLERANCE, axis=0)
        allowed &= np.ptp(faces, axis=0) <= 0.5 * _FACE_TOLERANCE
        pick = allowed if allowed.any() else np.ones(faces.shape[1], dtype=bool)
        thetas = np.repeat(self._thetas, len(self._ends))
        ends = np.tile(self._ends, len(self._thetas))
        lift = rotate(q, self._end_body)[2]
        rims = {float(theta): self._model(q, float(theta)) for theta in np.unique(thetas[pick])}
        highest = max(
            z_face + rims[float(theta)][1] - rims[float(theta)][0][2] - lift * end
            for theta, end, z_face in zip(thetas[pick], ends[pick], faces[0, pick], strict=True)
        )
        # Up clear of the face first (by as much as the turn can lower the end's rim), turn
        # about the pinch point (the end moves a few millimetres over the datum's face, which has
        # room for it), down to just above the contact.
        s = obs.gripper
        clear = t.radius * math.sin(abs(angle) + c.max_tilt) + c.hover
        lifted = s.p_world + np.array([0.0, 0.0, clear])
        turned = lifted.copy()
        turned[2] = max(highest, t.believed_bottom(obs)[2]) + clear - rotate(q, st.tip_offset())[2]
        near, above = turned.copy(), turned.copy()
        near[2] = highest + c.hop_lift - rotate(q, st.tip_offset())[2]
        above[2] = highest + c.hover - rotate(q, st.tip_offset())[2]
        w = [Waypoint.of(s.p_world, s.quat_world, 0.0), Waypoint.of(lifted, s.quat_world, 0.0)]
        w += [Waypoint.of(turned, q, 0.0), Waypoint.of(near, q, 0.0), Waypoint.of(above, q, 0.0)]
        limits = [st.quick(), st.quick(), st.quick(), st.landing_limits()]
        self._trajectory = TrajectorySequence(
            [t.planner.plan(a, b, lim) for a, b, lim in zip(w, w[1:], limits, strict=False)]
        )
        self._target = self._trajectory.sample(0.0)
        self._state, self._t0 = "move", obs.t

    def step(self, obs: Observation) -> None:
        if self.tilt is not None:
            return
        if self._state == "move":
            self._target = self._trajectory.sample(obs.t - self._t0)
            if obs.t - self._t0 >= self._trajectory.duration:
                self._landing = self.strategy.land(obs, PRESS_AXES)
                self._target, self._state = self._landing.target, "land"
            return
        if not self._landing.update(obs):
            return
        self.landings.append(self._landing)
        if len(self.landings) <= len(self._angles):
            self._next(obs)
            return
        self._fit()

    def _fit(self) -> None:
        """Least squares over the grid (the face's height the same for every landing), the tilt
        refined by a parabola through the best three at the best end offset."""
        faces = np.array([self._faces(landing) for landing in self.landings])
        n_end = len(self._ends)
        best = int(np.argmin(faces.var(axis=0)))
        j = best % n_end
        self.end = float(self._ends[j])
        faces = faces.reshape(len(self.landings), len(self._thetas), n_end)[:, :, j]
        cost = faces.var(axis=0)
        k = int(np.clip(np.argmin(cost), 1, len(cost) - 2))
        c0, c1, c2 = cost[k - 1 : k + 2]
        curve = c0 - 2.0 * c1 + c2
        step = float(self._thetas[1] - self._thetas[0])
        self.tilt = float(self._thetas[k]) + (0.5 * step * (c0 - c2) / curve if curve > 0 else 0.0)
        self.axis_body = _turned(self.task.up_body, PAD_NORMAL, self.tilt)
        self.z_face = float(np.mean(faces[:, k]))


_FACE_TOLERANCE = 0.0002  # a landing's height on the face matches the drawing's to this [m]
PAD_NORMAL = np.array([1.0, 0.0, 0.0])  # the jaw's closing direction, gripper frame: the peg turns about it


def _turned(v: _Vec, axis: _Vec, angle: float) -> _Vec:
    """``v`` turned by ``angle`` [rad] about unit ``axis``."""
    return rotate(about(axis, angle), v)


def upright(up_body: _Vec, q0: _Vec) -> _Vec:
    """The hand orientation nearest ``q0`` that points the peg's axis ``up_body`` straight up."""
    up_world = rotate(q0, up_body)
    axis = np.cross(up_world, np.array([0.0, 0.0, 1.0]))
    n = float(np.linalg.norm(axis))
    if n < 1e-12:
        return np.asarray(q0, dtype=float)
    return quat_mul(about(axis / n, math.atan2(n, float(up_world[2]))), q0)
