"""Motions the insertion strategies play: holds, presses, a spiral, a slide.

Each is a :data:`~peg_ctrl.tasks.phases.Motion`: ``duration`` [s] (0 for an open-ended motion
that a phase's guard or time budget ends) and ``sample(t) -> GripperTarget``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.tasks.phases import Motion

__all__ = ["Guided", "Hold", "Pressing", "Pressed", "Spiral", "Slide", "down", "about"]

_Vec = NDArray[np.float64]
_ZERO = (0.0, 0.0, 0.0)


def down(force: float) -> _Vec:
    """A push of ``force`` [N] straight down, as a world-frame force."""
    return np.array([0.0, 0.0, -force])


def about(axis: _Vec, angle: float) -> _Vec:
    """The quaternion of a turn by ``angle`` [rad] about the unit ``axis``."""
    q = np.empty(4)
    mujoco.mju_axisAngle2Quat(q, axis, angle)
    return q


class Hold:
    """A constant target (a pose, with a wrench on some axes) until it is replaced."""

    duration = 0.0

    def __init__(self, target: GripperTarget) -> None:
        self.target = target

    def sample(self, t: float) -> GripperTarget:
        return self.target


class Pressing:
    """Hold ``at`` laterally and in orientation, pushing down with ``force`` [N] (adjustable);
    ``axes`` (6 booleans), when given, also frees other axes (the lateral forces, at zero)."""

    duration = 0.0

    def __init__(self, at: Waypoint, force: float, axes: tuple[bool, ...] | None = None) -> None:
        self._at = at
        self._axes = axes
        self._push = math.nan  # the push of the target built last [N]
        self.set_force(force)

    def set_force(self, force: float) -> None:
        # A force of exactly 0 would hand z back to position control: keep a token push.
        push = max(force, 1e-3)
        if push == self._push:  # the target already built (targets are immutable): most steps
            return
        self._push = push
        at = self._at
        self._target = GripperTarget.trusted(
            at.p_world, at.quat_world, np.zeros(3), np.zeros(3), 0.0, down(push), wrench_axes=self._axes
        )

    def sample(self, t: float) -> GripperTarget:
        return self._target


class Pressed:
    """A planned motion with a downward force on z."""

    def __init__(self, trajectory: Motion, force: float) -> None:
        self.trajectory = trajectory
        self.duration = trajectory.duration
        self._force = down(force)

    def sample(self, t: float) -> GripperTarget:
        return self.trajectory.sample(t).with_force(self._force)


class Guided:
    """A planned motion with the flagged ``axes`` (6 booleans) wrench-controlled at zero: those
    axes follow whatever guides them (a bore, a chamfer), the others track the plan, which
    starts after a dwell of ``delay`` [s] at its first pose."""

    def __init__(self, trajectory: Motion, axes: tuple[bool, ...], *, delay: float = 0.0) -> None:
        self.trajectory = trajectory
        self.delay = delay
        self.duration = delay + trajectory.duration
        self._axes = np.asarray(axes, dtype=bool)

    def sample(self, t: float) -> GripperTarget:
        return self.trajectory.sample(max(0.0, t - self.delay)).with_wrench(np.zeros(3), axes=self._axes)


class Spiral:
    """An Archimedean spiral ``r = pitch theta / 2 pi`` about ``at``, at ``speed`` [m/s] along
    the path, pressing down with ``force`` [N]."""

    def __init__(self, at: Waypoint, pitch: float, speed: float, force: float) -> None:
        self.centre = np.asarray(at.p_world)
        self.quat = np.asarray(at.quat_world)
        self.a = pitch / (2.0 * math.pi)
        self.speed = speed
        self.duration = 0.0  # open-ended: the phase's guard or time budget ends it
        self._force = down(force)
        self._centre = self.centre.astype(float).tolist()

    def sample(self, t: float) -> GripperTarget:
        # Arc length s = a theta^2 / 2 (to first order) at constant speed. Plain floats (every
        # control step), the arithmetic of centre + [r c, r s, 0] and [...] * rate.
        a = self.a
        theta = math.sqrt(2.0 * self.speed * max(t, 0.0) / a)
        r = a * theta
        c, s = math.cos(theta), math.sin(theta)
        cx, cy, cz = self._centre
        p = (cx + r * c, cy + r * s, cz + 0.0)
        rate = self.speed / math.sqrt(a * a + r * r)  # d theta / dt
        v = ((a * c - r * s) * rate, (a * s + r * c) * rate, 0.0 * rate)
        return GripperTarget.trusted(p, self.quat, v, _ZERO, 0.0, self._force)


class Slide:
    """A straight slide from ``at`` along ``direction`` at ``speed`` [m/s], pressing down with ``force``."""

    def __init__(self, at: Waypoint, direction: _Vec, speed: float, force: float) -> None:
        self.start = np.asarray(at.p_world)
        self.quat = np.asarray(at.quat_world)
        self.v = direction * speed
        self.duration = 0.0  # open-ended: the phase's guard or time budget ends it
        self._force = down(force)

    def sample(self, t: float) -> GripperTarget:
        return GripperTarget.trusted(
            self.start + self.v * t, self.quat, self.v, np.zeros(3), 0.0, self._force
        )
