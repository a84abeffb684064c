"""Sampling-based predictive control through contact, on MuJoCo rollouts of a belief model.

Every ``replan_dt`` the planner rolls out candidate plans on a model of the world *as the task
believes it* (:mod:`peg_ctrl.controllers.belief_model`: the hole where the task thinks it is, the
peg in the believed grasp, never the simulation's true state) from the hand's measured state,
with :func:`mujoco.rollout.rollout` in C (``threads`` worker threads), scores them, and keeps the
best. A plan is a piecewise-linear trajectory through ``knots`` setpoints over the ``horizon``
of the tip's position and its turn about the tip; the hand executes it through a compliant inner
loop — the ``impedance`` controller (``inner``) with its centre of compliance at the believed tip —
which the belief model reproduces as position actuators with the same stiffness and damping.

Methods (``method``), as in MuJoCo MPC's planners:

- ``predictive_sampling``: Gaussian perturbations of the nominal plan (``noise_pos`` [m],
  ``noise_rot`` [rad] per knot), the nominal itself among them; the cheapest wins.
- ``mppi``: the plans averaged with weights ``exp(-(J - J_min) / temperature)`` (the temperature
  relative to the spread of the costs).
- ``cem``: ``iterations`` rounds of sampling around a mean and refitting mean and spread to the
  ``elites`` cheapest.

Plans are offsets from a reference: the target's pose, extrapolated at its velocity and angular
velocity, except on the target's wrench-controlled axes, where the reference is an
accommodation law on the sensed wrench (it moves at ``(F - F*) / force_damping``, capped at
``max_contact_speed``, and turns at ``(M - M*) / moment_damping``, capped at ``max_turn_rate``),
so a free axis approaches a surface and a tilted peg turns flat even where the belief model sees
no contact. The nominal offsets of the next replan are the chosen ones, shifted in time (warm
start); the reference itself (zero offset) is always one of the samples.

Cost of a rollout, summed over its steps (units: m, rad, N, N m)::

    w_pose   |tip - tip_target|^2 + w_turn |turn - turn_target|^2     on the pose axes
    w_force  (F + f*)^2                                                 on the force axes
    w_moment (M + tau*)^2                                               on the moment axes
    w_budget max(0, |F| - budget)^2  +  w_wrist |M|^2                    contact force, wrist torque
    w_smooth |knot_{j+1} - knot_j|^2                                     the plan's smoothness
    w_offset |offset_j|^2                                                its offset from the reference

(the last two once per plan, over its knots: the position part of the offsets for w_smooth, all
of it for w_offset).

``F``, ``M``: the contact wrench on the hand about the tip. The belief model is wrong where the
task's belief is (a hole 2 mm off, a peg tilted in the hand), so its wrench is corrected by the
measured one (offset-free MPC): ``F = F_sensed + (F_model - F_model(start))``, likewise ``M``. The
target's pose is extrapolated over the horizon at its velocity.

**Planning over the belief.** When the task hands over (its belief carries ``plan_depth``: the
``plan`` strategy), the controller stops tracking the target and plans towards the goal itself
on hypotheses of the belief weighed by a filter, with a cost of named residual terms:
:mod:`peg_ctrl.controllers.belief_planner`, :mod:`peg_ctrl.controllers.residuals`,
docs/planning.md. Its fields (``hypotheses``, ``particles``, ``risk``, the priors, the filter's
scales, ``w_<term>``) are not used while it tracks.

The belief model is trusted only while it explains the present contact: where its wrench at the
measured state differs from the sensed one by more than ``trust_force`` or ``trust_moment`` (the
hole is not where the task thinks, the peg is tilted in the hand), its predictions would mislead,
and the hand follows the reference (the replan's status is ``distrust``). The wall time of
every replan is kept (``plan_times``, reported by :meth:`timings` as ``plan``); the episode
summary gives its p50/p99 and the real-time factor, mean planning time over ``replan_dt``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import ClassVar

import mujoco
import mujoco.rollout
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.base import (
    ControllerBase,
    ControllerConfig,
    Effort,
    InvalidField,
    SolveTiming,
    check_multiple,
    check_target,
)
from peg_ctrl.controllers.belief_model import BeliefModelSpec, build_belief_model
from peg_ctrl.controllers.belief_planner import RISKS, BeliefPlanner, PlannerSettings, knot_setpoints
from peg_ctrl.controllers.impedance import ImpedanceConfig, ImpedanceController
from peg_ctrl.controllers.residuals import TERMS
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.jaw import JawCalibration
from peg_ctrl.sim.rotations import cross, quat_mul, rotate, rotate_inv
from peg_ctrl.sim.scene import BALL_JOINT, SLIDE_JOINTS
from peg_ctrl.sim.sensing import WristSensor
from peg_ctrl.sim.state import ControlState

__all__ = ["SamplingMPCConfig", "SamplingMPCController", "METHODS"]

METHODS = ("predictive_sampling", "mppi", "cem")
_Vec = NDArray[np.float64]


@dataclasses.dataclass(frozen=True, kw_only=True)
class SamplingMPCConfig(ControllerConfig):
    """Planner, cost and inner loop (``control_dt`` [s], the inner loop's, from the base class)."""

    name: ClassVar[str] = "sampling_mpc"
    GAINS: ClassVar[tuple[str, ...]] = ()
    VECTORS: ClassVar[tuple[str, ...]] = ("compliance_center",)
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (
        "w_turn",
        "w_force",
        "w_moment",
        "w_budget",
        "w_wrist",
        "w_smooth",
        "w_offset",
        "tare_time",
        "seed",
        "w_depth",
        "w_lateral",
        "w_sink_speed",
        "w_side_speed",
        "w_bore_speed",
        "w_tilt",
        "w_slip",
        "w_effort",
        "w_accel",
        "grasp_sigma",
        "depth_sigma",
        "tilt_sigma",
        "filter_moment",
        "plan_noise_rot",
    )
    method: str = "predictive_sampling"  # predictive_sampling, mppi or cem
    control_dt: float = 0.001  # the inner loop's period [s]
    replan_dt: float = 0.02  # [s], a whole multiple of control_dt
    horizon: float = 0.1  # [s]
    model_dt: float = 0.002  # the belief model's timestep [s]
    samples: int = 12  # rollouts per replan (per CEM iteration)
    knots: int = 3  # plan knots over the horizon (the first is the present setpoint)
    noise_pos: float = 5e-5  # perturbation of a knot's tip position [m]
    noise_rot: float = 5e-4  # ... of its turn [rad]
    temperature: float = 0.1  # MPPI's, relative to the costs' spread
    elites: int = 3  # CEM's
    iterations: int = 2  # CEM's
    threads: int = 1  # rollout threads
    seed: int = 0  # the planner's random stream
    friction: float = 0.6  # sliding friction the belief model assumes
    budget: float = 10.0  # contact-force budget [N]
    w_pose: float = 1.0e6  # [1/m^2]
    w_turn: float = 1.0e3  # [1/rad^2]
    w_force: float = 1.0  # [1/N^2]
    w_moment: float = 1.0e4  # [1/(N m)^2]
    w_budget: float = 10.0  # [1/N^2]
    w_wrist: float = 10.0  # [1/(N m)^2]
    w_smooth: float = 1.0e4  # [1/m^2 per knot]
    w_offset: float = 1.0e5  # on the plan's offset from the reference [1/m^2, 1/rad^2 per knot]
    trust_force: float = 1.0  # the model is trusted while it explains the sensed force to this [N]
    trust_moment: float = 0.01  # ... and the sensed moment to this [N m]
    tare_time: float = 0.25  # sensor tare over the first seconds after reset [s]
    force_damping: float = 400.0  # the reference's accommodation on force axes [N s/m]
    moment_damping: float = 0.5  # ... on moment axes [N m s/rad]
    max_contact_speed: float = 0.01  # [m/s]
    max_turn_rate: float = 0.05  # [rad/s]
    # Planning over the belief, once a task hands over (Belief.plan_depth; the ``plan`` strategy):
    # controllers/belief_planner.py, docs/planning.md. The cost's terms and their weights
    # (controllers/residuals.py) [1/unit^2], w_budget and the budget above being shared.
    hypotheses: int = 4  # drawn from the belief to score every plan on; 1: the nominal model alone
    particles: int = 64  # the belief's hypotheses, weighed by the filter
    risk: str = "mean"  # a plan's score over its hypotheses: mean or worst
    grasp_sigma: float = 0.002  # the prior on the end's offset in the hand along the pads' plane [m]
    depth_sigma: float = 0.0002  # ... in height (the face's tolerance, a slip in the pads) [m]
    tilt_sigma: float = 0.0  # ... the peg's tilt in the hand about the pads' normal [rad]
    friction_low: float = 0.3  # the friction's range, uniform
    friction_high: float = 0.9
    filter_position: float = 2e-4  # the likelihood's scale on the end's move over a replan [m]
    filter_force: float = 3.0  # ... on the contact force [N]
    filter_moment: float = 0.0  # ... on its moment about the believed end [N m]; 0: not compared
    plan_noise_pos: float = 3e-4  # a candidate's step per knot [m]
    plan_noise_rot: float = 0.0  # ... in turn [rad]; 0: the plans keep the hand's orientation
    slip_force: float = 20.0  # the force along the peg the pads hold [N]
    w_depth: float = 1.0e3
    w_lateral: float = 1.0e6
    w_sink_speed: float = 7.0e3
    w_side_speed: float = 2.0e3
    w_bore_speed: float = 0.0
    w_tilt: float = 1.0e2
    w_slip: float = 10.0
    w_effort: float = 1.0e4
    w_accel: float = 1.0e5
    inner: ImpedanceConfig = ImpedanceConfig(
        k_pos=(3000.0, 3000.0, 3000.0), k_rot=(30.0, 30.0, 30.0), damping_compensation=0.9
    )  # executes the plan; its compliance_center is the believed tip, its control_dt ours
    # Without a task's belief (a task that states none) the model is the hand alone in free
    # space, turning about this point of the gripper frame [m].
    compliance_center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        counts = (("samples", 2), ("knots", 2), ("elites", 1), ("iterations", 1), ("threads", 1))
        for field, low in (*counts, ("hypotheses", 1), ("particles", 2)):
            value = getattr(self, field)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= low):
                raise InvalidField(self.name, field, f"must be an integer >= {low}, got {value!r}")
        if not (isinstance(self.seed, int) and not isinstance(self.seed, bool) and self.seed >= 0):
            raise InvalidField(self.name, "seed", f"must be an integer >= 0, got {self.seed!r}")
        super().__post_init__()
        if self.method not in METHODS:
            raise InvalidField(
                self.name, "method", f"must be one of {', '.join(METHODS)}, got {self.method!r}"
            )
        if self.risk not in RISKS:
            raise InvalidField(self.name, "risk", f"must be one of {', '.join(RISKS)}, got {self.risk!r}")
        if not self.friction_low <= self.friction_high:
            raise InvalidField(
                self.name,
                "friction_high",
                f"must be >= friction_low ({self.friction_low}), got {self.friction_high!r}",
            )
        check_multiple(self, "replan_dt")
        if self.horizon < 2.0 * self.model_dt:
            raise InvalidField(
                self.name, "horizon", f"must cover at least 2 model steps, got {self.horizon!r}"
            )
        if self.elites > self.samples:
            raise InvalidField(
                self.name, "elites", f"must be <= samples ({self.samples}), got {self.elites!r}"
            )

    def build(self, model: mujoco.MjModel) -> SamplingMPCController:
        return SamplingMPCController(model, self)

    def planner_settings(self) -> PlannerSettings:
        """The belief planner's parameters, from this config's fields of the same names."""
        return PlannerSettings(
            hypotheses=self.hypotheses,
            particles=self.particles,
            risk=self.risk,
            samples=self.samples,
            grasp_sigma=self.grasp_sigma,
            depth_sigma=self.depth_sigma,
            tilt_sigma=self.tilt_sigma,
            friction_range=(self.friction_low, self.friction_high),
            friction=self.friction,
            filter_position=self.filter_position,
            filter_force=self.filter_force,
            filter_moment=self.filter_moment,
            plan_noise_pos=self.plan_noise_pos,
            plan_noise_rot=self.plan_noise_rot,
            budget=self.budget,
            slip_force=self.slip_force,
            weights={term.name: float(getattr(self, f"w_{term.name}")) for term in TERMS},
        )


