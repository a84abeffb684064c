"""The contact model of the MPC's ``contact`` formulation: a QP over the wrench-controlled axes.

A target's wrench-controlled axes (``target.wrench_axes``: forces along world x, y, z; moments
about world x, y, z through the centre of compliance ``c``, the held peg's tip) are planned by
a receding-horizon QP on a quasi-static contact model, re-anchored on the force/torque sensor
every solve::

    w_k = w_0 - K (s_k - s_0)          predicted contact wrench on the hand along axis i, k steps
                                       ahead, when the command s (the tip's position along the
                                       axis, or the turn about it) has moved by s_k - s_0

``w_0`` is the measured wrench (:class:`~peg_ctrl.sim.sensing.WristSensor`, tared); ``K`` the modelled
stiffness of the contact seen through the inner tracking loop (``contact_stiffness`` along the
force axes — the inner MPC's own position stiffness, its LQR gain, by default — and
``contact_rot_stiffness`` about the moment axes). In units of force (``y_k = K (s_k - s_0)``) the
QP over the horizon of ``N`` steps of ``h = contact_dt`` (the mpc's ``contact_dt``, by
default its ``control_dt``) is, per active axis::

    minimise   sum_k (y_k - (w_0 - w*))^2 + rho sum_k (y_k - y_{k-1})^2
    subject to |y_k - y_{k-1}| <= K v_max h           rate: v_max = clip(|w_0 - w*| / D, v_min, v_cap)
               w_0 - B <= y_k <= w_0 + B             the contact-force budget |w_k| <= B (force axes)

with ``w* = -f*`` (the target's force or moment is what the hand exerts on its surroundings).
The rate bound is an accommodation law (``D`` = ``force_damping``, ``moment_damping``): far from
the wrench it asks for, the command moves at most at ``v_cap``, and slower as it gets close, so a
free axis approaches a surface gently; the budget is a hard constraint on the *predicted* force
(where the predicted force is already over budget, the command backs off as fast as the rate
allows). The first step of the plan is executed over the next ``h``, then the QP is solved
again from the new reading. Moment axes turn the command about ``c``: the QP's model puts the
rotation about the peg's tip, so a moment there turns the peg about its tip, as a remote
centre of compliance does.

**A late sensor** (``sensor_latency`` > 0, the latency ``L`` the F/T reading is assumed to
have): re-anchoring on a reading ``L`` old (and filtered, later still) would plan from a wrench
that the command's own motion since has already changed. A Smith predictor on the same contact
model (:class:`~peg_ctrl.sim.sensing.WrenchPredictor`) corrects it first::

    w_0 = w_read - K (s_now - s_seen)      s_seen: the command delayed by L and passed through
                                           the reading's own filter (force_filter_hz,
                                           moment_filter_hz), so the filter's lag is predicted too

An axis that has just become wrench-controlled starts with no correction. ``sensor_latency``
0 (the default) leaves ``w_0`` the filtered reading, bit for bit. The prediction is only as
good as ``K``: along the force axes the inner loop's stiffness is close to the contact's
(4447 against the 2500-3600 N/m measured on a flat peg); about the moment axes
``contact_rot_stiffness`` (2 N m/rad) is a peg on its rim, while a peg lying flat is some
50-150 N m/rad stiff, so on the moment axes the predictor changes little. Measured on the
``align`` press (docs/controllers.md): it neither causes nor cures the limit cycle there
(including the filter's lag or not); the reversal backoff below does.

**Reversal backoff** (``reversal_backoff`` > 1): about a moment axis a peg pressed on a face is a
relay — the moment about its tip is the normal force times the lever to the rim it stands on,
the same until its end lies flat and the opposite once it has turned past — and a relay with a
delay (the latency, the moment filter's lag) always limit-cycles: the command overshoots flat
by about ``rate x delay`` and rocks the peg from rim to rim. Each time the moment error on a
moment axis reverses (beyond ``reversal_band``, or 3 sigma of the moment's noise), that axis's
``D`` is multiplied and its ``v_min`` divided by ``reversal_backoff``
(:class:`~peg_ctrl.controllers.backoff.ReversalBackoff`), so the rocking dies out geometrically
whatever the delay; an axis that never reverses (the peg turning on its rim towards flat)
keeps its full rate. The backoff restarts when the axis becomes moment-controlled again.

In the terms of :mod:`peg_ctrl.controllers.prediction` (shared with the effort QP), ``y`` is the
predicted trajectory of an integrator from ``y_0 = 0``: the QP plans it directly, and its
smoothing and rate rows act on its increments.

The per-axis problems are independent (a diagonal model); the active ones are stacked into one
QP and solved by DAQP, a dense active-set solver, called directly (``contact_solver: daqp``, the
fastest measured on this QP: docs/controllers.md), or by any other solver through
:mod:`qpsolvers` (``osqp``, ...).
"""

