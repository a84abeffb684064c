"""Six-axis admittance control with force regulation, on top of the stiff reference controller.

The commanded pose yields to the contact wrench measured by the simulated force/torque sensor at
the gripper mount. Both the force and the torque are taken about a *centre of compliance* ``c``
(``compliance_center``, in the gripper frame; at the held peg's tip it is a remote centre of
compliance), so a force at the tip moves the peg sideways and a moment about the tip turns it
about the tip::

    F_ext   = m_g (a_ref - g) - R f_s                              (world; sensor force f_s)
    tau_ext = -R t_s - (r_com - r_s) x m_g g + (r_s - c) x F_ext   (about c; sensor torque t_s)

    M  dd(x)   + D  d(x)   + K  x   = deadband(lowpass(F_ext))     translation offset x [m]
    Ir dd(phi) + Dr d(phi) + Kr phi = deadband(lowpass(tau_ext))   rotation phi about c [rad]
                                                                    (with ``rotational: true``)

    commanded pose: turned by phi about the centre of the reference, then shifted by x;
    tracked by the ``pd`` controller.

Force-controlled axes (a non-zero ``target.force_world`` entry) are regulated in closed loop
with the sensor (an accommodation law): the command along the axis starts at the measured
position when the axis becomes force-controlled and moves as ``M dd(s) + D_f d(s) = F_ext + f_d``,
so it comes to rest exactly when the gripper pushes with ``f_d``; ``force_damping`` sets how fast
(about ``D_f / k_inner`` seconds per unit of force error with the inner PD's stiffness).

The acceleration term uses the commanded acceleration of the reference (zero for rest-to-rest
holds); what is left (accelerations, the held peg's 16 g) stays below the deadbands. The
gripper's weight and centre of mass below the sensor come from the model at the home pose.

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
from peg_ctrl.rotations import cross, quat_mul, rotate
from peg_ctrl.scene import FT_SITE, HOME_KEY
from peg_ctrl.state import ControlState, ft_world

__all__ = ["AdmittanceConfig", "AdmittanceController"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class AdmittanceConfig(ControllerConfig):
    """Virtual mass-spring-dampers of the command offset (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "admittance"
    GAINS: ClassVar[tuple[str, ...]] = ("stiffness", "rot_stiffness")
    VECTORS: ClassVar[tuple[str, ...]] = ("compliance_center",)
    mass: float = 2.0  # virtual mass [kg]
    stiffness: float = 300.0  # virtual spring to the reference [N/m]
    damping_ratio: float = 1.0  # D = 2 zeta sqrt(K M), translation and rotation
    deadband: float = 1.0  # measured force below this is ignored [N]
    filter_hz: float = 20.0  # low-pass on the measured force and torque [Hz]
    max_offset: float = 0.02  # the command never yields further than this [m]
    rotational: bool = False  # also yield in rotation (six axes); off: orientation tracked stiffly
    rot_inertia: float = 0.005  # virtual rotational inertia [kg m^2]
    rot_stiffness: float = 2.0  # virtual rotational spring [N m/rad]
    torque_deadband: float = 0.02  # measured torque below this is ignored [N m]
    max_rotation: float = 0.1  # the command never turns further than this [rad]
    compliance_center: tuple[float, float, float] = (0.0, 0.0, 0.0)  # gripper frame [m]
    force_damping: float = 400.0  # D_f of force-controlled axes [N s/m]
    # [s] 1 kHz: the force regulation on the sensor is rate-sensitive (a held push's median peak
    # force rose from 14 N at 1 kHz to 24 N at 500 Hz and 56 N at 200 Hz; docs/performance.md)
    control_dt: float = 0.001
    inner: PDConfig = PDConfig()  # tracks the shifted target; its control_dt is replaced by ours

    def build(self, model: mujoco.MjModel) -> AdmittanceController:
        return AdmittanceController(model, self)


def _lowpass_alpha(hz: float, dt: float) -> float:
    return 1.0 - math.exp(-2.0 * math.pi * hz * dt)


def _deadband(v: np.ndarray, width: float) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    return v * (max(0.0, norm - width) / norm) if norm > 0 else np.zeros(3)


class AdmittanceController(ControllerBase[AdmittanceConfig]):
    """Six-axis admittance with force regulation on top of the reference PD. See the module docstring.

    Attributes:
        offset: (3,) Current yield of the command, world frame [m].
        offset_rate: (3,) Its rate [m/s].
        rotation: (3,) Current turn of the command about the centre of compliance, world [rad].
        force_filtered: (3,) Low-passed external force, world frame [N].
        torque_filtered: (3,) Low-passed external torque about the centre, world frame [N m].
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
        root = model.body("gripper_root").id
        self._mass_below = float(model.body_subtreemass[mount])
        self._gravity = model.opt.gravity.copy()
        # Sensor site and centre of mass below it, in the gripper frame (home pose, jaw open).
        scratch = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, scratch, model.key(HOME_KEY).id)
        mujoco.mj_kinematics(model, scratch)
        mujoco.mj_comPos(model, scratch)
        r_root = scratch.xmat[root].reshape(3, 3)
        self._site_body = r_root.T @ (scratch.site_xpos[model.site(FT_SITE).id] - scratch.xpos[root])
        self._com_body = r_root.T @ (scratch.subtree_com[mount] - scratch.xpos[root])
        self._centre_body = np.asarray(c.compliance_center, dtype=float)
        self._d = 2.0 * c.damping_ratio * math.sqrt(c.stiffness * c.mass)
        self._d_rot = 2.0 * c.damping_ratio * math.sqrt(c.rot_stiffness * c.rot_inertia)
        self._alpha = _lowpass_alpha(c.filter_hz, c.control_dt)
        self.reset_offset()

    def reset_offset(self) -> None:
        self.offset = np.zeros(3)
        self.offset_rate = np.zeros(3)
        self.rotation = np.zeros(3)
        self.rotation_rate = np.zeros(3)
        self.force_filtered = np.zeros(3)
        self.torque_filtered = np.zeros(3)
        self._force_axes = np.zeros(3, dtype=bool)
        self._setpoint = np.zeros(3)  # command along force-controlled axes [m]
        self._setpoint_rate = np.zeros(3)
        self._prev_v_ref: np.ndarray | None = None

    def _reset(self, state: ControlState) -> None:
        self.reset_offset()
        self.inner.reset(state)

    def external_force(self, state: ControlState, accel_ref: np.ndarray) -> np.ndarray:
        """Contact force on the gripper from the sensor, world frame [N] (unfiltered)."""
        return self.external_wrench(state, accel_ref)[0]

    def external_wrench(self, state: ControlState, accel_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact force [N] and its torque about the centre of compliance [N m], world frame."""
        f_world, t_world = ft_world(state)
        f_ext = self._mass_below * (accel_ref - self._gravity) - f_world
        q = state.quat_world
        site = rotate(q, self._site_body)  # relative to the pinch point
        com = rotate(q, self._com_body)
        centre = rotate(q, self._centre_body)
        weight = self._mass_below * self._gravity
        tau = -t_world - cross(com - site, weight) + cross(site - centre, f_ext)
        return f_ext, tau

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        c = self.config
        dt = c.control_dt
        v_ref = np.asarray(target.v_world)
        accel_ref = np.zeros(3) if self._prev_v_ref is None else (v_ref - self._prev_v_ref) / dt
        self._prev_v_ref = v_ref.copy()
        f_ext, tau_ext = self.external_wrench(state, accel_ref)
        a = self._alpha
        self.force_filtered += a * (f_ext - self.force_filtered)
        self.torque_filtered += a * (tau_ext - self.torque_filtered)

        # Translation: spring-damper to the reference, except along force-controlled axes.
        f_cmd = np.asarray(target.force_world)
        axes = f_cmd != 0.0
        drive = _deadband(np.where(axes, 0.0, self.force_filtered), c.deadband)
        acc = (drive - self._d * self.offset_rate - c.stiffness * self.offset) / c.mass
        self.offset_rate += acc * dt  # semi-implicit Euler
        self.offset += self.offset_rate * dt
        self.offset[axes] = 0.0
        self.offset_rate[axes] = 0.0
        n = float(np.linalg.norm(self.offset))
        if n > c.max_offset:
            self.offset *= c.max_offset / n
            self.offset_rate[:] = 0.0
        # Force-controlled axes: the setpoint moves until the measured force is the commanded one.
        entering = axes & ~self._force_axes
        self._setpoint[entering] = state.p_world[entering]
        self._setpoint_rate[entering] = 0.0
        self._force_axes = axes
        if axes.any():
            error = self.force_filtered + f_cmd  # contact force on us + what we should exert
            acc_f = (error - c.force_damping * self._setpoint_rate) / c.mass
            self._setpoint_rate[axes] += acc_f[axes] * dt
            self._setpoint[axes] += self._setpoint_rate[axes] * dt

        # Rotation about the centre of compliance.
        angle = 0.0
        if c.rotational:
            drive_r = _deadband(self.torque_filtered, c.torque_deadband)
            acc_r = (
                drive_r - self._d_rot * self.rotation_rate - c.rot_stiffness * self.rotation
            ) / c.rot_inertia
            self.rotation_rate += acc_r * dt
            self.rotation += self.rotation_rate * dt
            angle = float(np.linalg.norm(self.rotation))
            if angle > c.max_rotation:
                self.rotation *= c.max_rotation / angle
                self.rotation_rate[:] = 0.0
                angle = c.max_rotation

        p_ref, q_ref = np.asarray(target.p_world), np.asarray(target.quat_world)
        p_cmd = p_ref + self.offset
        q_cmd = q_ref
        v_cmd = v_ref + self.offset_rate
        omega = np.asarray(target.omega_body)
        if angle > 1e-12:
            q_rot = np.empty(4)
            mujoco.mju_axisAngle2Quat(q_rot, self.rotation / angle, angle)
            arm = -rotate(q_ref, self._centre_body)  # pinch point relative to the reference centre
            p_cmd = p_cmd + rotate(q_rot, arm) - arm
            q_cmd = quat_mul(q_rot, q_ref)
            v_cmd = v_cmd + cross(self.rotation_rate, rotate(q_rot, arm))
            q_inv = np.array([q_cmd[0], -q_cmd[1], -q_cmd[2], -q_cmd[3]])
            omega = omega + rotate(q_inv, self.rotation_rate)
        if axes.any():
            p_cmd = np.where(axes, self._setpoint, p_cmd)
            v_cmd = np.where(axes, self._setpoint_rate, v_cmd)
        shifted = GripperTarget.trusted(p_cmd, q_cmd, v_cmd, omega, target.jaw_sep_m)
        return self.inner.control_law(state, shifted)
