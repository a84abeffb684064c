"""Differential inverse kinematics with mink, tracked by a joint-space PD.

Every ``ik_dt`` (default 10 ms, 100 Hz) a QP (``mink.solve_ik``) finds base joint velocities that
move the ``gripper_root`` frame towards the target pose — a frame task (position + orientation),
a damping task on every DoF, velocity limits and the slide configuration limits — and integrates
them into a setpoint. At every control step (1 kHz) the reference ``pd`` controller tracks that
setpoint, with the IK velocity as feed-forward.

mink runs on the robot-only model (base stack + gripper, fingers held open); the ball joint is
unlimited (mink's configuration limit would otherwise treat its range as a total-angle bound).
Limits are built once, not per call.

Force- and moment-controlled axes (``target.wrench_axes``, or a non-zero ``target.force_world``
entry) are handed to the inner PD, which realises them open loop (see
:mod:`peg_ctrl.controllers.pd`) — unless the ``admittance`` field sets an admittance outer loop on
the force/torque sensor (:class:`~peg_ctrl.controllers.admittance.AdmittanceLoop`): then every
control step the admittance law turns the target (its force- and moment-controlled axes
included) into a shifted pose, closed loop on the sensor about the ``compliance_center`` it
names (the held peg's tip), and the IK tracks that pose. The outer loop runs at the controller's
``control_dt``; the IK at ``ik_dt``. (The admittance config's own ``inner`` and ``control_dt``
are not used there.)

The inner ``pd`` controller is configured by the ``inner`` field (its gains are scaled with the
IK costs by :meth:`~peg_ctrl.controllers.base.ControllerConfig.scaled`); it runs at the
controller's ``control_dt`` (``inner.control_dt`` is replaced by it), and only its control law
is called, so saturation and packing happen once.
"""

from __future__ import annotations

import dataclasses
import time
from typing import ClassVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.admittance import AdmittanceConfig, AdmittanceLoop
from peg_ctrl.controllers.base import (
    ControllerBase,
    ControllerConfig,
    Effort,
    InvalidField,
    SolveTiming,
    check_multiple,
    check_target,
)
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.scene import BALL_JOINT, SLIDE_JOINTS, build_robot_spec
from peg_ctrl.sim.state import ControlState

__all__ = ["DiffIKConfig", "DiffIKController"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class DiffIKConfig(ControllerConfig):
    """IK task weights, limits and rate (``control_dt`` [s], the inner PD's, from the base class)."""

    name: ClassVar[str] = "diffik"
    GAINS: ClassVar[tuple[str, ...]] = ("position_cost", "orientation_cost")
    control_dt: float = 0.005  # [s] 200 Hz: outcomes as at 1 kHz (docs/performance.md)
    ik_dt: float = 0.01  # IK period [s] (100 Hz), a whole multiple of control_dt
    solver: str = "daqp"  # any qpsolvers solver: daqp (default), osqp, ...
    position_cost: float = 1.0  # frame task weight on the position error
    orientation_cost: float = 1.0  # frame task weight on the orientation error
    damping_cost: float = 1e-3  # damping task weight on every DoF
    lm_damping: float = 1e-6  # Levenberg-Marquardt damping of the frame task
    v_max: float = 0.5  # slide velocity limit [m/s]
    omega_max: float = 1.5  # ball joint velocity limit [rad/s]
    inner: PDConfig = PDConfig()  # tracks the IK setpoint; its control_dt is replaced by ours
    admittance: AdmittanceConfig | None = None  # an outer admittance loop on the F/T sensor

    def __post_init__(self) -> None:
        super().__post_init__()
        check_multiple(self, "ik_dt")
        import qpsolvers

        if self.solver not in qpsolvers.available_solvers:
            raise InvalidField(
                self.name,
                "solver",
                f"{self.solver!r} is not installed; available: "
                f"{', '.join(sorted(qpsolvers.available_solvers))}",
            )

    def build(self, model: mujoco.MjModel) -> DiffIKController:
        return DiffIKController(model, self)


class DiffIKController(ControllerBase[DiffIKConfig]):
    """Differential IK (mink) at ``ik_dt``, tracked by the reference PD. See the module docstring."""

    name = "diffik"

    def __init__(
        self,
        model: mujoco.MjModel,
        config: DiffIKConfig | None = None,
        *,
        jaw_calibration: JawCalibration | None = None,
    ) -> None:
        import mink

        super().__init__(model, config or DiffIKConfig(), jaw_calibration=jaw_calibration)
        self._mink = mink
        c = self.config
        self._every = check_multiple(c, "ik_dt")
        self.inner = PDController(
            model, dataclasses.replace(c.inner, control_dt=c.control_dt), jaw_calibration=self._jaw
        )
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
        self.solve_times: list[float] = []  # wall time of every QP solve [s]
        self.outer = (
            AdmittanceLoop(model, c.admittance, control_dt=c.control_dt, bumpless=True)
            if c.admittance is not None
            else None
        )

    def _reset(self, state: ControlState) -> None:
        self._q = self.robot.qpos0.copy()
        self._q[:3] = state.p_world
        self._q[3:7] = state.quat_world
        self._v = np.zeros(self.robot.nv)
        self._count = 0
        self.inner.reset(state)
        if self.outer is not None:
            self.outer.reset(state)
        self.solve_times = []

    def timings(self) -> list[SolveTiming]:
        return [SolveTiming("ik_qp", self.config.ik_dt, self.solve_times)]

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

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        status = "hold"
        if self.outer is not None:
            check_target(target)
            target = self.outer.shape(state, target)
        if self._count % self._every == 0:
            check_target(target)  # a failed QP would otherwise hide a non-finite target
            t0 = time.perf_counter()
            try:
                self._v = self.ik_velocity(self._q, target)
                status = "ok"
            except self._mink.exceptions.NoSolutionFound as exc:  # the QP solver's own failure:
                # hold the setpoint, reported in the diagnostics; any other error propagates
                self._v = np.zeros(self.robot.nv)
                status = f"qp_failed: {type(exc).__name__}"
            self.solve_times.append(time.perf_counter() - t0)
            self.configuration.update(self._q)
            self._q = self.configuration.integrate(self._v, self.config.ik_dt)
        self._count += 1
        setpoint = GripperTarget.trusted(
            self._q[:3],
            self._q[3:7],
            self._v[:3],
            self._v[3:6],
            target.jaw_sep_m,
            target.force_world,
            torque_world=target.torque_world,
            wrench_axes=target.wrench_axes,
        )
        effort = self.inner.control_law(state, setpoint)
        return Effort(effort.force_world, effort.torque_body, status, 1 if status == "ok" else 0)
