"""The reference controller (SPEC §4): slide PD and a quaternion-log / angular-velocity loop.

Slides (world frame)::

    F = sat( cap(Kp (p_d - p)) + Kd (v_d - v) + b v_d + m g )

``cap`` limits ``|Kp e|`` to ``(b + Kd) v_max`` so far targets are approached at about
``v_max`` (a soft velocity cap); ``b`` is the slide damping of the model (a feed-forward that
cancels it along the reference), ``m g`` the weight of the gripper subtree.

Force-controlled axes (``target.force_axes``: a non-zero ``target.force_world`` entry, or an axis
flagged in ``target.wrench_axes``): the stiffness term is replaced by the commanded force, open
loop (no force feedback; the damping term stays), so in quasi-static contact the gripper pushes
with that force. Moment-controlled axes (``target.moment_axes``, world axes): the orientation
error about those axes is dropped and the commanded ``target.torque_world`` (about the pinch
point: this controller has no other centre) is added, open loop; the angular-velocity loop still
damps them.

Ball joint (gripper frame, as MuJoCo's ball-joint velocities are)::

    theta   = Log(q^-1 q_d)                      (mju_subQuat: minimal angle, short way round)
    omega_d = cap(omega_ff + K_R theta)          (|omega_d| <= omega_max)
    tau     = sat( b_rot omega_d + K_w (omega_d - lowpass(omega)) + tau_gravity )

``Log(q^-1 q_d)`` is SPEC's ``Log(q_d q^-1)`` expressed in the body frame (``theta_body =
R^T theta_world``), which is the frame the torques act in. Saturation (element-wise, to the
actuator ranges) is done by :class:`~peg_ctrl.controllers.base.ControllerBase`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import mujoco

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.base import ControllerBase, ControllerConfig, Effort
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.scene import BALL_JOINT, HOME_KEY, SLIDE_JOINTS
from peg_ctrl.sim.sensing import lowpass_alpha
from peg_ctrl.sim.state import ControlState

__all__ = ["PDConfig", "PDController"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class PDConfig(ControllerConfig):
    """Gains and limits of the reference controller (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "pd"
    GAINS: ClassVar[tuple[str, ...]] = ("kp_pos", "kd_pos", "k_rot", "k_omega")
    control_dt: float = 0.005  # [s] 200 Hz: outcomes as at 1 kHz (docs/performance.md)
    kp_pos: float = 3000.0  # slide stiffness [N/m]
    kd_pos: float = 40.0  # slide damping on top of the joint damping [N s/m]
    v_max: float = 0.5  # soft cap on approach speed [m/s]
    k_rot: float = 8.0  # orientation error -> angular velocity gain [1/s]
    k_omega: float = 20.0  # angular velocity loop gain [N m s/rad]
    omega_max: float = 1.5  # soft cap on commanded angular speed [rad/s]
    omega_filter_hz: float = 40.0  # first-order low-pass cut-off on measured omega [Hz]
    model_feedforward: bool = True  # gravity and joint-damping feed-forward from the model

    def build(self, model: mujoco.MjModel) -> PDController:
        return PDController(model, self)


class PDController(ControllerBase[PDConfig]):
    """Reference PD / angular-velocity controller. See module docstring for the control law."""

    name = "pd"

    def __init__(
        self,
        model: mujoco.MjModel,
        config: PDConfig | None = None,
        *,
        jaw_calibration: JawCalibration | None = None,
    ) -> None:
        super().__init__(model, config or PDConfig(), jaw_calibration=jaw_calibration)
        slide_dofs = [model.joint(n).dofadr[0] for n in SLIDE_JOINTS]
        ball_dof = model.joint(BALL_JOINT).dofadr[0]
        self._b_slide = model.dof_damping[slide_dofs].copy()
        self._b_ball = model.dof_damping[ball_dof : ball_dof + 3].copy()
        root = model.body("gripper_root").id
        self._mass = float(model.body_subtreemass[root])
        self._gravity = model.opt.gravity.copy()
        # Centre of mass of the gripper subtree in the gripper frame, at the home pose (on a
        # scratch MjData: the controller never touches the simulation's).
        scratch = mujoco.MjData(model)
        key = model.key(HOME_KEY).id if model.nkey else -1
        if key >= 0:
            mujoco.mj_resetDataKeyframe(model, scratch, key)
        mujoco.mj_kinematics(model, scratch)
        mujoco.mj_comPos(model, scratch)
        r_world = scratch.subtree_com[root] - scratch.xpos[root]
        self._com_body = scratch.xmat[root].reshape(3, 3).T @ r_world
        self._alpha = lowpass_alpha(self.config.omega_filter_hz, self.control_dt)
        # Plain floats for the scalar inner loop.
        self._b_slide = tuple(float(b) for b in self._b_slide)
        self._b_ball = tuple(float(b) for b in self._b_ball)
        self._weight = tuple(float(g) * self._mass for g in self._gravity)  # m g, world [N]
        self._com_body = tuple(float(c) for c in self._com_body)
        self._slide_cap = (max(self._b_slide) + self.config.kd_pos) * self.config.v_max
        self._omega_f = [0.0, 0.0, 0.0]

    def _reset(self, state: ControlState) -> None:
        self._omega_f = [float(w) for w in state.omega_body]

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        # Scalar Python on purpose: at 1 kHz, numpy's per-call overhead on 3-vectors would cost
        # more than the physics step it controls (see `peg-sim bench`).
        return Effort(self._slide_force(state, target), self._ball_torque(state, target))

    def _slide_force(self, state: ControlState, target: GripperTarget) -> tuple[float, float, float]:
        """The slides: a saturated PD on position (plus the commanded force on force-controlled
        axes, whose position error is ignored) and, with the model feedforward, damping and weight."""
        cfg = self.config
        px, py, pz = state.p_world.tolist()
        vx, vy, vz = state.v_world.tolist()
        tx, ty, tz = target.p_world.tolist()
        tvx, tvy, tvz = target.v_world.tolist()
        kp, kd = cfg.kp_pos, cfg.kd_pos
        ex, ey, ez = kp * (tx - px), kp * (ty - py), kp * (tz - pz)
        fdx = fdy = fdz = 0.0
        if target.force_controlled:  # the position error along a force-controlled axis is ignored
            fdx, fdy, fdz = target.force_world.tolist()
            free_x, free_y, free_z = target.force_axes.tolist()
            ex, ey, ez = (0.0 if free_x else ex), (0.0 if free_y else ey), (0.0 if free_z else ez)
        norm = math.sqrt(ex * ex + ey * ey + ez * ez)
        if norm > self._slide_cap:
            scale = self._slide_cap / norm
            ex, ey, ez = ex * scale, ey * scale, ez * scale
        ex, ey, ez = ex + fdx, ey + fdy, ez + fdz
        fx = ex + kd * (tvx - vx)
        fy = ey + kd * (tvy - vy)
        fz = ez + kd * (tvz - vz)
        if cfg.model_feedforward:
            bx, by, bz = self._b_slide
            gx, gy, gz = self._weight
            fx += bx * tvx - gx
            fy += by * tvy - gy
            fz += bz * tvz - gz
        return fx, fy, fz

    def _ball_torque(self, state: ControlState, target: GripperTarget) -> tuple[float, float, float]:
        """The ball joint: a rate command from the orientation error theta = Log(q^-1 q_d) in the
        gripper frame, saturated, tracked by a filtered rate loop (plus feedforward and, on
        moment-controlled axes, the commanded moment open loop)."""
        cfg = self.config
        qw, qx, qy, qz = state.quat_world.tolist()
        thx, thy, thz = _rotation_error(qw, qx, qy, qz, *target.quat_world.tolist())
        moments = target.force_controlled and bool(target.moment_axes.any())
        if moments:  # no orientation error about the moment-controlled world axes
            thx, thy, thz = _drop_world_axes(qw, qx, qy, qz, (thx, thy, thz), target.moment_axes.tolist())
        fwx, fwy, fwz = target.omega_body.tolist()
        kr = cfg.k_rot
        wx, wy, wz = fwx + kr * thx, fwy + kr * thy, fwz + kr * thz
        w = math.sqrt(wx * wx + wy * wy + wz * wz)
        if w > cfg.omega_max:
            scale = cfg.omega_max / w
            wx, wy, wz = wx * scale, wy * scale, wz * scale
        a = self._alpha
        of = self._omega_f
        mx, my, mz = state.omega_body.tolist()
        of[0] += a * (mx - of[0])
        of[1] += a * (my - of[1])
        of[2] += a * (mz - of[2])
        kw = cfg.k_omega
        tqx, tqy, tqz = kw * (wx - of[0]), kw * (wy - of[1]), kw * (wz - of[2])
        if cfg.model_feedforward:
            bx, by, bz = self._b_ball
            gtx, gty, gtz = self._gravity_torque(qw, qx, qy, qz)
            tqx += bx * wx + gtx
            tqy += by * wy + gty
            tqz += bz * wz + gtz
        if moments:  # the commanded moment on those axes, open loop, into the gripper frame
            torques, axes = target.torque_world.tolist(), target.moment_axes.tolist()
            mx_, my_, mz_ = (t if on else 0.0 for t, on in zip(torques, axes, strict=True))
            cx_, cy_, cz_ = _rotate(qw, -qx, -qy, -qz, mx_, my_, mz_)
            tqx, tqy, tqz = tqx + cx_, tqy + cy_, tqz + cz_
        return tqx, tqy, tqz

    def _gravity_torque(self, qw: float, qx: float, qy: float, qz: float) -> tuple[float, float, float]:
        """Body-frame torque that cancels the gripper's weight about the pivot [N m].

        tau_body = -c x (R^T m g), with c the subtree centre of mass in the gripper frame.
        """
        gx, gy, gz = self._weight  # m g in the world frame
        # R^T v = rotate by the conjugate quaternion.
        bx, by, bz = _rotate(qw, -qx, -qy, -qz, gx, gy, gz)
        cx, cy, cz = self._com_body
        return (-(cy * bz - cz * by), -(cz * bx - cx * bz), -(cx * by - cy * bx))


def _rotation_error(
    qw: float, qx: float, qy: float, qz: float, dw: float, dx: float, dy: float, dz: float
) -> tuple[float, float, float]:
    """theta = Log(q^-1 q_d): the rotation vector from ``q`` to ``d`` in ``q``'s frame, the
    short way round [rad]; NaN in gives NaN out."""
    ew = qw * dw + qx * dx + qy * dy + qz * dz
    ex = qw * dx - qx * dw - qy * dz + qz * dy
    ey = qw * dy + qx * dz - qy * dw - qz * dx
    ez = qw * dz - qx * dy + qy * dx - qz * dw
    sin_half = math.sqrt(ex * ex + ey * ey + ez * ez)
    if not sin_half <= 1e-12:  # written so that a NaN takes this branch and propagates
        angle = 2.0 * math.atan2(sin_half, ew)
        if angle > math.pi:  # short way round
            angle -= 2.0 * math.pi
        k = angle / sin_half
        return k * ex, k * ey, k * ez
    return 0.0, 0.0, 0.0


def _drop_world_axes(
    qw: float, qx: float, qy: float, qz: float, v_body: tuple[float, float, float], axes: list[bool]
) -> tuple[float, float, float]:
    """``v_body`` (a gripper-frame vector) without its components along the flagged world axes."""
    wx, wy, wz = _rotate(qw, qx, qy, qz, *v_body)
    wx, wy, wz = (0.0 if axes[0] else wx), (0.0 if axes[1] else wy), (0.0 if axes[2] else wz)
    return _rotate(qw, -qx, -qy, -qz, wx, wy, wz)


def _rotate(
    w: float, x: float, y: float, z: float, vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    """Rotate ``v`` by the unit quaternion ``(w, x, y, z)``."""
    # t = 2 q_vec x v; v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )
