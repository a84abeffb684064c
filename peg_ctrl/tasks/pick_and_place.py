"""The pick-and-place insertion task (SPEC §6): pick the lying peg up, stand it upright, carry
it over the hole and drop it in.

Task
    The peg lies on the table; the gripper starts at its home pose above it.

Randomizations
    With ``randomization.enabled``: the peg's start position ± ``peg_xy`` [m] in x and y and its
    yaw ± ``peg_yaw`` [rad], drawn from the reset's random generator. The hole is fixed.

Phases (one row each in :meth:`PickAndPlaceTask.phase_table`)
    ``approach`` (above the peg, aligned in XY and yaw) → ``descend`` (to grasp height) →
    ``grasp`` (close, wait ``grasp_time``) → ``lift`` → ``rotate`` (about the gripper's X axis
    until the peg is upright) → ``align`` (gripper XY = hole XY − measured peg offset) →
    [``insert``: optional force-guarded descent] → ``release`` (lower to the release height,
    open) → ``settle`` → ``done``. A phase ends when its guard holds or its time budget runs
    out (outcome ``timeout``; the machine goes on and the success check decides). A grasp that
    closes on nothing ends the episode with ``grasp_lost``.

    The align target rests on one sample of the sensed gripper position; with sensor noise the
    hand then settles with the peg off the hole axis by that sample's error (0.3-0.5 mm with
    0.2 mm of noise), and a descent into a tighter fit pushes the held peg into the mouth's
    edge (130-150 N on a 1 mm chamfer; on a sharp mouth, a force spike). So ``align`` also
    averages the peg's offset from the gripper over its motion, and if that average predicts
    the hand settling with the peg off the axis by more than the radial clearance (outcome
    ``off_axis``), runs again, up to ``CENTER_PASSES`` times, aimed with the average.
    ``settle`` does not end while a seated hold is under way: the hold decides.

Success
    Peg depth ≥ ``success.min_depth``, lateral error at the mouth ≤ ``success.max_lateral_error``
    and tilt ≤ ``success.max_tilt``, after release, for ``success.consecutive_steps`` control
    steps in a row.

Failure
    At the hole, when the machine finished without success: ``missed`` (the peg never entered the
    bore), ``jammed`` or ``wedged`` (stuck in it; :func:`~peg_ctrl.tasks.monitors.classify_end_state`),
    the detail giving its lateral error, tilt and depth now and when it was released;
    ``excessive_tilt`` (the peg lies tilted at the end); ``timeout`` otherwise (not at the hole,
    or deep enough but off the axis); ``grasp_lost`` (closed on nothing). The loop's monitors
    add the others.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import JAW_SEP_MAX_M, GripperTarget
from peg_ctrl.errors import ConfigError, EpisodeFailure
from peg_ctrl.planners.base import MotionLimits, Planner, Waypoint
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.rotations import quat_mul, rotate_inv, yaw_quat
from peg_ctrl.sim.scene import PEG_LYING_QUAT, SceneConfig
from peg_ctrl.tasks.base import Capabilities, Evaluation, Observation, PhaseRecord, TaskContext, TaskSpec
from peg_ctrl.tasks.monitors import (
    InsertionMeasure,
    InsertionMonitor,
    SeatedCriterion,
    SeatedHold,
    classify_end_state,
    not_at_hole_detail,
)
from peg_ctrl.tasks.phases import (
    DONE,
    Motion,
    PhaseMachine,
    PhaseSpec,
    PlannedMoves,
    Timeout,
    TrajectorySequence,
)

__all__ = [
    "PHASES",
    "TaskConfig",
    "PickAndPlaceConfig",
    "SuccessConfig",
    "RandomizationConfig",
    "PickAndPlaceTask",
    "initial_qpos",
]

PHASES = ("approach", "descend", "grasp", "lift", "rotate", "align", "insert", "release", "settle", DONE)
SETTLED_FOR = 0.2  # the peg must stay slower than settle_speed this long [s]
CENTER_PASSES = 3  # corrective align passes at most; then the release goes ahead


@dataclasses.dataclass(frozen=True)
class TaskConfig(TaskSpec):
    """Tolerances [m, rad, jaw bytes] and time budgets [s] of the state machine (SPEC §6 defaults)."""

    name: ClassVar[str] = "pick_and_place"

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
                raise ConfigError(f"task.{f.name} must be finite and >= 0, got {value!r}")
        if self.grasp_height >= self.approach_height:
            raise ConfigError("task.grasp_height must be below task.approach_height")
        if not 0.0 < self.insert_speed_scale <= 1.0:
            raise ConfigError(f"task.insert_speed_scale must be in (0, 1], got {self.insert_speed_scale}")

    def build(self, context: TaskContext) -> PickAndPlaceTask:
        return PickAndPlaceTask(
            scene=context.scene,
            config=self,
            success=context.success,
            randomization=context.randomization,
            planner=context.planner,
            limits=context.limits,
            jaw=context.jaw,
        )

    def draws_from_seed(self, randomization: RandomizationConfig) -> bool:
        """The start pose is drawn from the seed only with ``randomization.enabled``."""
        return randomization.enabled


PickAndPlaceConfig = TaskConfig  # the name in the task family


@dataclasses.dataclass(frozen=True)
class SuccessConfig:
    """When an insertion counts as done, and what counts as failure."""

    min_depth: float = 0.04  # peg bottom at least this far below the hole mouth [m]
    max_lateral_error: float = 0.0025  # peg axis to hole axis at the mouth [m]
    max_tilt: float = 0.1  # peg axis to vertical [rad]
    consecutive_steps: int = 100  # control steps the three must hold in a row
    force_spike: float = 150.0  # any contact force above this fails the episode [N]
    max_in_hand_tilt: float = 0.35  # peg rotation in the pads since the grasp [rad]
    grasp_lost_distance: float = 0.02  # peg moved this far in the pads while held: grasp lost [m]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"success.{f.name} must be finite and > 0, got {value!r}")


@dataclasses.dataclass(frozen=True)
class RandomizationConfig:
    enabled: bool = False
    peg_xy: float = 0.015  # +- range of the peg's start x and y [m]
    peg_yaw: float = 0.2  # +- range of the peg's start yaw [rad]

    def __post_init__(self) -> None:
        for name in ("peg_xy", "peg_yaw"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f"randomization.{name} must be finite and >= 0, got {value!r}")


def initial_qpos(
    model: mujoco.MjModel, scene: SceneConfig, randomization: RandomizationConfig, rng: np.random.Generator
) -> NDArray[np.float64]:
    """The ``home`` keyframe with the peg lying at its start pose, randomised from ``rng`` if enabled."""
    qpos = model.key("home").qpos.copy()
    adr = model.joint("peg_free").qposadr[0]
    x, y = scene.peg_xy
    yaw = 0.0
    if randomization.enabled:
        dx, dy = rng.uniform(-randomization.peg_xy, randomization.peg_xy, size=2)
        yaw = float(rng.uniform(-randomization.peg_yaw, randomization.peg_yaw))
        x, y = x + dx, y + dy
    qpos[adr : adr + 3] = [x, y, scene.assets.peg_radius]
    qpos[adr + 3 : adr + 7] = quat_mul(yaw_quat(yaw), np.asarray(PEG_LYING_QUAT))
    return qpos


class PickAndPlaceTask(PlannedMoves):
    """Turns observations into gripper targets, phase by phase; evaluates the insertion."""

    name = "pick_and_place"
    phases: tuple[str, ...] = PHASES
    capabilities: ClassVar[Capabilities] = Capabilities(insertion=True)

    def __init__(
        self,
        *,
        scene: SceneConfig,
        config: TaskConfig,
        success: SuccessConfig,
        randomization: RandomizationConfig,
        planner: Planner,
        limits: MotionLimits,
        jaw: JawCalibration,
    ) -> None:
        self.scene = scene
        self.cfg = config
        self.success_cfg = success
        self.randomization = randomization
        self.planner = planner
        self.limits = limits
        self.jaw = jaw
        self.block_top = float(scene.assets.block_size[2])
        self.insertion = InsertionMonitor(
            scene, SeatedCriterion(success.min_depth, success.max_lateral_error, success.max_tilt)
        )
        self.machine = PhaseMachine(self.phase_table())
        self._goal = Waypoint.of((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)
        self._yaw = yaw_quat(0.0)
        self._settled_since: float | None = None
        self._grasped = False  # between a successful grasp and the jaw opening
        self._released = False
        self._center_passes = 0  # corrective align passes so far
        self._offset_sum = (0.0, 0.0)  # sum of (peg bottom - gripper) XY over align [m]
        self._offset_n = 0  # samples in it
        self._at_release: InsertionMeasure | None = None  # the peg when the jaw let go
        self.seated = SeatedHold(success.consecutive_steps)

    def phase_table(self) -> dict[str, PhaseSpec]:
        """The phases: how each is entered, its guard, its time budget and what follows."""
        c = self.cfg
        settle_in = Timeout(c.positioning_time, after_motion=True)
        return {
            "approach": PhaseSpec(self._enter_approach, self._above_peg, "descend", settle_in),
            "descend": PhaseSpec(self._enter_descend, self._at_height, "grasp", settle_in),
            "grasp": PhaseSpec(self._enter_grasp, self._grasp_waited, "lift", exit=self._check_grasp),
            "lift": PhaseSpec(self._enter_lift, self._at_height, "rotate", Timeout(c.lift_timeout)),
            "rotate": PhaseSpec(self._enter_rotate, self._upright, "align", Timeout(c.rotation_timeout)),
            "align": PhaseSpec(
                self._enter_align,
                self._over_hole,
                self._after_align,
                Timeout(c.alignment_timeout),
                tick=self._track_offset,
            ),
            "insert": PhaseSpec(self._enter_insert, self._insert_stopped, "release"),
            "release": PhaseSpec(
                self._enter_release,
                self._opened,
                "settle",
                Timeout(c.release_time),
                tick=self._track_opening,
                exit=self._let_go,
            ),
            "settle": PhaseSpec(
                self._enter_settle,
                self._settled,
                DONE,
                Timeout(c.settling_timeout),
                tick=self._track_settling,
            ),
        }

    # -- the Task interface -------------------------------------------------------------------
    @property
    def phase(self) -> str:
        return self.machine.phase

    @property
    def grasped(self) -> bool:
        return self._grasped

    @property
    def released(self) -> bool:
        return self._released

    @property
    def records(self) -> list[PhaseRecord]:
        return self.machine.records

    @property
    def time_to_insert(self) -> float | None:
        """When the seated hold that succeeded (or is under way) began [s]."""
        return self.seated.since

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        data.qpos[:] = initial_qpos(model, self.scene, self.randomization, rng)
        self._settled_since = None
        self._grasped = self._released = False
        self._center_passes = 0
        self._offset_sum, self._offset_n = (0.0, 0.0), 0
        self._at_release = None
        self.seated.reset()

    def start(self, obs: Observation) -> None:
        """Plan the approach from the gripper's current pose, the jaw yawed across the peg."""
        s = obs.gripper
        self._goal = Waypoint.of(s.p_world, s.quat_world, min(max(s.jaw_sep_m, 0.0), JAW_SEP_MAX_M))
        # Yaw so the jaw closes across the peg (its axis along the gripper's Y); the peg is
        # symmetric, so take the smallest turn.
        ax, ay = float(obs.peg.axis_world[0]), float(obs.peg.axis_world[1])
        yaw = (math.atan2(-ax, ay) + math.pi / 2) % math.pi - math.pi / 2
        self._yaw = yaw_quat(yaw)
        self.machine.start("approach", obs)

    def target(self, obs: Observation) -> GripperTarget:
        return self.machine.update(obs)

    def evaluate(self, obs: Observation) -> Evaluation:
        m = self.insertion.measure(obs.peg)
        if self.seated.update(obs.t, self._released and self.insertion.criterion(m)):
            self.finish(obs.t, "inserted")
            return Evaluation(True, True, "", "inserted", m)
        if self.machine.phase == DONE:
            return self._failure(m)
        return Evaluation(False, False, "", "", m)

    def _failure(self, m: InsertionMeasure) -> Evaluation:
        """The verdict on a machine that finished without a seated peg: where the peg is and why."""
        tilted = m.tilt_rad > self.success_cfg.max_tilt
        if not m.at_hole or m.depth_m >= self.success_cfg.min_depth:
            if tilted:
                where = f" at the hole: {_pose_text(m)}" if m.at_hole else ""
                return Evaluation(
                    True, False, "excessive_tilt", f"peg came to rest tilted {m.tilt_rad:.2f} rad{where}", m
                )
            if not m.at_hole:
                return Evaluation(True, False, "timeout", not_at_hole_detail(m), m)
            # Deep enough but off the axis, or the seated hold was cut short.
            lateral = m.lateral_error_m * 1e3
            detail = f"peg not inserted (depth {m.depth_m * 1e3:.1f} mm, lateral {lateral:.1f} mm)"
            return Evaluation(True, False, "timeout", detail, m)
        # Stuck short of the success depth: name how, with where it is and where it was let go.
        a = self.scene.assets
        state = classify_end_state(m, clearance=a.clearance, chamfer=a.chamfer, radius=a.peg_radius)
        stuck = f"{state} after release" if self._released else f"{state}, never released"
        return Evaluation(True, False, state, f"{stuck}: {_pose_text(m)}{self._release_text()}", m)

    def _release_text(self) -> str:
        r = self._at_release
        return f" (released {_pose_text(r)})" if r is not None and r.at_hole else ""

    def finish(self, t: float, outcome: str) -> None:
        self.machine.close_record(t, outcome)

    # -- motions ------------------------------------------------------------------------------
    def _enter_approach(self, obs: Observation) -> Motion:
        p = obs.peg.p_world
        above = (p[0], p[1], p[2] + self.cfg.approach_height)
        return self._move(Waypoint.of(above, self._yaw, JAW_SEP_MAX_M))

    def _enter_descend(self, obs: Observation) -> Motion:
        g = self._goal
        p = (g.p_world[0], g.p_world[1], obs.peg.p_world[2] + self.cfg.grasp_height)
        return self._move(Waypoint.of(p, g.quat_world, JAW_SEP_MAX_M))

    def _enter_grasp(self, obs: Observation) -> Motion:
        return self._move(dataclasses.replace(self._goal, jaw_sep_m=0.0))

    def _enter_lift(self, obs: Observation) -> Motion:
        g = self._goal
        return self._move(
            Waypoint.of((g.p_world[0], g.p_world[1], self.cfg.lift_height), g.quat_world, g.jaw_sep_m)
        )

    def _enter_rotate(self, obs: Observation) -> Motion:
        g = self._goal
        return self._move(
            Waypoint.of(g.p_world, quat_mul(np.asarray(g.quat_world), self._turn(obs)), g.jaw_sep_m)
        )

    def _enter_align(self, obs: Observation) -> Motion:
        hx, hy = self.scene.hole_xy
        g = self._goal
        if self._center_passes:
            # Re-centring: the same target with the offset averaged over align.
            ox, oy = self._mean_offset()
            return self._move(Waypoint.of((hx - ox, hy - oy, g.p_world[2]), g.quat_world, g.jaw_sep_m))
        self._offset_sum, self._offset_n = (0.0, 0.0), 0
        # Gripper XY = hole XY - (peg bottom - gripper) XY, measured now.
        ox = obs.peg.bottom_world[0] - obs.gripper.p_world[0]
        oy = obs.peg.bottom_world[1] - obs.gripper.p_world[1]
        return self._move(Waypoint.of((hx - ox, hy - oy, g.p_world[2]), g.quat_world, g.jaw_sep_m))

    def _enter_insert(self, obs: Observation) -> Motion:
        below = obs.gripper.p_world[2] - obs.peg.bottom_world[2]  # peg bottom below the pinch
        g = self._goal
        p = (g.p_world[0], g.p_world[1], self.block_top - self.cfg.insert_depth + below)
        return self._move(
            Waypoint.of(p, g.quat_world, g.jaw_sep_m), self.limits.scaled(self.cfg.insert_speed_scale)
        )

    def _enter_release(self, obs: Observation) -> Motion:
        """Lower to the release height (peg bottom ``release_depth`` inside the mouth), or hold
        where a guarded descent stopped; then open."""
        g = self._goal
        if self.cfg.force_guarded_insert:
            stop = Waypoint.of(obs.gripper.p_world, g.quat_world, g.jaw_sep_m)
        else:
            below = obs.gripper.p_world[2] - obs.peg.bottom_world[2]
            z = self.block_top - self.cfg.release_depth + below
            stop = Waypoint.of((g.p_world[0], g.p_world[1], z), g.quat_world, g.jaw_sep_m)
        opened = dataclasses.replace(stop, jaw_sep_m=JAW_SEP_MAX_M)
        parts = [self.planner.plan(g, stop, self.limits), self.planner.plan(stop, opened, self.limits)]
        self._goal = opened
        return TrajectorySequence(parts)

    def _enter_settle(self, obs: Observation) -> Motion:
        self._settled_since = None
        return self._move(self._goal)

    def _turn(self, obs: Observation) -> NDArray[np.float64]:
        """Rotation about the gripper's X axis that stands the peg upright (or the fixed turn)."""
        if self.cfg.turn_angle is not None:
            angle = self.cfg.turn_angle
        else:
            b = rotate_inv(obs.gripper.quat_world, obs.peg.axis_world)  # peg axis in the gripper frame
            angle = math.atan2(b[1], b[2])
            if angle < 0.0:
                angle += math.pi  # either end may go down; turn the positive way
        return np.array([math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0])

    # -- guards and hooks -----------------------------------------------------------------------
    def _motion_over(self, obs: Observation) -> bool:
        return self.machine.motion_over(obs.t)

    def _above_peg(self, obs: Observation) -> str | None:
        p, g = obs.gripper.p_world, self._goal.p_world
        near = math.hypot(p[0] - g[0], p[1] - g[1]) < self.cfg.alignment_distance
        return "ok" if self._motion_over(obs) and near else None

    def _at_height(self, obs: Observation) -> str | None:
        near = abs(obs.gripper.p_world[2] - self._goal.p_world[2]) < self.cfg.height_completion
        return "ok" if self._motion_over(obs) and near else None

    def _grasp_waited(self, obs: Observation) -> str | None:
        assert self.machine.motion is not None
        wait = Timeout(self.cfg.grasp_time, after_motion=True)
        return "ok" if wait.expired(self.machine.elapsed(obs.t), self.machine.motion.duration) else None

    def _check_grasp(self, obs: Observation) -> None:
        """A jaw that closed as far as commanded closed on nothing."""
        commanded = self.jaw.sep_to_byte(self._goal.jaw_sep_m)
        measured = self.jaw.sep_to_byte(obs.gripper.jaw_sep_m)
        if abs(commanded - measured) <= self.cfg.jaw_tolerance:
            raise EpisodeFailure(
                "grasp_lost",
                f"jaw closed on nothing (measured {obs.gripper.jaw_sep_m * 1e3:.1f} mm, "
                f"{measured:.0f} vs commanded {commanded:.0f} byte)",
            )
        self._grasped = True

    def _upright(self, obs: Observation) -> str | None:
        err = np.zeros(3)
        mujoco.mju_subQuat(err, np.asarray(self._goal.quat_world), obs.gripper.quat_world)
        return (
            "ok" if self._motion_over(obs) and float(np.linalg.norm(err)) < self.cfg.rotation_error else None
        )

    def _over_hole(self, obs: Observation) -> str | None:
        hx, hy = self.scene.hole_xy
        b = obs.peg.bottom_world
        near = math.hypot(b[0] - hx, b[1] - hy) < self.cfg.alignment_distance
        if not (self._motion_over(obs) and near):
            return None
        if self._center_passes >= CENTER_PASSES:
            return "ok"
        # Where the peg comes to rest once the hand reaches its goal, from the averaged offset.
        ox, oy = self._mean_offset()
        g = self._goal.p_world
        off = math.hypot(g[0] + ox - hx, g[1] + oy - hy)
        return "off_axis" if off > self.scene.assets.clearance else "ok"

    def _track_offset(self, obs: Observation) -> None:
        b, p, (sx, sy) = obs.peg.bottom_world, obs.gripper.p_world, self._offset_sum
        self._offset_sum = (sx + float(b[0] - p[0]), sy + float(b[1] - p[1]))
        self._offset_n += 1

    def _mean_offset(self) -> tuple[float, float]:
        """(peg bottom - gripper) XY averaged over align, which averages out sensor noise [m]."""
        (x, y), n = self._offset_sum, max(self._offset_n, 1)
        return x / n, y / n

    def _after_align(self, obs: Observation) -> str:
        if self.machine.records[-1].outcome == "off_axis":
            self._center_passes += 1
            return "align"
        return "insert" if self.cfg.force_guarded_insert else "release"

    def _insert_stopped(self, obs: Observation) -> str | None:
        if obs.peg.force_block > self.cfg.insert_force:
            return "contact"
        return "depth" if self._motion_over(obs) else None

    def _track_opening(self, obs: Observation) -> None:
        motion = self.machine.motion
        assert isinstance(motion, TrajectorySequence)
        if self._grasped and self.machine.elapsed(obs.t) >= motion.parts[0].duration:
            self._let_go(obs)

    def _let_go(self, obs: Observation) -> None:
        if not self._released:
            self._at_release = self.insertion.last  # as evaluated one control step ago
        self._grasped = False
        self._released = True

    def _opened(self, obs: Observation) -> str | None:
        opened = obs.gripper.jaw_sep_m > self._goal.jaw_sep_m - 0.01
        return "ok" if self._motion_over(obs) and opened else None

    def _track_settling(self, obs: Observation) -> None:
        if obs.peg.speed < self.cfg.settle_speed:
            if self._settled_since is None:
                self._settled_since = obs.t
        else:
            self._settled_since = None

    def _settled(self, obs: Observation) -> str | None:
        if self.seated.since is not None:
            return None  # a seated hold is under way: it decides, not the peg's stillness
        since = self._settled_since
        return "ok" if since is not None and obs.t - since >= SETTLED_FOR else None


def _pose_text(m: InsertionMeasure) -> str:
    return (
        f"peg {m.lateral_error_m * 1e3:.2f} mm off axis, {math.degrees(m.tilt_rad):.2f} deg tilt, "
        f"depth {m.depth_m * 1e3:.1f} mm"
    )
