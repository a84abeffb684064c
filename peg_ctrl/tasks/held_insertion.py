"""The held-insertion task family: the peg starts in the hand above the hole and is inserted
without letting go, by one of four insertion strategies.

Task
    The peg is held upright in the closed jaw (the pads ``grip_above_centre`` above its centre),
    its lower end ``start_height`` above the hole mouth. The episode ends with success once the
    peg is seated, still in the hand.

Disturbances (``task.*``, drawn per seed from the reset's random generator)
    ``lateral_error`` [m]: the peg axis meets the mouth plane this far from the hole axis, in a
    direction drawn uniformly; the task believes it is centred, so this is the lateral error at
    first contact (exactly, when ``position_noise`` is 0 and the strategy moves straight down).
    ``tilt_error`` [rad]: the peg is tilted in the grasp by this angle, in the plane of the pads;
    the gripper's yaw is drawn uniformly, so the tilt's direction is uniform. The task believes the
    peg is upright in the hand. ``position_noise`` [m]: standard deviation of Gaussian noise on
    the observed hole position (x and y); the task first moves to where it observes the hole.
    The hole's size (``scene.assets.clearance``, ``scene.assets.chamfer``) and the physics
    (``physics.profile``, ``precision`` for contact studies) are the scene's.

What the task senses
    The gripper's state (with any sensor noise) and the force/torque sensor at the gripper mount,
    tared while the hand settles; never the true hole pose or the peg-block contact force. Its
    idea of the peg's lower end comes from the nominal grasp; its depth from the block's height.

Strategies (``task.strategy``), each a row set of the phase table
    - ``straight``: ``approach`` (Ruckig) → ``push``: a position-controlled descent at
      ``descent_speed`` to ``seat_margin`` below the seated depth, whatever the contact (the
      stiff baseline).
    - ``force``: ``approach`` → ``descend`` (Ruckig, at ``descent_speed``, until the sensed
      contact force exceeds ``contact_force``) → ``insert``: a force-regulated push at
      ``insert_force`` with the lateral position held.
    - ``spiral``: ``approach`` → ``descend`` → ``search``: an Archimedean spiral about the observed
      hole (pitch ``spiral_pitch``, below the chamfer's capture range, at ``spiral_speed``, out to
      ``search_radius``) pressing down with ``search_force``, until the lower end is sensed inside
      the bore → ``insert`` from there. A search that runs out of time (the spiral's length at its
      speed) ends the episode.
    - ``tilt``: ``approach`` with the peg tilted by ``tilt_angle`` (its lowest rim towards +x) and
      that rim ``slide_start`` beyond the observed chamfer's edge → ``descend`` onto the top face →
      ``slide`` towards -x pressing with ``search_force`` until the rim drops into the bore →
      ``straighten`` (Ruckig, still pressing: the pinch point moves on the chord of the arc about
      the lower end, which drifts by about 0.1 mm) → ``insert``. A slide that runs out of time
      ends the episode.
    - ``align``: ``approach`` a datum on the block's top face ``datum_offset`` beside the observed
      hole → ``touch`` it (a light force-controlled press) → ``align``: press with
      ``align_force`` with the tilt axes moment-controlled at zero about the believed lower end,
      so the peg turns about its tip until its end lies flat on the face (the moment falls below
      ``align_tolerance``); the gripper's orientation then tells the peg's true axis in the hand,
      and the task re-derives the lower end, the face's height and where the hole is (its belief
      that the peg started centred, with the corrected lower end) → ``transfer`` over the hole
      keeping that orientation → ``search``: hops over a hexagonal lattice
      (:mod:`peg_ctrl.tasks.hop_search`) until the peg drops onto the chamfer, then onto the
      hole's axis with the chamfer guiding it → ``insert`` with the lateral axes free. The peg's
      tilt is corrected *before* it meets the bore: at μ = 0.9 a 0.05 mm clearance wedges any peg
      that enters tilted by more than about 0.3° (Whitney's wedging condition, two-point contact
      shallower than μ times the diameter).
    In contact the strategies command a force along z (``GripperTarget.force_world``; ``align``
    also moments and free lateral axes, ``GripperTarget.wrench_axes``) and leave the rest to the
    controller's compliance: each controller realises the wrench as documented in its module
    (open loop for pd, impedance and diffik without an outer loop, closed loop on the sensor for
    admittance and diffik with one, the force model of the contact-aware mpc).

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
from typing import ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError
from peg_ctrl.planners.base import MotionLimits, Planner, Waypoint
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.grasp_start import GRASP_OFFSET, Q_TURN, HeldRig, close_on_held_peg, place_held_peg
from peg_ctrl.sim.rotations import quat_mul, rotate, rotate_inv, yaw_quat
from peg_ctrl.sim.scene import PEG_LYING_QUAT, SceneConfig
from peg_ctrl.sim.sensing import WristSensor
from peg_ctrl.sim.state import ft_world
from peg_ctrl.tasks.base import Evaluation, Observation, PhaseRecord, TaskContext, TaskSpec
from peg_ctrl.tasks.hop_search import GUIDE_AXES, HexLattice, Hold, HopSearch, HopSettings
from peg_ctrl.tasks.monitors import (
    ENTRY_MARGIN,
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
from peg_ctrl.tasks.pick_and_place import SuccessConfig

__all__ = ["STRATEGIES", "PHASES", "HeldInsertionConfig", "HeldInsertionTask", "Disturbance"]

STRATEGIES = ("straight", "force", "spiral", "tilt", "align")
PHASES = (
    "settle",
    "approach",
    "descend",
    "push",
    "touch",
    "align",
    "transfer",
    "search",
    "slide",
    "straighten",
    "insert",
    DONE,
)
_ALIGN_AXES = (False, False, True, True, True, False)  # press along z, tilt axes moment-free
_PRESS_AXES = (False, False, True, False, False, False)  # press along z, pose held otherwise
_FORCE_FILTER_HZ = 30.0  # low-pass on the sensed contact force [Hz]


@dataclasses.dataclass(frozen=True)
class HeldInsertionConfig(TaskSpec):
    """Disturbances [m, rad], strategy and its parameters [m, m/s, N, rad, s]."""

    name: ClassVar[str] = "held_insertion"
    strategy: str = "force"  # straight, force, spiral, tilt or align
    lateral_error: float = 0.0015  # peg axis to hole axis at the mouth at first contact [m]
    tilt_error: float = 0.0  # peg tilt in the grasp [rad]
    position_noise: float = 0.0  # std of the observed hole position, x and y [m]
    start_height: float = 0.003  # the peg's lower end above the mouth at the start [m]
    grip_above_centre: float = 0.02  # pads above the peg's centre: the fingers clear the block [m]
    settle_time: float = 0.3  # hold after the start while the sensor is tared [s]
    descent_speed: float = 0.005  # guarded descent, and the straight push [m/s]
    contact_force: float = 1.5  # sensed force that counts as contact [N]
    insert_force: float = 3.0  # force-regulated push [N]
    insert_speed: float = 0.01  # above this descent speed the push eases off, to 0 N at twice it [m/s]
    search_force: float = 3.0  # pressing force while searching or sliding [N]
    spiral_pitch: float = 0.0012  # radial step per turn of the spiral [m]
    spiral_speed: float = 0.005  # along the spiral [m/s]
    search_radius: float = 0.0045  # the spiral gives up beyond this radius [m]
    tilt_angle: float = 0.12  # tilt of the tilt-and-slide strategy [rad]
    turn_speed: float = 0.1  # straightening, about the peg's lower end [rad/s]
    slide_start: float = 0.0045  # lowest rim this far beyond the observed chamfer edge [m]
    slide_speed: float = 0.005  # [m/s]
    seat_margin: float = 0.002  # the straight push aims this far below the seated depth [m]
    insert_time: float = 8.0  # budget of the force-regulated insert [s] (the straight push: its
    # motion and 1 s)
    # The align strategy (see the module docstring and peg_ctrl.tasks.hop_search).
    datum_offset: float = 0.03  # the datum touch, this far from the observed hole towards -x, -y [m]
    touch_gap: float = 0.0012  # the approach stops the lower end this far above the face [m]
    touch_force: float = 0.6  # light press: touching the datum, every search hop [N]
    align_force: float = 3.0  # press while the peg turns flat [N]
    align_tolerance: float = 0.002  # flat once the moment about the tip stays below this [N m]
    align_time: float = 4.0  # budget of the alignment [s]
    search_pitch: float = 0.0016  # hexagonal lattice pitch [m] (<= sqrt(3) x the capture range)
    hop_lift: float = 0.0002  # lift between hops [m]
    hop_hover: float = 0.00008  # the press starts this far above the face [m]
    hop_speed: float = 0.02  # lateral hop speed [m/s]
    hop_lower_speed: float = 0.003  # descent to the hover height [m/s]
    drop_min: float = 0.00003  # a press this far below the face is on the chamfer [m]
    search_time: float = 10.0  # budget of the hop search [s]

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise ConfigError(f"task.strategy must be one of {', '.join(STRATEGIES)}, got {self.strategy!r}")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, str):
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"task.{f.name} must be a finite number, got {value!r}")
            if f.name in ("lateral_error", "tilt_error", "position_noise"):
                if value < 0:
                    raise ConfigError(f"task.{f.name} must be >= 0, got {value!r}")
            elif value <= 0:
                raise ConfigError(f"task.{f.name} must be > 0, got {value!r}")
        if self.tilt_error >= 0.2:
            raise ConfigError(f"task.tilt_error must be below 0.2 rad, got {self.tilt_error!r}")
        if not 0.0 < self.tilt_angle < 0.5:
            raise ConfigError(f"task.tilt_angle must be in (0, 0.5) rad, got {self.tilt_angle!r}")
        if self.drop_min >= self.hop_hover + 0.001:
            raise ConfigError(
                f"task.drop_min must be below hop_hover + 1 mm ({self.hop_hover + 0.001:.4g} m), "
                f"got {self.drop_min!r}"
            )

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
        a = scene.assets
        rim = a.peg_radius * math.sin(self.tilt_error)  # the low rim below the lower end's centre
        if self.start_height <= rim:
            raise ConfigError(
                f"task.start_height must be above the tilted rim's drop of {rim * 1e3:.2f} mm, "
                f"got {self.start_height!r}"
            )
        if self.grip_above_centre >= 0.5 * a.peg_length - 0.01:
            raise ConfigError(
                f"task.grip_above_centre must leave 10 mm of peg above the pads (< "
                f"{0.5 * a.peg_length - 0.01:g} m), got {self.grip_above_centre!r}"
            )
        if self.strategy == "align":
            self._check_align(scene)

    def _check_align(self, scene: SceneConfig) -> None:
        """The datum must lie on the top face, clear of the hole and its chamfer whatever the
        lateral error, the tilt (which moves the believed lower end) and the noise; the lattice
        must leave no gap in the chamfer's capture range."""
        a = scene.assets
        half = 0.5 * min(a.block_size[0], a.block_size[1])
        reach = self.datum_offset / math.sqrt(2.0) + a.peg_radius  # along x and y (a diagonal)
        if reach >= half - 0.002:
            raise ConfigError(
                f"task.datum_offset: the datum touch reaches {reach * 1e3:.1f} mm from the hole along x "
                f"and y, beyond the block's top face ({half * 1e3:.1f} mm); must be < "
                f"{(half - 0.002 - a.peg_radius) * math.sqrt(2.0):.4g} m"
            )
        mouth = a.peg_radius + a.clearance + a.chamfer
        lean = (self.grip_above_centre + 0.5 * a.peg_length) * math.sin(self.tilt_error)
        error = self.lateral_error + lean + 3.0 * self.position_noise
        if self.datum_offset - a.peg_radius - error <= mouth + 0.001:
            raise ConfigError(
                f"task.datum_offset: {self.datum_offset!r} m puts the datum touch within 1 mm of the "
                f"hole's mouth (radius {mouth * 1e3:.2f} mm) for a lateral error of "
                f"{error * 1e3:.2f} mm (lateral error, tilt, noise); must be > "
                f"{mouth + 0.001 + a.peg_radius + error:.4g} m"
            )
        capture = a.clearance + a.chamfer
        if self.search_pitch > math.sqrt(3.0) * (capture - self.drop_min):
            raise ConfigError(
                f"task.search_pitch: {self.search_pitch!r} m leaves gaps in the chamfer's capture range "
                f"({capture * 1e3:.2f} mm); must be <= {math.sqrt(3.0) * (capture - self.drop_min):.4g} m"
            )


