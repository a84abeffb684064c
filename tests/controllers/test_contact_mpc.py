"""The MPC's contact formulation: its QP's contract on a fixed reading, and its configuration."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.controllers.contact_mpc import ContactQP, ContactSettings
from peg_ctrl.controllers.mpc import MPCConfig, MPCController
from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.state import ControlState

from ..conftest import target

FORCE_Z = np.array([False, False, True, False, False, False])
MOMENT_XY = np.array([False, False, False, True, True, False])


def _settings(**changes: object) -> ContactSettings:
    base = {
        "centre_body": (0.0, 0.0, 0.0),
        "stiffness": (4000.0,) * 3 + (2.0,) * 3,
        "damping": (400.0,) * 3 + (0.5,) * 3,
        "rate_cap": (0.01,) * 3 + (0.05,) * 3,
        "rate_min": (1e-4,) * 3 + (5e-4,) * 3,
        "budget": 10.0,
        "smoothing": 0.1,
        "horizon": 10,
        "dt": 0.001,
        "solver": "daqp",
        "tare_time": 0.0,
        "force_filter_hz": 20.0,
        "moment_filter_hz": 5.0,
    }
    base.update(changes)
    return ContactSettings(**base)  # type: ignore[arg-type]


def _wrench(fz: float = 0.0, mx: float = 0.0, my: float = 0.0) -> np.ndarray:
    return np.array([0.0, 0.0, fz, mx, my, 0.0])


def test_a_free_force_axis_approaches_at_the_accommodation_rate() -> None:
    """No contact sensed, 0.6 N wanted: the command moves down at min(v_cap, 0.6 N / D)."""
    qp = ContactQP(_settings())
    plan = qp.solve(FORCE_Z, _wrench(), _wrench(fz=0.6))
    assert plan.status == "ok"
    assert plan.rate[2] == pytest.approx(-0.6 / 400.0, rel=1e-6)  # down, into the contact
    assert np.all(plan.rate[[0, 1, 3, 4, 5]] == 0.0)


def test_the_rate_is_capped() -> None:
    qp = ContactQP(_settings())
    plan = qp.solve(FORCE_Z, _wrench(), _wrench(fz=30.0))
    assert plan.rate[2] == pytest.approx(-0.01, rel=1e-6)


def test_the_wanted_force_is_a_fixed_point() -> None:
    qp = ContactQP(_settings())
    plan = qp.solve(FORCE_Z, _wrench(fz=3.0), _wrench(fz=3.0))
    assert abs(plan.rate[2]) < 1e-9


def test_the_predicted_force_keeps_the_budget() -> None:
    """Asked for 15 N with a 10 N budget: no predicted force beyond 10 N over the horizon."""
    qp = ContactQP(_settings(rate_cap=(1.0,) * 3 + (0.05,) * 3, damping=(1.0,) * 3 + (0.5,) * 3))
    plan = qp.solve(FORCE_Z, _wrench(fz=2.0), _wrench(fz=15.0))
    assert plan.predicted.shape == (1, 10)
    assert plan.predicted.max() <= 10.0 + 1e-6
    assert plan.predicted[0, -1] == pytest.approx(10.0, abs=1e-3)


def test_over_budget_the_command_backs_off() -> None:
    """A sensed 14 N with a 10 N budget and 3 N wanted: the command moves away (up)."""
    qp = ContactQP(_settings())
    plan = qp.solve(FORCE_Z, _wrench(fz=14.0), _wrench(fz=3.0))
    assert plan.rate[2] > 0.0


def test_a_moment_axis_turns_with_the_moment() -> None:
    """Zero moment wanted: the command turns the way the contact's moment pushes it."""
    qp = ContactQP(_settings())
    plan = qp.solve(MOMENT_XY, _wrench(mx=0.03, my=-0.01), _wrench())
    assert plan.rate[3] > 0.0 and plan.rate[4] < 0.0
    # At the accommodation's rate, M / D = 0.06 rad/s about x, capped at max_turn_rate (0.05).
    assert plan.rate[3] == pytest.approx(0.05)


@pytest.mark.filterwarnings("ignore:The default value of raise_error:PendingDeprecationWarning")
def test_osqp_through_qpsolvers_plans_the_same_step() -> None:
    a = ContactQP(_settings()).solve(FORCE_Z | MOMENT_XY, _wrench(fz=1.0, mx=0.02), _wrench(fz=3.0))
    b = ContactQP(_settings(solver="osqp")).solve(
        FORCE_Z | MOMENT_XY, _wrench(fz=1.0, mx=0.02), _wrench(fz=3.0)
    )
    np.testing.assert_allclose(a.rate, b.rate, atol=1e-3)  # OSQP to its default tolerance


def test_no_axis_no_plan() -> None:
    plan = ContactQP(_settings()).solve(np.zeros(6, dtype=bool), _wrench(fz=5.0), _wrench())
    assert plan.status == "idle" and np.all(plan.rate == 0.0)


# -- the controller ------------------------------------------------------------------------------


def test_formulation_and_solver_are_checked() -> None:
    with pytest.raises(
        ConfigError, match=r"mpc.formulation: must be one of 'effort', 'contact', got 'force'"
    ):
        MPCConfig(formulation="force")
    with pytest.raises(ConfigError, match=r"mpc.contact_solver: 'nope' is not installed; available: .*daqp"):
        MPCConfig(contact_solver="nope")
    with pytest.raises(ConfigError, match=r"mpc.contact_dt: must be a whole multiple"):
        MPCConfig(control_dt=0.002, contact_dt=0.003)


def test_the_contact_model_defaults_to_the_inner_stiffness(model: mujoco.MjModel) -> None:
    c = MPCController(model, MPCConfig(formulation="contact", control_dt=0.001))
    assert c.contact is not None
    assert c.contact.s.stiffness[0] == pytest.approx(-c.k_lqr[0, 0])
    assert c.contact.s.budget == c.config.force_limit


def test_a_pose_target_passes_the_contact_loop_unchanged(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """Without wrench-controlled axes the contact formulation is the effort MPC."""
    effort = MPCController(model, MPCConfig(control_dt=0.001))
    contact = MPCController(model, MPCConfig(control_dt=0.001, formulation="contact"))
    effort.reset(home_state)
    contact.reset(home_state)
    goal = target(home_state.p_world + [0.01, 0.0, -0.01])
    for _ in range(20):
        assert effort.compute(home_state, goal).ctrl == contact.compute(home_state, goal).ctrl


def test_solve_times_are_kept_per_optimiser(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = MPCController(model, MPCConfig(control_dt=0.001, formulation="contact"))
    c.reset(home_state)
    pressing = target(home_state.p_world).with_wrench(
        (0.0, 0.0, -3.0), axes=(False, False, True, False, False, False)
    )
    for _ in range(30):
        c.compute(home_state, pressing)
    timings = {t.name: t for t in c.timings()}
    assert set(timings) == {"effort_qp", "contact_qp"}
    assert len(timings["effort_qp"].times_s) == 3 and timings["effort_qp"].period_s == c.config.mpc_dt
    assert len(timings["contact_qp"].times_s) == 30 and timings["contact_qp"].period_s == 0.001
