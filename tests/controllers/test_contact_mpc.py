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


def test_a_backoff_slows_the_accommodation() -> None:
    """``backoff`` multiplies an axis's damping and divides its minimum rate."""
    qp = ContactQP(_settings())
    backoff = np.array([1.0, 1.0, 1.0, 4.0, 1.0, 1.0])
    plan = qp.solve(MOMENT_XY, _wrench(mx=0.01, my=0.01), _wrench(), backoff)
    assert plan.rate[3] == pytest.approx(0.01 / (0.5 * 4.0))
    assert plan.rate[4] == pytest.approx(0.01 / 0.5)
    creep = qp.solve(MOMENT_XY, _wrench(mx=1e-4), _wrench(), backoff)  # below D v_min
    assert creep.rate[3] == pytest.approx(5e-4 / 4.0)  # the minimum rate, slowed too


# -- a late sensor -------------------------------------------------------------------------------

PRESS = (False, False, True, True, True, False)


def _pressing(c: MPCController, state: ControlState, steps: int) -> list[np.ndarray]:
    """Run ``c`` on ``state`` pushed by 2 N from below, pressing 3 N down with the tilt axes
    moment-controlled; the wrench each contact QP solve was handed."""
    assert c.contact is not None
    handed: list[np.ndarray] = []
    solve = c.contact.qp.solve

    def spy(axes: np.ndarray, measured: np.ndarray, wanted: np.ndarray, backoff: np.ndarray | None = None):  # type: ignore[no-untyped-def]
        handed.append(measured.copy())
        return solve(axes, measured, wanted, backoff)

    c.contact.qp.solve = spy  # type: ignore[method-assign]
    c.reset(state)
    goal = target(state.p_world).with_wrench((0.0, 0.0, -3.0), axes=PRESS)
    for k in range(steps):
        pushed = state._replace(t=0.001 * k, ft_wrench=state.ft_wrench + [0.0, 0.0, 2.0, 0.01, 0.0, 0.0])
        c.compute(pushed, goal)
    return handed


def test_without_a_latency_the_qp_plans_from_the_filtered_reading(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    c = MPCController(model, MPCConfig(formulation="contact", control_dt=0.001, sensor_latency=0.0))
    assert c.contact is not None and c.contact.predictor is None
    handed = _pressing(c, home_state, 20)
    sensor = c.contact.sensor
    np.testing.assert_array_equal(handed[-1], np.concatenate([sensor.force, sensor.moment]))
    assert len(handed) == 20


def test_with_a_latency_the_qp_plans_from_the_predicted_wrench(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    c = MPCController(model, MPCConfig(formulation="contact", control_dt=0.001, sensor_latency=0.01))
    assert c.contact is not None and c.contact.predictor is not None
    handed = _pressing(c, home_state, 60)
    sensor, predictor = c.contact.sensor, c.contact.predictor
    reading = np.concatenate([sensor.force, sensor.moment])
    np.testing.assert_allclose(handed[-1], reading + predictor.correction, rtol=0, atol=1e-15)
    # The command moved down into the push (a turn too): the prediction is the reading corrected
    # for it, on the wrench-controlled axes only.
    assert predictor.correction[2] != 0.0 and predictor.correction[3] != 0.0
    np.testing.assert_array_equal(predictor.correction[[0, 1, 5]], 0.0)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("sensor_latency", -0.01, "must be finite and >= 0"),
        ("reversal_backoff", 0.5, r"must be >= 1 \(1: never\), got 0.5"),
        ("reversal_band", -1e-3, "must be finite and >= 0"),
    ],
)
def test_the_latency_fields_are_checked(field: str, value: float, message: str) -> None:
    with pytest.raises(ConfigError, match=rf"mpc.{field}: {message}"):
        MPCConfig(**{field: value})  # type: ignore[arg-type]


# -- the align press with a late sensor (physics) ------------------------------------------------

TIP = (0.0, -0.07, -0.01)
CONTACT_MPC = {  # the contact MPC of the studies (contact_hard)
    "name": "mpc",
    "formulation": "contact",
    "compliance_center": list(TIP),
    "force_limit": 10.0,
    "force_damping": [2000.0, 2000.0, 400.0],
    "tare_time": 0.25,
    "control_dt": 0.001,
    "contact_dt": 0.002,
}


def _align_press(controller: dict[str, object], budget: float) -> tuple[float, np.ndarray, float]:
    """The held insertion's align press (friction 0.9, the hole seen 1 mm off, 2 degrees) with the F/T reading
    10 ms late: (its duration [s], the peg-block force over its last 0.3 s [N], the peg's tilt
    at its end [deg]); stopped ``budget`` s in if it has not ended."""
    from peg_ctrl.run.episode import build_loop, episode_config_from_mapping

    config = episode_config_from_mapping(
        {
            "controller": controller,
            "seed": 100,
            "task": {
                "name": "held_insertion",
                "strategy": {"name": "align"},
                # The peg where the task believes it in the hand (an offset there is read as a
                # moment about the believed tip: the press would never read flat).
                "lateral_error": 0.0,
                "position_noise": 0.001,
                "tilt_error": float(np.radians(2.0)),
            },
            "physics": {"profile": "precision"},
            "scene": {"assets": {"clearance": 0.00005, "chamfer": 0.001}, "friction": 0.9},
            "randomization": {"enabled": True},
            "domain": {"ft_latency": 0.01},
        }
    )
    loop = build_loop(config)
    loop.reset(np.random.default_rng(100))
    start, force = None, []
    while True:
        loop.step()
        t = float(loop.data.time)
        if loop.task.phase == "align":
            start = t if start is None else start
            force.append(loop.peg.force_block)
        if start is not None and (loop.task.phase != "align" or t - start >= budget):
            break
    axis = loop.peg.axis_world
    return t - start, np.array(force[-300:]), float(np.degrees(np.arccos(abs(axis[2]))))


@pytest.mark.slow
def test_with_10_ms_latency_the_align_press_settles_with_the_reversal_backoff() -> None:
    """Uncompensated, the press rocks the peg from rim to rim (the force swings by several N)
    and never passes the flatness test; with the backoff and a 3.5 Hz moment filter it settles
    flat within 2 s with the force within 0.2 N of the 3 N asked."""
    rocking, force, _ = _align_press(CONTACT_MPC, budget=2.5)
    assert rocking >= 2.5 and np.ptp(force) > 1.0
    settled, force, tilt = _align_press(
        {**CONTACT_MPC, "reversal_backoff": 2.0, "moment_filter_hz": 3.5}, budget=2.5
    )
    assert settled < 2.0
    # The last 0.3 s include the flatness hold and the 0.15 s light press that ends the phase.
    assert np.all(np.abs(force[:100] - 3.0) < 0.2)
    assert tilt < 0.02
