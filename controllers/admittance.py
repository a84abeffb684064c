"""Admittance control: the commanded position yields to the contact force measured by the
simulated force/torque sensor at the gripper mount, on top of the stiff reference controller.

    F_ext = m_g a - m_g g - R_s f_s        (world; sensor force f_s, gripper mass m_g below it)
    M dd(x) + D d(x) + K x = deadband(lowpass(F_ext))        (x: offset of the command [m])
    target' = target shifted by x (and its rate), tracked by the ``pd`` controller

The acceleration term uses the commanded acceleration of the reference (zero for rest-to-rest
holds); what is left (accelerations, the held peg's 16 g) stays below the deadband. Only the
translation yields; the orientation is tracked stiffly.

The inner ``pd`` controller is configured by the ``inner`` field (its gains are scaled with the
admittance's by :meth:`~peg_ctrl.controllers.base.ControllerConfig.scaled`); it runs at the
admittance's ``control_dt`` (``inner.control_dt`` is replaced by it), and only its control law
is called, so saturation and packing happen once.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import mujoco
import numpy as np

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.base import ControllerBase, ControllerConfig, Effort
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.jaw import JawCalibration
from peg_ctrl.state import ControlState

__all__ = ["AdmittanceConfig", "AdmittanceController"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class AdmittanceConfig(ControllerConfig):
    """Virtual mass-spring-damper of the command offset (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "admittance"
    GAINS: ClassVar[tuple[str, ...]] = ("stiffness",)
    mass: float = 2.0  # virtual mass [kg]
    stiffness: float = 300.0  # virtual spring to the reference [N/m]
    damping_ratio: float = 1.0  # D = 2 zeta sqrt(K M)
    deadband: float = 1.0  # measured force below this is ignored [N]
    filter_hz: float = 20.0  # low-pass on the measured force [Hz]
    max_offset: float = 0.02  # the command never yields further than this [m]
    inner: PDConfig = PDConfig()  # tracks the shifted target; its control_dt is replaced by ours

    def build(self, model: mujoco.MjModel) -> AdmittanceController:
        return AdmittanceController(model, self)


class AdmittanceController(ControllerBase[AdmittanceConfig]):
    """Admittance on top of the reference PD. See the module docstring.

    Attributes:
        offset: (3,) Current yield of the command, world frame [m].
        offset_rate: (3,) Its rate [m/s].
        force_filtered: (3,) Low-passed external force, world frame [N].
    """

    name = "admittance"

    def __init__(
        self,
        model: mujoco.MjModel,
        config: AdmittanceConfig | None = None,
        *,
        jaw_calibration: JawCalibration | None = None,
    ) -> None:
        super().__init__(model, config or AdmittanceConfig(), jaw_calibration=jaw_calibration)
        c = self.config
        self.inner = PDController(
            model, dataclasses.replace(c.inner, control_dt=c.control_dt), jaw_calibration=self._jaw
        )
        mount = model.body("gripper_mount").id
        self._mass_below = float(model.body_subtreemass[mount])
        self._gravity = model.opt.gravity.copy()
        self._d = 2.0 * c.damping_ratio * math.sqrt(c.stiffness * c.mass)
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * c.filter_hz * c.control_dt)
        self.reset_offset()

    def reset_offset(self) -> None:
        self.offset = np.zeros(3)
        self.offset_rate = np.zeros(3)
        self.force_filtered = np.zeros(3)
        self._prev_v_ref: np.ndarray | None = None

    def _reset(self, state: ControlState) -> None:
        self.reset_offset()
        self.inner.reset(state)

    def external_force(self, state: ControlState, accel_ref: np.ndarray) -> np.ndarray:
        """Contact force on the gripper from the sensor, world frame [N] (unfiltered)."""
        f = state.ft_wrench[:3]
        f_site = np.array([f[0], -f[1], -f[2]])  # sensor frame -> gripper frame (180 deg about X)
        f_world = np.empty(3)
        mujoco.mju_rotVecQuat(f_world, f_site, state.quat_world)
        return self._mass_below * (accel_ref - self._gravity) - f_world

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        c = self.config
        dt = c.control_dt
        v_ref = np.asarray(target.v_world)
        accel_ref = np.zeros(3) if self._prev_v_ref is None else (v_ref - self._prev_v_ref) / dt
        self._prev_v_ref = v_ref.copy()
        f_ext = self.external_force(state, accel_ref)
        self.force_filtered += self._alpha * (f_ext - self.force_filtered)
        f = self.force_filtered
        norm = float(np.linalg.norm(f))
        drive = f * (max(0.0, norm - c.deadband) / norm) if norm > 0 else np.zeros(3)
        acc = (drive - self._d * self.offset_rate - c.stiffness * self.offset) / c.mass
        self.offset_rate += acc * dt  # semi-implicit Euler
        self.offset += self.offset_rate * dt
        n = float(np.linalg.norm(self.offset))
        if n > c.max_offset:
            self.offset *= c.max_offset / n
            self.offset_rate[:] = 0.0
        shifted = GripperTarget.trusted(
            target.p_world + self.offset,
            target.quat_world,
            target.v_world + self.offset_rate,
            target.omega_body,
            target.jaw_sep_m,
        )
        return self.inner.control_law(state, shifted)
