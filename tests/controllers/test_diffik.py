"""Differential IK: its config (with the inner PD's), the IK step and its rate (no physics)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.controllers.diffik import DiffIKConfig, DiffIKController
from peg_ctrl.controllers.pd import PDConfig
from peg_ctrl.sim.state import ControlState

from ..conftest import HOME, target


@pytest.fixture(scope="module")
def diffik(model: mujoco.MjModel) -> DiffIKController:
    return DiffIKController(model)


def test_scaled_scales_its_costs_and_the_inner_pd() -> None:
    cfg = DiffIKConfig(position_cost=2.0, orientation_cost=0.5, inner=PDConfig(k_omega=10.0))
    scaled = cfg.scaled(0.9)
    assert DiffIKConfig.GAINS == ("position_cost", "orientation_cost")
    assert scaled.position_cost == 2.0 * 0.9
    assert scaled.orientation_cost == 0.5 * 0.9
    assert scaled.inner == cfg.inner.scaled(0.9)
    assert scaled.inner.k_omega == 10.0 * 0.9
    assert (scaled.damping_cost, scaled.ik_dt, scaled.solver) == (cfg.damping_cost, cfg.ik_dt, cfg.solver)
    assert cfg.scaled(1.0) == cfg


def test_inner_pd_is_configured_and_runs_at_our_period(model: mujoco.MjModel) -> None:
    cfg = DiffIKConfig(control_dt=0.002, inner=PDConfig(kp_pos=1000.0))
    c = DiffIKController(model, cfg)
    assert c.control_dt == 0.002
    assert c.inner.config == dataclasses.replace(cfg.inner, control_dt=0.002)


def test_zero_velocity_at_the_target(diffik: DiffIKController) -> None:
    c = diffik
    q = c.robot.qpos0.copy()
    q[:3] = HOME
    q[3:7] = euler_to_quat(0.2, 0.1, -0.4)
    v = c.ik_velocity(q, target(HOME, q[3:7]))
    assert np.abs(v).max() < 1e-9


def test_moves_towards_the_target_within_the_limits(diffik: DiffIKController) -> None:
    c = diffik
    q = c.robot.qpos0.copy()
    q[:3] = HOME
    q[3:7] = euler_to_quat(0.2, 0.1, -0.4)
    v = c.ik_velocity(q, target(HOME + [0.01, 0.0, 0.0], q[3:7]))
    assert 0 < v[0] <= c.config.v_max + 1e-9
    assert np.abs(v[1:3]).max() < 1e-6


def test_ik_runs_every_ik_dt_and_holds_between(diffik: DiffIKController, home_state: ControlState) -> None:
    c = diffik
    c.reset(home_state)
    tgt = target(HOME + [0.01, 0.0, 0.0])
    statuses = [c.compute(home_state, tgt).diagnostics for _ in range(20)]
    every = round(c.config.ik_dt / c.control_dt)  # 2 at the default 200 Hz and 100 Hz IK
    assert [d.status for d in statuses] == (["ok"] + ["hold"] * (every - 1)) * (20 // every)
    assert [d.iterations for d in statuses] == ([1] + [0] * (every - 1)) * (20 // every)


def test_scaled_config_builds_a_working_controller(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = DiffIKController(model, DiffIKConfig().scaled(1.1))
    c.reset(home_state)
    ctrl = c.compute(home_state, target(HOME + [0.01, 0.0, 0.0])).ctrl
    assert len(ctrl) == model.nu and np.all(np.isfinite(ctrl))


def test_only_the_qp_solvers_failure_is_a_failed_solve(
    model: mujoco.MjModel, home_state: ControlState, monkeypatch: pytest.MonkeyPatch
) -> None:
    """mink's NoSolutionFound holds the setpoint and is reported; any other error is a bug and
    propagates."""
    import mink

    c = DiffIKController(model, DiffIKConfig())
    c.reset(home_state)

    def no_solution(q, goal):  # type: ignore[no-untyped-def]
        raise mink.exceptions.NoSolutionFound("daqp")

    monkeypatch.setattr(c, "ik_velocity", no_solution)
    out = c.compute(home_state, target(HOME))
    assert out.diagnostics.status == "qp_failed: NoSolutionFound"
    assert out.diagnostics.iterations == 0

    def broken(q, goal):  # type: ignore[no-untyped-def]
        raise ValueError("shapes (7,) and (6,) not aligned")

    monkeypatch.setattr(c, "ik_velocity", broken)
    c.reset(home_state)
    with pytest.raises(ValueError, match="not aligned"):
        c.compute(home_state, target(HOME))
