"""The task interface: what the loop asks of a task, and what a task reports back.

A task resets the scene from a random generator, turns observations into gripper targets, and
evaluates named metrics and success or failure after every control step (ManiSkill's
``evaluate()``). It never steps or forwards the simulation during an episode: the loop owns
time. (Building the initial state in :meth:`Task.reset` may simulate, as the held-insertion
task closes the jaw on its peg; the episode's clock starts after it.)

What a task offers beyond :class:`Task` is declared, not probed: its class states its
:class:`Capabilities`, each promising the members of a typed protocol (:class:`InsertionTask`,
:class:`BeliefTask`). The loop checks the declaration against the task once, when it is built
(:func:`check_capabilities`); the layers above then reach a capability through
:func:`insertion_task` and :func:`belief_task`.
"""

from __future__ import annotations

import dataclasses
import inspect
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, Protocol, cast

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.errors import ConfigError, UnknownComponent
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.state import ControlState, PegObservation
from peg_ctrl.tasks.monitors import InsertionMonitor, SeatedHold

if TYPE_CHECKING:
    from peg_ctrl.planners.base import MotionLimits, Planner
    from peg_ctrl.sim.jaw import JawCalibration
    from peg_ctrl.sim.scene import SceneConfig

__all__ = [
    "Observation",
    "Evaluation",
    "Task",
    "Capabilities",
    "InsertionTask",
    "BeliefTask",
    "SkillTask",
    "check_capabilities",
    "insertion_task",
    "belief_task",
    "skill_task",
    "TaskSpec",
    "TaskContext",
    "PhaseRecord",
    "close_open_record",
    "DEFAULT_TASK",
]

#: The task a config gets when its ``task`` mapping names none.
DEFAULT_TASK = "pick_and_place"


class Observation(NamedTuple):
    """What a task sees at time ``t`` [s]: the gripper as sensed (with any sensor noise) and the peg."""

    t: float
    gripper: ControlState
    peg: PegObservation


class Evaluation(NamedTuple):
    """A task's verdict after a control step.

    ``done`` ends the episode; ``success`` says how; ``reason`` (one of
    :data:`~peg_ctrl.errors.FAILURE_REASONS`, empty on success) and ``detail`` explain a failure;
    ``metrics`` holds the task's named measurements (a NamedTuple, e.g. an
    :class:`~peg_ctrl.tasks.monitors.InsertionMeasure`).
    """

    done: bool
    success: bool
    reason: str
    detail: str
    metrics: Any


class PhaseRecord:
    """One phase of a task: its name, start and end time [s], and outcome ("ok", "timeout", ...)."""

    __slots__ = ("phase", "t_start", "t_end", "outcome")

    def __init__(self, phase: str, t_start: float, t_end: float | None = None, outcome: str = "") -> None:
        self.phase = phase
        self.t_start = t_start
        self.t_end = t_end
        self.outcome = outcome

    def to_dict(self) -> dict[str, Any]:
        return {"phase": self.phase, "t_start": self.t_start, "t_end": self.t_end, "outcome": self.outcome}


def close_open_record(records: list[PhaseRecord], t: float, outcome: str) -> None:
    """End the last record at ``t`` [s] if it is still open; an outcome set earlier is kept."""
    if records and records[-1].t_end is None:
        records[-1].t_end = t
        records[-1].outcome = records[-1].outcome or outcome


@dataclasses.dataclass(frozen=True)
class Capabilities:
    """What a task offers beyond the :class:`Task` protocol, declared by its class.

    Each flag promises the members of one protocol, which :func:`check_capabilities` verifies
    when the loop is built; a task that has those members without declaring them is refused too.

    Attributes:
        insertion: The task measures the peg at the hole and holds it to a seated criterion
            (:class:`InsertionTask`: ``insertion``, ``seated``, ``time_to_insert``); the episode
            summary's hole metrics and time to insert come from it.
        belief: The task states what it believes about the hole and the grasp
            (:class:`BeliefTask`: ``belief``), which the loop hands to a controller that
            observes beliefs.
        skills: The task's strategy plays skills into a belief (:class:`SkillTask`: ``readings``,
            ``skill_log``); the episode summary records them (``belief``, ``skills``).
    """

    insertion: bool = False
    belief: bool = False
    skills: bool = False


