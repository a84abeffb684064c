"""Differential inverse kinematics with mink, tracked by a joint-space PD.

Every ``ik_dt`` (default 10 ms, 100 Hz) a QP (``mink.solve_ik``) finds base joint velocities that
move the ``gripper_root`` frame towards the target pose — a frame task (position + orientation),
a damping task on every DoF, velocity limits and the slide configuration limits — and integrates
them into a setpoint. At every control step (1 kHz) the reference ``pd`` controller tracks that
setpoint, with the IK velocity as feed-forward.

mink runs on the robot-only model (base stack + gripper, fingers held open); the ball joint is
unlimited (mink's configuration limit would otherwise treat its range as a total-angle bound).
Limits are built once, not per call.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from controllers.base import ControlOutput, Diagnostics
from controllers.pd import PDConfig, PDController
from peg_ctrl.commands import GripperTarget
from peg_ctrl.scene import BALL_JOINT, SLIDE_JOINTS, build_robot_spec
from peg_ctrl.sim import control_decimation
from peg_ctrl.state import ControlState

__all__ = ["DiffIKConfig", "DiffIKController"]


@dataclasses.dataclass(frozen=True)
class DiffIKConfig:
    name: ClassVar[str] = "diffik"
    GAINS: ClassVar[tuple[str, ...]] = ("position_cost", "orientation_cost")
    ik_dt: float = 0.01  # IK period [s] (100 Hz), a whole multiple of control_dt
    solver: str = "daqp"  # any qpsolvers solver: daqp (default), osqp, ...
    position_cost: float = 1.0
    orientation_cost: float = 1.0
    damping_cost: float = 1e-3  # damping task weight on every DoF
    lm_damping: float = 1e-6  # Levenberg-Marquardt damping of the frame task
    v_max: float = 0.5  # slide velocity limit [m/s]
    omega_max: float = 1.5  # ball joint velocity limit [rad/s]
    control_dt: float = 0.001  # inner PD period [s]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, str):
                continue
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"diffik.{f.name} must be finite and > 0, got {value!r}")
        control_decimation(self.ik_dt, self.control_dt)
        import qpsolvers

        if self.solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"diffik.solver {self.solver!r} is not installed; available: "
                f"{', '.join(sorted(qpsolvers.available_solvers))}"
            )


class DiffIKController:
    name = "diffik"

    def __init__(self, model: mujoco.MjModel, config: DiffIKConfig | None = None) -> None:
        import mink

        self._mink = mink
        self.config = config or DiffIKConfig()
        c = self.config
        self.control_dt = c.control_dt
        self._every = control_decimation(c.ik_dt, c.control_dt)
        self.inner = PDController(model, PDConfig(control_dt=c.control_dt))
        self.robot = build_robot_spec().compile()
        self.configuration = mink.Configuration(self.robot)
        self.frame_task = mink.FrameTask(
            "gripper_root",
            "body",
            position_cost=c.position_cost,
            orientation_cost=c.orientation_cost,
            lm_damping=c.lm_damping,
        )
        self.damping_task = mink.DampingTask(self.robot, cost=c.damping_cost)
        velocities: dict[str, float | NDArray[np.float64]] = {name: c.v_max for name in SLIDE_JOINTS}
        velocities[BALL_JOINT] = np.full(3, c.omega_max)
        # Built once: passing limits=None would make mink rebuild its defaults on every call.
        self.limits = [mink.ConfigurationLimit(self.robot), mink.VelocityLimit(self.robot, velocities)]
        self._q = self.robot.qpos0.copy()
        self._v = np.zeros(self.robot.nv)
        self._count = 0
        self.last_status = "ok"

    def reset(self, state: ControlState) -> None:
        self._q = self.robot.qpos0.copy()
        self._q[:3] = state.p_world
        self._q[3:7] = state.quat_world
        self._v = np.zeros(self.robot.nv)
        self._count = 0
        self.inner.reset(state)

    def ik_velocity(self, q: NDArray[np.float64], target: GripperTarget) -> NDArray[np.float64]:
        """One IK step: joint velocities (nv,) moving configuration ``q`` towards ``target``."""
        mink = self._mink
        self.configuration.update(q)
        self.frame_task.set_target(
            mink.SE3.from_rotation_and_translation(
                mink.SO3(np.asarray(target.quat_world)), np.asarray(target.p_world)
            )
        )
        return mink.solve_ik(
            self.configuration,
            [self.frame_task, self.damping_task],
            self.config.ik_dt,
            self.config.solver,
            limits=self.limits,
        )

    def compute(self, state: ControlState, target: GripperTarget) -> ControlOutput:
        t0 = time.perf_counter()
        status = "hold"
        if self._count % self._every == 0:
            if not (np.all(np.isfinite(target.p_world)) and np.all(np.isfinite(target.quat_world))):
                raise ValueError(f"target must be finite, got p_world={target.p_world.tolist()}")
            try:
                self._v = self.ik_velocity(self._q, target)
                status = "ok"
            except Exception as exc:  # a failed QP holds the setpoint; reported in diagnostics
                self._v = np.zeros(self.robot.nv)
                status = f"qp_failed: {type(exc).__name__}"
            self.configuration.update(self._q)
            self._q = self.configuration.integrate(self._v, self.config.ik_dt)
        self._count += 1
        setpoint = GripperTarget.trusted(
            self._q[:3], self._q[3:7], self._v[:3], self._v[3:6], target.jaw_sep_m
        )
        out = self.inner.compute(state, setpoint)
        return ControlOutput(
            out.ctrl, Diagnostics(time.perf_counter() - t0, status, 1 if status == "ok" else 0)
        )