@dataclasses.dataclass(frozen=True)
class Disturbance:
    """One seed's draw: lateral error direction and gripper yaw [rad], observation noise (x, y) [m]."""

    lateral_direction: float
    yaw: float
    tilt_sign: float
    noise: tuple[float, float]

    @classmethod
    def draw(cls, rng: np.random.Generator, position_noise: float) -> Disturbance:
        direction, yaw = (float(v) for v in rng.uniform(0.0, 2.0 * math.pi, size=2))
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        nx, ny = (float(v) for v in rng.normal(0.0, 1.0, size=2) * position_noise)
        return cls(direction, yaw, sign, (nx, ny))


def _about(axis: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    q = np.empty(4)
    mujoco.mju_axisAngle2Quat(q, axis, angle)
    return q


class _ContactSense:
    """The contact force on the hand from the mount's force/torque sensor, tared, world frame."""

    def __init__(self, control_dt: float = 0.001) -> None:
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * _FORCE_FILTER_HZ * control_dt)
        self.tare = np.zeros(3)
        self._tare_sum = np.zeros(3)
        self._tare_n = 0
        self.force = np.zeros(3)  # filtered contact force on the hand [N]

    def accumulate_tare(self, obs: Observation) -> None:
        self._tare_sum += ft_world(obs.gripper)[0]
        self._tare_n += 1
        self.tare = self._tare_sum / self._tare_n

    def update(self, obs: Observation) -> None:
        contact = -(ft_world(obs.gripper)[0] - self.tare)
        self.force += self.alpha * (contact - self.force)


