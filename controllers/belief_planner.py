"""Sampling MPC over the belief: plans scored on hypotheses of the world, weighed by the sensors.

When a task hands over (its :class:`~peg_ctrl.sim.belief.Belief` carries ``plan_depth``: seat the
peg's end that far below the face), ``sampling_mpc`` stops tracking the task's reference and
plans towards the goal itself with this module. Nothing in it is a script: no landing, search
or centring; what the hand does comes out of the cost (:mod:`peg_ctrl.controllers.residuals`)
and the belief.

**Hypotheses.** ``particles`` hypotheses of what the belief leaves open, drawn from the task's
prior and the planner's: where the peg's end truly is against the hole (the camera's error,
``Belief.hole_sigma`` per axis, and the offset in the hand, ``grasp_sigma`` along the pads'
plane, ``depth_sigma`` in height: the face's tolerance and a slip in the pads), the peg's tilt in
the hand about the pads' normal (``tilt_sigma``) and the friction (uniform over
``friction_range``). All of them are one belief model (:mod:`~peg_ctrl.controllers.belief_model`)
entered at a shifted state: an end ``o`` off against the hole is the model's end at the measured
one plus ``o`` (the plan's setpoints likewise), a tilt in the hand the model's turn plus it; the
friction is the model copy's.

**The filter.** Every replan, each hypothesis replays the last ``replan_dt`` of the executed plan
from the state measured then; its likelihood compares what it predicts with what the hand did
and the wrist sensor read, over the period: the end's displacement (``filter_position`` [m] per
axis), the contact force's magnitude (``filter_force`` [N]) and, if ``filter_moment`` [N m] is
not 0, its moment about the believed end per axis (a peg tilted in the hand presses the bore's
walls into a moment an upright one does not). A hypothesis that has the end dropping into
the hole where the hand stopped on the face loses weight; contact is information. Below half the
particles' effective size they are resampled with Liu and West's kernel
(:meth:`Hypotheses.resample`).

**Planning.** ``hypotheses`` of them are drawn by weight (systematic resampling); each of
``samples`` candidate plans (the last plan shifted in time, a hold, and random walks along the
knots from it: steps of ``plan_noise_pos`` [m] and ``plan_noise_rot`` [rad] per knot) is rolled
out on all of them with :func:`mujoco.rollout`, in one batch, and scored by its expected cost
(``risk: mean``) or its worst (``risk: worst``); the cheapest is executed. ``hypotheses: 1`` is
the ablation: the nominal model alone (the end where the task believes it, friction
``friction``), no filter.

Attributes recorded for the report (:attr:`BeliefPlanner.history`): per replan the time, the
belief's mean offset and its spread (the root of the covariance's trace in x, y) [m], the
effective sample size, and the chosen plan's cost by term.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any

import mujoco
import mujoco.rollout
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.controllers.residuals import Rollouts, term_costs
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.rotations import rotate

__all__ = ["PlannerSettings", "Hypotheses", "BeliefPlanner", "PlanRecord", "RISKS", "knot_setpoints"]

RISKS = ("mean", "worst")
_FREE_MARGIN = 0.0005  # [m] the end is in the bore this far below the chamfer
_NEAR_HEIGHT = 0.0005  # [m] ... and near the face below this height above it
_Vec = NDArray[np.float64]


def knot_setpoints(times: _Vec, plans: _Vec, at: NDArray[np.floating[Any]]) -> _Vec:
    """(n, len(at), 6) the setpoints of ``plans`` (n, knots, 6) at the times ``at`` [s]: linear
    interpolation through the knots at ``times``, held beyond the last."""
    out = np.empty((len(plans), len(at), 6))
    for j in range(len(plans)):
        for i in range(6):
            out[j, :, i] = np.interp(at, times, plans[j, :, i])
    return out


@dataclasses.dataclass(frozen=True)
class PlannerSettings:
    """The belief planner's parameters (``sampling_mpc``'s fields of the same names)."""

    hypotheses: int
    particles: int
    risk: str
    samples: int
    grasp_sigma: float
    depth_sigma: float
    tilt_sigma: float
    friction_range: tuple[float, float]
    friction: float
    filter_position: float
    filter_force: float
    filter_moment: float
    plan_noise_pos: float
    plan_noise_rot: float
    budget: float
    slip_force: float
    weights: dict[str, float]


@dataclasses.dataclass(frozen=True)
class PlanRecord:
    """One replan: time [s], the belief's mean offset (3,) and x-y spread [m], its effective
    size, and the chosen plan's expected cost per term."""

    t: float
    mean: tuple[float, float, float]
    spread: float
    ess: float
    costs: dict[str, float]


