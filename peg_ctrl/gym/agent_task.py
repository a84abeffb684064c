"""The task an agent drives in ``peg_ctrl/PegInsertion-v0``: its actions are the targets.

A task family's task (``held_insertion``, ``pick_and_place``) gives the start state and the
insertion check; its own phase machine is not run.
"""

from __future__ import annotations

from typing import ClassVar

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.config import ConfigError
from peg_ctrl.tasks.base import (
    Capabilities,
    Evaluation,
    Observation,
    PhaseRecord,
    Task,
    close_open_record,
    insertion_task,
)

__all__ = ["AgentTask"]


class AgentTask:
    """A task whose targets are an agent's commands: the start state and the insertion check
    come from ``inner`` (a task family's task), whose own phase machine is not run.

    Success is ``inner``'s seated criterion held for its ``SeatedHold`` steps; the episode
    never ends by itself otherwise (the environment truncates it).
    """

    name = "agent"
    phases: tuple[str, ...] = ("agent",)
    capabilities: ClassVar[Capabilities] = Capabilities(insertion=True)

    def __init__(self, inner: Task) -> None:
        inserting = insertion_task(inner)
        if inserting is None:
            raise ConfigError(f"task {inner.name!r} has no insertion check to drive with actions")
        self.inner = inner
        self.insertion = inserting.insertion
        self.seated = inserting.seated
        self.command: GripperTarget | None = None
        self._records: list[PhaseRecord] = []

    @property
    def phase(self) -> str:
        return "agent"

    @property
    def grasped(self) -> bool:
        return self.inner.grasped

    @property
    def time_to_insert(self) -> float | None:
        return self.seated.since

    @property
    def records(self) -> list[PhaseRecord]:
        return self._records

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        self.inner.reset(model, data, rng)
        self.seated.reset()
        self._records = []
        self.command = None

    def start(self, obs: Observation) -> None:
        self._records.append(PhaseRecord("agent", obs.t))

    def target(self, obs: Observation) -> GripperTarget:
        if self.command is None:
            raise RuntimeError("AgentTask.target before a command was set")
        return self.command

    def evaluate(self, obs: Observation) -> Evaluation:
        m = self.insertion.measure(obs.peg)
        if self.seated.update(obs.t, self.insertion.criterion(m)):
            self.finish(obs.t, "inserted")
            return Evaluation(True, True, "", "seated", m)
        return Evaluation(False, False, "", "", m)

    def finish(self, t: float, outcome: str) -> None:
        close_open_record(self._records, t, outcome)
