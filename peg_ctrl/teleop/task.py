"""Teleoperation as a task: the operator's keys set the target; the insertion monitor watches."""

from __future__ import annotations

from typing import ClassVar

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import Capabilities, Evaluation, Observation, PhaseRecord, close_open_record
from peg_ctrl.tasks.monitors import InsertionMeasure, InsertionMonitor, SettledCriterion
from peg_ctrl.tasks.pick_and_place import RandomizationConfig, initial_qpos
from peg_ctrl.teleop.mapper import TeleopConfig, TeleopMapper

__all__ = ["TeleopTask", "crossed"]

_RUNNING = Evaluation(False, False, "", "", None)


def crossed(before: int, now: int, every: int) -> bool:
    """Whether a step count going from ``before`` to ``now`` passed a multiple of ``every``."""
    return now // every != before // every


class TeleopTask:
    """Targets from a :class:`TeleopMapper`, advanced one control period per step.

    Task
        Whatever the operator does; the peg starts lying on the table (randomised from the
        reset's generator with ``randomize``).
    Success
        SPEC §5: peg centre within ``insert_radius`` of the hole axis, its bottom below block
        centre + ``insert_height``, speed ≤ ``settle_speed``; checked every ``check_every``
        physics steps. The episode never ends by itself: the operator quits or resets.
    """

    name = "teleop"
    phases: tuple[str, ...] = ("teleop",)
    # Its insertion check is the operator's settled criterion, read by the session, not a seated hold.
    capabilities: ClassVar[Capabilities] = Capabilities()
    grasped = False  # the operator may let go at any time: no slip monitoring

    def __init__(
        self,
        mapper: TeleopMapper,
        *,
        scene: SceneConfig,
        config: TeleopConfig,
        randomize: bool,
        decimation: int,
    ) -> None:
        self.mapper = mapper
        self.scene = scene
        self.cfg = config
        self.randomization = RandomizationConfig(enabled=randomize)
        self.decimation = decimation
        self.insertion = InsertionMonitor(
            scene,
            SettledCriterion(
                max_radial=config.insert_radius,
                max_bottom_z=scene.block_pos[2] + config.insert_height,
                max_speed=config.settle_speed,
            ),
        )
        self.step_count = 0  # physics steps over all attempts
        self.inserted = False
        self.time_to_insert: float | None = None  # when this attempt's insertion was detected [s]
        self.last_check: InsertionMeasure | None = None
        self.records: list[PhaseRecord] = []
        self._dt = 0.0

    @property
    def phase(self) -> str:
        return "teleop"

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData, rng: np.random.Generator) -> None:
        data.qpos[:] = initial_qpos(model, self.scene, self.randomization, rng)
        self._dt = self.decimation * float(model.opt.timestep)
        self.mapper.reset_command()
        self.inserted = False
        self.time_to_insert = None

    def start(self, obs: Observation) -> None:
        self.records.append(PhaseRecord("teleop", obs.t))

    def target(self, obs: Observation) -> GripperTarget:
        self.mapper.step(self._dt)
        return self.mapper.target()

    def evaluate(self, obs: Observation) -> Evaluation:
        before = self.step_count
        self.step_count += self.decimation
        if crossed(before, self.step_count, self.cfg.check_every):
            self.last_check = self.insertion.measure(obs.peg)
            if not self.inserted and self.insertion.criterion(self.last_check):
                self.inserted = True
                self.time_to_insert = obs.t
        return _RUNNING

    def finish(self, t: float, outcome: str) -> None:
        close_open_record(self.records, t, outcome)
