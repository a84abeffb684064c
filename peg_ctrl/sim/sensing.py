"""The contact wrench on the hand, from the force/torque sensor at the gripper mount.

The sensor (``ft_sensor``, :func:`peg_ctrl.sim.state.ft_world`) reads what the base exerts on
everything below it: the hand's weight, its inertia, and the contact. :class:`WristModel`
removes the weight (and the inertia along a known reference acceleration) with the hand's mass
and centre of mass taken from the model at the home pose, and moves the moment to a point of
the gripper frame (a centre of compliance; for the held peg, its lower end)::

    F_c   = m_h (a_ref - g) - f_s                                  contact force on the hand [N]
    tau_c = -t_s + (r_com - r_s) x m_h (a_ref - g) + (r_s - c) x F_c   its moment about c [N m]

(``f_s``, ``t_s`` the sensor's world-frame reading; ``r_s``, ``r_com``, ``c`` the sensor site,
the hand's centre of mass and the point, from the pinch point.) What the model does not know —
the jaw closed instead of open moves the fingers' mass, a held peg adds its own weight — is a
bias of a few mN m that a moment-regulating loop would integrate into a drift. :class:`WristSensor`
removes it with a tare taken while the hand is known to be free, and low-passes the result.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.ft_model import DelayLine
from peg_ctrl.sim.rotations import Floats3, cross, cross_floats, rotate, rotate_floats, rotate_inv
from peg_ctrl.sim.scene import FT_SITE, HOME_KEY
from peg_ctrl.sim.state import ControlState

__all__ = ["Detector", "WristModel", "WristSensor", "WrenchPredictor", "lowpass_alpha", "within"]

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
        self._gravity = tuple(self.gravity.tolist())
        self._site_body = tuple(self.site_body.tolist())
        self._com_body = tuple(self.com_body.tolist())

    def contact_wrench(self, state: ControlState, centre_body: _Vec, accel_ref: _Vec) -> tuple[_Vec, _Vec]:
        """Contact force on the hand [N] and its moment about ``centre_body`` (gripper frame,
        from the pinch point) [N m], both world frame, unfiltered and untared. ``accel_ref``
        (3,) [m/s^2] is the hand's expected acceleration (zero for quasi-static use)."""
        f, tau = self.contact_wrench_floats(
            state.quat_world.tolist(),
            state.ft_wrench.tolist(),
            np.asarray(centre_body, dtype=float).tolist(),
            np.asarray(accel_ref, dtype=float).tolist(),
        )
        return np.array(f), np.array(tau)

    def contact_wrench_floats(
        self,
        quat: Sequence[float],
        ft: Sequence[float],
        centre_body: Sequence[float],
        accel_ref: Sequence[float],
    ) -> tuple[Floats3, Floats3]:
        """:meth:`contact_wrench` in plain floats (every control step: no array is worth its
        cost here), from the gripper's ``quat`` and the sensor's reading ``ft`` (6,); the same
        arithmetic as its array form, so the same bits."""
        fx, fy, fz, tx, ty, tz = ft
        f_world = rotate_floats(quat, (fx, -fy, -fz))  # sensor frame -> gripper frame: 180 deg about X
        t_world = rotate_floats(quat, (tx, -ty, -tz))
        m = self.mass
        g0, g1, g2 = self._gravity
        a0, a1, a2 = accel_ref
        inertia = (m * (a0 - g0), m * (a1 - g1), m * (a2 - g2))  # the hand's weight and inertia [N]
        f_ext = (inertia[0] - f_world[0], inertia[1] - f_world[1], inertia[2] - f_world[2])
        sx, sy, sz = rotate_floats(quat, self._site_body)  # relative to the pinch point
        cx, cy, cz = rotate_floats(quat, self._com_body)
        ox, oy, oz = rotate_floats(quat, centre_body)
        u = cross_floats((cx - sx, cy - sy, cz - sz), inertia)
        w = cross_floats((sx - ox, sy - oy, sz - oz), f_ext)
        tau = (-t_world[0] + u[0] + w[0], -t_world[1] + u[1] + w[1], -t_world[2] + u[2] + w[2])
        return f_ext, tau


