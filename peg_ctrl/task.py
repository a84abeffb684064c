"""The autonomous insertion task: its configuration and state machine (SPEC §6).

Task
    Pick up the peg lying on the table, turn it upright, carry it over the hole and drop it in.

Phases
    ``approach`` (above the peg, aligned in XY and yaw) → ``descend`` (to grasp height) →
    ``grasp`` (close, wait ``grasp_time``) → ``lift`` → ``rotate`` (about the gripper's X axis
    until the peg is upright) → ``align`` (gripper XY = hole XY − measured peg offset) →
    [``insert``: optional force-guarded descent] → ``release`` (lower to the release height,
    open) → ``settle`` → ``done``.

Every phase follows one planned trajectory (any planner) and ends when its trajectory is over
and its guard holds, or when its time budget runs out (the phase outcome is then ``timeout``
and the machine goes on, as in the original; the success check at the end decides). A grasp
that closes on nothing ends the episode with ``grasp_lost``.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import JAW_SEP_MAX_M, GripperTarget
from peg_ctrl.jaw import JawCalibration
from peg_ctrl.scene import SceneConfig
from peg_ctrl.state import ControlState
from planners.base import MotionLimits, Planner, Trajectory, Waypoint

__all__ = [
    "Phase",
    "TaskConfig",
    "SuccessConfig",
    "PegObservation",
    "PhaseRecord",
    "InsertionStateMachine",
    "GraspLost",
]


class Phase(str, enum.Enum):
    APPROACH = "approach"
    DESCEND = "descend"
    GRASP = "grasp"
    LIFT = "lift"
    ROTATE = "rotate"
    ALIGN = "align"
    INSERT = "insert"
    RELEASE = "release"
    SETTLE = "settle"
    DONE = "done"


PHASE_ORDER = tuple(Phase)


@dataclasses.dataclass(frozen=True)
class TaskConfig:
    """Tolerances [m, rad, jaw bytes] and time budgets [s] of the state machine (SPEC §6 defaults)."""

    rotation_error: float = 0.1  # rotate is done below this orientation error [rad]
    alignment_distance: float = 0.005  # align is done below this peg-to-hole XY error [m]
    jaw_tolerance: float = 10.0  # closed-on-nothing test: measured vs commanded jaw [byte]
    height_completion: float = 0.01  # descend/lift are done within this height error [m]
    grasp_time: float = 0.5  # wait after the jaw closes [s]
    lift_timeout: float = 3.0  # [s]
    rotation_timeout: float = 12.0  # [s]
    alignment_timeout: float = 4.0  # [s]
    positioning_time: float = 2.0  # extra time for approach/descend after their motion [s]
    release_time: float = 4.0  # [s]
    settling_timeout: float = 7.0  # [s]
    approach_height: float = 0.08  # pinch height above the peg axis before descending [m]
    grasp_height: float = 0.010  # pinch above the peg axis when grasping; keeps closed pads off the table [m]
    lift_height: float = 0.15  # pinch height after lifting [m]
    turn_angle: float | None = None  # fixed turn about X [rad]; None: measured so the peg ends upright
    release_depth: float = 0.01  # peg bottom this far below the hole mouth when released [m]
    force_guarded_insert: bool = False  # descend until contact (or insert_depth) before releasing
    insert_force: float = 5.0  # contact force that stops the guarded descent [N]
    insert_depth: float = 0.03  # deepest guarded descent of the peg bottom below the mouth [m]
    insert_speed_scale: float = 0.2  # guarded descent speed as a fraction of the limits
    settle_speed: float = 0.005  # peg speed below which it counts as settled [m/s]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or value is None:
                continue
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"task.{f.name} must be finite and >= 0, got {value!r}")
        if self.grasp_height >= self.approach_height:
            raise ValueError("task.grasp_height must be below task.approach_height")
        if not 0.0 < self.insert_speed_scale <= 1.0:
            raise ValueError(f"task.insert_speed_scale must be in (0, 1], got {self.insert_speed_scale}")


@dataclasses.dataclass(frozen=True)
class SuccessConfig:
    """When an insertion counts as done, and what counts as failure."""

    min_depth: float = 0.04  # peg bottom at least this far below the hole mouth [m]
    max_lateral_error: float = 0.0025  # peg axis to hole axis at the mouth [m]
    max_tilt: float = 0.1  # peg axis to vertical [rad]
    consecutive_steps: int = 100  # control steps the three must hold in a row
    force_spike: float = 150.0  # any contact force above this fails the episode [N]
    max_in_hand_tilt: float = 0.35  # peg rotation in the pads since the grasp [rad]
    grasp_lost_distance: float = 0.02  # peg centre to pinch point while held [m]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"success.{f.name} must be finite and > 0, got {value!r}")


class PegObservation(NamedTuple):
    """Peg state the task needs each control step (world frame)."""

    p_world: NDArray[np.float64]  # centre (3,) [m]
    quat_world: NDArray[np.float64]  # (4,)
    axis_world: NDArray[np.float64]  # unit axis (3,)
    bottom_world: NDArray[np.float64]  # lower end of the axis (3,) [m]
    speed: float  # [m/s]
    force_block: float  # net peg-block contact force [N]


@dataclasses.dataclass
class PhaseRecord:
    phase: str
    t_start: float
    t_end: float | None = None
    outcome: str = ""


class GraspLost(Exception):
    """The jaw closed on nothing (or let go)."""


def _yaw_quat(yaw: float) -> NDArray[np.float64]:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def _mul(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.empty(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def _rotate_inv(quat: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    q_inv = np.empty(4)
    mujoco.mju_negQuat(q_inv, quat)
    out = np.empty(3)
    mujoco.mju_rotVecQuat(out, v, q_inv)
    return out


class _Sequence:
    """Trajectories played one after another."""

    def __init__(self, parts: list[Trajectory]) -> None:
        self.parts = parts
        self.duration = sum(p.duration for p in parts)

    def sample(self, t: float) -> GripperTarget:
        for part in self.parts[:-1]:
            if t < part.duration:
                return part.sample(t)
            t -= part.duration
        return self.parts[-1].sample(t)


class InsertionStateMachine:
    """Turns observations into gripper targets, phase by phase. Never touches the simulation."""

    def __init__(
        self,
        *,
        scene: SceneConfig,
        task: TaskConfig,
        planner: Planner,
        limits: MotionLimits,
        jaw: JawCalibration,
    ) -> None:
        self.scene = scene
        self.cfg = task
        self.planner = planner
        self.limits = limits
        self.jaw = jaw
        self.phase = Phase.APPROACH
        self.records: list[PhaseRecord] = []
        self._traj: Trajectory | _Sequence | None = None
        self._t0 = 0.0
        self._goal: Waypoint | None = None
        self._yaw_quat = np.array([1.0, 0.0, 0.0, 0.0])
        self._settled_since: float | None = None
        self.grasped = False  # between a successful grasp and the jaw opening
        self.released = False

    # -- geometry ---------------------------------------------------------------------------
    @property
    def block_top(self) -> float:
        return self.scene.assets.block_size[2]

    # -- phase plumbing ---------------------------------------------------------------------
    def _enter(self, phase: Phase, t: float, goal: Waypoint, limits: MotionLimits | None = None) -> None:
        assert self._goal is not None
        self._finish_record(t, "ok")
        self.phase = phase
        self._t0 = t
        self._traj = self.planner.plan(self._goal, goal, limits or self.limits)
        self._goal = goal
        self.records.append(PhaseRecord(phase.value, t))

    def _finish_record(self, t: float, outcome: str) -> None:
        if self.records and self.records[-1].t_end is None:
            self.records[-1].t_end = t
            self.records[-1].outcome = self.records[-1].outcome or outcome

    def _mark(self, outcome: str) -> None:
        self.records[-1].outcome = outcome

    def _elapsed(self, t: float) -> float:
        return t - self._t0

    def _motion_over(self, t: float) -> bool:
        assert self._traj is not None
        return self._elapsed(t) >= self._traj.duration

    def _past(self, t: float, extra: float) -> bool:
        """More than ``extra`` seconds after the motion ended."""
        assert self._traj is not None
        return self._elapsed(t) > self._traj.duration + extra

    def start(self, t: float, state: ControlState, peg: PegObservation) -> None:
        """Plan the approach from the gripper's current pose."""
        self._goal = Waypoint.of(
            state.p_world, state.quat_world, min(max(state.jaw_sep_m, 0.0), JAW_SEP_MAX_M)
        )
        # Yaw the jaw so it closes across the peg: the peg's axis along the gripper's Y.
        ax, ay = float(peg.axis_world[0]), float(peg.axis_world[1])
        yaw = math.atan2(-ax, ay)
        yaw = (yaw + math.pi / 2) % math.pi - math.pi / 2  # the peg is symmetric: smallest turn
        self._yaw_quat = _yaw_quat(yaw)
        above = (peg.p_world[0], peg.p_world[1], peg.p_world[2] + self.cfg.approach_height)
        self.records = [PhaseRecord("start", t, t, "ok")]
        self._enter(Phase.APPROACH, t, Waypoint.of(above, self._yaw_quat, JAW_SEP_MAX_M))

    def target(self, t: float) -> GripperTarget:
        assert self._traj is not None
        return self._traj.sample(self._elapsed(t))

    # -- the machine ------------------------------------------------------------------------
    def update(self, t: float, state: ControlState, peg: PegObservation) -> GripperTarget:
        """Advance the phase if its guard holds, and return the target for time ``t``."""
        cfg = self.cfg
        goal = self._goal
        assert goal is not None
        phase = self.phase
        if phase is Phase.APPROACH:
            err_xy = math.hypot(state.p_world[0] - goal.p_world[0], state.p_world[1] - goal.p_world[1])
            done = self._motion_over(t) and err_xy < cfg.alignment_distance
            if done or self._past(t, cfg.positioning_time):
                if not done:
                    self._mark("timeout")
                z = peg.p_world[2] + cfg.grasp_height
                p = (goal.p_world[0], goal.p_world[1], z)
                self._enter(Phase.DESCEND, t, Waypoint.of(p, goal.quat_world, JAW_SEP_MAX_M))
        elif phase is Phase.DESCEND:
            done = self._motion_over(t) and abs(state.p_world[2] - goal.p_world[2]) < cfg.height_completion
            if done or self._past(t, cfg.positioning_time):
                if not done:
                    self._mark("timeout")
                self._enter(Phase.GRASP, t, dataclasses.replace(goal, jaw_sep_m=0.0))
        elif phase is Phase.GRASP:
            if self._past(t, cfg.grasp_time):
                commanded = self.jaw.sep_to_byte(goal.jaw_sep_m)
                measured = self.jaw.sep_to_byte(state.jaw_sep_m)
                if abs(commanded - measured) <= cfg.jaw_tolerance:
                    self._mark("grasp_lost")
                    raise GraspLost(
                        f"jaw closed on nothing (measured {state.jaw_sep_m * 1e3:.1f} mm, "
                        f"{measured:.0f} vs commanded {commanded:.0f} byte)"
                    )
                self.grasped = True
                p = (goal.p_world[0], goal.p_world[1], cfg.lift_height)
                self._enter(Phase.LIFT, t, Waypoint.of(p, goal.quat_world, goal.jaw_sep_m))
        elif phase is Phase.LIFT:
            done = self._motion_over(t) and abs(state.p_world[2] - goal.p_world[2]) < cfg.height_completion
            if done or self._elapsed(t) > max(cfg.lift_timeout, self._traj.duration if self._traj else 0.0):
                if not done:
                    self._mark("timeout")
                q_goal = _mul(np.asarray(goal.quat_world), self._turn(state, peg))
                self._enter(Phase.ROTATE, t, Waypoint.of(goal.p_world, q_goal, goal.jaw_sep_m))
        elif phase is Phase.ROTATE:
            err = np.zeros(3)
            mujoco.mju_subQuat(err, np.asarray(goal.quat_world), state.quat_world)
            done = self._motion_over(t) and float(np.linalg.norm(err)) < cfg.rotation_error
            if done or self._elapsed(t) > cfg.rotation_timeout:
                if not done:
                    self._mark("timeout")
                # Gripper XY = hole XY - (peg bottom - gripper) XY, measured now.
                hx, hy = self.scene.hole_xy
                ox = peg.bottom_world[0] - state.p_world[0]
                oy = peg.bottom_world[1] - state.p_world[1]
                p = (hx - ox, hy - oy, goal.p_world[2])
                self._enter(Phase.ALIGN, t, Waypoint.of(p, goal.quat_world, goal.jaw_sep_m))
        elif phase is Phase.ALIGN:
            hx, hy = self.scene.hole_xy
            err_xy = math.hypot(peg.bottom_world[0] - hx, peg.bottom_world[1] - hy)
            done = self._motion_over(t) and err_xy < cfg.alignment_distance
            if done or self._elapsed(t) > max(
                cfg.alignment_timeout, self._traj.duration if self._traj else 0.0
            ):
                if not done:
                    self._mark("timeout")
                below = state.p_world[2] - peg.bottom_world[2]  # peg bottom below the pinch
                if cfg.force_guarded_insert:
                    z = self.block_top - cfg.insert_depth + below
                    p = (goal.p_world[0], goal.p_world[1], z)
                    slow = self.limits.scaled(cfg.insert_speed_scale)
                    self._enter(Phase.INSERT, t, Waypoint.of(p, goal.quat_world, goal.jaw_sep_m), slow)
                else:
                    self._enter_release(t, state, peg, lower=True)
        elif phase is Phase.INSERT:
            contact = peg.force_block > cfg.insert_force
            if contact or self._motion_over(t):
                self._mark("contact" if contact else "depth")
                self._enter_release(t, state, peg, lower=False)
        elif phase is Phase.RELEASE:
            if self._traj is not None and isinstance(self._traj, _Sequence):
                opening_started = self._elapsed(t) >= self._traj.parts[0].duration
            else:
                opening_started = True
            if opening_started and self.grasped:
                self.grasped = False
                self.released = True
            opened = state.jaw_sep_m > goal.jaw_sep_m - 0.01
            done = self._motion_over(t) and opened
            if done or self._elapsed(t) > max(cfg.release_time, self._traj.duration if self._traj else 0.0):
                if not done:
                    self._mark("timeout")
                self.grasped = False
                self.released = True
                self._enter(Phase.SETTLE, t, goal)
                self._settled_since = None
        elif phase is Phase.SETTLE:
            if peg.speed < cfg.settle_speed:
                if self._settled_since is None:
                    self._settled_since = t
            else:
                self._settled_since = None
            settled = self._settled_since is not None and t - self._settled_since >= 0.2
            if settled or self._elapsed(t) > cfg.settling_timeout:
                self._mark("ok" if settled else "timeout")
                self._finish_record(t, "ok")
                self.phase = Phase.DONE
        return self.target(t)

    def _enter_release(self, t: float, state: ControlState, peg: PegObservation, *, lower: bool) -> None:
        """Lower to the release height (peg bottom ``release_depth`` inside the mouth), then open."""
        assert self._goal is not None
        goal = self._goal
        parts = []
        start = goal
        if lower:
            below = state.p_world[2] - peg.bottom_world[2]
            z = self.block_top - self.cfg.release_depth + below
            lowered = Waypoint.of((goal.p_world[0], goal.p_world[1], z), goal.quat_world, goal.jaw_sep_m)
            parts.append(self.planner.plan(start, lowered, self.limits))
            start = lowered
        else:
            # Hold where the guarded descent stopped.
            here = Waypoint.of(state.p_world, goal.quat_world, goal.jaw_sep_m)
            parts.append(self.planner.plan(goal, here, self.limits))
            start = here
        opened = dataclasses.replace(start, jaw_sep_m=JAW_SEP_MAX_M)
        parts.append(self.planner.plan(start, opened, self.limits))
        self._finish_record(t, "ok")
        self.phase = Phase.RELEASE
        self._t0 = t
        self._traj = _Sequence(parts)
        self._goal = opened
        self.records.append(PhaseRecord(Phase.RELEASE.value, t))

    def _turn(self, state: ControlState, peg: PegObservation) -> NDArray[np.float64]:
        """Rotation about the gripper's X axis that stands the peg upright (or the fixed turn)."""
        if self.cfg.turn_angle is not None:
            angle = self.cfg.turn_angle
        else:
            b = _rotate_inv(state.quat_world, peg.axis_world)  # peg axis in the gripper frame
            angle = math.atan2(b[1], b[2])
            if angle < 0.0:
                angle += math.pi  # either end may go down; turn the positive way
        return np.array([math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0])

    def finish(self, t: float, outcome: str) -> None:
        self._finish_record(t, outcome)