class HeldInsertionTask(PlannedMoves):
    """Phases of one insertion strategy for a held peg; evaluates the insertion."""

    name = "held_insertion"
    phases: tuple[str, ...] = PHASES

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
        a = scene.assets
        self.block_top = float(a.block_size[2])
        self.radius = float(a.peg_radius)
        self.hole_radius = float(a.peg_radius + a.clearance)
        self.chamfer = float(a.chamfer)
        self.insertion = InsertionMonitor(
            scene, SeatedCriterion(success.min_depth, success.max_lateral_error, success.max_tilt)
        )
        self._sense = _ContactSense(self.control_dt)
        self.machine = PhaseMachine(self.phase_table())
        self.disturbance: Disturbance | None = None
        self.observed_hole = np.zeros(2)  # where the task believes the hole is (x, y) [m]
        self._b_body = np.zeros(3)  # nominal lower end of the peg, gripper frame [m]
        self._up_body = np.zeros(3)  # nominal peg axis (up), gripper frame
        self._goal = Waypoint.of((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)
        self.seated = SeatedHold(success.consecutive_steps)
        self._pressing = _Pressing(self._goal, config.insert_force)
        # The align strategy's belief and sensing (see _recalibrate).
        self._grip_length = config.grip_above_centre + 0.5 * float(a.peg_length)  # pads to lower end [m]
        self._grasp_body = np.zeros(3)  # where the pads hold the peg's axis, gripper frame [m]
        self._start = Waypoint.of((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)  # the pose at the start
        self._noise = np.zeros(2)  # the observation noise on the hole's position [m]
        self.z_face = self.block_top  # the face's height as the believed lower end senses it [m]
        self.aligned_tilt: float | None = None  # the peg's tilt in the hand the alignment found [rad]
        self._wrist: WristSensor | None = None
        self._hold = Hold(
            GripperTarget.trusted(np.zeros(3), (1.0, 0.0, 0.0, 0.0), np.zeros(3), np.zeros(3), 0.0)
        )
        self._search: HopSearch | None = None
        self._flat_since: float | None = None
        self._settle_from: float | None = None
        self._belief: Belief | None = None
        self._belief_key: tuple[float, ...] = ()

    # -- the phase table ------------------------------------------------------------------------
    def phase_table(self) -> dict[str, PhaseSpec]:
        c = self.cfg
        last = Timeout(c.insert_time)
        settle = PhaseSpec(self._enter_hold, self._settled, "approach", tick=self._tare)
        approach = PhaseSpec(
            self._enter_approach, self._motion_done, self._after_approach, Timeout(1.0, True)
        )
        insert = PhaseSpec(self._enter_insert, _never, DONE, last, tick=self._govern)
        if c.strategy == "align":
            return self._align_table(settle, last)
        if c.strategy == "straight":
            return {
                "settle": settle,
                "approach": approach,
                "push": PhaseSpec(self._enter_push, _never, DONE, Timeout(1.0, True)),
            }
        table = {
            "settle": settle,
            "approach": approach,
            "descend": PhaseSpec(
                self._enter_descend, self._touched, self._after_descend, Timeout(1.0, True), tick=self._feel
            ),
            "insert": insert,
        }
        if c.strategy == "spiral":
            turns = c.search_radius / c.spiral_pitch
            length = math.pi * c.search_radius * turns  # of the spiral out to the search radius
            table["search"] = PhaseSpec(
                self._enter_search,
                self._in_bore,
                self._after_search,
                Timeout(length / c.spiral_speed),
                tick=self._feel,
            )
        elif c.strategy == "tilt":
            span = self.cfg.slide_start + 2.0 * (self.chamfer + 0.002)
            table["slide"] = PhaseSpec(
                self._enter_slide,
                self._in_bore,
                self._after_search,
                Timeout(span / c.slide_speed),
                tick=self._feel,
            )
            table["straighten"] = PhaseSpec(
                self._enter_straighten, self._motion_done, "insert", Timeout(0.3, True), tick=self._feel
            )
        return table

    def _align_table(self, settle: PhaseSpec, last: Timeout) -> dict[str, PhaseSpec]:
        c = self.cfg
        return {
            "settle": settle,
            "approach": PhaseSpec(self._enter_datum, self._motion_done, "touch", Timeout(1.0, True)),
            "touch": PhaseSpec(
                self._enter_touch, self._touched_datum, self._after_touch, Timeout(2.0), tick=self._feel
            ),
            "align": PhaseSpec(
                self._enter_align, self._aligned, "transfer", Timeout(c.align_time), tick=self._feel
            ),
            "transfer": PhaseSpec(
                self._enter_transfer, self._motion_done, "search", Timeout(1.0, True), tick=self._feel
            ),
            "search": PhaseSpec(
                self._enter_hop_search,
                self._found,
                self._after_search,
                Timeout(c.search_time),
                tick=self._hop,
            ),
            "insert": PhaseSpec(self._enter_guided_insert, _never, DONE, last, tick=self._govern),
        }

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
    def belief(self) -> Belief:
        """The hole and the grasp as the task believes them (a new object when they change)."""
        key = (
            *self.observed_hole.tolist(),
            self.z_face,
            *self._b_body.tolist(),
            *self._up_body.tolist(),
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
            )
        return self._belief

    @property
    def time_to_insert(self) -> float | None:
        """When the seated hold that succeeded (or is under way) began [s]."""
        return self.seated.since

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Draw the disturbances; place the peg in the closed hand above the hole."""
        c, scene = self.cfg, self.scene
        d = self.disturbance = Disturbance.draw(rng, c.position_noise)
        q_grip = quat_mul(yaw_quat(d.yaw), Q_TURN)
        # Tilt in the plane of the pads: about the jaw's closing direction (the gripper's x).
        closing = rotate(q_grip, np.array([1.0, 0.0, 0.0]))
        q_peg = quat_mul(
            _about(closing, d.tilt_sign * c.tilt_error), quat_mul(q_grip, np.asarray(PEG_LYING_QUAT))
        )
        up = rotate(q_peg, np.array([0.0, 0.0, 1.0]))
        up = up if up[2] > 0 else -up
        hx, hy = scene.hole_xy
        mouth = np.array(
            [
                hx + c.lateral_error * math.cos(d.lateral_direction),
                hy + c.lateral_error * math.sin(d.lateral_direction),
                self.block_top,
            ]
        )
        bottom = mouth + (c.start_height / up[2]) * up
        rig = HeldRig(model)
        pinch, _ = place_held_peg(
            model,
            data,
            rig,
            scene,
            bottom=bottom,
            q_grip=q_grip,
            q_peg=q_peg,
            grip_above_centre=c.grip_above_centre,
        )
        close_on_held_peg(model, data, rig, pinch, q_grip)
        data.time = 0.0  # the closing builds the start state; the episode's clock starts here
        # The nominal grasp (peg upright in the hand), in the gripper frame.
        half = 0.5 * scene.assets.peg_length
        b_world = -(c.grip_above_centre + half) * np.array([0.0, 0.0, 1.0]) + rotate(
            q_grip, np.array([0.0, 0.0, -GRASP_OFFSET])
        )
        self._b_body = rotate_inv(q_grip, b_world)
        self._up_body = rotate_inv(q_grip, np.array([0.0, 0.0, 1.0]))
        believed_bottom = pinch + b_world
        self.observed_hole = believed_bottom[:2] + np.asarray(d.noise)
        self._sense = _ContactSense(self.control_dt)
        self._noise = np.asarray(d.noise, dtype=float)
        self._grasp_body = self._b_body + self._grip_length * self._up_body
        self.z_face = self.block_top
        self.aligned_tilt = None
        self._search = None
        self._wrist = (
            WristSensor(model, centre_body=self._b_body, dt=self.control_dt)
            if c.strategy == "align"
            else None
        )
        self.machine = PhaseMachine(self.phase_table())
        self.seated.reset()

    def start(self, obs: Observation) -> None:
        s = obs.gripper
        self._goal = Waypoint.of(s.p_world, s.quat_world, 0.0)
        self._start = self._goal
        self.machine.start("settle", obs)

    def target(self, obs: Observation) -> GripperTarget:
        return self.machine.update(obs)

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
        """The peg's lower end (centre) from the gripper pose and the nominal grasp [m]."""
        return obs.gripper.p_world + rotate(obs.gripper.quat_world, self._b_body)

    def believed_depth(self, obs: Observation) -> float:
        """Depth below the mouth of the lowest point of the peg's lower face, as believed [m]."""
        b = self.believed_bottom(obs)
        up = rotate(obs.gripper.quat_world, self._up_body)
        lowest = b[2] - self.radius * math.sqrt(max(0.0, 1.0 - up[2] * up[2]))
        return self.block_top - lowest

    def _pinch_for(self, bottom: NDArray[np.float64], q_grip: NDArray[np.float64]) -> NDArray[np.float64]:
        """The pinch position that puts the nominal lower end at ``bottom`` with orientation ``q_grip``."""
        return bottom - rotate(q_grip, self._b_body)

    # -- motions ------------------------------------------------------------------------------
    def _slow(self) -> MotionLimits:
        return self.limits.scaled(self.cfg.descent_speed / self.limits.v_lin)

    def _enter_hold(self, obs: Observation) -> Motion:
        return self._move(self._goal)

    def _tilted(self) -> NDArray[np.float64]:
        """The gripper orientation that tilts the peg by ``tilt_angle`` with its lowest rim towards +x."""
        q0 = np.asarray(self._goal.quat_world)
        return quat_mul(_about(np.array([0.0, 1.0, 0.0]), self.cfg.tilt_angle), q0)

    def _enter_approach(self, obs: Observation) -> Motion:
        """Over the observed hole, the lower end ``start_height`` above the mouth (for ``tilt``:
        tilted, the lowest rim ``slide_start`` beyond the chamfer's edge along +x)."""
        c = self.cfg
        q = np.asarray(self._goal.quat_world)
        target = np.array([*self.observed_hole, self.block_top + c.start_height])
        if c.strategy == "tilt":
            q = self._tilted()
            a = c.tilt_angle
            rim = self.hole_radius + self.chamfer + c.slide_start  # of the lowest rim from the axis
            target[0] += rim - self.radius * math.cos(a)
            target[2] += self.radius * math.sin(a)
        return self._move(Waypoint.of(self._pinch_for(target, q), q, 0.0))

    def _after_approach(self, obs: Observation) -> str:
        return "push" if self.cfg.strategy == "straight" else "descend"

    def _seated_goal(self) -> Waypoint:
        g = self._goal
        q = np.asarray(g.quat_world)
        bottom = self.believed_bottom_of(g)
        bottom[2] = self.block_top - self.success_cfg.min_depth - self.cfg.seat_margin
        return Waypoint.of(self._pinch_for(bottom, q), q, 0.0)

    def believed_bottom_of(self, w: Waypoint) -> NDArray[np.float64]:
        return np.asarray(w.p_world) + rotate(np.asarray(w.quat_world), self._b_body)

    def _enter_push(self, obs: Observation) -> Motion:
        return self._move(self._seated_goal(), self._slow())

    def _enter_descend(self, obs: Observation) -> Motion:
        return self._move(self._seated_goal(), self._slow())

    def _touched(self, obs: Observation) -> str | None:
        if self._in_bore(obs):
            return "entered"  # the chamfer guided the peg in: push
        if self._sense.force[2] > self.cfg.contact_force:
            return "contact"
        return "no_contact" if self.machine.motion_over(obs.t) else None

    def _after_descend(self, obs: Observation) -> str:
        if self._in_bore(obs):  # already in: a tilted peg straightens first
            return "straighten" if self.cfg.strategy == "tilt" else "insert"
        return {"force": "insert", "spiral": "search", "tilt": "slide"}[self.cfg.strategy]

    def _after_search(self, obs: Observation) -> str:
        """Push if the search found the bore; a search that ran out of time has missed."""
        if self._in_bore(obs):
            return "straighten" if self.cfg.strategy == "tilt" else "insert"
        return DONE

    def _hold_here(self, obs: Observation) -> None:
        """The last goal becomes the present pose (the motion ended in contact)."""
        s = obs.gripper
        self._goal = Waypoint.of(s.p_world, self._goal.quat_world, 0.0)

    def _enter_insert(self, obs: Observation) -> Motion:
        self._hold_here(obs)
        self._pressing = _Pressing(self._goal, self.cfg.insert_force)
        return self._pressing

    def _govern(self, obs: Observation) -> None:
        """Ease the push off above ``insert_speed``: a peg that drops freely down the bore
        rattles against its walls, each tap a force spike."""
        self._sense.update(obs)
        c = self.cfg
        excess = max(0.0, -float(obs.gripper.v_world[2]) - c.insert_speed)
        self._pressing.set_force(c.insert_force * max(0.0, 1.0 - excess / c.insert_speed))

    def _enter_search(self, obs: Observation) -> Motion:
        self._hold_here(obs)
        return _Spiral(self._goal, self.cfg.spiral_pitch, self.cfg.spiral_speed, self.cfg.search_force)

    def _enter_slide(self, obs: Observation) -> Motion:
        self._hold_here(obs)
        return _Slide(self._goal, np.array([-1.0, 0.0, 0.0]), self.cfg.slide_speed, self.cfg.search_force)

    def _enter_straighten(self, obs: Observation) -> Motion:
        """Upright again, turning about the peg's lower end, pressing down."""
        self._hold_here(obs)
        g = self._goal
        bottom = self.believed_bottom_of(g)
        q_up = quat_mul(_about(np.array([0.0, 1.0, 0.0]), -self.cfg.tilt_angle), np.asarray(g.quat_world))
        goal = Waypoint.of(self._pinch_for(bottom, q_up), q_up, 0.0)
        trajectory = self.planner.plan(g, goal, self.limits.scaled(self.cfg.turn_speed / self.limits.v_rot))
        self._goal = goal
        return _Pressed(trajectory, self.cfg.search_force)

    # -- the align strategy ---------------------------------------------------------------------
    def _tip_waypoint(self, tip: NDArray[np.float64], q: NDArray[np.float64]) -> Waypoint:
        return Waypoint.of(self._pinch_for(tip, q), q, 0.0)

    def _held(self, target: GripperTarget) -> Hold:
        self._hold.target = target
        return self._hold

    def _press_here(self, obs: Observation, force: float, axes: tuple[bool, ...]) -> GripperTarget:
        """Hold the present pose, pressing down with ``force`` [N] on the flagged ``axes``."""
        s = obs.gripper
        self._goal = Waypoint.of(s.p_world, s.quat_world, 0.0)
        return GripperTarget.trusted(
            s.p_world, s.quat_world, np.zeros(3), np.zeros(3), 0.0, _down(force), wrench_axes=axes
        )

    def _enter_datum(self, obs: Observation) -> Motion:
        """Over the datum, the lower end ``touch_gap`` above the face."""
        c = self.cfg
        q = np.asarray(self._goal.quat_world)
        off = c.datum_offset / math.sqrt(2.0)  # along the diagonal, where the face is widest
        tip = np.array(
            [self.observed_hole[0] - off, self.observed_hole[1] - off, self.block_top + c.touch_gap]
        )
        return self._move(self._tip_waypoint(tip, q))

    def _enter_touch(self, obs: Observation) -> Motion:
        self._flat_since = None
        return self._held(self._press_here(obs, self.cfg.touch_force, _PRESS_AXES))

    def _touched_datum(self, obs: Observation) -> str | None:
        """Contact: the sensed push lasts 20 ms (the sensor also reads the hand's accelerations)."""
        assert self._wrist is not None
        pressed = self.machine.elapsed(obs.t) > 0.05 and self._wrist.force[2] > 0.8 * self.cfg.touch_force
        self._flat_since = (self._flat_since or obs.t) if pressed else None
        return "contact" if self._flat_since is not None and obs.t - self._flat_since >= 0.02 else None

    def _after_touch(self, obs: Observation) -> str:
        return "align" if self._flat_since is not None else DONE

    def _enter_align(self, obs: Observation) -> Motion:
        self._flat_since = self._settle_from = None
        return self._held(self._press_here(obs, self.cfg.align_force, _ALIGN_AXES))

    def _aligned(self, obs: Observation) -> str | None:
        """Flat once the moment about the lower end stays below ``align_tolerance`` for 0.1 s;
        then a light press with the orientation held, 0.15 s, before the belief is updated."""
        assert self._wrist is not None
        t = obs.t
        if self._settle_from is None:
            m = self._wrist.moment
            pressed = self._wrist.force[2] > 0.5 * self.cfg.align_force  # flat on the face, not in the air
            flat = (
                pressed
                and self.machine.elapsed(t) > 0.2
                and math.hypot(m[0], m[1]) < self.cfg.align_tolerance
            )
            self._flat_since = (self._flat_since or t) if flat else None
            if self._flat_since is not None and t - self._flat_since >= 0.1:
                self._settle_from = t
                self._hold.target = self._press_here(obs, self.cfg.touch_force, _PRESS_AXES)
            return None
        return "flat" if t - self._settle_from >= 0.15 else None

    def _recalibrate(self, obs: Observation) -> None:
        """The peg's end lies flat on the face: its axis is vertical now. The pads still hold it
        where they did, so the lower end is ``_grip_length`` below them along that axis; the
        face's height follows, and so does the hole (the task believes the peg started centred)."""
        assert self._wrist is not None
        q = obs.gripper.quat_world
        up_body = rotate_inv(q, np.array([0.0, 0.0, 1.0]))
        self.aligned_tilt = math.acos(max(-1.0, min(1.0, float(np.dot(up_body, self._up_body)))))
        self._up_body = up_body
        self._b_body = self._grasp_body - self._grip_length * up_body
        self._wrist.centre_body = self._b_body
        self.z_face = float(self.believed_bottom(obs)[2])
        start = self._start
        start_tip = np.asarray(start.p_world) + rotate(np.asarray(start.quat_world), self._b_body)
        self.observed_hole = start_tip[:2] + self._noise

    def _enter_transfer(self, obs: Observation) -> Motion:
        """Up off the datum, over the hole, down to the hover height, keeping the orientation."""
        self._recalibrate(obs)
        c = self.cfg
        s = obs.gripper
        q = s.quat_world
        here = Waypoint.of(s.p_world, q, 0.0)
        up = self.believed_bottom(obs) + np.array([0.0, 0.0, 0.002])
        over = np.array([*self.observed_hole, up[2]])
        hover = np.array([*self.observed_hole, self.z_face + c.hop_hover])
        lower = dataclasses.replace(self.limits, v_lin=c.hop_lower_speed, a_lin=0.5, j_lin=20.0)
        lift = self.planner.plan(here, self._tip_waypoint(up, q), self.limits)
        across = self.planner.plan(self._tip_waypoint(up, q), self._tip_waypoint(over, q), self.limits)
        down = self.planner.plan(self._tip_waypoint(over, q), self._tip_waypoint(hover, q), lower)
        self._goal = self._tip_waypoint(hover, q)
        return TrajectorySequence([lift, across, down])

    def _enter_hop_search(self, obs: Observation) -> Motion:
        c, a = self.cfg, self.scene.assets
        settings = HopSettings(
            press_force=c.touch_force,
            hover=c.hop_hover,
            lift=c.hop_lift,
            hop_speed=c.hop_speed,
            lower_speed=c.hop_lower_speed,
            drop_min=c.drop_min,
            capture=a.clearance + a.chamfer,
            settle_time=0.05,
            guide_time=1.0,
        )
        self._search = HopSearch(
            centre=self.observed_hole,
            z_face=self.z_face,
            quat=np.asarray(self._goal.quat_world),
            lattice=HexLattice(c.search_pitch, c.search_radius),
            settings=settings,
            planner=self.planner,
            limits=self.limits,
            tip_to_pinch=self._pinch_for,
            t0=obs.t,
        )
        return self._search

    def _hop(self, obs: Observation) -> None:
        self._feel(obs)
        assert self._search is not None and self._wrist is not None
        self._search.step(obs.t, self.believed_bottom(obs), self._wrist.force, self._wrist.moment)

    def _found(self, obs: Observation) -> str | None:
        if self._in_bore(obs):
            return "entered"
        assert self._search is not None
        return "exhausted" if self._search.exhausted else None

    def _enter_guided_insert(self, obs: Observation) -> Motion:
        """Push down with the lateral axes free: the bore guides the peg."""
        self._hold_here(obs)
        self._pressing = _Pressing(self._goal, self.cfg.insert_force, GUIDE_AXES)
        return self._pressing

    # -- guards and hooks -----------------------------------------------------------------------
    def _tare(self, obs: Observation) -> None:
        self._sense.accumulate_tare(obs)
        if self._wrist is not None:
            self._wrist.accumulate_tare(obs.gripper)

    def _feel(self, obs: Observation) -> None:
        self._sense.update(obs)
        if self._wrist is not None:
            self._wrist.update(obs.gripper)

    def _settled(self, obs: Observation) -> str | None:
        return "ok" if self.machine.elapsed(obs.t) >= self.cfg.settle_time else None

    def _motion_done(self, obs: Observation) -> str | None:
        return "ok" if self.machine.motion_over(obs.t) else None

    def _in_bore(self, obs: Observation) -> str | None:
        return "entered" if self.believed_depth(obs) > self.chamfer + ENTRY_MARGIN else None


def _never(obs: Observation) -> None:
    return None


def _down(force: float) -> NDArray[np.float64]:
    return np.array([0.0, 0.0, -force])


class _Pressing:
    """Hold ``at`` laterally and in orientation, pushing down with ``force`` [N] (adjustable);
    ``axes`` (6 booleans), when given, also frees other axes (the lateral forces, at zero)."""

    duration = 0.0

    def __init__(self, at: Waypoint, force: float, axes: tuple[bool, ...] | None = None) -> None:
        self._at = at
        self._axes = axes
        self.set_force(force)

    def set_force(self, force: float) -> None:
        # A force of exactly 0 would hand z back to position control: keep a token push.
        at = self._at
        self._target = GripperTarget.trusted(
            at.p_world,
            at.quat_world,
            np.zeros(3),
            np.zeros(3),
            0.0,
            _down(max(force, 1e-3)),
            wrench_axes=self._axes,
        )

    def sample(self, t: float) -> GripperTarget:
        return self._target


class _Pressed:
    """A planned motion with a downward force on z."""

    def __init__(self, trajectory: Motion, force: float) -> None:
        self.trajectory = trajectory
        self.duration = trajectory.duration
        self._force = _down(force)

    def sample(self, t: float) -> GripperTarget:
        return self.trajectory.sample(t).with_force(self._force)


class _Spiral:
    """An Archimedean spiral ``r = pitch theta / 2 pi`` about ``at``, at ``speed`` [m/s] along
    the path, pressing down with ``force`` [N]."""

    def __init__(self, at: Waypoint, pitch: float, speed: float, force: float) -> None:
        self.centre = np.asarray(at.p_world)
        self.quat = np.asarray(at.quat_world)
        self.a = pitch / (2.0 * math.pi)
        self.speed = speed
        self.duration = 0.0  # open-ended: the phase's guard or time budget ends it
        self._force = _down(force)

    def sample(self, t: float) -> GripperTarget:
        # Arc length s = a theta^2 / 2 (to first order) at constant speed.
        theta = math.sqrt(2.0 * self.speed * max(t, 0.0) / self.a)
        r = self.a * theta
        c, s = math.cos(theta), math.sin(theta)
        p = self.centre + np.array([r * c, r * s, 0.0])
        rate = self.speed / math.sqrt(self.a * self.a + r * r)  # d theta / dt
        v = np.array([self.a * c - r * s, self.a * s + r * c, 0.0]) * rate
        return GripperTarget.trusted(p, self.quat, v, np.zeros(3), 0.0, self._force)


class _Slide:
    """A straight slide from ``at`` along ``direction`` at ``speed`` [m/s], pressing down with ``force``."""

    def __init__(self, at: Waypoint, direction: NDArray[np.float64], speed: float, force: float) -> None:
        self.start = np.asarray(at.p_world)
        self.quat = np.asarray(at.quat_world)
        self.v = direction * speed
        self.duration = 0.0  # open-ended: the phase's guard or time budget ends it
        self._force = _down(force)

    def sample(self, t: float) -> GripperTarget:
        return GripperTarget.trusted(
            self.start + self.v * t, self.quat, self.v, np.zeros(3), 0.0, self._force
        )
