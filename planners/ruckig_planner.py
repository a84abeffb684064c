"""Jerk-limited, time-synchronised trajectories with Ruckig (offline, rest to rest).

Five DoF are planned together: x, y, z [m], the rotation angle about the fixed axis [rad] and
the jaw separation [m]. Ruckig's time synchronisation makes them all start and finish together.
"""

from __future__ import annotations

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Synchronization
from ruckig import Trajectory as RuckigTrajectory

from peg_ctrl.commands import GripperTarget
from peg_ctrl.planners.base import MotionLimits, RotationPath, Waypoint

__all__ = ["RuckigPlanner", "RuckigMotion", "PlanningError"]


class PlanningError(RuntimeError):
    """Ruckig could not compute a trajectory; the message carries Ruckig's result code."""


class RuckigMotion:
    """A computed Ruckig trajectory, sampled as gripper targets."""

    def __init__(self, start: Waypoint, goal: Waypoint, trajectory: RuckigTrajectory) -> None:
        self._traj = trajectory
        self._rotation = RotationPath(np.asarray(start.quat_world), np.asarray(goal.quat_world))
        self._goal = goal
        self._duration = float(trajectory.duration)

    @property
    def duration(self) -> float:
        return self._duration

    @property
    def rotation_angle(self) -> float:
        return self._rotation.angle

    def state_at(self, t: float) -> tuple[list[float], list[float], list[float]]:
        """Raw (position, velocity, acceleration) of the 5 DoF at ``t`` [s]."""
        pos, vel, acc = self._traj.at_time(min(max(t, 0.0), self._duration))
        return list(pos), list(vel), list(acc)

    def sample(self, t: float) -> GripperTarget:
        if t >= self._duration:
            g = self._goal
            return GripperTarget.trusted(
                g.p_world, g.quat_world, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), g.jaw_sep_m
            )
        pos, vel, _ = self._traj.at_time(max(t, 0.0))
        axis = self._rotation.axis_body
        quat = self._rotation.quat_at(pos[3])
        omega = (axis[0] * vel[3], axis[1] * vel[3], axis[2] * vel[3])
        jaw = min(max(pos[4], 0.0), 0.085)
        return GripperTarget.trusted(pos[:3], quat, vel[:3], omega, jaw)


class RuckigPlanner:
    """Jerk-limited trajectories (Ruckig), the default planner."""

    name = "ruckig"

    def __init__(self) -> None:
        self._otg = Ruckig(5)

    def plan(self, start: Waypoint, goal: Waypoint, limits: MotionLimits) -> RuckigMotion:
        rotation = RotationPath(np.asarray(start.quat_world), np.asarray(goal.quat_world))
        inp = InputParameter(5)
        inp.current_position = [*start.p_world, 0.0, start.jaw_sep_m]
        inp.current_velocity = [0.0] * 5
        inp.current_acceleration = [0.0] * 5
        inp.target_position = [*goal.p_world, rotation.angle, goal.jaw_sep_m]
        inp.target_velocity = [0.0] * 5
        inp.target_acceleration = [0.0] * 5
        inp.max_velocity = [limits.v_lin] * 3 + [limits.v_rot, limits.v_jaw]
        inp.max_acceleration = [limits.a_lin] * 3 + [limits.a_rot, limits.a_jaw]
        inp.max_jerk = [limits.j_lin] * 3 + [limits.j_rot, limits.j_jaw]
        inp.synchronization = Synchronization.Time
        trajectory = RuckigTrajectory(5)
        result = self._otg.calculate(inp, trajectory)
        if result not in (Result.Working, Result.Finished):
            raise PlanningError(f"Ruckig failed with {result} from {start} to {goal}")
        return RuckigMotion(start, goal, trajectory)
