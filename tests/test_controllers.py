"""Every registered controller: the shared contract, plus an analytic check of each."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from controllers import REGISTRY, UnknownController, make_controller
from controllers.admittance import AdmittanceController
from controllers.diffik import DiffIKController
from controllers.dynamics import BaseDynamics, robot_mjcf, to_pinocchio_q
from controllers.impedance import ImpedanceController
from controllers.mpc import MPCController
from peg_ctrl.commands import euler_to_quat
from peg_ctrl.sim import Simulation

from .conftest import HOME, target

NAMES = sorted(REGISTRY)


@pytest.fixture(scope="module")
def controllers(model: mujoco.MjModel) -> dict:
    return {name: make_controller(name, model) for name in NAMES}


@pytest.mark.parametrize("name", NAMES)
def test_contract_finite_command_of_the_right_shape(
    name: str, model: mujoco.MjModel, sim: Simulation
) -> None:
    ctrl_a = make_controller(name, model)
    ctrl_b = make_controller(name, model)
    state = sim.state()
    tgt = target(HOME + [0.02, -0.01, -0.03], euler_to_quat(0.3, -0.1, 0.2), jaw=0.03, v=(0.05, 0, 0))
    ctrl_a.reset(state)
    ctrl_b.reset(state)
    for _ in range(12):  # past the first slow-rate update of diffik and mpc
        a, b = ctrl_a.compute(state, tgt), ctrl_b.compute(state, tgt)
        assert len(a.ctrl) == model.nu
        assert np.all(np.isfinite(a.ctrl))
        np.testing.assert_array_equal(a.ctrl, b.ctrl)  # same inputs, same outputs
        assert a.diagnostics.solve_time_s >= 0.0
    lo, hi = model.actuator_ctrlrange.T
    assert np.all(np.asarray(a.ctrl) >= lo - 1e-9) and np.all(np.asarray(a.ctrl) <= hi + 1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_contract_nan_state_raises(name: str, model: mujoco.MjModel, sim: Simulation) -> None:
    c = make_controller(name, model)
    state = sim.state()
    c.reset(state)
    bad = state._replace(p_world=np.array([np.nan, 0.0, 0.2]))
    with pytest.raises(ValueError):
        for _ in range(12):
            c.compute(bad, target(HOME))


@pytest.mark.parametrize("name", NAMES)
def test_every_controller_holds_a_pose(name: str, model: mujoco.MjModel) -> None:
    sim = Simulation(model, make_controller(name, model))
    goal = target(HOME + [0.03, 0.02, -0.04], euler_to_quat(0.4, 0.0, -0.3))
    state = sim.hold(goal, 2.5)
    assert np.linalg.norm(state.p_world - goal.p_world) < 2e-3
    err = np.zeros(3)
    mujoco.mju_subQuat(err, goal.quat_world, state.quat_world)
    assert np.linalg.norm(err) < 0.02


def test_registry_lists_every_controller(model: mujoco.MjModel) -> None:
    assert set(NAMES) == {"pd", "diffik", "mpc", "impedance", "admittance"}
    with pytest.raises(UnknownController, match="known: admittance, diffik, impedance, mpc, pd"):
        make_controller("lqg", model)


# -- analytic checks ---------------------------------------------------------------------------


def test_diffik_zero_velocity_at_the_target(controllers: dict, sim: Simulation) -> None:
    c: DiffIKController = controllers["diffik"]
    q = c.robot.qpos0.copy()
    q[:3] = HOME
    q[3:7] = euler_to_quat(0.2, 0.1, -0.4)
    v = c.ik_velocity(q, target(HOME, q[3:7]))
    assert np.abs(v).max() < 1e-9
    # And towards a target it moves the right way, within the velocity limits.
    v = c.ik_velocity(q, target(HOME + [0.01, 0.0, 0.0], q[3:7]))
    assert v[0] > 0 and abs(v[0]) <= c.config.v_max + 1e-9 and np.abs(v[1:3]).max() < 1e-6


def test_unconstrained_mpc_is_lqr(controllers: dict) -> None:
    c: MPCController = controllers["mpc"]
    z0 = np.zeros(12)
    z0[0], z0[1], z0[4], z0[7], z0[10] = 0.004, -0.01, -0.003, 0.05, -0.02  # small: no bound active
    du = c.solve(z0, np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(du, -c.k_lqr @ z0, rtol=1e-6, atol=1e-8)


def test_mpc_respects_effort_bounds(controllers: dict) -> None:
    c: MPCController = controllers["mpc"]
    z0 = np.zeros(12)
    z0[0], z0[6] = 0.5, 2.0  # far away: effort saturates
    du = c.solve(z0, np.zeros(6), np.zeros(6))
    assert np.all(np.abs(du) <= c.u_max + 1e-6)
    lqr = -c.k_lqr @ z0
    assert 0 < du[0] < lqr[0] and 0 < du[3] < lqr[3]  # the constraints cut the LQR answer back


def test_impedance_steady_state_force_against_a_wall(controllers: dict, sim: Simulation) -> None:
    """Pressed 5 mm into a wall the command cannot reach, the push equals K * 5 mm (plus bias)."""
    c: ImpedanceController = controllers["impedance"]
    state = sim.state()
    wall = state._replace(v_world=np.zeros(3), omega_body=np.zeros(3))
    tgt = target(state.p_world + [0.005, 0.0, 0.0], state.quat_world)
    ctrl = np.asarray(c.compute(wall, tgt).ctrl)
    bias = c.dynamics.bias(wall.p_world, wall.quat_world, np.zeros(3), np.zeros(3))
    assert ctrl[c._act.slides[0]] - bias[0] == pytest.approx(c.config.k_pos[0] * 0.005, rel=1e-9)
    assert abs(ctrl[c._act.slides[1]] - bias[1]) < 1e-9


def test_admittance_yields_along_an_applied_force(model: mujoco.MjModel) -> None:
    sim = Simulation(model, make_controller("admittance", model))
    goal = target(HOME)
    sim.hold(goal, 0.5)
    body = model.body("2f85/base").id  # below the sensor, as a contact on the gripper would be
    sim.data.xfrc_applied[body, :3] = [4.0, 0.0, -3.0]  # a 5 N push from outside
    sim.hold(goal, 1.5)
    offset = sim.controller.offset  # type: ignore[attr-defined]
    assert offset[0] > 1e-3 and offset[2] < -1e-3 and abs(offset[1]) < 1e-4
    # Spring-like: steady offset ~ (|F| - deadband) / K along F.
    expected = (5.0 - sim.controller.config.deadband) / sim.controller.config.stiffness  # type: ignore[attr-defined]
    assert np.linalg.norm(offset) == pytest.approx(expected, rel=0.15)
    sim.data.xfrc_applied[body] = 0.0
    sim.hold(goal, 1.5)
    assert np.linalg.norm(sim.controller.offset) < 1e-4  # type: ignore[attr-defined]


def test_admittance_sees_no_force_in_free_space(model: mujoco.MjModel) -> None:
    sim = Simulation(model, make_controller("admittance", model))
    c: AdmittanceController = sim.controller  # type: ignore[assignment]
    sim.hold(target(HOME, euler_to_quat(1.2, 0.0, 0.4)), 2.0)
    assert np.linalg.norm(c.external_force(sim.state(), np.zeros(3))) < 0.05


# -- Pinocchio agrees with MuJoCo ------------------------------------------------------------


def test_pinocchio_matches_mujoco_on_the_base_stack() -> None:
    import pinocchio as pin

    path = robot_mjcf()
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    dyn = BaseDynamics()
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = mj.qpos0.copy()  # fingers open: see controllers.dynamics on joint offsets
        q[:3] = rng.uniform(-0.3, 0.3, 3)
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        v = np.zeros(mj.nv)
        v[:6] = rng.normal(size=6)
        data.qpos[:], data.qvel[:] = q, v
        mujoco.mj_forward(mj, data)
        m_full = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, data, m_full)
        np.testing.assert_allclose(dyn.mass_matrix(q[:3], q[3:7]), m_full[:6, :6], atol=1e-6)
        np.testing.assert_allclose(dyn.bias(q[:3], q[3:7], v[:3], v[3:6]), data.qfrc_bias[:6], atol=1e-6)
        jac_p, jac_r = np.zeros((3, mj.nv)), np.zeros((3, mj.nv))
        mujoco.mj_jacSite(mj, data, jac_p, jac_r, mj.site("2f85/pinch").id)
        np.testing.assert_allclose(
            dyn.pinch_jacobian(q[:3], q[3:7]), np.vstack([jac_p, jac_r])[:, :6], atol=1e-6
        )
        # The full model (fingers included) agrees too where the fingers are at rest and open.
        full = dyn.full_model
        m_pin = pin.crba(full, full.createData(), to_pinocchio_q(q))
        np.testing.assert_allclose(np.triu(m_pin)[:6, :6], np.triu(m_full)[:6, :6], atol=1e-6)
