"""Task-space impedance: its config and its control law at a fixed state (no physics)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.controllers.impedance import ImpedanceConfig, ImpedanceController
from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.state import ControlState

from ..conftest import target


@pytest.fixture(scope="module")
def impedance(model: mujoco.MjModel) -> ImpedanceController:
    return ImpedanceController(model)


def test_scaled_scales_tuple_gains() -> None:
    cfg = ImpedanceConfig(k_pos=(1200.0, 1200.0, 1200.0), k_rot=(100.0, 110.0, 120.0))
    scaled = cfg.scaled(0.9)
    assert ImpedanceConfig.GAINS == ("k_pos", "k_rot")
    assert scaled.k_pos == (1200.0 * 0.9,) * 3
    assert scaled.k_rot == (100.0 * 0.9, 110.0 * 0.9, 120.0 * 0.9)
    assert (scaled.damping_ratio, scaled.v_max, scaled.control_dt) == (1.0, 0.5, 0.005)
    assert cfg.scaled(1.0) == cfg


def test_stiffness_needs_three_values() -> None:
    with pytest.raises(ConfigError, match=r"impedance\.k_pos: must hold 3 values"):
        ImpedanceConfig(k_pos=(1.0, 2.0))  # type: ignore[arg-type]


def test_scaled_config_builds_a_working_controller(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = ImpedanceController(model, ImpedanceConfig(k_pos=(1200.0, 1200.0, 1200.0)).scaled(1.1))
    c.reset(home_state)
    ctrl = c.compute(home_state, target(home_state.p_world + [0.01, 0.0, 0.0])).ctrl
    assert len(ctrl) == model.nu and np.all(np.isfinite(ctrl))


def test_steady_state_force_against_a_wall(impedance: ImpedanceController, home_state: ControlState) -> None:
    """Pressed 5 mm into a wall the command cannot reach, the push equals K * 5 mm (plus bias)."""
    c = impedance
    wall = home_state._replace(v_world=np.zeros(3), omega_body=np.zeros(3))
    tgt = target(wall.p_world + [0.005, 0.0, 0.0], wall.quat_world)
    ctrl = np.asarray(c.compute(wall, tgt).ctrl)
    bias = c.dynamics.bias(wall.p_world, wall.quat_world, np.zeros(3), np.zeros(3))
    assert ctrl[c._act.slides[0]] - bias[0] == pytest.approx(c.config.k_pos[0] * 0.005, rel=1e-9)
    assert abs(ctrl[c._act.slides[1]] - bias[1]) < 1e-9


def test_pinch_jacobian_is_the_identity_at_home(
    impedance: ImpedanceController, home_state: ControlState
) -> None:
    """The pinch point is the ball joint's centre, as the module docstring says."""
    jac = impedance.dynamics.pinch_jacobian(home_state.p_world, home_state.quat_world)
    np.testing.assert_allclose(jac, np.eye(6), atol=1e-12)


def test_compliance_center_must_be_three_finite_numbers() -> None:
    with pytest.raises(ConfigError, match=r"impedance\.compliance_center: must be 3 finite numbers"):
        ImpedanceConfig(compliance_center=(0.0, float("nan"), 0.0))
    with pytest.raises(ConfigError, match=r"impedance\.damping_compensation: must be in \[0, 1\), got 1.0"):
        ImpedanceConfig(damping_compensation=1.0)


def _slides_and_ball(ctrl: object, model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    ctrl = np.asarray(ctrl)
    slides = [model.actuator(n).id for n in ("act_transX", "act_transY", "act_transZ")]
    balls = [model.actuator(n).id for n in ("act_rotX", "act_rotY", "act_rotZ")]
    return ctrl[slides], ctrl[balls]


def test_a_turn_about_the_compliance_center_moves_no_force(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """Remote centre of compliance: a target turned about the centre (70 mm below the pinch)
    asks for a torque and no net force; the same target with the centre at the pinch asks for a
    force as well, since the pinch point itself has to move."""
    centre = np.array([0.0, 0.0, -0.07])  # gripper frame = world frame at home
    angle = 0.02
    q = np.array([np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0])  # about world y
    r = np.empty(3)
    mujoco.mju_rotVecQuat(r, centre, q)
    p_turned = home_state.p_world + centre - r  # keeps the centre where it is
    forces = {}
    for c_body in ((0.0, 0.0, 0.0), tuple(centre)):
        cfg = ImpedanceConfig(compliance_center=c_body)  # type: ignore[arg-type]
        c = ImpedanceController(model, cfg)
        c.reset(home_state)
        at_rest, _ = _slides_and_ball(c.compute(home_state, target(home_state.p_world)).ctrl, model)
        turned, torque = _slides_and_ball(c.compute(home_state, target(p_turned, q)).ctrl, model)
        forces[c_body] = turned - at_rest  # without the gravity feed-forward
        assert abs(torque[1]) > 0.1
    assert np.abs(forces[tuple(centre)]).max() < 1e-6
    assert np.abs(forces[(0.0, 0.0, 0.0)]).max() > 1.0