class Task(Protocol):
    """What the loop needs from a task."""

    name: str
    phases: tuple[str, ...]  # every phase name, in order (the force trace stores their index)

    @property
    def capabilities(self) -> Capabilities:
        """What the task offers beyond this protocol (a class attribute)."""
        ...

    @property
    def phase(self) -> str:
        """The current phase, for logs."""
        ...

    @property
    def grasped(self) -> bool:
        """Whether the peg is meant to be held (the loop then watches for slip)."""
        ...

    @property
    def records(self) -> list[PhaseRecord]:
        """Phases so far, the current one last."""
        ...

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        """Set the initial state in ``data`` (already at the ``home`` keyframe), drawing from ``rng``."""
        ...

    def start(self, obs: Observation) -> None:
        """Called once after :meth:`reset`, with the first observation (noise-free)."""
        ...

    def target(self, obs: Observation) -> GripperTarget:
        """The gripper target for this control step."""
        ...

    def evaluate(self, obs: Observation) -> Evaluation:
        """Metrics and verdict after the physics step (``obs.gripper`` is the state the step started from)."""
        ...

    def finish(self, t: float, outcome: str) -> None:
        """The episode ended at ``t`` [s] with ``outcome``: close the open phase record."""
        ...


class InsertionTask(Task, Protocol):
    """A task with ``Capabilities(insertion=True)``: it measures the peg at the hole and holds
    it to a seated criterion."""

    insertion: InsertionMonitor  # the peg's measures at the hole, the last one and the criterion
    seated: SeatedHold  # how long the criterion has held

    @property
    def time_to_insert(self) -> float | None:
        """When the seated hold that succeeded (or is under way) began [s]; None before."""
        ...


class BeliefTask(Task, Protocol):
    """A task with ``Capabilities(belief=True)``: it states what it believes about the world."""

    @property
    def belief(self) -> Belief:
        """The hole and the grasp as the task believes them (a new object when they change)."""
        ...


class SkillTask(Task, Protocol):
    """A task with ``Capabilities(skills=True)``: its strategy plays skills whose readings a
    belief takes in (:mod:`peg_ctrl.tasks.belief`)."""

    @property
    def readings(self) -> list[dict[str, Any]]:
        """What the task's belief took in so far, reading by reading: the time, the skill, the
        information [bits] and the belief's spreads after it."""
        ...

    @property
    def skill_log(self) -> list[dict[str, Any]]:
        """The skills its strategy chose and played, with its decisions (a planning strategy's;
        empty for a script)."""
        ...


_ABSENT = object()

#: Each capability (a :class:`Capabilities` field) and the protocol whose members it promises.
_PROTOCOLS: dict[str, type] = {"insertion": InsertionTask, "belief": BeliefTask, "skills": SkillTask}


def _members(protocol: type) -> tuple[str, ...]:
    """The members a capability's protocol adds to :class:`Task`, in a fixed order."""
    own = {name for name in vars(protocol) if not name.startswith("_")}
    return tuple(sorted(own | set(vars(protocol).get("__annotations__", {}))))