from __future__ import annotations

import dataclasses
import time

import daqp
import mujoco
import numpy as np
import qpsolvers
import scipy.linalg
import scipy.sparse
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.backoff import ReversalBackoff
from peg_ctrl.controllers.prediction import INTEGRATOR, increments, prediction
from peg_ctrl.sim.rotations import cross, quat_mul, rotate, rotate_inv
from peg_ctrl.sim.sensing import WrenchPredictor, WristSensor, lowpass_alpha
from peg_ctrl.sim.state import ControlState

__all__ = ["ContactQP", "ContactQPSolution", "ContactLoop", "ContactSettings"]

_Vec = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class ContactSettings:
    """The contact formulation's numbers, per axis where it says (6,): forces then moments."""

    centre_body: tuple[float, float, float]  # centre of compliance, gripper frame [m]
    stiffness: tuple[float, ...]  # modelled contact stiffness (6,) [N/m, N m/rad]
    damping: tuple[float, ...]  # accommodation D of the rate bound (6,) [N s/m, N m s/rad]
    rate_cap: tuple[float, ...]  # v_cap (6,) [m/s, rad/s]
    rate_min: tuple[float, ...]  # v_min (6,) [m/s, rad/s]
    budget: float  # contact-force budget B along each force axis [N]
    smoothing: float  # rho
    horizon: int  # N
    dt: float  # h = contact_dt [s]
    solver: str  # a qpsolvers solver
    tare_time: float  # sensor tare over the first seconds after reset [s]
    force_filter_hz: float
    moment_filter_hz: float
    accel_filter_hz: float = 0.0  # the sensor's acceleration compensation [Hz]; 0: none
    latency: float = 0.0  # the sensor's latency the wrench is predicted across [s]; 0: none
    reversal_backoff: float = 1.0  # a moment axis's damping grows by this at each reversal; 1: never
    reversal_band: float = 0.004  # a reversal crosses from beyond +band to beyond -band [N m]


@dataclasses.dataclass(frozen=True)
class ContactQPSolution:
    """The plan: ``rate`` (6,) of the command over the next step [m/s, rad/s] (zero on inactive
    axes), ``predicted`` (n_active, N) wrenches [N, N m], solver ``status``."""

    rate: _Vec
    predicted: _Vec
    status: str


