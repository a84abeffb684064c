"""Tasks: what the gripper should do, and whether it succeeded (see :mod:`peg_ctrl.tasks.base`)."""

from peg_ctrl.tasks.base import Evaluation, Observation, PhaseRecord, Task
from peg_ctrl.tasks.phases import DONE, PhaseMachine, PhaseSpec, Timeout
from peg_ctrl.tasks.pick_and_place import PickAndPlaceTask
from peg_ctrl.tasks.tracking import TrackingTask

__all__ = [
    "Evaluation",
    "Observation",
    "PhaseRecord",
    "Task",
    "DONE",
    "PhaseMachine",
    "PhaseSpec",
    "Timeout",
    "PickAndPlaceTask",
    "TrackingTask",
]
