"""Linear model-predictive control of the base with CasADi (condensed QP, built once).

Model, per DoF (x, y, z slides; three ball-joint body rates), from the compiled MuJoCo model:

    m dv/dt = u - b v        (m: mass or rotational inertia at the pinch incl. armature,
                              b: joint damping; gravity/bias forces are compensated outside)

discretised exactly with a zero-order hold of ``mpc_dt``. The reference moves at the target's
velocity over the horizon; with the feed-forward ``u_ff = b v_ref`` the tracking error
``z = [p_ref - p, v_ref - v]`` obeys ``z+ = A z - B du``. The QP minimises

    sum_k z_k' Q z_k + du_k' R du_k  +  z_N' P z_N        (P: the DARE solution, so the
                                                          unconstrained optimum is LQR)

subject to the actuator range on ``u_ff + du``, a box on the velocity and a *contact-force
limit*: the net slide effort ``|du_i| <= force_limit``. Gravity and bias forces are compensated
outside the QP and the joint damping by ``u_ff``, so in quasi-static contact ``du`` is the force
the gripper exerts: the QP plans every motion knowing that it may never push harder than the
limit (a stiff position tracker otherwise; impacts add their own, brief, force).

Force-controlled axes (``target.force_axes``, force ``f``): the reference along the axis is put
``REACH`` beyond the current position in the direction of ``f`` (no position error for ``f = 0``)
and the effort bound becomes ``[min(0, f), max(0, f)]`` (``f`` clipped to the force limit):
pressed against a surface the QP saturates at exactly ``f``; moving freely it is still held to
the velocity box. Moment-controlled axes (``target.moment_axes``): the orientation error about
them is dropped and the commanded ``target.torque_world`` (about the pinch point) added outside
the QP, open loop.

The prediction and its condensing are :mod:`peg_ctrl.controllers.prediction`'s (shared with the
contact QP). The QP's Hessian and constraint matrix are constant: CasADi's ``conic`` interface is built once
and re-solved with new linear terms and bounds, warm-started from the previous solution. Default
solver qpOASES (``osqp`` selectable). Runs every ``mpc_dt`` (default 10 ms, 100 Hz), zero-order hold between.

``formulation: contact`` (the default is ``effort``, all of the above) adds a model of the contact
in front of it: every ``contact_dt`` (default: every control step) a second QP
(:mod:`peg_ctrl.controllers.contact_mpc`) plans the wrench-controlled axes of the target on the
force/torque sensor's reading — force tracking along the force axes with the contact-force budget
``force_limit`` as a constraint on the *predicted* force, moments about the centre of compliance
(``compliance_center``, the held peg's tip) turning the command about the tip — and the effort
QP above tracks the pose it plans. Its contact model's stiffness along the force axes is the
effort QP's own position stiffness (the LQR gain), unless ``contact_stiffness`` says otherwise.
A late F/T reading (``sensor_latency``) and the reversal backoff of the moment axes
(``reversal_backoff``, ``reversal_band``) are described there too.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import sys
import time
from collections.abc import Iterator
from typing import ClassVar

import mujoco
import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.backoff import check_backoff
from peg_ctrl.controllers.base import (
    ControllerBase,
    ControllerConfig,
    Diagnostics,
    Effort,
    InvalidField,
    SolveTiming,
    check_multiple,
    check_target,
)
from peg_ctrl.controllers.contact_mpc import ContactLoop, ContactSettings
from peg_ctrl.controllers.dynamics import BaseDynamics
from peg_ctrl.controllers.prediction import condense
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.rotations import rotate, rotate_inv
from peg_ctrl.sim.scene import BALL_JOINT, HOME_KEY, SLIDE_JOINTS
from peg_ctrl.sim.state import ControlState

__all__ = ["MPCConfig", "MPCController", "condense", "discretise", "lqr_gain"]

_NAN3 = (math.nan, math.nan, math.nan)
REACH = 0.01  # a force-controlled axis's reference lies this far beyond the gripper [m]
FORMULATIONS = ("effort", "contact")


@dataclasses.dataclass(frozen=True, kw_only=True)
class MPCConfig(ControllerConfig):
    """Horizon, rate, weights and boxes of the MPC (``control_dt`` [s] from the base class)."""

    name: ClassVar[str] = "mpc"
    GAINS: ClassVar[tuple[str, ...]] = ("q_pos", "q_rot")
    VECTORS: ClassVar[tuple[str, ...]] = ("compliance_center",)
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (
        "tare_time",
        "contact_smoothing",
        "sensor_latency",
        "reversal_band",
        "accel_filter_hz",
    )
    horizon: int = 15  # steps
    control_dt: float = 0.005  # [s] 200 Hz: outcomes as at 1 kHz (docs/performance.md)
    mpc_dt: float = 0.01  # [s], a whole multiple of control_dt
    q_pos: float = 4.0e4  # weight on position error (translation) [1/m^2]
    q_vel: float = 10.0  # weight on velocity error [s^2/m^2]
    q_rot: float = 2.0e3  # weight on orientation error [1/rad^2]
    q_omega: float = 1.0  # weight on angular velocity error [s^2/rad^2]
    r_force: float = 1e-3  # weight on force effort [1/N^2]
    r_torque: float = 1e-3  # weight on torque effort [1/(N m)^2]
    v_max: float = 0.5  # velocity box [m/s]
    omega_max: float = 2.0  # angular velocity box [rad/s]
    solver: str = "qpoases"  # qpoases or osqp
    force_limit: float = 1000.0  # bound on the net slide effort [N] (default: above the actuators' range)
    # The contact formulation (module docstring, peg_ctrl.controllers.contact_mpc).
    formulation: str = "effort"  # effort, or contact: plans the wrench-controlled axes on the sensor
    compliance_center: tuple[float, float, float] = (0.0, 0.0, 0.0)  # gripper frame [m]
    contact_stiffness: float | None = None  # modelled contact stiffness, force axes [N/m]; None: the LQR's
    contact_rot_stiffness: float = 2.0  # modelled contact stiffness, moment axes [N m/rad]
    contact_dt: float | None = None  # the contact QP's period [s], a multiple of control_dt; None: control_dt
    contact_horizon: int = 10  # steps of contact_dt
    contact_smoothing: float = 0.1  # weight on the planned wrench's increments, relative
    # Accommodation of the rate bound along the force axes x, y, z [N s/m]: a larger D on the
    # lateral axes keeps a peg that a bore guides from rattling between its walls.
    force_damping: tuple[float, float, float] = (400.0, 400.0, 400.0)
    moment_damping: float = 0.5  # ... moment axes [N m s/rad]
    max_contact_speed: float = 0.01  # cap on the command's speed along the force axes [m/s]
    max_turn_rate: float = 0.05  # ... and its turn rate about the moment axes [rad/s]
    contact_solver: str = "daqp"  # a qpsolvers solver for the contact QP
    tare_time: float = 0.0  # sensor tare over the first seconds after reset [s]; 0: none
    force_filter_hz: float = 20.0  # low-pass on the sensed force [Hz]
    moment_filter_hz: float = 5.0  # low-pass on the sensed moment [Hz]
    # The hand's inertia taken out of the reading along its measured acceleration, low-passed at
    # this [Hz] (peg_ctrl.sim.sensing.WristSensor); 0: not (a hop or a stop then reads as a push).
    accel_filter_hz: float = 0.0
    # The F/T reading's latency [s] that the contact QP predicts the wrench across (a Smith
    # predictor on its contact model, peg_ctrl.controllers.contact_mpc); 0: the reading as it is.
    sensor_latency: float = 0.0
    # Each time the moment on a moment axis reverses (crosses from beyond +reversal_band to
    # beyond -reversal_band [N m], or 3 sigma of its noise), that axis's accommodation slows by
    # reversal_backoff (its damping up, its minimum rate down); 1: never.
    reversal_backoff: float = 1.0
    reversal_band: float = 0.004

    def __post_init__(self) -> None:
        for field in ("horizon", "contact_horizon"):
            value = getattr(self, field)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 2):
                raise InvalidField(self.name, field, f"must be an integer >= 2, got {value!r}")
        super().__post_init__()
        if self.solver not in ("qpoases", "osqp"):
            raise InvalidField(self.name, "solver", f"must be one of 'qpoases', 'osqp', got {self.solver!r}")
        if self.formulation not in FORMULATIONS:
            raise InvalidField(
                self.name,
                "formulation",
                f"must be one of {', '.join(map(repr, FORMULATIONS))}, got {self.formulation!r}",
            )
        import qpsolvers

        if self.contact_solver not in qpsolvers.available_solvers:
            raise InvalidField(
                self.name,
                "contact_solver",
                f"{self.contact_solver!r} is not installed; available: "
                f"{', '.join(sorted(qpsolvers.available_solvers))}",
            )
        check_backoff(self.name, self.reversal_backoff)
        check_multiple(self, "mpc_dt")
        if self.contact_dt is not None:
            check_multiple(self, "contact_dt")

    def build(self, model: mujoco.MjModel) -> MPCController:
        return MPCController(model, self)


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence C-level writes to stdout (file descriptor 1)."""
    import ctypes

    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    libc.fflush(None)
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        with contextlib.redirect_stdout(io.StringIO()):  # CasADi prints through Python's stdout
            yield
    finally:
        libc.fflush(None)  # C stdio buffers what it printed; drop it before stdout comes back
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def discretise(mass: float, damping: float, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact ZOH discretisation of ``m dv/dt = u - b v``, state ``[p, v]``: (A (2,2), B (2,1))."""
    a_c = np.array([[0.0, 1.0], [0.0, -damping / mass]])
    b_c = np.array([[0.0], [1.0 / mass]])
    block = np.zeros((3, 3))
    block[:2, :2] = a_c
    block[:2, 2:] = b_c
    e = scipy.linalg.expm(block * dt)
    return e[:2, :2], e[:2, 2:]


def lqr_gain(
    a: NDArray[np.float64], b: NDArray[np.float64], q: NDArray[np.float64], r: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Discrete LQR: gain ``K`` (u = -K x) and the DARE solution ``P``."""
    p = scipy.linalg.solve_discrete_are(a, b, q, r)
    k = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
    return k, p


def _base_inertia(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """The base's six DoFs (three slides, the ball's three): their diagonal mass at the home
    keyframe and their joint damping."""
    slide_dofs = [model.joint(n).dofadr[0] for n in SLIDE_JOINTS]
    ball = model.joint(BALL_JOINT).dofadr[0]
    dofs = [*slide_dofs, ball, ball + 1, ball + 2]
    scratch = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, scratch, model.key(HOME_KEY).id)
    mujoco.mj_forward(model, scratch)
    full_m = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, scratch, full_m)
    return np.array([full_m[d, d] for d in dofs]), model.dof_damping[dofs].copy()


