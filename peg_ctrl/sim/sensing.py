"""The contact wrench on the hand, from the force/torque sensor at the gripper mount.

The sensor (``ft_sensor``, :func:`peg_ctrl.sim.state.ft_world`) reads what the base exerts on
everything below it: the hand's weight, its inertia, and the contact. :class:`WristModel`
removes the weight (and the inertia along a known reference acceleration) with the hand's mass
and centre of mass taken from the model at the home pose, and moves the moment to a point of
the gripper frame (a centre of compliance; for the held peg, its lower end)::

    F_c   = m_h (a_ref - g) - f_s                                  contact force on the hand [N]
    tau_c = -t_s - (r_com - r_s) x m_h g + (r_s - c) x F_c         its moment about c [N m]

(``f_s``, ``t_s`` the sensor's world-frame reading; ``r_s``, ``r_com``, ``c`` the sensor site,
the hand's centre of mass and the point, from the pinch point.) What the model does not know —
the jaw closed instead of open moves the fingers' mass, a held peg adds its own weight — is a
bias of a few mN m that a moment-regulating loop would integrate into a drift. :class:`WristSensor`
removes it with a tare taken while the hand is known to be free, and low-passes the result.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.rotations import cross, rotate, rotate_inv
from peg_ctrl.sim.scene import FT_SITE, HOME_KEY
from peg_ctrl.sim.state import ControlState, ft_world

__all__ = ["ContactSense", "WristModel", "WristSensor", "lowpass_alpha"]

_Vec = NDArray[np.float64]


def lowpass_alpha(hz: float, dt: float) -> float:
    """Gain of a first-order low-pass with cut-off ``hz`` [Hz] sampled every ``dt`` [s]."""
    return 1.0 - math.exp(-2.0 * math.pi * hz * dt)


class WristModel:
    """The hand below the sensor: its mass [kg], and the sensor site and centre of mass in the
    gripper frame [m], from ``model`` at the home pose (jaw open)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        mount = model.body("gripper_mount").id
        root = model.body("gripper_root").id
        self.mass = float(model.body_subtreemass[mount])
        self.gravity = model.opt.gravity.copy()
        scratch = mujoco.MjData(model)  # a controller never touches the simulation's data
        mujoco.mj_resetDataKeyframe(model, scratch, model.key(HOME_KEY).id)
        mujoco.mj_kinematics(model, scratch)
        mujoco.mj_comPos(model, scratch)
        r_root = scratch.xmat[root].reshape(3, 3)
        self.site_body = r_root.T @ (scratch.site_xpos[model.site(FT_SITE).id] - scratch.xpos[root])
        self.com_body = r_root.T @ (scratch.subtree_com[mount] - scratch.xpos[root])

    def contact_wrench(self, state: ControlState, centre_body: _Vec, accel_ref: _Vec) -> tuple[_Vec, _Vec]:
        """Contact force on the hand [N] and its moment about ``centre_body`` (gripper frame,
        from the pinch point) [N m], both world frame, unfiltered and untared. ``accel_ref``
        (3,) [m/s^2] is the hand's expected acceleration (zero for quasi-static use)."""
        f_world, t_world = ft_world(state)
        f_ext = self.mass * (accel_ref - self.gravity) - f_world
        q = state.quat_world
        site = rotate(q, self.site_body)  # relative to the pinch point
        com = rotate(q, self.com_body)
        centre = rotate(q, centre_body)
        weight = self.mass * self.gravity
        tau = -t_world - cross(com - site, weight) + cross(site - centre, f_ext)
        return f_ext, tau


class WristSensor:
    """Tared, low-passed contact wrench about a point of the gripper frame.

    The tare is the mean reading while :meth:`accumulate_tare` is called (or, with
    ``tare_time`` > 0, over the first ``tare_time`` seconds after :meth:`reset`, which must be
    free of contact); the force bias is kept in world axes, the moment bias in the gripper frame
    (it comes from the hand's own mass distribution).

    Attributes:
        force: (3,) filtered contact force on the hand, world frame [N].
        moment: (3,) filtered moment of the contact about the point, world frame [N m].
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        *,
        centre_body: _Vec,
        dt: float,
        force_hz: float = 20.0,
        moment_hz: float = 5.0,
        tare_time: float = 0.0,
    ) -> None:
        self.wrist = WristModel(model)
        self.centre_body = np.asarray(centre_body, dtype=float)
        self.tare_time = tare_time
        self._a_force = lowpass_alpha(force_hz, dt)
        self._a_moment = lowpass_alpha(moment_hz, dt)
        self._zero = np.zeros(3)
        self.reset(None)

    def reset(self, state: ControlState | None) -> None:
        """Forget the tare and the filters; the timed tare starts at ``state.t``."""
        self._t0 = state.t if state is not None else 0.0
        self._n = 0
        self.force_bias = np.zeros(3)
        self.moment_bias_body = np.zeros(3)
        self.force = np.zeros(3)
        self.moment = np.zeros(3)

    def raw(self, state: ControlState) -> tuple[_Vec, _Vec]:
        """The tared, unfiltered wrench (force [N], moment [N m], world)."""
        f, tau = self.wrist.contact_wrench(state, self.centre_body, self._zero)
        return f - self.force_bias, tau - rotate(state.quat_world, self.moment_bias_body)

    def accumulate_tare(self, state: ControlState) -> None:
        """Add this reading to the tare (the hand must be free of contact and at rest)."""
        f, tau = self.wrist.contact_wrench(state, self.centre_body, self._zero)
        self._n += 1
        self.force_bias += (f - self.force_bias) / self._n
        self.moment_bias_body += (rotate_inv(state.quat_world, tau) - self.moment_bias_body) / self._n

    def update(self, state: ControlState) -> tuple[_Vec, _Vec]:
        """Filter in this reading (taring first while the timed tare runs); the filtered wrench."""
        if state.t - self._t0 < self.tare_time:
            self.accumulate_tare(state)
        f, tau = self.raw(state)
        self.force += self._a_force * (f - self.force)
        self.moment += self._a_moment * (tau - self.moment)
        return self.force, self.moment

    def moment_about(self, state: ControlState, point_body: _Vec) -> _Vec:
        """The filtered moment moved to another point of the gripper frame [N m], world."""
        q = state.quat_world
        return self.moment + cross(rotate(q, self.centre_body) - rotate(q, point_body), self.force)


class ContactSense:
    """The contact force on the hand from the mount's force/torque sensor: the reading minus its
    mean while tared (:meth:`accumulate_tare`), sign-flipped, low-passed at ``hz``, world frame.

    Attributes:
        tare: (3,) The mean reading while tared, world frame [N].
        force: (3,) The filtered contact force on the hand [N].
    """

    def __init__(self, control_dt: float = 0.001, hz: float = 30.0) -> None:
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * hz * control_dt)
        self.tare = np.zeros(3)
        self._tare_sum = np.zeros(3)
        self._tare_n = 0
        self.force = np.zeros(3)

    def accumulate_tare(self, state: ControlState) -> None:
        self._tare_sum += ft_world(state)[0]
        self._tare_n += 1
        self.tare = self._tare_sum / self._tare_n

    def update(self, state: ControlState) -> None:
        contact = -(ft_world(state)[0] - self.tare)
        self.force += self.alpha * (contact - self.force)
