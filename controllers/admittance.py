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

(:class:`peg_ctrl.sim.sensing.WristSensor` estimates ``F_ext`` and ``tau_ext``: the tare and
the filters below are its.) Force-controlled axes
(``target.force_axes``: flagged in ``target.wrench_axes`` or a non-zero ``target.force_world``
entry) are regulated in closed loop with the sensor (an accommodation law): the command along the
axis starts at the measured position when the axis becomes force-controlled and moves as
``M dd(s) + D_f d(s) = F_ext + f_d``, so it comes to rest exactly when the gripper pushes with
``f_d`` (zero: it follows whatever pushes it); ``force_damping`` sets how fast (about
``D_f / k_inner`` seconds per unit of force error with the inner PD's stiffness).

Moment-controlled axes (``target.moment_axes``) turn the command about the centre of compliance
by an accommodation law of their own, with no spring to the reference::

    d(psi) = clip((lowpass_m(tau_ext) + tau_d) / D_m, +-max_turn_rate)   on those world axes

so the command turns until the contact's moment about the centre is the commanded
``target.torque_world`` (zero: a held peg pressed on a flat face turns about its tip until its end
lies flat). The moment filter (``moment_filter_hz``, slower than the force filter) and the rate
cap keep the loop clear of the hand's own inertial torques, which the sensor reads too. With
``reversal_backoff`` > 1 an axis turns that many times slower each time its moment reverses
(:class:`~peg_ctrl.controllers.backoff.ReversalBackoff`): a peg on a face is a relay about its
tip, and a late reading would otherwise rock it from rim to rim for ever. The turn
``psi`` is dropped on an axis as soon as it is no longer moment-controlled: the task re-anchors
its reference at the present pose. A tare (``tare_time`` > 0: the mean reading over the first
seconds after reset, which must be free of contact) removes the sensor bias the model does not
know (the closed jaw, a held peg): a moment loop would integrate it into a drift.

A late sensor (``domain.ft_latency``) destabilises two parts of the law (docs/controllers.md):
the moment axes' accommodation (the rocking above; ``reversal_backoff`` 2 with
``moment_filter_hz`` 3.5 settles it) and, with ``rotational``, the rotational spring-damper,
whose virtual inertia ``rot_inertia`` must exceed the hand's own about the centre of compliance
(about 0.02 kg m^2 about a held peg's tip): the sensor reads the hand's inertial torque, and
below it the law amplifies its own motion.

The acceleration term uses the commanded acceleration of the reference (zero for rest-to-rest
holds); what is left (accelerations, the held peg's 16 g) stays below the deadbands. The
gripper's weight and centre of mass below the sensor come from the model at the home pose.

:class:`AdmittanceLoop` is the law as an outer loop (target in, shifted target out), so another
controller can sit inside it (``diffik`` does, with its ``admittance`` field). In ``admittance``
the inner ``pd`` controller is configured by the ``inner`` field (its gains are scaled with the
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
from peg_ctrl.controllers.backoff import ReversalBackoff, check_backoff
from peg_ctrl.controllers.base import ControllerBase, ControllerConfig, Effort
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.rotations import cross, quat_mul, rotate
from peg_ctrl.sim.sensing import WristSensor
from peg_ctrl.sim.state import ControlState

__all__ = ["AdmittanceConfig", "AdmittanceController", "AdmittanceLoop"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class AdmittanceConfig(ControllerConfig):
    """Virtual mass-spring-dampers of the command offset (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "admittance"
    GAINS: ClassVar[tuple[str, ...]] = ("stiffness", "rot_stiffness")
    VECTORS: ClassVar[tuple[str, ...]] = ("compliance_center",)
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("tare_time", "reversal_band")
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
    moment_damping: float = 0.5  # D_m of moment-controlled axes [N m s/rad]
    max_turn_rate: float = 0.05  # cap on their turn rate [rad/s]
    moment_filter_hz: float = 5.0  # low-pass on the moment they regulate [Hz]
    # Each time the moment on a moment-controlled axis reverses (crosses from beyond
    # +reversal_band to beyond -reversal_band [N m], or 3 sigma of its noise), that axis turns
    # reversal_backoff times slower (controllers/backoff.py); 1: never.
    reversal_backoff: float = 1.0
    reversal_band: float = 0.004
    tare_time: float = 0.0  # sensor tare over the first seconds after reset [s]; 0: none
    # [s] 1 kHz: the force regulation on the sensor is rate-sensitive (a held push's median peak
    # force rose from 14 N at 1 kHz to 24 N at 500 Hz and 56 N at 200 Hz; docs/performance.md)
    control_dt: float = 0.001
    inner: PDConfig = PDConfig()  # tracks the shifted target; its control_dt is replaced by ours

    def __post_init__(self) -> None:
        super().__post_init__()
        check_backoff(self.name, self.reversal_backoff)

    def build(self, model: mujoco.MjModel) -> AdmittanceController:
        return AdmittanceController(model, self)


def _deadband(v: np.ndarray, width: float) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    return v * (max(0.0, norm - width) / norm) if norm > 0 else np.zeros(3)


class AdmittanceLoop:
    """The admittance law as an outer loop: :meth:`shape` turns a target into the shifted
    target an inner controller tracks. See the module docstring.

    Attributes:
        sensor: The estimator of the contact wrench (tare, filters: ``filter_hz`` on the force
            and, as its fast moment, the torque; ``moment_filter_hz`` on its moment).
        offset: (3,) Current yield of the command, world frame [m].
        offset_rate: (3,) Its rate [m/s].
        rotation: (3,) Current turn of the command about the centre of compliance, world [rad].
        turn: (3,) Turn on the moment-controlled axes, world [rad].
    """

    def __init__(
        self, model: mujoco.MjModel, config: AdmittanceConfig, *, control_dt: float, bumpless: bool = False
    ) -> None:
        c = self.config = config
        self.dt = control_dt
        # A force-controlled axis's command starts at the measured position (the admittance's
        # own PD) or, bumpless, at the target's (an inner loop with a velocity feed-forward, like
        # the IK, would otherwise turn the step of its static error into a velocity kick).
        self.bumpless = bumpless
        self._centre_body = np.asarray(c.compliance_center, dtype=float)
        self.sensor = WristSensor(
            model,
            centre_body=self._centre_body,
            dt=control_dt,
            force_hz=c.filter_hz,
            moment_hz=c.moment_filter_hz,
            tare_time=c.tare_time,
            fast_moment=True,
        )
        self.backoff = ReversalBackoff(factor=c.reversal_backoff, band=c.reversal_band, size=3)
        self._d = 2.0 * c.damping_ratio * math.sqrt(c.stiffness * c.mass)
        self._d_rot = 2.0 * c.damping_ratio * math.sqrt(c.rot_stiffness * c.rot_inertia)
        self.reset(None)

    def reset(self, state: ControlState | None) -> None:
        """Zero the offsets, the filters and the tare."""
        self.offset = np.zeros(3)
        self.offset_rate = np.zeros(3)
        self.rotation = np.zeros(3)
        self.rotation_rate = np.zeros(3)
        self.turn = np.zeros(3)
        self._force_axes = np.zeros(3, dtype=bool)
        self._setpoint = np.zeros(3)  # command along force-controlled axes [m]
        self._setpoint_rate = np.zeros(3)
        self._prev_v_ref: np.ndarray | None = None
        self._moment_axes = np.zeros(3, dtype=bool)
        self.backoff.reset()
        self.sensor.reset(state)

    @property
    def force_filtered(self) -> np.ndarray:
        """(3,) Low-passed external force, world frame [N]."""
        return self.sensor.force

    @property
    def torque_filtered(self) -> np.ndarray:
        """(3,) Low-passed external torque about the centre, world frame [N m] (``filter_hz``)."""
        return self.sensor.moment_fast

    @property
    def moment_filtered(self) -> np.ndarray:
        """(3,) The same torque through the slower moment filter (``moment_filter_hz``) [N m]."""
        return self.sensor.moment

    def external_wrench(self, state: ControlState, accel_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact force [N] and its torque about the centre of compliance [N m], world frame
        (unfiltered; tared once a tare was taken)."""
        return self.sensor.raw(state, accel_ref=accel_ref)

    def shape(self, state: ControlState, target: GripperTarget) -> GripperTarget:
        """The target shifted by the admittance, for the inner controller."""
        c = self.config
        v_ref = np.asarray(target.v_world)
        self._sense(state, v_ref)
        self._translate(state, target)
        angle = self._rotate_compliantly() if c.rotational else 0.0
        total, turn_rate = self._turn(target)
        if total is not None:
            total = total + self.rotation if c.rotational else total
            angle = float(np.linalg.norm(total))
            rate = turn_rate + self.rotation_rate if c.rotational else turn_rate
        else:
            total, rate = self.rotation, self.rotation_rate
        return self._command(target, v_ref, total, rate, angle)

    def _sense(self, state: ControlState, v_ref: np.ndarray) -> None:
        """Tare (in the first ``tare_time``), filter the contact wrench, compensating the
        reference's acceleration."""
        accel_ref = np.zeros(3) if self._prev_v_ref is None else (v_ref - self._prev_v_ref) / self.dt
        self._prev_v_ref = v_ref.copy()
        self.sensor.update(state, accel_ref=accel_ref)

    def _translate(self, state: ControlState, target: GripperTarget) -> None:
        """Translation: a spring-damper to the reference, except along force-controlled axes,
        where a setpoint moves until the measured force is the commanded one."""
        c, dt = self.config, self.dt
        f_cmd = np.asarray(target.force_world)
        axes = target.force_axes
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
        entering = axes & ~self._force_axes
        start = target.p_world if self.bumpless else state.p_world
        self._setpoint[entering] = start[entering]
        self._setpoint_rate[entering] = 0.0
        self._force_axes = axes
        if axes.any():
            error = self.force_filtered + f_cmd  # contact force on us + what we should exert
            acc_f = (error - c.force_damping * self._setpoint_rate) / c.mass
            self._setpoint_rate[axes] += acc_f[axes] * dt
            self._setpoint[axes] += self._setpoint_rate[axes] * dt

    def _rotate_compliantly(self) -> float:
        """Rotation about the centre of compliance: advance it; its angle [rad]."""
        c, dt = self.config, self.dt
        drive_r = _deadband(self.torque_filtered, c.torque_deadband)
        acc_r = (drive_r - self._d_rot * self.rotation_rate - c.rot_stiffness * self.rotation) / c.rot_inertia
        self.rotation_rate += acc_r * dt
        self.rotation += self.rotation_rate * dt
        angle = float(np.linalg.norm(self.rotation))
        if angle > c.max_rotation:
            self.rotation *= c.max_rotation / angle
            self.rotation_rate[:] = 0.0
            angle = c.max_rotation
        return angle

    def _command(
        self, target: GripperTarget, v_ref: np.ndarray, total: np.ndarray, rate: np.ndarray, angle: float
    ) -> GripperTarget:
        """The reference moved by the offset, turned by ``total`` about the centre of compliance
        (at ``rate``), with the setpoints on force-controlled axes."""
        axes = target.force_axes
        p_ref, q_ref = np.asarray(target.p_world), np.asarray(target.quat_world)
        p_cmd = p_ref + self.offset
        q_cmd = q_ref
        v_cmd = v_ref + self.offset_rate
        omega = np.asarray(target.omega_body)
        if angle > 1e-12:
            q_rot = np.empty(4)
            mujoco.mju_axisAngle2Quat(q_rot, total / angle, angle)
            arm = -rotate(q_ref, self._centre_body)  # pinch point relative to the reference centre
            p_cmd = p_cmd + rotate(q_rot, arm) - arm
            q_cmd = quat_mul(q_rot, q_ref)
            v_cmd = v_cmd + cross(rate, rotate(q_rot, arm))
            q_inv = np.array([q_cmd[0], -q_cmd[1], -q_cmd[2], -q_cmd[3]])
            omega = omega + rotate(q_inv, rate)
        if axes.any():
            p_cmd = np.where(axes, self._setpoint, p_cmd)
            v_cmd = np.where(axes, self._setpoint_rate, v_cmd)
        return GripperTarget.trusted(p_cmd, q_cmd, v_cmd, omega, target.jaw_sep_m)

    def _turn(self, target: GripperTarget) -> tuple[np.ndarray | None, np.ndarray]:
        """Advance the turn on the moment-controlled axes; (turn or None when there is none, rate)."""
        c = self.config
        axes = target.moment_axes
        self.backoff.reset(axes & ~self._moment_axes)  # a new regulation starts at full rate
        self._moment_axes = axes
        if not axes.any():
            self.turn[:] = 0.0
            return None, np.zeros(3)
        error = self.moment_filtered + target.torque_world
        scale = self.backoff.update(error, axes, self.sensor.sigma_moment)
        rate = np.clip(error / (c.moment_damping * scale), -c.max_turn_rate, c.max_turn_rate)
        rate[~axes] = 0.0
        self.turn[~axes] = 0.0
        self.turn += rate * self.dt
        return self.turn.copy(), rate


class AdmittanceController(ControllerBase[AdmittanceConfig]):
    """Six-axis admittance with force regulation on top of the reference PD. See the module docstring.

    ``loop`` is the :class:`AdmittanceLoop`; its state (``offset``, ``rotation``,
    ``force_filtered``, ...) is readable here too.
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
        self.loop = AdmittanceLoop(model, c, control_dt=c.control_dt)

    offset = property(lambda self: self.loop.offset)
    rotation = property(lambda self: self.loop.rotation)
    turn = property(lambda self: self.loop.turn)
    force_filtered = property(lambda self: self.loop.force_filtered)
    torque_filtered = property(lambda self: self.loop.torque_filtered)

    def _reset(self, state: ControlState) -> None:
        self.loop.reset(state)
        self.inner.reset(state)

    def external_force(self, state: ControlState, accel_ref: np.ndarray) -> np.ndarray:
        """Contact force on the gripper from the sensor, world frame [N] (unfiltered)."""
        return self.loop.external_wrench(state, accel_ref)[0]

    def external_wrench(self, state: ControlState, accel_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact force [N] and its torque about the centre of compliance [N m], world frame."""
        return self.loop.external_wrench(state, accel_ref)

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        return self.inner.control_law(state, self.loop.shape(state, target))