class MPCController(ControllerBase[MPCConfig]):
    """Condensed linear MPC at ``mpc_dt``, zero-order hold between. See the module docstring.

    Attributes:
        last_solve: Diagnostics of the latest QP solve (solve time [s], status, iterations).
    """

    name = "mpc"

    def __init__(
        self,
        model: mujoco.MjModel,
        config: MPCConfig | None = None,
        *,
        jaw_calibration: JawCalibration | None = None,
    ) -> None:
        super().__init__(model, config or MPCConfig(), jaw_calibration=jaw_calibration)
        c = self.config
        self._every = check_multiple(c, "mpc_dt")
        self.dynamics = BaseDynamics()
        self.mass, self.damping = _base_inertia(model)
        self.u_max = np.concatenate([self._act.slide_limit, self._act.ball_limit])
        n, h = 6, c.horizon
        self.a, self.b, self.q, self.r = self._per_dof_models()
        self.k_lqr, self.p_terminal = lqr_gain(self.a, self.b, self.q, self.r)
        self._phi, self._gamma, self._hess, self._lin = condense(
            self.a, self.b, self.q, self.p_terminal, self.r, h
        )
        # Velocity rows of the prediction: v_k = v_ref - z_v(k).
        vel_rows = [k * 2 * n + 2 * i + 1 for k in range(h) for i in range(n)]
        self._vel_rows = np.array(vel_rows)
        self._a_con = self._gamma[self._vel_rows]
        self._vel_limit = np.tile(np.array([c.v_max] * 3 + [c.omega_max] * 3), h)
        self._make_solver()
        self._u = np.zeros(n)
        self._warm_x = np.zeros(h * n)
        self._warm_lam_x = np.zeros(h * n)
        self._warm_lam_a = np.zeros(len(vel_rows))
        self._count = 0
        self._err = np.zeros(3)
        self._quat = np.array([1.0, 0.0, 0.0, 0.0])
        self.last_solve = Diagnostics()
        with _quiet_stdout():  # ... or on its first solve
            self.solve(np.zeros(12), np.zeros(6), np.zeros(6))
        self.reset_warm_start()
        self.contact = self._contact_loop(model) if c.formulation == "contact" else None
        self._contact_every = check_multiple(c, "contact_dt") if c.contact_dt is not None else 1
        self.solve_times: list[float] = []  # wall time of every QP solve [s]

    def _per_dof_models(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-DoF models (A, B, Q, R), stacked block-diagonally: state [p_0, v_0, p_1, v_1, ...]."""
        c = self.config
        a_blocks, b_blocks, q_blocks, r_diag = [], [], [], []
        for i in range(6):
            a_i, b_i = discretise(self.mass[i], self.damping[i], c.mpc_dt)
            a_blocks.append(a_i)
            b_blocks.append(-b_i)  # the error falls when the effort rises
            q_blocks.append(np.diag([c.q_pos, c.q_vel] if i < 3 else [c.q_rot, c.q_omega]))
            r_diag.append(c.r_force if i < 3 else c.r_torque)
        block = scipy.linalg.block_diag
        return block(*a_blocks), block(*b_blocks), block(*q_blocks), np.diag(r_diag)

    def _make_solver(self) -> None:
        """CasADi's conic solver for the QP's sparsity (qpOASES or OSQP)."""
        import casadi as ca

        c = self.config
        options = (
            {"printLevel": "none"}
            if c.solver == "qpoases"
            else {"osqp": {"verbose": False}, "warm_start_primal": True}
        )
        with _quiet_stdout():  # qpOASES prints its licence banner when it is created
            self._solver = ca.conic(
                "mpc",
                c.solver,
                {"h": ca.DM(self._hess).sparsity(), "a": ca.DM(self._a_con).sparsity()},
                options,  # type: ignore[arg-type]
            )
        self._hess_dm = ca.DM(self._hess)
        self._a_dm = ca.DM(self._a_con)

    def _contact_loop(self, model: mujoco.MjModel) -> ContactLoop:
        c = self.config
        k_pos = -float(self.k_lqr[0, 0])  # the effort QP's position stiffness [N/m]
        k_force = c.contact_stiffness if c.contact_stiffness is not None else k_pos
        settings = ContactSettings(
            centre_body=c.compliance_center,
            stiffness=(k_force,) * 3 + (c.contact_rot_stiffness,) * 3,
            damping=(*c.force_damping, *(c.moment_damping,) * 3),
            rate_cap=(c.max_contact_speed,) * 3 + (c.max_turn_rate,) * 3,
            rate_min=(0.01 * c.max_contact_speed,) * 3 + (0.01 * c.max_turn_rate,) * 3,
            budget=c.force_limit,
            smoothing=c.contact_smoothing,
            horizon=c.contact_horizon,
            dt=c.contact_dt if c.contact_dt is not None else c.control_dt,
            solver=c.contact_solver,
            tare_time=c.tare_time,
            force_filter_hz=c.force_filter_hz,
            moment_filter_hz=c.moment_filter_hz,
            accel_filter_hz=c.accel_filter_hz,
            latency=c.sensor_latency,
            reversal_backoff=c.reversal_backoff,
            reversal_band=c.reversal_band,
        )
        return ContactLoop(model, settings, control_dt=c.control_dt)

    def reset_warm_start(self) -> None:
        self._warm_x[:] = 0.0
        self._warm_lam_x[:] = 0.0
        self._warm_lam_a[:] = 0.0

    def _reset(self, state: ControlState) -> None:
        self._u[:] = 0.0
        self.reset_warm_start()
        self._count = 0
        if self.contact is not None:
            self.contact.reset(state)
        self.solve_times = []

    def timings(self) -> list[SolveTiming]:
        c = self.config
        out = [SolveTiming("effort_qp", c.mpc_dt, self.solve_times)]
        if self.contact is not None:
            period = c.contact_dt if c.contact_dt is not None else c.control_dt
            out.append(SolveTiming("contact_qp", period, self.contact.solve_times))
        return out

    def _effort_bounds(
        self, target: GripperTarget, z0: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Bounds on ``du`` (6,): the force limit on the slides, the commanded force on
        force-controlled axes (whose position error ``z0`` is replaced by ``REACH`` towards it)."""
        limit = self.config.force_limit
        lo = np.full(6, -np.inf)
        hi = np.full(6, np.inf)
        lo[:3], hi[:3] = -limit, limit
        if target.force_controlled:
            forces = target.force_world.tolist()
            for i, on in enumerate(target.force_axes.tolist()):
                if on:
                    f = max(-limit, min(limit, forces[i]))  # never beyond the limit
                    z0[2 * i] = math.copysign(REACH, f) if f else 0.0
                    lo[i], hi[i] = min(0.0, f), max(0.0, f)
            if target.moment_axes.any():  # no orientation error about the moment-controlled axes
                err_world = rotate(self._quat, z0[6::2])
                err_world[target.moment_axes] = 0.0
                z0[6::2] = rotate_inv(self._quat, err_world)
        return lo, hi

    def error_state(self, state: ControlState, target: GripperTarget) -> NDArray[np.float64]:
        """``z0`` (12,): per DoF (position or orientation error, velocity error)."""
        self._quat = state.quat_world
        mujoco.mju_subQuat(self._err, target.quat_world, state.quat_world)
        pos = np.concatenate([target.p_world - state.p_world, self._err])
        vel = np.concatenate([target.v_world - state.v_world, target.omega_body - state.omega_body])
        z = np.empty(12)
        z[0::2] = pos
        z[1::2] = vel
        return z

    def solve(
        self,
        z0: NDArray[np.float64],
        u_ff: NDArray[np.float64],
        v_ref: NDArray[np.float64],
        du_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    ) -> NDArray[np.float64]:
        """The first effort correction ``du_0`` (6,) of the QP from error ``z0``; ``du_bounds``
        (low, high) (6,) further bound the correction (the contact-force limit)."""
        h = self.config.horizon
        g = self._lin @ z0
        lo, hi = -self.u_max - u_ff, self.u_max - u_ff
        if du_bounds is not None:
            lo, hi = np.maximum(lo, du_bounds[0]), np.minimum(hi, du_bounds[1])
            hi = np.maximum(lo, hi)
        lbx = np.tile(lo, h)
        ubx = np.tile(hi, h)
        # v_k = v_ref - (Phi z0 + Gamma U)_vel must stay in [-v_max, v_max].
        free = self._phi[self._vel_rows] @ z0
        v_ref_rows = np.tile(v_ref, h)
        lba = v_ref_rows - self._vel_limit - free
        uba = v_ref_rows + self._vel_limit - free
        lba = np.minimum(lba, uba)  # an infeasible start (already too fast) relaxes to equality
        sol = self._solver(
            h=self._hess_dm,
            g=g,
            a=self._a_dm,
            lbx=lbx,
            ubx=ubx,
            lba=lba,
            uba=uba,
            x0=self._warm_x,
            lam_x0=self._warm_lam_x,
            lam_a0=self._warm_lam_a,
        )
        x = np.asarray(sol["x"]).reshape(-1)
        self._warm_x = np.concatenate([x[6:], x[-6:]])  # shift the plan for the next solve
        self._warm_lam_x = np.asarray(sol["lam_x"]).reshape(-1)
        self._warm_lam_a = np.asarray(sol["lam_a"]).reshape(-1)
        return x[:6]

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        contact_status = ""
        if self.contact is not None:
            solving = self._count % self._contact_every == 0
            check_target(target)
            target = self.contact.shape(state, target, solve=solving)
            last = self.contact.last
            if solving and last is not None and last.status != "ok":
                contact_status = f"contact_{last.status}"
        v_ref = np.concatenate([target.v_world, target.omega_body])
        u_ff = self.damping * v_ref
        status, iterations = "hold", 0
        if self._count % self._every == 0:
            check_target(target)
            z0 = self.error_state(state, target)
            if not np.all(np.isfinite(z0)):
                return Effort(_NAN3, _NAN3, "non_finite")  # the base class raises, naming the cause
            bounds = self._effort_bounds(target, z0)
            t0 = time.perf_counter()
            try:
                self._u = self.solve(z0, u_ff, v_ref, bounds)
                stats = self._solver.stats()
                status = "ok" if stats.get("success", True) else str(stats.get("return_status", "failed"))
                iterations = int(stats.get("iter_count", 0) or 0)
            except RuntimeError as exc:
                # Fall back to the LQR law within the same bounds, reported.
                self._u = np.clip(-self.k_lqr @ z0, bounds[0], bounds[1])
                status = f"qp_failed: {exc}".splitlines()[0]
            self.last_solve = Diagnostics(time.perf_counter() - t0, status, iterations)
            self.solve_times.append(self.last_solve.solve_time_s)
        self._count += 1
        tau = (
            u_ff
            + self._u
            + self.dynamics.bias(state.p_world, state.quat_world, state.v_world, state.omega_body)
        )
        if target.force_controlled and target.moment_axes.any():  # the commanded moment, open loop
            tau[3:] += rotate_inv(state.quat_world, np.where(target.moment_axes, target.torque_world, 0.0))
        if contact_status and status == "ok":
            status = contact_status
        return Effort(tau[:3].tolist(), tau[3:].tolist(), status, iterations)
