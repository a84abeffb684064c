"""Tasks: what the gripper should do, and whether it succeeded (see :mod:`peg_ctrl.tasks.base`).

:data:`TASKS` maps each task config's ``name`` to its class (``task: {name: held_insertion}``).
"""

from peg_ctrl.tasks.base import Evaluation, Observation, PhaseRecord, Task, TaskContext, TaskSpec
from peg_ctrl.tasks.held_insertion import HeldInsertionConfig, HeldInsertionTask
from peg_ctrl.tasks.phases import DONE, PhaseMachine, PhaseSpec, Timeout
from peg_ctrl.tasks.pick_and_place import PickAndPlaceConfig, PickAndPlaceTask
from peg_ctrl.tasks.strategies import STRATEGIES, StrategyConfig, register_strategy
from peg_ctrl.tasks.tracking import TrackingTask

__all__ = [
    "Evaluation",
    "Observation",
    "PhaseRecord",
    "Task",
    "TaskContext",
    "TaskSpec",
    "TASKS",
    "STRATEGIES",
    "StrategyConfig",
    "register_strategy",
    "DONE",
    "PhaseMachine",
    "PhaseSpec",
    "Timeout",
    "PickAndPlaceConfig",
    "PickAndPlaceTask",
    "HeldInsertionConfig",
    "HeldInsertionTask",
    "TrackingTask",
]

#: Task name -> its config class (whose ``build(context)`` makes the task).
TASKS: dict[str, type[TaskSpec]] = {cfg.name: cfg for cfg in (PickAndPlaceConfig, HeldInsertionConfig)}
