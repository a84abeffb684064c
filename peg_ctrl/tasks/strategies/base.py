"""What an insertion strategy is: a config that names it, and the phases it plays on a held peg.

A strategy is one research axis of the held insertion (:mod:`peg_ctrl.tasks.held_insertion`),
as a controller is another: a frozen config dataclass with a registered ``name`` and its own
parameters (:class:`StrategyConfig`), which builds the :class:`Strategy` for one episode. The
strategy contributes the rows of the task's phase table after ``settle`` (the hand at rest
while the sensor is tared): how each phase is entered (a motion), the guard that ends it, its
time budget and the phase that follows (:class:`~peg_ctrl.tasks.phases.PhaseSpec`). It drives
the task through :class:`HeldInsertion`, the part of the task a strategy may use: what the task
believes (the hole, the grasp, the peg's lower end), its motions, its sensing.

The task keeps the start, the disturbance and success; the loop and the controllers do not
know which strategy runs. See docs/architecture.md, "A new strategy".
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import ConfigError, UnknownComponent
from peg_ctrl.planners.base import MotionLimits, Planner, Waypoint
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.sensing import Detector, WristSensor
from peg_ctrl.sim.state import ControlState
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.belief import TaskBelief
from peg_ctrl.tasks.phases import Motion, PhaseMachine, PhaseSpec
from peg_ctrl.tasks.strategies.motions import Pressing

__all__ = [
    "DEFAULT_STRATEGY",
    "HeldInsertion",
    "PushIn",
    "Strategy",
    "StrategyConfig",
    "TaskDisturbance",
    "never",
]

_Vec = NDArray[np.float64]

#: The strategy a held insertion gets when its config names none.
DEFAULT_STRATEGY = "force"


class TaskDisturbance(Protocol):
    """The held-insertion disturbances a strategy's :meth:`StrategyConfig.check` may read [m, rad]."""

    @property
    def lateral_error(self) -> float: ...

    @property
    def tilt_error(self) -> float: ...

    @property
    def position_noise(self) -> float: ...

    @property
    def grip_above_centre(self) -> float: ...


class HeldInsertion(Protocol):
    """The held-insertion task as a strategy sees it.

    Geometry from the drawing [m]: ``block_top`` (the hole's mouth), ``radius`` (the peg's),
    ``hole_radius``, ``chamfer`` and ``drawing_sides`` (the hole's axis to the block's +x, -x, +y,
    -y sides). Belief: ``observed_hole`` (x, y) [m, world frame: a camera's estimate] and
    ``z_face`` [m], which a strategy may revise (:meth:`recalibrate`). Motion: ``goal`` (the last planned
    waypoint), :meth:`move` plans from it; ``planner``, ``limits``. Sensing: ``wrist`` (the
    estimated contact wrench about the peg's believed lower end, with its noise:
    :class:`~peg_ctrl.sim.sensing.WristSensor`) and ``contact`` (the detection of a push on the
    hand from it, k sigma with hysteresis); :meth:`feel` updates both (``feel_free`` while the
    hand is clear of the block, so the estimate follows the sensor's bias). ``machine`` is the
    phase machine (time in phase).
    """

    scene: SceneConfig
    planner: Planner
    limits: MotionLimits
    control_dt: float
    start_height: float
    block_top: float
    radius: float
    hole_radius: float
    chamfer: float
    observed_hole: _Vec
    drawing_sides: _Vec
    z_face: float
    machine: PhaseMachine
    knowledge: TaskBelief  # the task's belief over what the cell leaves open (peg_ctrl.tasks.belief)
    knowledge_across: _Vec  # its frame: the direction across the pads (world x, y) at the start
    knowledge_quat: _Vec  # ... and the hand's orientation then
    plan_depth: float | None  # set: the strategy hands over to a planning controller (Belief.plan_depth)

    contact: Detector

    @property
    def wrist(self) -> WristSensor: ...

    @property
    def pose_repeatability(self) -> float: ...

    @property
    def drawing_tolerance(self) -> float: ...

    @property
    def speed_noise(self) -> float: ...

    @property
    def hand_velocity(self) -> _Vec: ...

    @property
    def goal(self) -> Waypoint: ...

    @goal.setter
    def goal(self, value: Waypoint) -> None: ...

    @property
    def min_depth(self) -> float:
        """The success criterion's depth [m]."""
        ...

    def move(self, goal: Waypoint, limits: MotionLimits | None = None) -> Motion:
        """Plan from the last goal to ``goal``, which becomes the last goal."""
        ...

    def hold_here(self, obs: Observation) -> None:
        """The last goal becomes the present position (a motion ended in contact)."""
        ...

    def believed_bottom(self, obs: Observation) -> _Vec: ...

    def believed_bottom_of(self, w: Waypoint) -> _Vec: ...

    def believed_depth(self, obs: Observation) -> float: ...

    def pinch_for(self, bottom: _Vec, q_grip: _Vec) -> _Vec: ...

    def in_bore(self, obs: Observation) -> str | None: ...

    def seated_detected(self, obs: Observation) -> bool: ...

    def feel(self, obs: Observation, *, free: bool = False) -> None: ...

    def feel_free(self, obs: Observation) -> None: ...

    def recalibrate(self, obs: Observation, *, quat: _Vec | None = None) -> None: ...

    @property
    def grasp_body(self) -> _Vec: ...

    @property
    def grip_length(self) -> float: ...

    @property
    def up_body(self) -> _Vec: ...

    def revise_axis(self, up_body: _Vec, state: ControlState, *, grasp_shift: _Vec | None = None) -> None: ...