class _Plan:
    """Knot setpoints (knots, 6) at times ``t0 + times`` [s]: tip position [m], turn [rad]; and
    the ``offsets`` (knots, 6) from the reference they were planned as."""

    def __init__(self, t0: float, times: _Vec, knots: _Vec, offsets: _Vec) -> None:
        self.t0, self.times, self.knots, self.offsets = t0, times, knots, offsets

    def offset_at(self, t: float) -> _Vec:
        s = min(max(t - self.t0, 0.0), float(self.times[-1]))
        return np.array([np.interp(s, self.times, self.offsets[:, i]) for i in range(6)])

    def at(self, t: float) -> tuple[_Vec, _Vec]:
        """Setpoint (6,) and its rate (6,) at time ``t``."""
        s = min(max(t - self.t0, 0.0), float(self.times[-1]))
        j = min(int(np.searchsorted(self.times, s, side="right")) - 1, len(self.times) - 2)
        span = float(self.times[j + 1] - self.times[j])
        rate = (self.knots[j + 1] - self.knots[j]) / span
        value = self.knots[j] + rate * (s - self.times[j])
        if t - self.t0 > self.times[-1]:
            rate = np.zeros(6)
        return value, rate


def _turn_to_quat(turn: _Vec) -> _Vec:
    """The rotation of the hinge chain x, y, z (intrinsic) by ``turn`` [rad]."""
    q = np.array([1.0, 0.0, 0.0, 0.0])
    for i, angle in enumerate(turn.tolist()):
        axis = np.zeros(3)
        axis[i] = 1.0
        qi = np.empty(4)
        mujoco.mju_axisAngle2Quat(qi, axis, angle)
        q = quat_mul(q, qi)
    return q


