"""The interface every controller implements."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.scene import BALL_ACTUATORS, JAW_ACTUATOR, SLIDE_ACTUATORS
from peg_ctrl.state import ControlState

__all__ = ["Controller", "ControlOutput", "Diagnostics", "ActuatorMap", "check_target"]


class Diagnostics(NamedTuple):
    """Per-call diagnostics for the logs: wall time of ``compute`` [s], solver status, iterations."""

    solve_time_s: float = 0.0
    status: str = "ok"
    iterations: int = 0


class ControlOutput(NamedTuple):
    """Actuator controls ``ctrl`` (nu,) in model order, plus diagnostics.

    (NamedTuples rather than frozen dataclasses: they are built at 1 kHz.)
    """

    ctrl: Sequence[float]
    diagnostics: Diagnostics = Diagnostics()


class Controller(Protocol):
    """A controller gets the model at construction and never steps or forwards the simulation.

    The episode loop owns time: it calls :meth:`reset` once with the initial state, then
    :meth:`compute` every control period and writes ``ControlOutput.ctrl`` into ``data.ctrl``.
    """

    name: str
    control_dt: float  # control period [s], a whole multiple of the physics timestep

    def reset(self, state: ControlState) -> None: ...

    def compute(self, state: ControlState, target: GripperTarget) -> ControlOutput: ...


class ActuatorMap:
    """Indices of the slide, ball and jaw actuators in ``data.ctrl``, resolved once."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.nu = model.nu
        self.slides = np.array([model.actuator(n).id for n in SLIDE_ACTUATORS])
        self.ball = np.array([model.actuator(n).id for n in BALL_ACTUATORS])
        self.jaw = int(model.actuator(JAW_ACTUATOR).id)
        self.slide_limit = model.actuator_ctrlrange[self.slides, 1].copy()
        self._slides = [int(i) for i in self.slides]
        self._ball = [int(i) for i in self.ball]
        self.ball_limit = model.actuator_ctrlrange[self.ball, 1].copy()

    def pack(
        self, force_world: Sequence[float], torque_body: Sequence[float], jaw_byte: float
    ) -> list[float]:
        """``ctrl`` (nu,) from slide forces [N], ball torques [N m] and the jaw byte."""
        values = [0.0] * self.nu
        for i, f in zip(self._slides, force_world, strict=True):
            values[i] = f
        for i, t in zip(self._ball, torque_body, strict=True):
            values[i] = t
        values[self.jaw] = jaw_byte
        return values


def check_target(target: GripperTarget) -> None:
    """Reject a target with non-finite entries (``GripperTarget`` validates on construction,
    but arrays are mutable, so controllers re-check cheaply)."""
    total = (
        float(target.p_world.sum())
        + float(target.quat_world.sum())
        + float(target.v_world.sum())
        + float(target.omega_body.sum())
        + float(target.jaw_sep_m)
    )
    if not math.isfinite(total):  # a NaN or inf anywhere makes the sum non-finite
        raise ValueError(
            f"target must be finite, got p_world={target.p_world.tolist()}, "
            f"quat_world={target.quat_world.tolist()}, jaw_sep_m={target.jaw_sep_m}"
        )
