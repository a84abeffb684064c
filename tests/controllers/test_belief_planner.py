"""The belief planner: its cost's residual terms, its hypotheses and their filter, on the belief model."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import mujoco.rollout
import numpy as np
import pytest

from peg_ctrl.controllers.belief_model import build_belief_model
from peg_ctrl.controllers.belief_planner import BeliefPlanner, Hypotheses, PlannerSettings
from peg_ctrl.controllers.residuals import TERMS, Rollouts, term_costs
from peg_ctrl.controllers.sampling_mpc import SamplingMPCConfig
from peg_ctrl.errors import ConfigError

from .test_sampling_mpc import BELIEF, Q_REF, SPEC


def settings(**changes: object) -> PlannerSettings:
    return dataclasses.replace(SamplingMPCConfig().planner_settings(), **changes)  # type: ignore[arg-type]


def test_every_term_is_weighed_by_a_config_field() -> None:
    """A term is one entry of TERMS; its weight is sampling_mpc's ``w_<name>``."""
    names = [t.name for t in TERMS]
    assert len(set(names)) == len(names)
    assert set(settings().weights) == set(names)
    for name in names:
        assert isinstance(getattr(SamplingMPCConfig(), f"w_{name}"), float)
        with pytest.raises(ConfigError, match=f"w_{name}: must be finite and >= 0"):
            SamplingMPCConfig(**{f"w_{name}": -1.0})  # type: ignore[arg-type]


