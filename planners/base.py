"""The planner interface: ``plan(start, goal, limits) -> Trajectory`` with ``sample(t)``.

A trajectory moves the gripper between two rest states: translation as 3 DoF in the world
frame, rotation as one angle about the fixed axis of ``Log(q_start^-1 q_goal)`` (the short way
round), and the jaw as 1 DoF. Samples are :class:`~peg_ctrl.commands.GripperTarget` objects, so
any controller can track them.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget

__all__ = ["Waypoint", "MotionLimits", "Trajectory", "Planner", "RotationPath"]


@dataclasses.dataclass(frozen=True)
class Waypoint:
    """A rest pose: pinch position ``p_world`` (3,) [m], ``quat_world`` (4,), ``jaw_sep_m`` [m]."""

    p_world: tuple[float, float, float]
    quat_world: tuple[float, float, float, float]
    jaw_sep_m: float

    @classmethod
    def of(cls, p_world, quat_world, jaw_sep_m: float) -> Waypoint:
        p = tuple(float(v) for v in p_world)
        q = np.asarray(quat_world, dtype=float)
        q = q / np.linalg.norm(q)
        return cls((p[0], p[1], p[2]), (q[0], q[1], q[2], q[3]), float(jaw_sep_m))

    @classmethod
    def of_target(cls, target: GripperTarget) -> Waypoint:
        return cls.of(target.p_world, target.quat_world, target.jaw_sep_m)


@dataclasses.dataclass(frozen=True)
class MotionLimits:
    """Velocity, acceleration and jerk limits; ``*_lin`` [m/s^k], ``*_rot`` [rad/s^k], ``*_jaw`` [m/s^k]."""

    v_lin: float = 0.25
    a_lin: float = 1.0
    j_lin: float = 10.0
    v_rot: float = 1.0
    a_rot: float = 2.0
    j_rot: float = 20.0
    v_jaw: float = 0.1
    a_jaw: float = 0.5
    j_jaw: float = 5.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"MotionLimits.{f.name} must be finite and > 0, got {value!r}")

    def scaled(self, factor: float) -> MotionLimits:
        """All velocity limits times ``factor`` (accelerations and jerks unchanged)."""
        return dataclasses.replace(
            self, v_lin=self.v_lin * factor, v_rot=self.v_rot * factor, v_jaw=self.v_jaw * factor
        )


class RotationPath:
    """Rotation from ``q_start`` to ``q_goal`` about one fixed axis, as a function of angle."""

    def __init__(self, q_start: NDArray[np.float64], q_goal: NDArray[np.float64]) -> None:
        rotvec = np.zeros(3)
        mujoco.mju_subQuat(rotvec, np.asarray(q_goal, float), np.asarray(q_start, float))
        self.angle = float(np.linalg.norm(rotvec))  # [rad], in [0, pi]
        self.axis_body = rotvec / self.angle if self.angle > 1e-12 else np.array([1.0, 0.0, 0.0])
        self.q_start = np.asarray(q_start, float)
        self.q_goal = np.asarray(q_goal, float)

    def quat_at(self, angle: float) -> NDArray[np.float64]:
        """Orientation after turning ``angle`` [rad] about the axis (in the start frame)."""
        if angle >= self.angle:
            return self.q_goal.copy()
        q = self.q_start.copy()
        mujoco.mju_quatIntegrate(q, self.axis_body, angle)
        return q


class Trajectory(Protocol):
    """A time-parametrised motion between two rest states."""

    @property
    def duration(self) -> float:
        """Total duration [s]."""
        ...

    def sample(self, t: float) -> GripperTarget:
        """Target at time ``t`` [s] from the start; clamps to the end state past ``duration``."""
        ...


class Planner(Protocol):
    """Turns a start and goal waypoint into a trajectory respecting ``limits``."""

    name: str

    def plan(self, start: Waypoint, goal: Waypoint, limits: MotionLimits) -> Trajectory: ...