def _quat_to_turn(q: _Vec) -> _Vec:
    """Hinge angles x, y, z (intrinsic) of the rotation ``q``."""
    m = np.empty(9)
    mujoco.mju_quat2Mat(m, q)
    r = m.reshape(3, 3)
    b = math.asin(max(-1.0, min(1.0, r[0, 2])))
    a = math.atan2(-r[1, 2], r[2, 2])
    c = math.atan2(-r[0, 1], r[0, 0])
    return np.array([a, b, c])


class SamplingMPCController(ControllerBase[SamplingMPCConfig]):
    """Sampling MPC on a belief model, executed by an impedance. See the module docstring.

    Attributes:
        plan_times: Wall time of every replan so far [s].
    """

    name = "sampling_mpc"
    observes_belief = True  # its model of the world is built from the task's belief

    def __init__(
        self,
        model: mujoco.MjModel,
        config: SamplingMPCConfig | None = None,
        *,
        jaw_calibration: JawCalibration | None = None,
    ) -> None:
        super().__init__(model, config or SamplingMPCConfig(), jaw_calibration=jaw_calibration)
        c = self.config
        self._model = model
        self._every = check_multiple(c, "replan_dt")
        self._steps = max(2, round(c.horizon / c.model_dt))
        self._times = np.linspace(0.0, self._steps * c.model_dt, c.knots)
        self._rng = np.random.default_rng(c.seed)
        self._rollout = mujoco.rollout.Rollout(nthread=c.threads)
        slide_dofs = [model.joint(n).dofadr[0] for n in SLIDE_JOINTS]
        ball = model.joint(BALL_JOINT).dofadr[0]
        self._joint_damping = np.concatenate(
            [model.dof_damping[slide_dofs], model.dof_damping[ball : ball + 3]]
        )
        self._inner: ImpedanceController | None = None
        self._belief: Belief | None = None
        self._belief_model: mujoco.MjModel | None = None
        self._belief_data: mujoco.MjData | None = None
        self._thread_data: list[mujoco.MjData] = []
        self._sensor: WristSensor | None = None
        self._plan: _Plan | None = None
        self._count = 0
        self._q_ref = np.array([1.0, 0.0, 0.0, 0.0])
        self.plan_times: list[float] = []
        self.planner: BeliefPlanner | None = None  # once the task hands over
        self._reset_reference()
        self._mismatch = (0.0, 0.0)

    def _reset_reference(self) -> None:
        self._acc_axes = _NO_AXES
        self._acc_tip = np.zeros(3)
        self._acc_turn = np.zeros(3)
        self._acc_rate = np.zeros(6)

    # -- belief ----------------------------------------------------------------------------------
    def observe_belief(self, belief: Belief | None) -> None:
        """Rebuild the belief model for the task's new belief (see :mod:`peg_ctrl.sim.belief`;
        None: the task states none, and the model is the hand alone)."""
        self._belief = belief if isinstance(belief, Belief) else None
        self._belief_model = None  # built at the next control step, at the present orientation

    @property
    def tip_body(self) -> _Vec:
        """The point the plan moves and turns about, gripper frame [m]: the believed tip."""
        if self._belief is not None:
            return np.asarray(self._belief.tip_body, dtype=float)
        return np.asarray(self.config.compliance_center, dtype=float)

    def _build(self, state: ControlState) -> None:
        c = self.config
        tip = self.tip_body
        if self._inner is None or not np.allclose(self._inner.config.compliance_center, tip):
            inner_cfg = dataclasses.replace(
                c.inner, control_dt=c.control_dt, compliance_center=tuple(tip.tolist())
            )
            self._inner = ImpedanceController(self._model, inner_cfg, jaw_calibration=self._jaw)
            self._inner.reset(state)
            if self._sensor is None:
                self._sensor = WristSensor(
                    self._model, centre_body=tip, dt=c.control_dt, tare_time=c.tare_time
                )
                self._sensor.reset(state)  # the timed tare starts now
            else:  # keep the tare taken so far and the filters, moments moved to the new centre
                self._sensor.move_centre(tip, state)
        inner = self._inner
        k = np.array([*inner.config.k_pos, *inner.config.k_rot])
        d = inner._d  # noqa: SLF001 - the impedance's damping, which the model must reproduce
        residual = (1.0 - inner.config.damping_compensation) * self._joint_damping
        spec = BeliefModelSpec(
            timestep=c.model_dt,
            friction=c.friction,
            kp=tuple(k.tolist()),
            kv=tuple(d.tolist()),
            damping=tuple(residual.tolist()),
        )
        self._q_ref = state.quat_world.copy()
        self._belief_model = build_belief_model(self._model, self._belief, self._q_ref, spec, tip_body=tip)
        self._belief_data = mujoco.MjData(self._belief_model)
        # One MjData per rollout thread (the first also serves the forward pass at the start).
        self._thread_data = [self._belief_data] + [
            mujoco.MjData(self._belief_model) for _ in range(c.threads - 1)
        ]
        self._plan = None
        self.planner = None
        if self._belief is not None and self._belief.plan_depth is not None:
            self.planner = BeliefPlanner(
                self._belief_model,
                self._belief,
                self._q_ref,
                c.planner_settings(),
                times=self._times,
                steps=self._steps,
                model_dt=c.model_dt,
                filter_steps=max(1, round(c.replan_dt / c.model_dt)),
                rollout=self._rollout,
                datas=self._thread_data,
                rng=self._rng,
            )

    # -- the tip frame ----------------------------------------------------------------------------
    def _tip_state(self, state: ControlState) -> tuple[_Vec, _Vec, _Vec, _Vec]:
        """Tip position, turn (hinge angles from the reference orientation), and their rates."""
        q = state.quat_world
        r = rotate(q, self.tip_body)
        tip = state.p_world + r
        omega = rotate(q, state.omega_body)
        v_tip = state.v_world + cross(omega, r)
        turn = _quat_to_turn(quat_mul(q, _conj(self._q_ref)))
        return tip, turn, v_tip, omega

    def _target_tip(self, target: GripperTarget) -> tuple[_Vec, _Vec, _Vec, _Vec]:
        """The reference's tip position, turn, tip velocity and turn rate (the accommodation on
        wrench axes; the target's angular velocity, world, on the pose axes: hinge rates for
        small turns)."""
        q = np.asarray(target.quat_world)
        r = rotate(q, self.tip_body)
        omega = rotate(q, target.omega_body)
        tip = target.p_world + r
        turn = _quat_to_turn(quat_mul(q, _conj(self._q_ref)))
        v = target.v_world + cross(omega, r)
        axes = self._acc_axes
        tip = np.where(axes[:3], self._acc_tip, tip)
        v = np.where(axes[:3], self._acc_rate[:3], v)
        turn = turn + self._acc_turn
        rate = np.where(axes[3:], 0.0, omega)
        return tip, turn, v, rate

    def _accommodate(self, state: ControlState, target: GripperTarget, wrench: tuple[_Vec, _Vec]) -> None:
        """Advance the reference along the wrench-controlled axes (see the module docstring)."""
        c = self.config
        axes = (
            np.concatenate([target.force_axes, target.moment_axes]) if target.force_controlled else _NO_AXES
        )
        q = np.asarray(target.quat_world)
        tip_t = target.p_world + rotate(q, self.tip_body)
        entering = axes[:3] & ~self._acc_axes[:3]
        self._acc_tip[entering] = tip_t[entering]
        self._acc_turn[~axes[3:]] = 0.0
        self._acc_axes = axes
        force, moment = wrench
        v = np.clip((force + target.force_world) / c.force_damping, -c.max_contact_speed, c.max_contact_speed)
        w = np.clip((moment + target.torque_world) / c.moment_damping, -c.max_turn_rate, c.max_turn_rate)
        self._acc_rate = np.where(axes, np.concatenate([v, w]), 0.0)
        self._acc_tip += self._acc_rate[:3] * c.control_dt
        self._acc_turn += self._acc_rate[3:] * c.control_dt

    # -- planning ---------------------------------------------------------------------------------
    def _rollout_costs(
        self,
        state: ControlState,
        target: GripperTarget,
        reference: _Vec,
        offsets: _Vec,
        wrench: tuple[_Vec, _Vec],
    ) -> _Vec:
        """Cost of each plan, ``reference`` (knots, 6) + ``offsets`` (n, knots, 6)."""
        plans = reference[None] + offsets
        c = self.config
        m, d = self._belief_model, self._belief_data
        assert m is not None and d is not None
        tip, turn, v_tip, omega = self._tip_state(state)
        d.qpos[:3], d.qpos[3:6] = tip, turn
        d.qvel[:3], d.qvel[3:6] = v_tip, omega
        d.ctrl[:] = plans[0, 0]
        mujoco.mj_forward(m, d)
        start_force, start_moment = d.sensordata[:3].copy(), d.sensordata[3:6].copy()
        self._mismatch = (
            float(np.linalg.norm(-start_force - wrench[0])),
            float(np.linalg.norm(-start_moment - wrench[1])),
        )
        size = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        initial = np.empty(size)
        mujoco.mj_getState(m, d, initial, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        n = plans.shape[0]
        steps = np.arange(1, self._steps + 1) * c.model_dt
        controls = knot_setpoints(self._times, plans, steps)
        data = self._thread_data if len(self._thread_data) > 1 else d
        states, sensors = self._rollout.rollout(m, data, np.tile(initial, (n, 1)), controls)
        qpos = states[:, :, 1 : 1 + m.nq]
        # The contact wrench on the hand about the tip (the sensors read the hand's push on the
        # peg, in the peg's frame; the turns are small), corrected by the measured one.
        force = -sensors[:, :, :3] - (-start_force) + wrench[0]
        moment = -sensors[:, :, 3:6] - (-start_moment) + wrench[1]
        tip_t, turn_t, v_t, w_t = self._target_tip(target)
        tip_ref = tip_t + steps[:, None] * v_t
        turn_ref = turn_t + steps[:, None] * w_t
        axes_f = target.force_axes if target.force_controlled else np.zeros(3, dtype=bool)
        axes_m = target.moment_axes if target.force_controlled else np.zeros(3, dtype=bool)
        cost = c.w_pose * np.sum(((qpos[:, :, :3] - tip_ref) ** 2) * ~axes_f, axis=(1, 2))
        cost += c.w_turn * np.sum(((qpos[:, :, 3:6] - turn_ref) ** 2) * ~axes_m, axis=(1, 2))
        if axes_f.any():
            cost += c.w_force * np.sum(((force + target.force_world) ** 2) * axes_f, axis=(1, 2))
        if axes_m.any():
            cost += c.w_moment * np.sum(((moment + target.torque_world) ** 2) * axes_m, axis=(1, 2))
        over = np.maximum(0.0, np.linalg.norm(force, axis=2) - c.budget)
        cost += c.w_budget * np.sum(over**2, axis=1)
        cost += c.w_wrist * np.sum(moment**2, axis=(1, 2))
        cost += c.w_smooth * np.sum(np.diff(offsets[:, :, :3], axis=1) ** 2, axis=(1, 2))
        cost += c.w_offset * np.sum(offsets**2, axis=(1, 2))
        return cost

    def _reference(self, target: GripperTarget) -> _Vec:
        """The target's pose at the knots (knots, 6), extrapolated at its velocity and turn rate
        (a reference that does not turn ahead leaves the inner loop no angular feed-forward: the
        hand lagged a 1.5 rad/s turn by 0.3 rad)."""
        tip_t, turn_t, v_t, w_t = self._target_tip(target)
        return np.array([np.concatenate([tip_t + v_t * s, turn_t + w_t * s]) for s in self._times])

    def _nominal(self, t: float) -> _Vec:
        """The warm start: the last plan's offsets from the reference, shifted to ``t``."""
        if self._plan is None:
            return np.zeros((len(self._times), 6))
        return np.array([self._plan.offset_at(t + s) for s in self._times])

    def _perturb(self, mean: _Vec, scale: _Vec, n: int) -> _Vec:
        noise = self._rng.normal(0.0, 1.0, (n, *mean.shape)) * scale
        noise[:, 0] = 0.0  # the first knot is the present setpoint
        return mean[None] + noise

    def _replan(self, state: ControlState, target: GripperTarget, wrench: tuple[_Vec, _Vec]) -> str:
        """Plans are offsets from the reference (the target's pose over the horizon): the
        samples explore around the last plan's offsets, and the reference itself (zero offset)
        is always among them, so free motion tracks the target and contact bends it."""
        c = self.config
        reference = self._reference(target)
        nominal = self._nominal(state.t)
        scale = np.array([c.noise_pos] * 3 + [c.noise_rot] * 3)
        self._rollout_costs(state, target, reference, np.zeros((1, *reference.shape)), wrench)
        if self._mismatch[0] > c.trust_force or self._mismatch[1] > c.trust_moment:
            # The belief model does not explain the present contact (a hole elsewhere, a peg
            # tilted in the hand): its predictions would mislead; follow the reference.
            self._plan = _Plan(state.t, self._times, reference, np.zeros_like(reference))
            return "distrust"
        if c.method == "cem":
            mean, spread = nominal, np.broadcast_to(scale, nominal.shape).copy()
            for _ in range(c.iterations):
                offsets = self._perturb(mean, spread, c.samples)
                offsets[0], offsets[1] = mean, 0.0
                costs = self._rollout_costs(state, target, reference, offsets, wrench)
                elite = offsets[np.argsort(costs)[: c.elites]]
                mean = elite.mean(axis=0)
                spread = np.maximum(elite.std(axis=0), 0.1 * scale)
            best = mean
        else:
            offsets = self._perturb(nominal, scale, c.samples)
            offsets[0], offsets[1] = nominal, 0.0
            costs = self._rollout_costs(state, target, reference, offsets, wrench)
            if c.method == "mppi":
                spread = max(float(np.ptp(costs)), 1e-12)
                weights = np.exp(-(costs - costs.min()) / (c.temperature * spread))
                best = np.tensordot(weights / weights.sum(), offsets, axes=1)
            else:
                best = offsets[int(np.argmin(costs))]
        self._plan = _Plan(state.t, self._times, reference + best, best)
        return "ok"

    def _plan_goal(self, state: ControlState, wrench: tuple[_Vec, _Vec]) -> str:
        """The belief planner's plan towards the task's goal (the target is not tracked)."""
        assert self.planner is not None
        tip, turn, v_tip, omega = self._tip_state(state)
        x = np.concatenate([tip, turn, v_tip, omega])
        setpoint = x[:6] if self._plan is None else self._plan.at(state.t)[0]
        knots = self.planner.replan(state.t, x, wrench, setpoint)
        self._plan = _Plan(state.t, self._times, knots, np.zeros_like(knots))
        return "ok"

    # -- the controller ---------------------------------------------------------------------------
    def timings(self) -> list[SolveTiming]:
        return [SolveTiming("plan", self.config.replan_dt, self.plan_times)]

    def _reset(self, state: ControlState) -> None:
        self._count = 0
        self._plan = None
        self._belief_model = None
        self._belief = None  # the task states its belief again after a reset
        self._inner = None
        self._sensor = None
        self.planner = None
        self._rng = np.random.default_rng(self.config.seed)
        self.plan_times = []
        self._reset_reference()

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        fresh = self._belief_model is None
        if fresh:
            self._build(state)
        assert self._sensor is not None and self._inner is not None
        wrench = self._sensor.update(state)
        self._accommodate(state, target, wrench)
        status = "hold"
        if fresh or self._count % self._every == 0:
            check_target(target)
            t0 = time.perf_counter()
            status = (
                self._replan(state, target, wrench)
                if self.planner is None
                else self._plan_goal(state, wrench)
            )
            self.plan_times.append(time.perf_counter() - t0)
        self._count += 1
        assert self._plan is not None
        setpoint, rate = self._plan.at(state.t)
        q_cmd = quat_mul(_turn_to_quat(setpoint[3:]), self._q_ref)
        arm = rotate(q_cmd, self.tip_body)
        omega = rate[3:]  # hinge rates ~ the world angular velocity for small turns
        command = GripperTarget.trusted(
            setpoint[:3] - arm,
            q_cmd,
            rate[:3] - cross(omega, arm),
            rotate_inv(q_cmd, omega),
            target.jaw_sep_m,
        )
        effort = self._inner.control_law(state, command)
        return Effort(effort.force_world, effort.torque_body, status, 1 if status == "ok" else 0)


_NO_AXES = np.zeros(6, dtype=bool)
_NO_AXES.setflags(write=False)


def _conj(q: _Vec) -> _Vec:
    return np.array([q[0], -q[1], -q[2], -q[3]])