def check_capabilities(task: object) -> None:
    """Check that ``task``'s class declares its :class:`Capabilities` and that each one it
    declares, and none other, matches the members the task has.

    Members are looked up without running them (a property is not evaluated), once per loop.

    Raises:
        TypeError: naming the task, the capability and the members that are missing, or that
            are there undeclared.
    """
    label = f"task {type(task).__name__}"
    declared = inspect.getattr_static(task, "capabilities", _ABSENT)
    if not isinstance(declared, Capabilities):
        raise TypeError(f"{label} does not declare its capabilities (capabilities = Capabilities(...))")
    for flag, claimed in dataclasses.asdict(declared).items():
        members = _members(_PROTOCOLS[flag])
        missing = [m for m in members if inspect.getattr_static(task, m, _ABSENT) is _ABSENT]
        if claimed and missing:
            raise TypeError(f"{label} declares capability {flag!r} but lacks {', '.join(missing)}")
        if not claimed and not missing:
            raise TypeError(
                f"{label} has {', '.join(members)} but does not declare capability {flag!r} "
                f"(capabilities = Capabilities({flag}=True))"
            )


def insertion_task(task: Task) -> InsertionTask | None:
    """``task`` as an :class:`InsertionTask` if it declares ``insertion``, else None."""
    return cast("InsertionTask", task) if task.capabilities.insertion else None


def belief_task(task: Task) -> BeliefTask | None:
    """``task`` as a :class:`BeliefTask` if it declares ``belief``, else None."""
    return cast("BeliefTask", task) if task.capabilities.belief else None


def skill_task(task: Task) -> SkillTask | None:
    """``task`` as a :class:`SkillTask` if it declares ``skills``, else None."""
    return cast("SkillTask", task) if task.capabilities.skills else None


class TaskContext(NamedTuple):
    """What every task is built with, besides its own config (from the episode's config)."""

    scene: SceneConfig
    success: Any  # peg_ctrl.tasks.pick_and_place.SuccessConfig
    randomization: Any  # peg_ctrl.tasks.pick_and_place.RandomizationConfig
    planner: Planner
    limits: MotionLimits
    jaw: JawCalibration
    control_dt: float = 0.001  # the controller's period [s]


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """Base of every task's config: a frozen dataclass with a registered ``name``.

    ``task: {name: held_insertion, strategy: spiral}`` in a config file picks the class from
    :data:`peg_ctrl.tasks.TASKS`; a mapping without ``name`` means :data:`DEFAULT_TASK`.
    """

    name: ClassVar[str]

    @property
    def strategy_name(self) -> str:
        """The name of the insertion strategy the task runs (``task.strategy``); "" for a task
        without strategies (the default)."""
        return ""

    def with_strategy(self, strategy: Any) -> TaskSpec:
        """This config running ``strategy`` (a strategy config) instead of its own.

        Raises:
            ConfigError: for a task without strategies (the default).
        """
        raise ConfigError(
            f"task {self.name!r} has no strategy to replace; use task: {{name: held_insertion}}"
        )

    def build(self, context: TaskContext) -> Task:
        """The task this config describes."""
        raise NotImplementedError(f"{type(self).__name__} does not build a task")

    def check(self, scene: SceneConfig) -> None:
        """Raise :class:`ConfigError` if this task cannot run in ``scene`` (default: it can)."""

    def draws_from_seed(self, randomization: Any) -> bool:
        """Whether the task's reset draws from the episode's seed, given the episode's
        ``randomization`` (a :class:`~peg_ctrl.tasks.pick_and_place.RandomizationConfig`).
        Default: it does."""
        return True

    @classmethod
    def select(cls, data: object, *, prefix: str = "task.") -> TaskSpec:
        """The config named by ``data``: a name, a mapping ``{"name": ..., <fields>}`` or a config.

        Raises:
            UnknownComponent: for a name that is not a registered task (the message lists them).
            ConfigError: for a bad field name or value, naming it as ``<prefix><field>``.
        """
        from peg_ctrl.config import load, named_fields
        from peg_ctrl.tasks import TASKS  # here: the registry imports this module

        if isinstance(data, TaskSpec):
            return data
        name, fields = named_fields(data, kind="task", default=DEFAULT_TASK, prefix=prefix)
        if name not in TASKS:
            raise UnknownComponent("task", name, TASKS, where=f"{prefix}name")
        return load(TASKS[name], fields, prefix=prefix)