class Hypotheses:
    """Weighted hypotheses: ``offset`` (m, 3) [m], the true end from the believed one against
    the hole (world); ``tilt`` (m,) [rad], the peg's turn in the hand about ``closing`` (world);
    ``friction`` (m,); ``weights`` (m,)."""

    def __init__(
        self,
        rng: np.random.Generator,
        count: int,
        s: PlannerSettings,
        sigma_hole: float,
        across: _Vec,
        closing: _Vec,
    ) -> None:
        self.closing = closing
        scale = np.array([sigma_hole, sigma_hole, s.depth_sigma])
        lo, hi = s.friction_range
        self._lo, self._hi = lo, hi
        self._reach = 4.0 * math.hypot(sigma_hole, s.grasp_sigma)
        if count == 1:  # the nominal model alone
            self.offset = np.zeros((1, 3))
            self.tilt = np.zeros(1)
            self.friction = np.array([s.friction])
        else:
            self.offset = rng.normal(size=(count, 3)) * scale
            self.offset += np.outer(rng.normal(size=count) * s.grasp_sigma, across)
            self.tilt = rng.normal(size=count) * s.tilt_sigma
            self.friction = rng.uniform(lo, hi, size=count)
        self.weights = np.full(count, 1.0 / count)

    @property
    def shifts(self) -> _Vec:
        """(m, 6) each hypothesis's shift of the model's state and setpoints: end, turn."""
        return np.hstack([self.offset, self.tilt[:, None] * self.closing[None]])

    @property
    def ess(self) -> float:
        return float(1.0 / np.sum(self.weights**2))

    @property
    def mean(self) -> _Vec:
        return self.weights @ self.offset

    @property
    def spread(self) -> float:
        rel = self.offset[:, :2] - self.mean[:2]
        return float(math.sqrt(self.weights @ np.einsum("ij,ij->i", rel, rel)))

    def reweigh(self, loglik: _Vec) -> None:
        w = np.log(np.maximum(self.weights, 1e-300)) + loglik
        w = np.exp(w - w.max())
        self.weights = w / w.sum()

    def draw(self, rng: np.random.Generator, k: int) -> NDArray[np.intp]:
        """``k`` indices by weight (systematic resampling)."""
        edges = (rng.uniform() + np.arange(k)) / k
        return np.minimum(np.searchsorted(np.cumsum(self.weights), edges), len(self.weights) - 1)

    def resample(self, rng: np.random.Generator, h: float = 0.2) -> None:
        """Resampled by weight, then shrunk towards the mean and jittered (Liu and West's kernel:
        ``a x + (1 - a) mean + N(0, h^2 cov)``, ``a = sqrt(1 - h^2)``), which keeps the belief's
        mean and spread: a filter that resamples often does not random-walk."""
        n = len(self.weights)
        a = math.sqrt(1.0 - h * h)
        x = np.hstack([self.offset, self.tilt[:, None], self.friction[:, None]])
        mean = self.weights @ x
        rel = x - mean
        cov = (rel * self.weights[:, None]).T @ rel
        chol = np.linalg.cholesky(cov + 1e-18 * np.eye(len(mean)))
        x = a * x[self.draw(rng, n)] + (1.0 - a) * mean + h * rng.normal(size=x.shape) @ chol.T
        # Nothing beyond four of the prior's sigmas: a filter whose model cannot explain what it
        # sees drifts rather than stays put, and the hole is not that far off.
        reach = np.linalg.norm(x[:, :2], axis=1, keepdims=True) / self._reach
        x[:, :2] /= np.maximum(reach, 1.0)
        self.offset, self.tilt = x[:, :3], x[:, 3]
        self.friction = np.clip(x[:, 4], self._lo, self._hi)
        self.weights = np.full(n, 1.0 / n)


