"""Tracking: follow given targets, with no success criterion of its own.

For benchmarks, controller tests and scripted studies: the driver sets the target (or hands over
a sequence, one target per control step); the task never ends the episode until a sequence is
exhausted.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.tasks.base import Capabilities, Evaluation, Observation, PhaseRecord, close_open_record

__all__ = ["TrackingTask"]

_RUNNING = Evaluation(False, False, "", "", None)
_FINISHED = Evaluation(True, True, "", "targets exhausted", None)


class TrackingTask:
    """Hold ``target`` (settable between steps), or play ``sequence`` one target per control step.

    ``qpos`` (nq,), if given, replaces the home keyframe's positions at reset.
    """

    name = "track"
    phases: tuple[str, ...] = ("track",)
    capabilities: ClassVar[Capabilities] = Capabilities()
    grasped = False

    def __init__(
        self,
        target: GripperTarget | None = None,
        *,
        sequence: Sequence[GripperTarget] | None = None,
        qpos: NDArray[np.float64] | None = None,
    ) -> None:
        if target is None and not sequence:
            raise ValueError("TrackingTask needs a target or a non-empty sequence")
        self.target_now = target if target is not None else sequence[0]  # type: ignore[index]
        self.sequence = sequence
        self.qpos = qpos
        self._index = 0
        self.records: list[PhaseRecord] = []

    @property
    def phase(self) -> str:
        return "track"

    def set_target(self, target: GripperTarget) -> None:
        self.target_now = target

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        if self.qpos is not None:
            data.qpos[:] = self.qpos
        self._index = 0

    def start(self, obs: Observation) -> None:
        self.records = [PhaseRecord("track", obs.t)]

    def target(self, obs: Observation) -> GripperTarget:
        if self.sequence is not None:
            self.target_now = self.sequence[min(self._index, len(self.sequence) - 1)]
            self._index += 1
        return self.target_now

    def evaluate(self, obs: Observation) -> Evaluation:
        if self.sequence is not None and self._index >= len(self.sequence):
            return _FINISHED
        return _RUNNING

    def finish(self, t: float, outcome: str) -> None:
        close_open_record(self.records, t, outcome)
