"""Track targets with a controller: the smallest driver of the loop.

For controller studies, tests and the benchmark: no task logic, no success criterion; the
caller sets a target and advances time. Everything still runs through :class:`~peg_ctrl.run.loop.Loop`.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.base import Controller, ControlOutput
from peg_ctrl.run.loop import Loop
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.state import ControlState
from peg_ctrl.tasks.tracking import TrackingTask

__all__ = ["Tracker"]


class Tracker:
    """A controller on ``model`` tracking the target set by :meth:`control_step` or :meth:`hold`.

    The scene starts at the ``home`` keyframe (or at ``qpos`` given to :meth:`reset`); the
    gripper holds its home pose until the first target.
    """

    def __init__(
        self, model: mujoco.MjModel, controller: Controller, *, scene: SceneConfig | None = None
    ) -> None:
        home = model.key("home").qpos
        self.task = TrackingTask(
            GripperTarget(p_world=home[:3].copy(), quat_world=home[3:7].copy(), jaw_sep_m=0.085)
        )
        self.loop = Loop(model=model, controller=controller, task=self.task, scene=scene or SceneConfig())
        self.model = model
        self.data = self.loop.data
        self.controller = controller
        self.decimation = self.loop.decimation
        self.reset()

    def reset(self, qpos: NDArray[np.float64] | None = None) -> ControlState:
        """Restore the ``home`` keyframe (or ``qpos``), zero velocities, one ``mj_forward``."""
        self.task.qpos = qpos
        self.loop.reset(np.random.default_rng(0))
        return self.state()

    def control_step(self, target: GripperTarget) -> ControlOutput:
        """One control update towards ``target`` and its physics steps."""
        self.task.set_target(target)
        self.loop.step()
        assert self.loop.output is not None
        return self.loop.output

    def hold(self, target: GripperTarget, duration_s: float) -> ControlState:
        """Track a constant ``target`` for ``duration_s`` [s]; returns the final state."""
        self.task.set_target(target)
        for _ in range(round(duration_s / self.loop.control_dt)):
            self.loop.step()
        return self.state()

    def state(self) -> ControlState:
        return self.loop.state()