class BeliefPlanner:
    """Plans on hypotheses of the belief model (see the module docstring).

    Args:
        model: the belief model (built at ``quat_ref``; its actuators are the tip's setpoints).
        belief: the task's belief, with ``plan_depth`` set.
        quat_ref: the gripper's orientation the model was built at (world).
        settings: the planner's parameters.
        times: (knots,) the plan's knot times over the horizon [s]; ``steps``, ``model_dt``:
            the horizon in model steps; ``filter_steps``: a replan period in model steps.
        rollout: the controller's :class:`mujoco.rollout.Rollout`; ``datas``: one MjData of the
            model per rollout thread; ``rng``: the controller's random stream.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        belief: Belief,
        quat_ref: _Vec,
        settings: PlannerSettings,
        *,
        times: _Vec,
        steps: int,
        model_dt: float,
        filter_steps: int,
        rollout: mujoco.rollout.Rollout,
        datas: list[mujoco.MjData],
        rng: np.random.Generator,
    ) -> None:
        assert belief.plan_depth is not None
        self.s, self.belief = settings, belief
        self._times, self._steps, self._dt, self._filter_steps = times, steps, model_dt, filter_steps
        self._rollout, self._rng = rollout, rng
        closing = rotate(quat_ref, np.array([1.0, 0.0, 0.0]))  # the pads' normal (the gripper's x)
        across = np.array([-closing[1], closing[0], 0.0])
        across /= max(float(np.linalg.norm(across)), 1e-12)
        count = 1 if settings.hypotheses == 1 else settings.particles
        self.hyp = Hypotheses(rng, count, settings, belief.hole_sigma, across, closing)
        self._axis0 = rotate(quat_ref, np.asarray(belief.axis_body, dtype=float))
        self._models = []
        for mu in self.hyp.friction.tolist():
            m = copy.copy(model)
            m.pair_friction[:, :2] = mu
            self._models.append(m)
        self._data = mujoco.MjData(model)  # the states' scratch
        self._datas = datas
        self._nq = model.nq
        self._hole = np.array([belief.hole_xy[0], belief.hole_xy[1], belief.face_z])
        self._last: tuple[_Vec, _Vec] | None = None  # the state measured, the controls executed since
        self._plan: _Vec | None = None  # knots (knots, 6), absolute
        self._plan_t = 0.0
        self.history: list[PlanRecord] = []

    # -- states --------------------------------------------------------------------------------
    def _states(self, x: _Vec, shifts: _Vec) -> _Vec:
        """Full-physics states (len(shifts), nstate) of the model at the measured ``x`` (12,):
        end, turn, their rates; each shifted by its hypothesis."""
        m, d = self._models[0], self._data
        d.qpos[:6], d.qvel[:6] = x[:6], x[6:]
        d.time = 0.0
        size = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        base = np.empty(size)
        mujoco.mj_getState(m, d, base, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        states = np.tile(base, (len(shifts), 1))
        states[:, 1:7] += shifts
        return states

    def _run(self, models: list[mujoco.MjModel], states: _Vec, controls: _Vec) -> tuple[_Vec, _Vec, _Vec]:
        """Positions (n, steps, 6), velocities (n, steps, 6) and contact forces (n, steps, 3)."""
        out, sensors = self._rollout.rollout(models, self._datas, states, controls)
        nq = self._nq
        return out[:, :, 1 : 1 + nq], out[:, :, 1 + nq : 1 + 2 * nq], -sensors[:, :, :6]

    # -- the filter ----------------------------------------------------------------------------
    def _update(self, x: _Vec, wrench: tuple[_Vec, _Vec]) -> None:
        """Weigh each hypothesis by how well it predicted the last period (see the module doc)."""
        if self._last is None or len(self.hyp.weights) == 1:
            return
        x0, controls = self._last
        tip0 = x0[:3]
        shifts = self.hyp.shifts
        n = len(shifts)
        ctrl = np.repeat(controls[None], n, axis=0) + shifts[:, None, :]
        qpos, _, w = self._run(self._models, self._states(x0, shifts), ctrl)
        moved = qpos[:, -1, :3] - (tip0 + shifts[:, :3])
        seen = x[:3] - tip0
        s = self.s
        loglik = -0.5 * np.sum(((moved - seen) / s.filter_position) ** 2, axis=1)
        # The wrench over the period (the sensor is filtered), the moment moved from each
        # hypothesis's end to the believed one, about which the wrist's estimate is taken (the
        # peg's frame is the world's while its axis is upright).
        predicted = np.linalg.norm(w[:, :, :3], axis=2).mean(axis=1)
        sensed = float(np.linalg.norm(wrench[0]))
        loglik += -0.5 * ((predicted - sensed) / s.filter_force) ** 2
        if s.filter_moment > 0:
            moment = w[:, :, 3:].mean(axis=1) + np.cross(shifts[:, :3], w[:, :, :3].mean(axis=1))
            loglik += -0.5 * np.sum(((moment - wrench[1]) / s.filter_moment) ** 2, axis=1)
        self.hyp.reweigh(loglik)
        if self.hyp.ess < 0.5 * n:
            self.hyp.resample(self._rng)
            for m, mu in zip(self._models, self.hyp.friction.tolist(), strict=True):
                m.pair_friction[:, :2] = mu

    # -- planning ------------------------------------------------------------------------------
    def _candidates(self, t: float, setpoint: _Vec) -> _Vec:
        """(samples, knots, 6): the last plan shifted to ``t``, a hold, and perturbations."""
        s, k = self.s, len(self._times)
        if self._plan is None:
            nominal = np.repeat(setpoint[None], k, axis=0)
        else:
            at = np.clip(t - self._plan_t + self._times, 0.0, self._times[-1])
            nominal = np.array([[np.interp(a, self._times, self._plan[:, i]) for i in range(6)] for a in at])
            nominal[0] = setpoint
        scale = np.array([s.plan_noise_pos] * 3 + [s.plan_noise_rot] * 3)
        # Random walks along the knots: a candidate moves on, it does not jitter about the nominal.
        steps = self._rng.normal(size=(s.samples, k, 6)) * scale
        steps[:, 0] = 0.0
        plans = nominal[None] + np.cumsum(steps, axis=1)
        plans[0] = nominal
        plans[1] = np.repeat(setpoint[None], k, axis=0)
        return plans

    def replan(self, t: float, x: _Vec, wrench: tuple[_Vec, _Vec], setpoint: _Vec) -> _Vec:
        """The plan's knots (knots, 6) from the measured ``x`` (12,: end, turn, rates, world),
        the sensed contact wrench on the hand about the believed end (force [N], moment [N m],
        world) and the present ``setpoint`` (6,)."""
        self._update(x, wrench)
        s, hyp = self.s, self.hyp
        idx = hyp.draw(self._rng, s.hypotheses) if len(hyp.weights) > 1 else np.zeros(1, dtype=np.intp)
        shifts = hyp.shifts[idx]
        plans = self._candidates(t, setpoint)
        n, k = len(plans), len(idx)
        controls = knot_setpoints(self._times, plans, np.arange(1, self._steps + 1) * self._dt)
        ctrl = np.repeat(controls, k, axis=0) + np.tile(shifts[:, None, :], (n, 1, 1))
        states = np.tile(self._states(x, shifts), (n, 1))
        models = [self._models[i] for i in idx.tolist()] * n
        qpos, qvel, w = self._run(models, states, ctrl)
        turn = qpos[:, :, 3:6]
        axis = self._axis0 + np.cross(turn, self._axis0)
        rolls = Rollouts(
            tip=qpos[:, :, :3] - self._hole,
            velocity=qvel[:, :, :3],
            tilt=axis[:, :, :2],
            force=w[:, :, :3],
            knots=np.repeat(plans[:, :, :3], k, axis=0),
            goal_depth=float(self.belief.plan_depth),  # type: ignore[arg-type]
            free_depth=self.belief.chamfer + _FREE_MARGIN,
            near_height=_NEAR_HEIGHT,
            budget=s.budget,
            slip_force=s.slip_force,
        )
        terms = term_costs(rolls, s.weights)
        total = np.sum(list(terms.values()), axis=0).reshape(n, k)
        score = total.mean(axis=1) if s.risk == "mean" else total.max(axis=1)
        best = int(np.argmin(score))
        self._plan, self._plan_t = plans[best], t
        self._last = (x.copy(), controls[best, : self._filter_steps])
        chosen = {name: float(c.reshape(n, k)[best].mean()) for name, c in terms.items()}
        self.history.append(PlanRecord(t, tuple(hyp.mean.tolist()), hyp.spread, hyp.ess, chosen))  # type: ignore[arg-type]
        return plans[best]
