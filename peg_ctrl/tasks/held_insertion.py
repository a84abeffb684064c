"""The held-insertion task family: the peg starts in the hand above the hole and is inserted
without letting go, by one of the insertion strategies (:mod:`peg_ctrl.tasks.strategies`).

Task
    The peg is held upright in the closed jaw (the pads ``grip_above_centre`` above its centre),
    its lower end ``start_height`` above the hole mouth. After ``settle`` (the hand at rest while
    the sensor is tared) the strategy's phases run (``task.strategy``: ``straight``, ``force``,
    ``spiral``, ``tilt``, ``align`` or a registered one, each with its own parameters:
    ``task: {strategy: {name: spiral, spiral_pitch: 0.001}}``). The episode ends with success
    once the peg is seated, still in the hand.

Disturbances (``task.*``, drawn per seed from the reset's random generator)
    ``lateral_error`` [m]: the peg sits this far from where the task believes it in the hand (an
    in-hand offset along the pads' plane, across the closing direction, either way: Isaac Lab's
    Factory tasks draw theirs in that plane too; with the gripper's yaw uniform, its direction in
    the world is uniform), and its axis meets
    the mouth plane this far from the hole axis at the start: a task that moves its believed lower
    end over the hole meets the mouth this far off (exactly, when ``position_noise`` is 0 and the
    peg is upright). ``tilt_error`` [rad]: the peg is tilted in the grasp by this angle, in the
    plane of the pads; the gripper's yaw is drawn uniformly, so the tilt's direction is uniform.
    The task believes the peg is upright in the hand. ``position_noise`` [m]: standard deviation
    per axis (x, y) of the hole's observed position, a world-frame estimate (a camera's) drawn
    once per episode, independent of the peg in the hand: nothing learnt about the grasp moves it.
    ``drawing_tolerance`` [m]: the block, its face and its hole, sits off the drawing by a draw
    uniform within ± this per axis; the task knows the drawing (the face's height
    ``block_top``). The hole's size (``scene.assets.clearance``, ``scene.assets.chamfer``) and
    the physics (``physics.profile``, ``precision`` for contact studies) are the scene's.

What the task senses
    The gripper's state (with any sensor noise) and the force/torque sensor at the gripper mount,
    tared while the hand settles; never the true hole pose or the peg-block contact force. Its
    idea of the peg's lower end comes from the nominal grasp (or what a strategy found,
    :meth:`HeldInsertionTask.recalibrate`); its depth from the block's height. In contact the
    strategies command a force along z (``GripperTarget.force_world``; ``align`` also moments
    and free lateral axes, ``GripperTarget.wrench_axes``) and leave the rest to the controller's
    compliance: each controller realises the wrench as documented in its module.

Success
    Peg depth ≥ ``success.min_depth``, lateral error ≤ ``success.max_lateral_error`` and tilt ≤
    ``success.max_tilt`` for ``success.consecutive_steps`` control steps in a row.

Failure
    When the strategy's last phase runs out of time, the peg's end state names the reason:
    ``missed`` (its lower end never got past the chamfer into the bore), ``wedged`` (stuck in
    the bore tilted to within 10 % of the two-point-contact limit for its depth) or ``jammed``
    (stuck in the bore, less tilted: held by friction). The loop's monitors add ``force_spike``,
    ``grasp_lost``, ``excessive_tilt`` (in the hand) and ``diverged``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import MotionLimits, Planner, Waypoint
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.rotations import rotate, rotate_inv
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.sensing import Detector, WristSensor, lowpass_alpha
from peg_ctrl.sim.state import ControlState
from peg_ctrl.tasks.base import Capabilities, Evaluation, Observation, PhaseRecord, TaskContext, TaskSpec
from peg_ctrl.tasks.belief import TaskBelief
from peg_ctrl.tasks.held_start import Disturbance, check_start, place_held_start
from peg_ctrl.tasks.monitors import (
    ENTRY_MARGIN,
    InsertionMeasure,
    InsertionMonitor,
    SeatedCriterion,
    SeatedHold,
    classify_end_state,
    not_at_hole_detail,
)
from peg_ctrl.tasks.phases import DONE, Motion, PhaseMachine, PhaseSpec, PlannedMoves
from peg_ctrl.tasks.pick_and_place import SuccessConfig
from peg_ctrl.tasks.strategies import ForceConfig, Strategy, StrategyConfig
from peg_ctrl.tasks.strategies.skills import PAD_NORMAL

__all__ = ["HeldInsertionConfig", "HeldInsertionTask", "Disturbance"]  # Disturbance: held_start

_DISTURBANCES = (
    "lateral_error",
    "tilt_error",
    "position_noise",
    "drawing_tolerance",
)  # >= 0; every other number > 0
_TOUCH_HOLD = 0.01  # a contact must last this long to count [s]
_ACCEL_HZ = 30.0  # the wrench estimate's acceleration filter [Hz]
_SPEED_RESOLUTION = 0.001  # the seated detection's floor on the speed noise [m/s]
_SPEED_HZ = 5.0  # the sensed hand velocity's low-pass (encoder velocities are differences) [Hz]


@dataclasses.dataclass(frozen=True)
class HeldInsertionConfig(TaskSpec):
    """The strategy, the disturbances [m, rad] and the start [m, s]."""

    name: ClassVar[str] = "held_insertion"
    strategy: StrategyConfig = ForceConfig()  # a name or {name: ..., <its fields>}
    lateral_error: float = 0.0015  # the peg's offset in the hand from the believed grasp [m]
    tilt_error: float = 0.0  # peg tilt in the grasp [rad]
    position_noise: float = 0.0  # std of the hole's observed position (world frame), x and y [m]
    drawing_tolerance: float = 0.0  # the block sits off its drawing within ± this, per axis [m]
    start_height: float = 0.003  # the peg's lower end above the mouth at the start [m]
    grip_above_centre: float = 0.02  # pads above the peg's centre: the fingers clear the block [m]
    settle_time: float = 0.3  # hold after the start while the sensor is tared [s]
    # The start: the believed lower end over the observed hole (a robot's start: it knows no
    # other), or over the true one (every study before this field: the start then tells a
    # strategy where the hole is to within the grasp's offset).
    start_over_observed: bool = False
    # The hand's position repeatability the cell states (a robot's datasheet, as one sigma) [m]:
    # the skills' measurement models read their noise from it (the task's belief, knowledge).
    pose_repeatability: float = 0.00003

    def __post_init__(self) -> None:
        if not isinstance(self.start_over_observed, bool):
            raise ConfigError(
                f"task.start_over_observed must be true or false, got {self.start_over_observed!r}"
            )
        for f in dataclasses.fields(self):
            if f.name in ("strategy", "start_over_observed"):
                continue
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"task.{f.name} must be a finite number, got {value!r}")
            if f.name in _DISTURBANCES:
                if value < 0:
                    raise ConfigError(f"task.{f.name} must be >= 0, got {value!r}")
            elif value <= 0:
                raise ConfigError(f"task.{f.name} must be > 0, got {value!r}")
        if self.tilt_error >= 0.2:
            raise ConfigError(f"task.tilt_error must be below 0.2 rad, got {self.tilt_error!r}")

    @property
    def strategy_name(self) -> str:
        return self.strategy.name

    def with_strategy(self, strategy: StrategyConfig) -> HeldInsertionConfig:
        return dataclasses.replace(self, strategy=strategy)

    def build(self, context: TaskContext) -> HeldInsertionTask:
        return HeldInsertionTask(
            scene=context.scene,
            config=self,
            success=context.success,
            planner=context.planner,
            limits=context.limits,
            control_dt=context.control_dt,
        )

    def check(self, scene: SceneConfig) -> None:
        check_start(self, scene)
        self.strategy.check(scene, self)


class HeldInsertionTask(PlannedMoves):
    """The held peg's start, disturbance, belief and success; the strategy's phases in between.
    It is the :class:`~peg_ctrl.tasks.strategies.HeldInsertion` its strategy drives."""

    name = "held_insertion"
    capabilities: ClassVar[Capabilities] = Capabilities(insertion=True, belief=True, skills=True)

    def __init__(
        self,
        *,
        scene: SceneConfig,
        config: HeldInsertionConfig,
        success: SuccessConfig,
        planner: Planner,
        limits: MotionLimits,
        control_dt: float = 0.001,
    ) -> None:
        self.scene = scene
        self.control_dt = control_dt
        self.cfg = config
        self.success_cfg = success
        self.planner = planner
        self.limits = limits
        self.phases: tuple[str, ...] = ("settle", *config.strategy.phases, DONE)
        self.start_height = config.start_height
        a = scene.assets
        self.block_top = float(a.block_size[2])
        self.radius = float(a.peg_radius)
        self.hole_radius = float(a.peg_radius + a.clearance)
        self.chamfer = float(a.chamfer)
        self.insertion = InsertionMonitor(
            scene, SeatedCriterion(success.min_depth, success.max_lateral_error, success.max_tilt)
        )
        self.contact = Detector(k_on=4.0, k_off=2.0, hold=_TOUCH_HOLD)
        self.disturbance: Disturbance | None = None
        self.observed_hole = np.zeros(2)  # where the task believes the hole is (x, y) [m]
        self.drawing_sides = np.zeros(4)  # the drawing's hole axis to the +x, -x, +y, -y sides [m]
        self._b_body = np.zeros(3)  # nominal lower end of the peg, gripper frame [m]
        self._up_body = np.zeros(3)  # nominal peg axis (up), gripper frame
        self._goal = Waypoint.of((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)
        self.seated = SeatedHold(success.consecutive_steps)
        self._grip_length = config.grip_above_centre + 0.5 * float(a.peg_length)  # pads to lower end [m]
        self._grasp_body = np.zeros(3)  # where the pads hold the peg's axis, gripper frame [m]
        self.z_face = self.block_top  # the face's height as the believed lower end senses it [m]
        self.aligned_tilt: float | None = None  # the peg's tilt in the hand a calibration found [rad]
        self._wrist: WristSensor | None = None
        self._v_alpha = lowpass_alpha(_SPEED_HZ, control_dt)  # the hand velocity's low-pass gain
        self._belief: Belief | None = None
        self._belief_key: tuple[float, ...] = ()
        self.plan_depth: float | None = None  # set when the strategy hands over to a planner
        self._reset_knowledge(np.array([1.0, 0.0, 0.0, 0.0]))  # the task's belief (start() sets its frame)
        self.strategy: Strategy = config.strategy.build(self)
        self.machine = PhaseMachine(self.phase_table())

    # -- the phase table ------------------------------------------------------------------------
    def phase_table(self) -> dict[str, PhaseSpec]:
        """``settle`` (the task's), then the strategy's rows."""
        settle = PhaseSpec(self._enter_hold, self._settled, self.strategy.first, tick=self._tare)
        return {"settle": settle, **self.strategy.phase_table()}

    # -- the Task interface -------------------------------------------------------------------
    @property
    def phase(self) -> str:
        return self.machine.phase

    @property
    def grasped(self) -> bool:
        return True

    @property
    def records(self) -> list[PhaseRecord]:
        return self.machine.records

    @property
    def wrist(self) -> WristSensor:
        """The contact wrench about the believed lower end (world) [N, N m] (after :meth:`reset`)."""
        assert self._wrist is not None, "reset() first"
        return self._wrist

    @property
    def goal(self) -> Waypoint:
        """The last planned waypoint: the next move starts from it."""
        return self._goal

    @goal.setter
    def goal(self, value: Waypoint) -> None:
        self._goal = value

    @property
    def min_depth(self) -> float:
        return self.success_cfg.min_depth

    @property
    def belief(self) -> Belief:
        """The hole and the grasp as the task believes them (a new object when they change)."""
        key = (
            *self.observed_hole.tolist(),
            self.z_face,
            *self._b_body.tolist(),
            *self._up_body.tolist(),
            self.plan_depth,
        )
        if self._belief is None or key != self._belief_key:
            self._belief_key = key
            a = self.scene.assets
            self._belief = Belief(
                hole_xy=(float(self.observed_hole[0]), float(self.observed_hole[1])),
                hole_sigma=self.cfg.position_noise,
                face_z=self.z_face,
                hole_radius=self.hole_radius,
                chamfer=self.chamfer,
                block_size=tuple(float(v) for v in a.block_size),  # type: ignore[arg-type]
                peg_radius=self.radius,
                peg_length=float(a.peg_length),
                tip_body=tuple(float(v) for v in self._b_body),  # type: ignore[arg-type]
                axis_body=tuple(float(v) for v in self._up_body),  # type: ignore[arg-type]
                plan_depth=self.plan_depth,
            )
        return self._belief

    @property
    def readings(self) -> list[dict[str, Any]]:
        return list(self.knowledge.history)

    @property
    def skill_log(self) -> list[dict[str, Any]]:
        return list(self.strategy.skill_log)

    @property
    def time_to_insert(self) -> float | None:
        """When the seated hold that succeeded (or is under way) began [s]."""
        return self.seated.since

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Draw the disturbances; place the peg in the closed hand above the hole."""
        start = place_held_start(model, data, rng, self.cfg, self.scene, self.insertion, self.block_top)
        self.disturbance, self.drawing_sides = start.disturbance, start.drawing_sides
        self._b_body, self._up_body, self.observed_hole = start.b_body, start.up_body, start.observed_hole
        self.contact.reset()
        self._v_samples: list[float] = []
        self._v_noise = 0.0  # standard deviation of the filtered vertical speed [m/s]
        self._v_filtered: NDArray[np.float64] | None = None
        self._grasp_body = self._b_body + self._grip_length * self._up_body
        self.z_face = self.block_top
        self.aligned_tilt = None
        self.plan_depth = None
        self._wrist = WristSensor(
            model, centre_body=self._b_body, dt=self.control_dt, force_hz=30.0, accel_hz=_ACCEL_HZ
        )
        self.strategy = self.cfg.strategy.build(self)
        self.machine = PhaseMachine(self.phase_table())
        self.seated.reset()

    def start(self, obs: Observation) -> None:
        s = obs.gripper
        self._goal = Waypoint.of(s.p_world, s.quat_world, 0.0)
        self._reset_knowledge(s.quat_world)
        self.machine.start("settle", obs)

    def _reset_knowledge(self, quat: NDArray[np.float64]) -> None:
        """The task's belief over what the cell leaves open (:class:`TaskBelief`: its prior), in
        the frame of the hand at ``quat``: the end can sit off the believed one across the pads
        (horizontal, square to their closing direction, the gripper's x)."""
        self.knowledge_quat = np.asarray(quat, dtype=float).copy()
        closing = rotate(self.knowledge_quat, PAD_NORMAL)
        self.knowledge_across = np.array([-closing[1], closing[0]]) / math.hypot(closing[0], closing[1])
        # A tilt about the pads' normal swings the end: grip_length (n x up) per radian, backwards.
        swing = -self._grip_length * rotate(self.knowledge_quat, np.cross(PAD_NORMAL, self._up_body))
        self.knowledge = TaskBelief.prior(
            self.observed_hole,
            self.cfg.position_noise,
            self.knowledge_across,
            self.cfg.lateral_error,
            self.cfg.tilt_error,
            self.block_top,
            self.cfg.drawing_tolerance,
            swing[:2],
        )

    def target(self, obs: Observation) -> GripperTarget:
        v = obs.gripper.v_world
        if self._v_filtered is None:
            self._v_filtered = np.array(v, dtype=float)
        else:
            self._v_filtered += self._v_alpha * (v - self._v_filtered)
        return self.machine.update(obs)

    @property
    def hand_velocity(self) -> NDArray[np.float64]:
        """The hand's sensed linear velocity through a first-order low-pass of ``_SPEED_HZ``,
        world frame [m/s] (a copy): a still hand is told from the noise of its speed sensing."""
        assert self._v_filtered is not None, "target() first"
        return self._v_filtered.copy()

    def evaluate(self, obs: Observation) -> Evaluation:
        m = self.insertion.measure(obs.peg)
        if self.seated.update(obs.t, self.insertion.criterion(m)):
            self.finish(obs.t, "inserted")
            return Evaluation(True, True, "", "seated", m)
        if self.machine.phase == DONE:
            state = self.end_state(m)
            detail = (
                f"peg {state} (depth {m.depth_m * 1e3:.1f} mm, lateral {m.lateral_error_m * 1e3:.2f} mm, "
                f"tilt {math.degrees(m.tilt_rad):.2f} deg)"
                if m.at_hole
                else not_at_hole_detail(m)
            )
            return Evaluation(True, False, state, detail, m)
        return Evaluation(False, False, "", "", m)

    def finish(self, t: float, outcome: str) -> None:
        self.machine.close_record(t, outcome)

    def end_state(self, m: InsertionMeasure) -> str:
        """``missed``, ``jammed`` or ``wedged`` for a peg that is not seated (see the module docstring)."""
        return classify_end_state(
            m, clearance=self.hole_radius - self.radius, chamfer=self.chamfer, radius=self.radius
        )

    # -- what the task believes -------------------------------------------------------------------
    def believed_bottom(self, obs: Observation) -> NDArray[np.float64]:
        """The peg's lower end (centre) from the gripper pose and the believed grasp [m]."""
        return obs.gripper.p_world + rotate(obs.gripper.quat_world, self._b_body)

    def believed_bottom_of(self, w: Waypoint) -> NDArray[np.float64]:
        """The believed lower end [m] when the gripper is at waypoint ``w``."""
        return np.asarray(w.p_world) + rotate(np.asarray(w.quat_world), self._b_body)

    def believed_depth(self, obs: Observation) -> float:
        """Depth below the mouth of the lowest point of the peg's lower face, as believed [m]."""
        b = self.believed_bottom(obs)
        up = rotate(obs.gripper.quat_world, self._up_body)
        lowest = b[2] - self.radius * math.sqrt(max(0.0, 1.0 - up[2] * up[2]))
        return self.block_top - lowest

    def pinch_for(self, bottom: NDArray[np.float64], q_grip: NDArray[np.float64]) -> NDArray[np.float64]:
        """The pinch position that puts the believed lower end at ``bottom`` with orientation ``q_grip``."""
        return bottom - rotate(q_grip, self._b_body)

    @property
    def grasp_body(self) -> NDArray[np.float64]:
        """Where the pads hold the peg's axis, gripper frame [m] (a copy)."""
        return self._grasp_body.copy()

    @property
    def pose_repeatability(self) -> float:
        """The hand's position repeatability the cell states [m] (``task.pose_repeatability``)."""
        return self.cfg.pose_repeatability

    @property
    def drawing_tolerance(self) -> float:
        """The block's tolerance on its drawing [m] (``task.drawing_tolerance``)."""
        return self.cfg.drawing_tolerance

    @property
    def grip_length(self) -> float:
        """From the pads to the peg's lower end, along its axis [m]."""
        return self._grip_length

    @property
    def up_body(self) -> NDArray[np.float64]:
        """The peg's axis (up) as the task believes it, gripper frame (a copy)."""
        return self._up_body.copy()

    def revise_axis(
        self,
        up_body: NDArray[np.float64],
        state: ControlState,
        *,
        grasp_shift: NDArray[np.float64] | None = None,
    ) -> None:
        """A calibration found the peg's axis in the hand (``up_body``, gripper frame), and where
        the pads hold it: ``grasp_shift`` [m] (gripper frame) from where the task believed. The
        lower end is ``grip_length`` below that point along the axis. The observed hole is a
        world-frame estimate: it does not move."""
        up_body = np.asarray(up_body, dtype=float) / np.linalg.norm(up_body)
        self.aligned_tilt = math.acos(max(-1.0, min(1.0, float(np.dot(up_body, self._up_body)))))
        # The belief's reference moves with the revision: the end by as much as the believed one
        # moved (in the belief's frame), the tilt by the turn about the pads' normal.
        turn = math.atan2(
            float(np.dot(np.cross(self._up_body, up_body), PAD_NORMAL)),
            float(np.dot(self._up_body, up_body)),
        )
        b_old = self._b_body
        self._up_body = up_body
        if grasp_shift is not None:
            self._grasp_body = self._grasp_body + np.asarray(grasp_shift, dtype=float)
        self._b_body = self._grasp_body - self._grip_length * up_body
        moved = rotate(self.knowledge_quat, self._b_body - b_old)
        self.knowledge.shift(end_x=float(moved[0]), end_y=float(moved[1]), tilt=turn)
        self.wrist.move_centre(self._b_body, state)

    def recalibrate(self, obs: Observation, *, quat: NDArray[np.float64] | None = None) -> None:
        """The peg's end lies flat on the face: its axis is vertical now (with the gripper at
        ``quat``, by default as observed): :meth:`revise_axis`, and the face's height is the
        believed lower end's."""
        q = obs.gripper.quat_world if quat is None else quat
        self.revise_axis(rotate_inv(q, np.array([0.0, 0.0, 1.0])), obs.gripper)
        self.z_face = float(self.believed_bottom(obs)[2])

    # -- motions, hooks and guards the strategies share --------------------------------------------
    def move(self, goal: Waypoint, limits: MotionLimits | None = None) -> Motion:
        return self._move(goal, limits)

    def hold_here(self, obs: Observation) -> None:
        """The last goal becomes the present position (a motion ended in contact)."""
        self._goal = Waypoint.of(obs.gripper.p_world, self._goal.quat_world, 0.0)

    def feel(self, obs: Observation, *, free: bool = False) -> None:
        """Update the wrench estimate and the contact detection with this observation; ``free``:
        the hand is known to be clear of the block, so the estimate follows the sensor's bias."""
        w = self.wrist
        force, _ = w.update(obs.gripper, free=free)
        self.contact.update(obs.t, float(force[2]), float(w.sigma_force[2]))

    def feel_free(self, obs: Observation) -> None:
        """:meth:`feel`, the hand in the air (a tick for phases that move it clear of the block)."""
        self.feel(obs, free=True)

    @property
    def speed_noise(self) -> float:
        """Standard deviation of the filtered vertical speed (:attr:`hand_velocity`), measured while
        tared [m/s]."""
        return self._v_noise

    def seated_detected(self, obs: Observation) -> bool:
        """The task's own judgement that the peg is seated: its believed depth reaches the
        success depth and the hand has stopped, its vertical speed within k sigma of the speed
        sensing's noise (measured while tared)."""
        if self.believed_depth(obs) < self.min_depth:
            return False
        sigma = max(self._v_noise, _SPEED_RESOLUTION)
        return abs(float(self.hand_velocity[2])) < self.contact.k_on * sigma

    def in_bore(self, obs: Observation) -> str | None:
        """``"entered"`` once the believed lower end is past the chamfer, else None."""
        return "entered" if self.believed_depth(obs) > self.chamfer + ENTRY_MARGIN else None

    def _enter_hold(self, obs: Observation) -> Motion:
        return self._move(self._goal)

    def _tare(self, obs: Observation) -> None:
        """Tare the wrench estimate; measure the speed sensing's noise (the hand is at rest)."""
        self.wrist.accumulate_tare(obs.gripper)
        self._v_samples.append(float(self.hand_velocity[2]))
        if len(self._v_samples) > 1:
            self._v_noise = float(np.std(self._v_samples, ddof=1))

    def _settled(self, obs: Observation) -> str | None:
        return "ok" if self.machine.elapsed(obs.t) >= self.cfg.settle_time else None