def test_the_residuals_of_a_rollout() -> None:
    """One rollout of three steps: 1 mm above the face, in the chamfer, in the bore."""
    tip = np.array([[[0.0003, -0.0004, 0.001], [0.0, 0.0, -0.0008], [0.0, 0.0, -0.002]]])
    velocity = np.array([[[0.001, 0.002, -0.01], [0.0, 0.0, -0.004], [0.0, 0.0, -0.03]]])
    force = np.array([[[0.0, 0.0, 0.0], [3.0, 0.0, 12.0], [0.0, 0.0, 25.0]]])
    knots = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, -0.001], [0.0, 0.001, -0.003]]])
    r = Rollouts(
        tip=tip,
        velocity=velocity,
        tilt=np.zeros((1, 3, 2)),
        force=force,
        knots=knots,
        goal_depth=0.04,
        free_depth=0.0015,
        near_height=0.0005,
        budget=10.0,
        slip_force=20.0,
    )
    by_name = {t.name: t.fn(r) for t in TERMS}
    np.testing.assert_allclose(by_name["depth"][0, :, 0], np.sqrt([0.041, 0.0392, 0.038]))
    np.testing.assert_allclose(by_name["lateral"][0, 0], [0.0003, -0.0004])
    # The descent is weighed near the face and above the bore only; sideways motion anywhere.
    np.testing.assert_allclose(by_name["sink_speed"][0, :, 0], [0.0, -0.004, 0.0])
    np.testing.assert_allclose(by_name["bore_speed"][0, :, 0], [0.0, 0.0, -0.03])
    np.testing.assert_allclose(by_name["side_speed"][0, 0], [0.001, 0.002])
    np.testing.assert_allclose(by_name["budget"][0, :, 0], [0.0, math.hypot(3.0, 12.0) - 10.0, 15.0])
    np.testing.assert_allclose(by_name["slip"][0, :, 0], [0.0, 0.0, 5.0])
    np.testing.assert_allclose(by_name["effort"][0], [[0.0, 0.0, -0.001], [0.0, 0.001, -0.003]])
    np.testing.assert_allclose(by_name["accel"][0], [[0.0, 0.001, -0.001]])
    weights = {t.name: 0.0 for t in TERMS} | {"slip": 2.0}
    assert term_costs(r, weights) == {"slip": pytest.approx(np.array([2.0 * 25.0]))}


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"hypotheses": 0}, "sampling_mpc.hypotheses: must be an integer >= 1, got 0"),
        ({"particles": 1}, "sampling_mpc.particles: must be an integer >= 2, got 1"),
        ({"risk": "cvar"}, "sampling_mpc.risk: must be one of mean, worst, got 'cvar'"),
        (
            {"friction_low": 0.9, "friction_high": 0.3},
            "sampling_mpc.friction_high: must be >= friction_low (0.9)",
        ),
    ],
)
def test_bad_planner_settings_are_named(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        SamplingMPCConfig(**fields)  # type: ignore[arg-type]


def _hypotheses(count: int, seed: int = 0) -> Hypotheses:
    closing = np.array([1.0, 0.0, 0.0])
    return Hypotheses(
        np.random.default_rng(seed),
        count,
        settings(grasp_sigma=0.002, tilt_sigma=0.01),
        0.0005,
        np.array([0.0, 1.0, 0.0]),
        closing,
    )


def test_the_prior_spreads_along_the_pads_plane() -> None:
    """The hole's sigma on both axes, the grasp's along the pads' plane (here y) on top."""
    h = _hypotheses(20000)
    np.testing.assert_allclose(
        np.std(h.offset[:, :2], axis=0), [0.0005, math.hypot(0.0005, 0.002)], rtol=0.03
    )
    assert h.friction.min() >= 0.3 and h.friction.max() <= 0.9
    nominal = _hypotheses(1)
    assert nominal.offset.tolist() == [[0.0, 0.0, 0.0]] and nominal.friction.tolist() == [0.6]


def test_resampling_keeps_the_beliefs_mean_and_spread() -> None:
    """Liu and West's kernel: the weighted mean and spread survive resampling (no random walk)."""
    h = _hypotheses(20000)
    h.reweigh(-0.5 * ((h.offset[:, 1] - 0.001) / 0.0008) ** 2)
    mean, spread = h.mean.copy(), h.spread
    h.resample(np.random.default_rng(1))
    np.testing.assert_allclose(h.mean, mean, atol=3e-5)
    assert h.spread == pytest.approx(spread, rel=0.03)
    assert h.ess == pytest.approx(20000.0)


def test_resampling_keeps_the_belief_within_four_prior_sigmas() -> None:
    h = _hypotheses(200)
    h.offset[:, 0] += 0.1  # a filter that drifted 100 mm
    h.resample(np.random.default_rng(2))
    reach = 4.0 * math.hypot(0.0005, 0.002)
    assert np.linalg.norm(h.offset[:, :2], axis=1).max() <= reach * (1 + 1e-12)


def test_systematic_draws_follow_the_weights() -> None:
    h = _hypotheses(4)
    h.weights = np.array([0.7, 0.1, 0.1, 0.1])
    idx = h.draw(np.random.default_rng(3), 10)
    assert np.count_nonzero(idx == 0) == 7


def test_a_landing_on_the_face_says_where_the_hole_is_not(model: mujoco.MjModel) -> None:
    """Two hypotheses: the end over the hole, or 4 mm beside it. The truth is the second: the
    commanded descent stops on the face. The filter moves the weight to it."""
    belief = dataclasses.replace(BELIEF, plan_depth=0.04)
    m = build_belief_model(model, belief, Q_REF, SPEC)
    planner = BeliefPlanner(
        m,
        belief,
        Q_REF,
        settings(particles=2, hypotheses=2),
        times=np.linspace(0.0, 0.1, 3),
        steps=50,
        model_dt=0.002,
        filter_steps=10,
        rollout=mujoco.rollout.Rollout(nthread=1),
        datas=[mujoco.MjData(m)],
        rng=np.random.default_rng(0),
    )
    h = planner.hyp
    h.offset = np.array([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0]])
    h.tilt, h.friction, h.weights = np.zeros(2), np.full(2, 0.6), np.full(2, 0.5)
    start = np.array([*belief.hole_xy, belief.face_z + 0.0002])
    x0 = np.concatenate([start, np.zeros(9)])
    controls = np.repeat([[*start[:2], start[2] - 0.002, 0.0, 0.0, 0.0]], 10, axis=0)
    # The truth: hypothesis 1, rolled out on the model.
    truth = planner._states(x0, h.shifts[1:])  # noqa: SLF001
    out, sensors = mujoco.rollout.rollout(m, mujoco.MjData(m), truth, (controls + h.shifts[1])[None])
    end = out[0, -1, 1:7] - h.shifts[1]
    x = np.concatenate([end[:3], end[3:], np.zeros(6)])
    wrench = (-sensors[0, -3:, :3].mean(axis=0), np.zeros(3))
    planner._last = (x0, controls)  # noqa: SLF001 - the filter's memory of the last period
    planner._update(x, wrench)  # noqa: SLF001
    assert x[2] > belief.face_z - 1e-4  # it stopped on the face
    assert h.weights[1] > 0.9  # from 0.5: the end over the hole would have dropped