class ContactQP:
    """The receding-horizon QP of the module docstring, for any set of active axes."""

    def __init__(self, settings: ContactSettings) -> None:
        self.s = settings
        n = settings.horizon
        # y is an integrator's trajectory from y_0 = 0 (controllers/prediction.py): dy = diff y,
        # and k steps of at most `step` each reach k `step` at most.
        _, gamma = prediction(*INTEGRATOR, n)
        self._diff = increments(*INTEGRATOR, n)
        self._reach = gamma @ np.ones(n)
        self._block = 2.0 * (np.eye(n) + settings.smoothing * self._diff.T @ self._diff)  # Hessian in y
        self._cache: dict[int, tuple[_Vec, _Vec]] = {}

    def _matrices(self, count: int) -> tuple[_Vec, _Vec]:
        if count not in self._cache:
            hess = scipy.linalg.block_diag(*([self._block] * count))
            rows = scipy.linalg.block_diag(*([self._diff] * count))  # the rate rows act on y's increments
            self._cache[count] = (hess, rows)
        return self._cache[count]

    def _qp(self, hess: _Vec, g: _Vec, rows: _Vec, rate: _Vec, lo: _Vec, hi: _Vec) -> _Vec | None:
        """argmin 1/2 y'Hy + g'y  s.t.  lo <= y <= hi, -rate <= rows y <= rate."""
        if self.s.solver == "daqp":
            x, _, flag, _ = daqp.solve(hess, g, rows, np.concatenate([hi, rate]), np.concatenate([lo, -rate]))
            return np.asarray(x) if flag > 0 else None
        constraints = np.vstack([rows, -rows])
        if self.s.solver in qpsolvers.sparse_solvers:
            hess, constraints = scipy.sparse.csc_matrix(hess), scipy.sparse.csc_matrix(constraints)
        return qpsolvers.solve_qp(
            hess, g, constraints, np.concatenate([rate, rate]), lb=lo, ub=hi, solver=self.s.solver
        )

    def problem(
        self, axes: NDArray[np.bool_], measured: _Vec, wanted: _Vec, backoff: _Vec | None = None
    ) -> tuple[_Vec, _Vec, _Vec, _Vec]:
        """The QP's data for the active ``axes``: linear term, bounds on y (lo, hi) and the
        rate bound on its increments (the module docstring's problem); ``backoff`` (6,)
        multiplies each axis's damping and divides its minimum rate (None: 1)."""
        s = self.s
        n = s.horizon
        idx = np.flatnonzero(axes)
        lin, lo, hi, cap = [], [], [], []
        for i in idx:
            k = s.stiffness[i]
            error = float(measured[i] - wanted[i])  # y that would bring the wrench to wanted
            slow = 1.0 if backoff is None else float(backoff[i])  # damping up, minimum rate down
            v = min(s.rate_cap[i], max(s.rate_min[i] / slow, abs(error) / (s.damping[i] * slow)))
            step = k * v * s.dt  # largest |dy| per step [N]
            lin.append(np.full(n, -2.0 * error))
            cap.append(np.full(n, step))
            if i < 3:  # the budget on the predicted force, relaxed to what the rate can reach
                reach = step * self._reach
                lo.append(np.minimum(measured[i] - s.budget, reach))
                hi.append(np.maximum(measured[i] + s.budget, -reach))
            else:
                lo.append(np.full(n, -np.inf))
                hi.append(np.full(n, np.inf))
        return np.concatenate(lin), np.concatenate(lo), np.concatenate(hi), np.concatenate(cap)

    def solve(
        self, axes: NDArray[np.bool_], measured: _Vec, wanted: _Vec, backoff: _Vec | None = None
    ) -> ContactQPSolution:
        """Plan the active ``axes`` (6,) from the measured wrench ``measured`` (6,) towards
        ``wanted`` (6,) (both on the hand [N, N m]); ``backoff`` as for :meth:`problem`."""
        s = self.s
        n = s.horizon
        idx = np.flatnonzero(axes)
        rate = np.zeros(6)
        if idx.size == 0:
            return ContactQPSolution(rate, np.zeros((0, n)), "idle")
        hess, rows = self._matrices(idx.size)
        lin, lo, hi, cap = self.problem(axes, measured, wanted, backoff)
        y = self._qp(hess, lin, rows, cap, lo, hi)
        status = "ok"
        if y is None:  # infeasible or failed: take the rate-limited step towards the wrench
            status = "qp_failed"
            first = np.clip(-lin[::n] / 2.0, -cap[::n], cap[::n])
            y = np.repeat(first, n)
        y = y.reshape(idx.size, n)
        for j, i in enumerate(idx):
            rate[i] = y[j, 0] / s.stiffness[i] / s.dt
        predicted = measured[idx, None] - y
        return ContactQPSolution(rate, predicted, status)


