"""The planner over skills (``plan``): its decisions on the belief, and an episode in the physics."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from peg_ctrl.errors import ConfigError
from peg_ctrl.run.episode import build_loop, episode_config_from_mapping
from peg_ctrl.sim.state import PegObservation
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.belief import TaskBelief
from peg_ctrl.tasks.strategies import STRATEGIES
from peg_ctrl.tasks.strategies.plan import PlanConfig, _Where

_MPC = {
    "name": "mpc",
    "formulation": "contact",
    "compliance_center": [0.0, -0.07, -0.01],
    "force_limit": 10.0,
    "force_damping": [2000.0, 2000.0, 100.0],
    "tare_time": 0.25,
    "control_dt": 0.001,
    "contact_dt": 0.002,
    "mpc_dt": 0.005,
    "q_vel": 100.0,
    "max_contact_speed": 0.002,
    "accel_filter_hz": 30.0,
    "moment_filter_hz": 3.5,
    "reversal_backoff": 2.0,
    "sensor_latency": 0.015,
    "velocity_filter_hz": 30.0,
}


def _config(seed: int, *, lateral: float, tilt: float, sensor: str = "wrist", **strategy: Any) -> Any:
    """contact_real_plan's cell (docs/planning.md): a robot's proprioception, the start over the
    observed hole."""
    return episode_config_from_mapping(
        {
            "seed": seed,
            "controller": _MPC,
            "task": {
                "name": "held_insertion",
                "strategy": {
                    "name": "plan",
                    "side_touches": 3,
                    "quick_datum": True,
                    "side_backoff": 0.0025,
                    "touch_speed": 0.005,
                    "centre_reanchor": True,
                    **strategy,
                },
                "lateral_error": lateral,
                "tilt_error": tilt,
                "position_noise": 0.0005 if sensor == "wrist" else 0.001,
                "drawing_tolerance": 0.00015,
                "start_over_observed": True,
            },
            "domain": {
                "ft_sensor": sensor,
                "position_noise": 3e-5,
                "position_error_time": 0.5,
                "position_white_noise": 2e-6,
                "velocity_noise": 0.001,
            },
            "scene": {"assets": {"chamfer": 0.001, "clearance": 0.00005}, "friction": 0.3},
            "physics": {"profile": "precision", "friction_time": 0.005},
        }
    )


def _strategy(cfg: Any) -> Any:
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(cfg.seed))
    return loop, loop.task.strategy  # type: ignore[attr-defined]


def test_plan_is_registered_and_checks_its_fields() -> None:
    assert STRATEGIES["plan"] is PlanConfig and PlanConfig.phases == ("approach", "skills", "hold")
    with pytest.raises(ConfigError, match="task.strategy.tilt_tolerance must be > 0"):
        PlanConfig(tilt_tolerance=0.0)
    with pytest.raises(ConfigError, match="fixed_order must be true or false"):
        PlanConfig(fixed_order=1)  # type: ignore[arg-type]


def test_what_may_come_next() -> None:
    """The mouth's search before the centring, the centring before the descent, each skill
    away from the mouth once, and leaving the mouth loses it."""
    where = _Where()
    assert where.options() == ("sides", "rock", "face", "mouth")
    where = where.after("mouth")
    assert where.options() == ("sides", "rock", "face", "centre")
    where = where.after("centre")
    assert where.options() == ("sides", "rock", "face", "descent")
    where = where.after("rock")
    assert where.options() == ("sides", "face", "mouth") and not where.in_mouth


@pytest.mark.parametrize(
    ("lateral", "tilt", "sensor", "first", "skills"),
    [
        # upright, 1 mm in the hand: the face's height for the search, no side, no rock
        (0.001, 0.0, "wrist", "face", {"face", "mouth", "centre", "descent"}),
        # tilted: the rock (which reads the end's offset too: no side touch)
        (0.001, 0.0349066, "wrist", "rock", {"rock", "mouth", "centre", "descent"}),
        # 3 mm in the hand: a search over that spread is slower than the rock that finds the end
        (0.003, 0.0, "wrist", "rock", {"rock", "mouth", "centre", "descent"}),
    ],
)
def test_the_plan_follows_what_the_cell_leaves_open(
    lateral: float, tilt: float, sensor: str, first: str, skills: set[str]
) -> None:
    """The first decision on each cell's prior: the skills its best sequence plays."""
    _, plan = _strategy(_config(100, lateral=lateral, tilt=tilt, sensor=sensor))
    task = plan.task
    task._reset_knowledge(np.array([1.0, 0.0, 0.0, 0.0]))
    skill, (expected, sequence), scores = plan.choose(task.knowledge, _Where())
    assert skill == first and set(sequence) == skills and sequence[-1] == "descent"
    assert expected > 0 and all(math.isfinite(v) and v >= 0 for v in scores.values())


