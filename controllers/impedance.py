"""Task-space impedance control of the pinch point, with Pinocchio bias compensation.

    F   = K_p (p_d - p) + D_p (v_d - v)                       (world frame) [N]
    tau = K_r Log(q^-1 q_d) + D_r (omega_d - omega)           (gripper frame) [N m]
    u   = J^T [F; tau] + b(q, qdot) + B qdot_d

``K`` per axis; ``D = 2 zeta sqrt(K m)`` from a damping ratio and the apparent mass/inertia at the
pinch point (Pinocchio's mass matrix at the home pose). ``b`` are gravity and Coriolis forces
from the Pinocchio model of the base + gripper, ``B qdot_d`` cancels the joints' own damping
along the reference only (so the impedance about the reference is what is commanded). The pinch
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
from peg_ctrl.jaw import JawCalibration
from peg_ctrl.rotations import rotate
from peg_ctrl.scene import BALL_JOINT, SLIDE_JOINTS
from peg_ctrl.state import ControlState

__all__ = ["ImpedanceConfig", "ImpedanceController"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class ImpedanceConfig(ControllerConfig):
    """Stiffness per axis and damping ratio (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "impedance"
    GAINS: ClassVar[tuple[str, ...]] = ("k_pos", "k_rot")
    k_pos: tuple[float, float, float] = (1500.0, 1500.0, 1500.0)  # translational stiffness [N/m]
    k_rot: tuple[float, float, float] = (120.0, 120.0, 120.0)  # rotational stiffness [N m/rad]
    damping_ratio: float = 1.0  # zeta of D = 2 zeta sqrt(K m)
    v_max: float = 0.5  # caps |K_p e| at the force that drives the damped slide at v_max [m/s]

    def __post_init__(self) -> None:
        super().__post_init__()
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

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        e = np.empty(6)
        e[:3] = target.p_world - state.p_world
        mujoco.mju_subQuat(self._err, target.quat_world, state.quat_world)
        e[3:] = self._err
        de = np.concatenate([target.v_world - state.v_world, target.omega_body - state.omega_body])
        wrench = self._k * e
        norm = float(np.linalg.norm(wrench[:3]))
        if norm > self._cap:
            wrench[:3] *= self._cap / norm
        wrench += self._d * de
        jac = self.dynamics.pinch_jacobian(state.p_world, state.quat_world)
        # J maps (v, omega_body) to world twist; the angular rows act on body rates through R.
        tau = jac.T @ np.concatenate([wrench[:3], rotate(state.quat_world, wrench[3:])])
        qd_ref = np.concatenate([target.v_world, target.omega_body])
        tau += self.dynamics.bias(state.p_world, state.quat_world, state.v_world, state.omega_body)
        tau += self._b * qd_ref
        return Effort(tau[:3].tolist(), tau[3:].tolist())
