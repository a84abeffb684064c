"""The original's baseline: move toward the goal at a constant speed.

Translation, rotation angle and jaw move along straight lines at constant velocity, scaled so
that all three finish together; the slowest one sets the duration (``v_lin``, ``v_rot`` and
``v_jaw`` of the limits). Velocity jumps at the start and the end: this is the baseline the
jerk-limited planner is compared against.
"""

from __future__ import annotations

import math

import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import MotionLimits, RotationPath, Waypoint

__all__ = ["FixedSpeedPlanner", "LinearMotion"]


class LinearMotion:
    """Constant-velocity motion between two waypoints."""

    def __init__(self, start: Waypoint, goal: Waypoint, limits: MotionLimits) -> None:
        self._p0 = np.asarray(start.p_world, float)
        self._dp = np.asarray(goal.p_world, float) - self._p0
        self._rotation = RotationPath(np.asarray(start.quat_world), np.asarray(goal.quat_world))
        self._jaw0 = start.jaw_sep_m
        self._djaw = goal.jaw_sep_m - start.jaw_sep_m
        self._goal = goal
        self._duration = max(
            float(np.linalg.norm(self._dp)) / limits.v_lin,
            self._rotation.angle / limits.v_rot,
            abs(self._djaw) / limits.v_jaw,
        )
        d = self._duration
        self._v = self._dp / d if d > 0 else np.zeros(3)
        self._w = self._rotation.axis_body * (self._rotation.angle / d) if d > 0 else np.zeros(3)

    @property
    def duration(self) -> float:
        return self._duration

    def sample(self, t: float) -> GripperTarget:
        if t >= self._duration:
            g = self._goal
            return GripperTarget.trusted(
                g.p_world, g.quat_world, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), g.jaw_sep_m
            )
        s = max(t, 0.0) / self._duration
        p = self._p0 + s * self._dp
        quat = self._rotation.quat_at(s * self._rotation.angle)
        jaw = self._jaw0 + s * self._djaw
        return GripperTarget.trusted(p, quat, self._v, self._w, jaw)


class FixedSpeedPlanner:
    """Constant-speed straight-line motion (the original's increments), for comparison."""

    name = "fixed_speed"

    def plan(self, start: Waypoint, goal: Waypoint, limits: MotionLimits) -> LinearMotion:
        if not all(math.isfinite(v) for v in (*start.p_world, *goal.p_world)):
            raise ValueError(f"non-finite waypoint: start={start}, goal={goal}")
        return LinearMotion(start, goal, limits)
