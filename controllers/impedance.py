"""Task-space impedance control about a centre of compliance, with Pinocchio bias compensation.

The spring acts on the point ``c`` fixed in the gripper frame (``compliance_center``; the pinch
point by default, the held peg's tip for a remote centre of compliance, RCC)::

    F     = K_p (c_d - c) + D_p (dc_d - dc)                   (world frame) [N], applied at c
    tau   = K_r Log(q^-1 q_d) + D_r (omega_d - omega)         (gripper frame) [N m]
    u     = J^T [F; R tau + r x F] + b(q, qdot) + B qdot_d     (r: c relative to the pinch point)

so a force at the peg tip translates the peg without turning it, and a moment about the tip turns
it about the tip with the rotational stiffness ``K_r``: a low ``k_rot`` with the centre at the
tip lets a tilted peg align with the hole as it is pushed in.

Force-controlled axes (``target.force_axes``): the spring term of ``F`` along the axis is replaced
by the commanded force (implicit force control, open loop). Moment-controlled axes
(``target.moment_axes``, world axes): the rotational spring about those axes is replaced by the
commanded ``target.torque_world`` about the centre of compliance, open loop (the damping stays;
``damping_compensation`` decides how freely the wrist then turns).

``K`` per axis; ``D = 2 zeta sqrt(K m)`` from a damping ratio and the apparent mass/inertia at the
pinch point (Pinocchio's mass matrix at the home pose). ``b`` are gravity and Coriolis forces
from the Pinocchio model of the base + gripper, ``B qdot_d`` cancels the joints' own damping
along the reference only (so the impedance about the reference is what is commanded);
``damping_compensation`` cancels that fraction of it along the measured motion as well, so a
compliant wrist is not held back by its joints' damping (the viscous load of a real wrist's
gearing, which a torque-controlled arm compensates the same way). The pinch
point is the ball joint's centre, so ``J`` is the identity in these coordinates; it is still
taken from Pinocchio and checked in the tests.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.base import ControllerBase, ControllerConfig, Effort, InvalidField
from peg_ctrl.controllers.dynamics import BaseDynamics
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.rotations import cross, rotate
from peg_ctrl.sim.scene import BALL_JOINT, SLIDE_JOINTS
from peg_ctrl.sim.state import ControlState

__all__ = ["ImpedanceConfig", "ImpedanceController"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class ImpedanceConfig(ControllerConfig):
    """Stiffness per axis and damping ratio (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "impedance"
    GAINS: ClassVar[tuple[str, ...]] = ("k_pos", "k_rot")
    VECTORS: ClassVar[tuple[str, ...]] = ("compliance_center",)
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("damping_compensation",)
    control_dt: float = 0.005  # [s] 200 Hz: outcomes as at 1 kHz (docs/performance.md)
    k_pos: tuple[float, float, float] = (1500.0, 1500.0, 1500.0)  # translational stiffness [N/m]
    k_rot: tuple[float, float, float] = (120.0, 120.0, 120.0)  # rotational stiffness [N m/rad]
    damping_ratio: float = 1.0  # zeta of D = 2 zeta sqrt(K m)
    v_max: float = 0.5  # caps |K_p e| at the force that drives the damped slide at v_max [m/s]
    compliance_center: tuple[float, float, float] = (0.0, 0.0, 0.0)  # gripper frame [m]
    damping_compensation: float = 0.0  # fraction of the joints' own damping cancelled, in [0, 1)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.damping_compensation < 1.0:
            raise InvalidField(
                self.name, "damping_compensation", f"must be in [0, 1), got {self.damping_compensation!r}"
            )
        for field in ("k_pos", "k_rot"):
            if len(getattr(self, field)) != 3:
                raise InvalidField(self.name, field, f"must hold 3 values, got {getattr(self, field)!r}")

    def build(self, model: mujoco.MjModel) -> ImpedanceController:
        return ImpedanceController(model, self)


class ImpedanceController(ControllerBase[ImpedanceConfig]):
    """Task-space impedance with Pinocchio bias compensation. See the module docstring."""

    name = "impedance"

    def __init__(
        self,
        model: mujoco.MjModel,
        config: ImpedanceConfig | None = None,
        *,
        jaw_calibration: JawCalibration | None = None,
    ) -> None:
        super().__init__(model, config or ImpedanceConfig(), jaw_calibration=jaw_calibration)
        self.dynamics = BaseDynamics()
        slide_dofs = [model.joint(n).dofadr[0] for n in SLIDE_JOINTS]
        ball = model.joint(BALL_JOINT).dofadr[0]
        self._b = np.concatenate([model.dof_damping[slide_dofs], model.dof_damping[ball : ball + 3]])
        m = self.dynamics.mass_matrix(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
        apparent = np.diag(m)
        k = np.array([*self.config.k_pos, *self.config.k_rot])
        self._k = k
        self._d = 2.0 * self.config.damping_ratio * np.sqrt(k * apparent)
        self._cap = (self._b[0] + self._d[0]) * self.config.v_max
        self._err = np.zeros(3)
        self._centre = np.asarray(self.config.compliance_center, dtype=float)

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        q, q_d = state.quat_world, target.quat_world
        r = rotate(q, self._centre)  # the centre relative to the pinch point, world [m]
        r_d = rotate(q_d, self._centre)
        omega = rotate(q, state.omega_body)
        omega_d = rotate(q_d, target.omega_body)
        e = np.empty(6)
        e[:3] = (target.p_world + r_d) - (state.p_world + r)
        mujoco.mju_subQuat(self._err, q_d, q)
        e[3:] = self._err
        de = np.empty(6)
        de[:3] = (target.v_world + cross(omega_d, r_d)) - (state.v_world + cross(omega, r))
        de[3:] = target.omega_body - state.omega_body
        wrench = self._k * e
        f = np.asarray(target.force_world)
        controlled = target.force_controlled
        forced = target.force_axes if controlled else f != 0.0
        if controlled:  # the position error along a force-controlled axis is ignored
            wrench[:3][forced] = 0.0
        norm = float(np.linalg.norm(wrench[:3]))
        if norm > self._cap:
            wrench[:3] *= self._cap / norm
        if controlled:
            wrench[:3][forced] = f[forced]
        moments = controlled and bool(target.moment_axes.any())
        spring_world = rotate(q, wrench[3:]) if moments else None
        wrench += self._d * de
        force = wrench[:3]
        torque = rotate(q, wrench[3:]) + cross(r, force)  # about the pinch point, world
        if spring_world is not None:  # the commanded moment about the centre replaces the spring
            axes = target.moment_axes
            torque[axes] += np.asarray(target.torque_world)[axes] - spring_world[axes]
        jac = self.dynamics.pinch_jacobian(state.p_world, q)
        # J maps (v, omega_body) to world twist; the angular rows act on body rates through R.
        tau = jac.T @ np.concatenate([force, torque])
        qd_ref = np.concatenate([target.v_world, target.omega_body])
        tau += self.dynamics.bias(state.p_world, q, state.v_world, state.omega_body)
        tau += self._b * qd_ref
        c = self.config.damping_compensation
        if c > 0.0:  # cancel part of the joints' damping along the measured motion
            tau += c * self._b * (np.concatenate([state.v_world, state.omega_body]) - qd_ref)
        return Effort(tau[:3].tolist(), tau[3:].tolist())