class ContactLoop:
    """Sensing and the command along the wrench-controlled axes, around :class:`ContactQP`.

    :meth:`shape` turns a target into the pose the inner loop tracks: the pose axes as the target
    has them, the force axes at the planned tip position, the moment axes turned about the tip.
    The QP is solved when ``solve`` is true (every ``contact_dt``); between solves the command moves
    at the planned rate. An axis that becomes wrench-controlled starts from the target's pose
    (bumpless for the inner MPC); one that stops being so returns to the target's pose (the task
    re-anchors its reference at the present pose).
    """

    def __init__(self, model: mujoco.MjModel, settings: ContactSettings, *, control_dt: float) -> None:
        self.s = settings
        self.dt = control_dt
        self.qp = ContactQP(settings)
        self.centre_body = np.asarray(settings.centre_body, dtype=float)
        self.sensor = WristSensor(
            model,
            centre_body=self.centre_body,
            dt=control_dt,
            force_hz=settings.force_filter_hz,
            moment_hz=settings.moment_filter_hz,
            tare_time=settings.tare_time,
            accel_hz=settings.accel_filter_hz,
        )
        self.backoff = ReversalBackoff(factor=settings.reversal_backoff, band=settings.reversal_band, size=6)
        self.predictor: WrenchPredictor | None = None
        if settings.latency > 0:
            alpha = [lowpass_alpha(settings.force_filter_hz, control_dt)] * 3
            alpha += [lowpass_alpha(settings.moment_filter_hz, control_dt)] * 3
            self.predictor = WrenchPredictor(
                stiffness=np.asarray(settings.stiffness),
                latency=settings.latency,
                dt=control_dt,
                alpha=np.array(alpha),
            )
        self.reset(None)

    def reset(self, state: ControlState | None) -> None:
        self.sensor.reset(state)
        self.axes = np.zeros(6, dtype=bool)
        self.tip = np.zeros(3)  # commanded tip position along the force axes [m]
        self.turn = np.zeros(3)  # commanded turn about the tip on the moment axes [rad]
        self.rate = np.zeros(6)
        self.wrench = np.zeros(6)  # the wrench the QP plans from: sensed, or predicted [N, N m]
        self.backoff.reset()
        self.last: ContactQPSolution | None = None
        self.solve_times: list[float] = []  # wall time of every QP solve [s]
        if self.predictor is not None:
            self.predictor.reset(np.zeros(6))

    def shape(self, state: ControlState, target: GripperTarget, *, solve: bool) -> GripperTarget:
        """The pose for the inner loop (see the class docstring)."""
        force, moment = self.sensor.update(state)
        axes = np.concatenate([target.force_axes, target.moment_axes]) if target.force_controlled else _NONE
        q_t = np.asarray(target.quat_world)
        tip_t = np.asarray(target.p_world) + rotate(q_t, self.centre_body)
        restart = axes & ~self.axes
        self.backoff.reset(restart)
        entering = axes[:3] & ~self.axes[:3]
        self.tip[entering] = tip_t[entering]
        self.turn[~axes[3:]] = 0.0
        self.rate[~axes] = 0.0
        self.wrench = np.concatenate([force, moment])
        if self.predictor is not None:
            command = np.concatenate([self.tip, self.turn])  # in effect since the last reading
            self.predictor.restart(~self.axes | ~axes, command)
            self.wrench = self.predictor.predict(self.wrench, command)
        self.axes = axes
        if not axes.any():
            self.last = None
            return target
        if solve:
            wanted = -np.concatenate([target.force_world, target.torque_world])
            sigma = np.concatenate([np.zeros(3), self.sensor.sigma_moment])
            # Only the moment axes back off: a force axis is a spring, not a relay.
            scale = self.backoff.update(self.wrench - wanted, axes & _MOMENT_AXES, sigma)
            t0 = time.perf_counter()
            self.last = self.qp.solve(axes, self.wrench, wanted, scale)
            self.solve_times.append(time.perf_counter() - t0)
            self.rate = self.last.rate
        self.tip += self.rate[:3] * self.dt
        self.turn += self.rate[3:] * self.dt
        tip = np.where(axes[:3], self.tip, tip_t)
        v_tip = np.where(axes[:3], self.rate[:3], target.v_world)
        q_cmd = q_t
        angle = float(np.linalg.norm(self.turn))
        if angle > 1e-12:
            q_rot = np.empty(4)
            mujoco.mju_axisAngle2Quat(q_rot, self.turn / angle, angle)
            q_cmd = quat_mul(q_rot, q_t)
        arm = rotate(q_cmd, self.centre_body)
        omega_world = self.rate[3:]
        p_cmd = tip - arm
        v_cmd = v_tip - cross(omega_world, arm)
        omega_body = np.asarray(target.omega_body) + rotate_inv(q_cmd, omega_world)
        return GripperTarget.trusted(p_cmd, q_cmd, v_cmd, omega_body, target.jaw_sep_m)


_NONE = np.zeros(6, dtype=bool)
_NONE.setflags(write=False)
_MOMENT_AXES = np.array([False] * 3 + [True] * 3)
_MOMENT_AXES.setflags(write=False)
