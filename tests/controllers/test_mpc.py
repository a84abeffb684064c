"""Linear MPC: its config, the QP against LQR and the bounds, and its rate (no physics)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import scipy.integrate

from peg_ctrl.controllers.mpc import MPCConfig, MPCController, discretise
from peg_ctrl.sim.state import ControlState

from ..conftest import HOME, target


@pytest.fixture(scope="module")
def mpc(model: mujoco.MjModel) -> MPCController:
    return MPCController(model)


def test_scaled_scales_the_error_weights() -> None:
    cfg = MPCConfig(q_pos=1e4)
    scaled = cfg.scaled(0.9)
    assert MPCConfig.GAINS == ("q_pos", "q_rot")
    assert scaled.q_pos == 1e4 * 0.9
    assert scaled.q_rot == cfg.q_rot * 0.9
    assert (scaled.q_vel, scaled.horizon, scaled.mpc_dt) == (cfg.q_vel, cfg.horizon, cfg.mpc_dt)
    assert cfg.scaled(1.0) == cfg


def test_discretise_matches_the_closed_form() -> None:
    m, b, dt = 2.0, 3.0, 0.01
    a, bd = discretise(m, b, dt)
    decay = np.exp(-b / m * dt)
    np.testing.assert_allclose(a, [[1.0, m / b * (1 - decay)], [0.0, decay]], rtol=1e-12)
    expected_b = scipy.integrate.quad(lambda s: np.exp(-b / m * s) / m, 0, dt)[0]
    assert bd[1, 0] == pytest.approx(expected_b, rel=1e-10)


def test_unconstrained_mpc_is_lqr(mpc: MPCController) -> None:
    z0 = np.zeros(12)
    z0[0], z0[1], z0[4], z0[7], z0[10] = 0.004, -0.01, -0.003, 0.05, -0.02  # small: no bound active
    du = mpc.solve(z0, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(du, -mpc.k_lqr @ z0, rtol=1e-6, atol=1e-8)


def test_respects_effort_bounds(mpc: MPCController) -> None:
    z0 = np.zeros(12)
    z0[0], z0[6] = 0.5, 2.0  # far away: effort saturates
    du = mpc.solve(z0, np.zeros(6), np.zeros(6))
    assert np.all(np.abs(du) <= mpc.u_max + 1e-6)
    lqr = -mpc.k_lqr @ z0
    assert 0 < du[0] < lqr[0] and 0 < du[3] < lqr[3]  # the constraints cut the LQR answer back


def test_solves_every_mpc_dt_and_holds_between(mpc: MPCController, home_state: ControlState) -> None:
    mpc.reset(home_state)
    tgt = target(HOME + [0.01, 0.0, 0.0])
    statuses = [mpc.compute(home_state, tgt).diagnostics.status for _ in range(20)]
    every = round(mpc.config.mpc_dt / mpc.control_dt)  # 2 at the default 200 Hz and 100 Hz QP
    assert statuses == (["ok"] + ["hold"] * (every - 1)) * (20 // every)
    assert mpc.last_solve.status == "ok"
    assert mpc.last_solve.solve_time_s > 0.0  # set by the solve, not the default


def test_horizon_must_be_an_integer_of_at_least_two() -> None:
    with pytest.raises(ValueError, match=r"mpc\.horizon"):
        MPCConfig(horizon=1)


def test_scaled_config_builds_a_working_controller(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = MPCController(model, MPCConfig().scaled(1.1))
    c.reset(home_state)
    ctrl = c.compute(home_state, target(HOME + [0.01, 0.0, 0.0])).ctrl
    assert len(ctrl) == model.nu and np.all(np.isfinite(ctrl))