def test_a_linear_reading_narrows_the_belief_by_its_information() -> None:
    """The update's spread after a reading is the one the information promised before it."""
    belief = TaskBelief.prior((0.0, 0.0), 0.001, (0.0, 1.0), 0.003, 0.0349, 0.025, 0.00015)
    from peg_ctrl.tasks.belief import Reading, rows

    reading = Reading("probe", np.array([rows(hole_x=1.0, end_x=-1.0)]), np.array([[1e-10]]))
    bits = belief.information(reading, of=("hole_x",))
    before = belief.sigma("hole_x")
    belief.update(reading.with_value([0.0005]), t=1.0)
    assert belief.sigma("hole_x") == pytest.approx(before * 2.0**-bits, rel=1e-9)
    assert belief.history[-1]["skill"] == "probe" and belief.history[-1]["bits"] > 0


def test_the_prior_ties_the_end_to_the_tilt() -> None:
    """A tilt about the pads' normal swings the end across them by grip_length per radian: the
    prior's covariance carries it, and a reading of the end alone then narrows the tilt."""
    belief = TaskBelief.prior(
        (0.0, 0.0), 0.001, (0.0, 1.0), 0.001, 0.0349, 0.025, 0.00015, swing=(0.0, -0.07)
    )
    assert belief.cov[3, 4] == pytest.approx(-0.07 * 0.0349**2)
    assert belief.sigma("end_y") == pytest.approx(math.hypot(0.001, 0.07 * 0.0349))
    from peg_ctrl.tasks.belief import Reading, rows

    before = belief.sigma("tilt")
    belief.update(Reading("end", np.array([rows(end_y=1.0)]), np.array([[1e-8]]), np.array([0.0])), t=0.0)
    assert belief.sigma("tilt") < 0.5 * before


def _run(cfg: Any, *, blind: bool) -> tuple[Any, np.ndarray]:
    """One episode; ``blind``: the task is handed a peg state of NaNs (its own judgement of
    success still reads the true one). Returns its end and every control step's actuator command."""
    loop = build_loop(cfg)
    loop.reset(np.random.default_rng(cfg.seed))
    task = loop.task
    if blind:
        target = task.target
        nan = PegObservation(
            *(np.full(len(np.atleast_1d(v)), np.nan) if np.ndim(v) else math.nan for v in loop.peg)
        )

        def blinded(obs: Observation) -> Any:
            return target(obs._replace(peg=nan))

        task.target = blinded  # type: ignore[method-assign]
    ctrl = []
    while True:
        ev = loop.step()
        ctrl.append(loop.data.ctrl.copy())
        if ev.done:
            return ev, np.array(ctrl)


@pytest.mark.slow  # two held insertions, ~40 s
def test_the_planner_seats_the_peg_and_reads_no_true_state() -> None:
    """The information audit: with the peg's true state set to NaN wherever the task decides,
    every actuator command is the same, step for step; and the planner seats the peg."""
    cfg = _config(100, lateral=0.001, tilt=0.0349066)
    seen, ctrl = _run(cfg, blind=False)
    blind, ctrl_blind = _run(cfg, blind=True)
    assert seen.success, seen.detail
    assert blind.success and ctrl.shape == ctrl_blind.shape
    np.testing.assert_array_equal(ctrl, ctrl_blind)
