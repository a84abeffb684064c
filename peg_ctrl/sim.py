"""A minimal closed loop: physics at the model timestep, a controller at its own period.

The loop, not the controller, owns time. The controller's period must be a whole multiple of
the physics timestep; between control updates the last command is held (zero-order hold).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from controllers.base import Controller, ControlOutput
from peg_ctrl.commands import GripperTarget
from peg_ctrl.scene import HOME_KEY
from peg_ctrl.state import ControlState, StateReader

__all__ = ["Simulation", "control_decimation"]


def control_decimation(control_dt: float, timestep: float) -> int:
    """Physics steps per control step; ``control_dt`` [s] must be a whole multiple of ``timestep``."""
    if not (math.isfinite(control_dt) and control_dt > 0):
        raise ValueError(f"control_dt must be finite and > 0 s, got {control_dt!r}")
    ratio = control_dt / timestep
    n = round(ratio)
    if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
        raise ValueError(
            f"control_dt {control_dt} s is not a whole multiple of the physics timestep {timestep} s"
        )
    return int(n)


class Simulation:
    """Model, data, state reader and controller, stepped together."""

    def __init__(self, model: mujoco.MjModel, controller: Controller) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.reader = StateReader(model)
        self.controller = controller
        self.decimation = control_decimation(controller.control_dt, model.opt.timestep)
        self.last_output: ControlOutput | None = None
        self.reset()

    def reset(self, qpos: np.ndarray | None = None) -> ControlState:
        """Restore the ``home`` keyframe (or ``qpos``), zero velocities, one ``mj_forward``."""
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key(HOME_KEY).id)
        if qpos is not None:
            self.data.qpos[:] = qpos
        mujoco.mj_forward(self.model, self.data)
        state = self.reader.control_state(self.data)
        self.controller.reset(state)
        return state

    def control_step(self, target: GripperTarget) -> ControlOutput:
        """One control update followed by ``decimation`` physics steps."""
        state = self.reader.control_state(self.data)
        out = self.controller.compute(state, target)
        self.data.ctrl[:] = out.ctrl
        self.last_output = out
        mujoco.mj_step(self.model, self.data, nstep=self.decimation)
        return out

    def state(self) -> ControlState:
        return self.reader.control_state(self.data)

    def hold(self, target: GripperTarget, duration_s: float) -> ControlState:
        """Track a constant ``target`` for ``duration_s`` [s]; returns the final state."""
        n = int(round(duration_s / (self.decimation * self.model.opt.timestep)))
        for _ in range(n):
            self.control_step(target)
        return self.state()