def never(obs: Observation) -> None:
    """A guard that never ends its phase (its time budget, or the task's success, does)."""
    return None


class PushIn:
    """The push to seated, for a strategy's last phase: hold the present pose laterally (or let
    the lateral ``axes`` free), push down with ``force`` [N], and ease off above ``speed``
    [m/s] of descent (to 0 N at twice it): a peg that drops freely down the bore rattles
    against its walls, each tap a force spike."""

    def __init__(self, task: HeldInsertion, force: float, speed: float) -> None:
        self.task = task
        self.force = force
        self.speed = speed
        self._pressing = Pressing(task.goal, force)

    def enter(self, obs: Observation, axes: tuple[bool, ...] | None = None) -> Motion:
        self.task.hold_here(obs)
        self._pressing = Pressing(self.task.goal, self.force, axes)
        return self._pressing

    def govern(self, obs: Observation) -> None:
        self.task.feel(obs)
        excess = max(0.0, -float(obs.gripper.v_world[2]) - self.speed)
        self._pressing.set_force(self.force * max(0.0, 1.0 - excess / self.speed))


class Strategy:
    """One episode of a strategy: its phase rows, driving ``task``. Subclasses write
    :meth:`phase_table` (and keep whatever state their phases need)."""

    #: The phase ``settle`` hands over to.
    first: ClassVar[str] = "approach"

    def __init__(self, task: HeldInsertion, config: Any) -> None:
        self.task = task
        self.cfg = config
        #: The skills played, with the decisions that chose them (a planning strategy's: ``plan``).
        self.skill_log: list[dict[str, Any]] = []

    def phase_table(self) -> dict[str, PhaseSpec]:
        """The strategy's rows of the phase table (``settle`` is the task's)."""
        raise NotImplementedError(f"{type(self).__name__} has no phase table")

    def motion_over(self, obs: Observation) -> bool:
        """Whether the running phase's motion has played out (a strategy that runs phases of
        its own inside one of the task's, ``plan``, answers for its own)."""
        return self.task.machine.motion_over(obs.t)

    def _motion_done(self, obs: Observation) -> str | None:
        """A guard: ``ok`` once the phase's motion has played out."""
        return "ok" if self.motion_over(obs) else None


@dataclasses.dataclass(frozen=True)
class StrategyConfig:
    """Base of every strategy's config: a frozen dataclass with a registered ``name``.

    ``task: {name: held_insertion, strategy: spiral}`` or ``strategy: {name: spiral,
    spiral_pitch: 0.001}`` picks the class from :data:`peg_ctrl.tasks.strategies.STRATEGIES`.
    Every numeric field must be finite and > 0 unless it is listed in ``NON_NEGATIVE``; a
    field declared ``bool`` must be true or false.
    """

    name: ClassVar[str]
    #: Every phase the strategy may enter, in order (the force trace stores their index).
    phases: ClassVar[tuple[str, ...]]
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type in (bool, "bool"):
                if not isinstance(value, bool):
                    raise ConfigError(f"task.strategy.{f.name} must be true or false, got {value!r}")
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"task.strategy.{f.name} must be a finite number, got {value!r}")
            if f.name in self.NON_NEGATIVE:
                if value < 0:
                    raise ConfigError(f"task.strategy.{f.name} must be >= 0, got {value!r}")
            elif value <= 0:
                raise ConfigError(f"task.strategy.{f.name} must be > 0, got {value!r}")

    def build(self, task: HeldInsertion) -> Strategy:
        """The strategy this config describes, for one episode of ``task``."""
        raise NotImplementedError(f"{type(self).__name__} does not build a strategy")

    def check(self, scene: SceneConfig, task: TaskDisturbance) -> None:
        """Raise :class:`ConfigError` if the strategy cannot run in ``scene`` with ``task``'s
        disturbances (default: it can)."""

    @classmethod
    def select(cls, data: object, *, prefix: str = "task.strategy.") -> StrategyConfig:
        """The config named by ``data``: a name, a mapping ``{"name": ..., <fields>}`` or a config.

        Raises:
            UnknownComponent: for a name that is not a registered strategy (the message lists them).
            ConfigError: for a bad field name or value, naming it as ``<prefix><field>``.
        """
        from peg_ctrl.config import load, named_fields
        from peg_ctrl.tasks.strategies import STRATEGIES  # here: the registry imports this module

        if isinstance(data, StrategyConfig):
            return data
        name, fields = named_fields(data, kind="strategy", default=DEFAULT_STRATEGY, prefix=prefix)
        if name not in STRATEGIES:
            raise UnknownComponent("strategy", name, STRATEGIES, where=prefix.rstrip("."))
        return load(STRATEGIES[name], fields, prefix=prefix)