class WristSensor:
    """The one estimator of the contact wrench on the hand: tare, noise level, bias, filters.

    Every controller and strategy that reads the wrist sensor reads it through this class:

    - **Tare and noise.** The tare is the mean reading while :meth:`accumulate_tare` is called (or,
      with ``tare_time`` > 0, over the first ``tare_time`` seconds after :meth:`reset`, which must
      be free of contact); the force bias is kept in world axes, the moment bias in the gripper
      frame (it comes from the hand's own mass distribution). The spread of the same readings is
      the sensor's noise, per reading (``noise_force``, ``noise_moment``): nothing assumes a
      datasheet value, so the detectors' thresholds follow whatever sensor is fitted.
    - **Bias.** A sensor's zero drifts. While the caller knows the hand is free of contact
      (``update(..., free=True)``: in the air, between touches), the bias follows the reading with
      the time constant ``bias_time``.
    - **Filters.** First-order low-passes, ``force_hz`` on the force and ``moment_hz`` on the
      moment about ``centre_body`` (a point of the gripper frame: the held peg's lower end).
      ``sigma_force`` and ``sigma_moment`` are the filtered estimates' standard deviations: the
      noise through the filter, with the hand model's own ``resolution`` as a floor (the weight
      and inertia the model leaves over, and the reading of a noise-free sensor, are not zero).
    - **Acceleration.** The hand's inertia is compensated along its measured acceleration (the
      finite difference of the sensed velocity, low-passed at ``accel_hz``), so a hop or a stop
      does not read as a touch; or along an acceleration the caller knows (``accel_ref``, e.g. the
      reference's: :meth:`update`, :meth:`raw` and :meth:`accumulate_tare` take it).

    Attributes:
        force: (3,) filtered contact force on the hand, world frame [N].
        moment: (3,) filtered moment of the contact about the point, world frame [N m].
        moment_fast: (3,) the same moment through the force's filter (``force_hz``), with
            ``fast_moment`` (a loop that needs a quicker moment than ``moment_hz`` gives); zero
            otherwise.
        force_bias: (3,) the force bias, world frame [N]; moment_bias_body (3,) the moment's,
            gripper frame [N m].
        noise_force: (3,) standard deviation of one force reading, world axes [N] (0 before a tare).
        noise_moment: (3,) ... of one moment reading, gripper axes (like its bias) [N m]. Both
            read-only: a new estimate is assigned, not written into them.
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
        accel_hz: float = 0.0,
        bias_time: float = 1.0,
        resolution: tuple[float, float] = (0.05, 5e-4),
        fast_moment: bool = False,
    ) -> None:
        self.wrist = WristModel(model)
        self.centre_body = np.asarray(centre_body, dtype=float)
        self.tare_time = tare_time
        self.dt = dt
        self._a_force = lowpass_alpha(force_hz, dt)
        self._a_moment = lowpass_alpha(moment_hz, dt)
        self._a_accel = lowpass_alpha(accel_hz, dt) if accel_hz > 0 else 0.0
        self._a_bias = dt / bias_time
        # Variance of a first-order low-pass's output per unit variance of white input.
        self._gain_force = self._a_force / (2.0 - self._a_force)
        self._gain_moment = self._a_moment / (2.0 - self._a_moment)
        self._sigma_force: _Vec | None = None  # from the noise and the resolution, when asked
        self._sigma_moment: _Vec | None = None
        self.resolution = resolution
        self.fast_moment = fast_moment
        self._zero = np.zeros(3)
        self.reset(None)

    def reset(self, state: ControlState | None) -> None:
        """Forget the tare, the noise estimate and the filters; the timed tare starts at ``state.t``."""
        self._t0 = state.t if state is not None else 0.0
        self._n = 0
        self.force_bias = np.zeros(3)
        self.moment_bias_body = np.zeros(3)
        self._m2_force = np.zeros(3)  # Welford sums of squared deviations
        self._m2_moment = np.zeros(3)
        self.noise_force = np.zeros(3)
        self.noise_moment = np.zeros(3)
        self.force = np.zeros(3)
        self.moment = np.zeros(3)
        self.moment_fast = np.zeros(3)
        self.accel = np.zeros(3)
        self._v_prev: Floats3 | None = None

    # The noise estimates and the resolution are read-only arrays, replaced (never changed in
    # place) when they change, so that the sigmas they give are computed once per change, not
    # at every reading a detector tests against them.
    @property
    def noise_force(self) -> _Vec:
        return self._noise_force

    @noise_force.setter
    def noise_force(self, value: _Vec) -> None:
        self._noise_force = _frozen(value)
        self._sigma_force = None

    @property
    def noise_moment(self) -> _Vec:
        return self._noise_moment

    @noise_moment.setter
    def noise_moment(self, value: _Vec) -> None:
        self._noise_moment = _frozen(value)
        self._sigma_moment = None

    @property
    def resolution(self) -> tuple[float, float]:
        """The floor of ``sigma_force`` [N] and ``sigma_moment`` [N m]."""
        return self._resolution

    @resolution.setter
    def resolution(self, value: tuple[float, float]) -> None:
        self._resolution = value
        self._sigma_force = self._sigma_moment = None

    @property
    def sigma_force(self) -> _Vec:
        """(3,) Standard deviation of the filtered force, world axes [N] (read-only)."""
        if self._sigma_force is None:
            self._sigma_force = _frozen(
                np.sqrt(self._noise_force**2 * self._gain_force + self._resolution[0] ** 2)
            )
        return self._sigma_force

    @property
    def sigma_moment(self) -> _Vec:
        """(3,) Standard deviation of the filtered moment [N m] (read-only)."""
        if self._sigma_moment is None:
            self._sigma_moment = _frozen(
                np.sqrt(self._noise_moment**2 * self._gain_moment + self._resolution[1] ** 2)
            )
        return self._sigma_moment

    def _wrench(self, state: ControlState, accel_ref: _Vec | None) -> tuple[_Vec, _Vec]:
        if accel_ref is None:
            accel_ref = self.accel if self._a_accel else self._zero
        return self.wrist.contact_wrench(state, self.centre_body, accel_ref)

    # Every control step (update, and raw for some controllers) runs in plain floats, the same
    # arithmetic as the arrays', operation for operation: the same bits, a fraction of the time.
    def _raw_floats(
        self, state: ControlState, quat: list[float], accel_ref: _Vec | None
    ) -> tuple[Floats3, Floats3]:
        if accel_ref is None:
            accel = self.accel.tolist() if self._a_accel else [0.0, 0.0, 0.0]
        else:
            accel = np.asarray(accel_ref, dtype=float).tolist()
        f, tau = self.wrist.contact_wrench_floats(
            quat, state.ft_wrench.tolist(), self.centre_body.tolist(), accel
        )
        b0, b1, b2 = self.force_bias.tolist()
        m0, m1, m2 = rotate_floats(quat, self.moment_bias_body.tolist())
        return (f[0] - b0, f[1] - b1, f[2] - b2), (tau[0] - m0, tau[1] - m1, tau[2] - m2)

    def raw(self, state: ControlState, *, accel_ref: _Vec | None = None) -> tuple[_Vec, _Vec]:
        """The tared, unfiltered wrench (force [N], moment [N m], world). ``accel_ref`` (3,)
        [m/s^2]: the hand's acceleration to compensate; None: the measured one (``accel_hz``),
        or zero."""
        f, tau = self._raw_floats(state, state.quat_world.tolist(), accel_ref)
        return np.array(f), np.array(tau)

    def accumulate_tare(self, state: ControlState, *, accel_ref: _Vec | None = None) -> None:
        """Add this reading to the tare and the noise estimate (the hand must be free of
        contact and at rest)."""
        self._track_accel(state)
        f, tau = self._wrench(state, accel_ref)
        tau_body = rotate_inv(state.quat_world, tau)
        self._n += 1
        d_f, d_m = f - self.force_bias, tau_body - self.moment_bias_body
        self.force_bias += d_f / self._n
        self.moment_bias_body += d_m / self._n
        self._m2_force += d_f * (f - self.force_bias)
        self._m2_moment += d_m * (tau_body - self.moment_bias_body)
        if self._n > 1:
            self.noise_force = np.sqrt(self._m2_force / (self._n - 1))
            self.noise_moment = np.sqrt(self._m2_moment / (self._n - 1))

    def update(
        self, state: ControlState, *, free: bool = False, accel_ref: _Vec | None = None
    ) -> tuple[_Vec, _Vec]:
        """Filter in this reading (taring first while the timed tare runs; following the bias
        while ``free``); the filtered wrench (:attr:`force` and :attr:`moment`, updated in
        place). ``accel_ref`` as for :meth:`raw`."""
        if state.t - self._t0 < self.tare_time:
            self.accumulate_tare(state, accel_ref=accel_ref)
        else:
            self._track_accel(state)
        quat = state.quat_world.tolist()
        f, tau = self._raw_floats(state, quat, accel_ref)
        if free and self._n:
            w, x, y, z = quat
            _add_scaled(self.force_bias, self._a_bias, f)
            _add_scaled(self.moment_bias_body, self._a_bias, rotate_floats((w, -x, -y, -z), tau))
        _follow(self.force, self._a_force, f)
        _follow(self.moment, self._a_moment, tau)
        if self.fast_moment:
            _follow(self.moment_fast, self._a_force, tau)
        return self.force, self.moment

    def _track_accel(self, state: ControlState) -> None:
        if not self._a_accel:
            return
        v = state.v_world.tolist()
        if self._v_prev is not None:
            a, dt, (p0, p1, p2) = self._a_accel, self.dt, self._v_prev
            accel = self.accel
            x0, x1, x2 = accel.tolist()
            accel[0] = x0 + a * ((v[0] - p0) / dt - x0)
            accel[1] = x1 + a * ((v[1] - p1) / dt - x1)
            accel[2] = x2 + a * ((v[2] - p2) / dt - x2)
        self._v_prev = (v[0], v[1], v[2])

    def move_centre(self, centre_body: _Vec, state: ControlState) -> None:
        """Take moments about another point of the gripper frame from now on, keeping the tare
        (its moment moved with the point) and the filters."""
        centre = np.asarray(centre_body, dtype=float)
        f_body = rotate_inv(state.quat_world, self.force_bias)
        self.moment_bias_body = self.moment_bias_body + cross(self.centre_body - centre, f_body)
        q = state.quat_world
        arm = rotate(q, self.centre_body) - rotate(q, centre)
        self.moment = self.moment + cross(arm, self.force)
        if self.fast_moment:
            self.moment_fast = self.moment_fast + cross(arm, self.force)
        self.centre_body = centre

    def moment_about(self, state: ControlState, point_body: _Vec) -> _Vec:
        """The filtered moment moved to another point of the gripper frame [N m], world."""
        q = state.quat_world
        return self.moment + cross(rotate(q, self.centre_body) - rotate(q, point_body), self.force)


def _frozen(value: _Vec) -> _Vec:
    """A read-only float copy of ``value``."""
    out = np.array(value, dtype=float)
    out.setflags(write=False)
    return out


# (3,) arrays written element by element: a third of the cost of a slice assignment.
def _follow(x: _Vec, alpha: float, target: Floats3) -> None:
    """One step of a first-order low-pass, in place: ``x += alpha * (target - x)``."""
    x0, x1, x2 = x.tolist()
    x[0], x[1], x[2] = (
        x0 + alpha * (target[0] - x0),
        x1 + alpha * (target[1] - x1),
        x2 + alpha * (target[2] - x2),
    )


def _add_scaled(x: _Vec, alpha: float, v: Floats3) -> None:
    """``x += alpha * v`` in place."""
    x0, x1, x2 = x.tolist()
    x[0], x[1], x[2] = x0 + alpha * v[0], x1 + alpha * v[1], x2 + alpha * v[2]


class WrenchPredictor:
    """The contact wrench *now*, from a filtered reading ``latency`` [s] old: a Smith predictor
    on a linear contact model.

    A controller that moves its command ``s`` along an axis against a contact of stiffness ``K``
    changes the contact wrench on the hand by ``-K ds``. The sensor reports that change
    ``latency`` late, and the estimate's first-order filter later still. The predictor corrects
    the filtered reading for the command's own motion that the reading cannot show yet::

        w_now = w_read - K (s_now - s_seen)

    ``s_seen`` is the command as the reading reflects it: ``s`` delayed by ``latency`` (a
    :class:`~peg_ctrl.sim.ft_model.DelayLine`, the sensor's own rule) and passed through the
    reading's filter (gain ``alpha`` per axis, :func:`lowpass_alpha`), so the filter's lag is
    predicted too. Where the model is right (``K`` the contact's stiffness) the loop no longer
    sees the delay nor the filter; where the contact is softer than ``K`` (free space, a peg
    turning on one point of its rim) the correction acts as extra damping, about ``K`` times
    the latency and the filter's time constant, on an accommodation law.

    Call :meth:`predict` once per reading, with the command in effect since the last one.
    """

    def __init__(
        self, *, stiffness: NDArray[np.float64], latency: float, dt: float, alpha: NDArray[np.float64]
    ) -> None:
        self.stiffness = np.asarray(stiffness, dtype=float)
        self.alpha = np.asarray(alpha, dtype=float)
        if self.alpha.shape != self.stiffness.shape:
            raise ValueError(f"alpha {self.alpha.shape} and stiffness {self.stiffness.shape} differ in shape")
        self.latency = latency
        self._line = DelayLine(latency=latency, dt=dt, width=self.stiffness.size)
        self.reset(np.zeros(self.stiffness.size))

    def reset(self, command: _Vec) -> None:
        """Forget the history: the command has been ``command`` (n,) for ever."""
        self._line.reset(command)
        self.seen = np.array(command, dtype=float)  # s_seen (n,)
        self.correction = np.zeros(self.stiffness.size)  # the last -K (s_now - s_seen) (n,)

    def restart(self, where: NDArray[np.bool_], command: _Vec) -> None:
        """Forget the history on the axes ``where`` (n,): an axis whose command starts afresh (it
        has just become wrench-controlled) has moved in no way the reading could miss."""
        if where.any():
            self._line.reset(command, where)
            self.seen[where] = command[where]

    def predict(self, reading: _Vec, command: _Vec) -> _Vec:
        """The wrench now (n,) from the filtered ``reading`` (n,) [N, N m] and the ``command``
        (n,) in effect [m, rad]."""
        self.seen += self.alpha * (self._line.push(command) - self.seen)
        self.correction = -self.stiffness * (command - self.seen)
        return reading + self.correction


class Detector:
    """A hysteresis test that a filtered estimate has risen past a level, in units of its
    standard deviation: on once ``value > level + k_on sigma`` has held for ``hold`` [s], off
    as soon as ``value < level + k_off sigma``. With ``k_on`` = 4 a false detection on Gaussian
    noise needs a 4-sigma excursion that lasts; the gap to ``k_off`` keeps a detection from
    chattering on the noise.

    Attributes:
        on: whether the test holds.
        since: when it last switched on [s] (None while off).
    """

    def __init__(self, *, k_on: float = 4.0, k_off: float = 2.0, hold: float = 0.0) -> None:
        if not k_on > k_off:
            raise ValueError(f"k_on must exceed k_off, got {k_on} and {k_off}")
        self.k_on, self.k_off, self.hold = k_on, k_off, hold
        self.reset()

    def reset(self) -> None:
        self.on = False
        self.since: float | None = None
        self._rising: float | None = None

    def update(self, t: float, value: float, sigma: float, level: float = 0.0) -> bool:
        """The test at time ``t`` [s] for ``value`` with standard deviation ``sigma``."""
        if self.on:
            if value < level + self.k_off * sigma:
                self.reset()
            return self.on
        if value > level + self.k_on * sigma:
            self._rising = t if self._rising is None else self._rising
            if t - self._rising >= self.hold - 1e-12:
                self.on, self.since = True, t
        else:
            self._rising = None
        return self.on


def within(value: float, sigma: float, tolerance: float, k: float = 3.0) -> bool:
    """Whether ``|value|`` is within ``tolerance``, or within ``k`` of its standard deviation
    ``sigma`` where the noise is wider than the tolerance (no test can be finer than its noise)."""
    return abs(value) < max(tolerance, k * sigma)
