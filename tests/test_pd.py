"""The reference controller: contracts and step responses (running the physics)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from controllers import PDConfig, UnknownController, make_controller
from peg_ctrl.commands import euler_to_quat
from peg_ctrl.sim import Simulation

from .conftest import HOME, IDENTITY, target


def _angle_error(q_d: np.ndarray, q: np.ndarray) -> float:
    err = np.zeros(3)
    mujoco.mju_subQuat(err, q_d, q)
    return float(np.linalg.norm(err))


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["x", "y", "z"])
@pytest.mark.parametrize("step", [0.1, -0.1])
def test_slide_step_response(sim: Simulation, axis: int, step: float) -> None:
    """10 cm step: within 1 mm by 0.5 s, overshoot <= 0.5 mm, within 0.01 mm at 2 s."""
    goal = HOME.copy()
    goal[axis] += step
    tgt = target(goal)
    positions = []
    for _ in range(2000):
        sim.control_step(tgt)
        positions.append(sim.state().p_world.copy())
    p = np.asarray(positions)
    err = np.linalg.norm(p - goal, axis=1)
    assert err[499] < 1e-3
    overshoot = np.max(np.sign(step) * (p[:, axis] - goal[axis]))
    assert overshoot <= 0.5e-3
    assert err[-1] < 1e-5
    other = [a for a in range(3) if a != axis]
    assert np.abs(p[:, other] - HOME[other]).max() < 1e-3  # axes stay decoupled


ROTATIONS = {
    "roll 0.5": (0.5, 0.0, 0.0),
    "pitch 0.5": (0.0, 0.5, 0.0),
    "yaw 0.5": (0.0, 0.0, 0.5),
    "roll 95deg": (math.radians(95), 0.0, 0.0),
    "pitch +90deg": (0.0, math.pi / 2, 0.0),
    "pitch -90deg": (0.0, -math.pi / 2, 0.0),
    "pitch 90 + yaw 45": (0.0, math.pi / 2, math.pi / 4),
}


@pytest.mark.parametrize("rpy", ROTATIONS.values(), ids=ROTATIONS.keys())
def test_rotation_step_response(sim: Simulation, rpy: tuple[float, float, float]) -> None:
    """Within 0.01 rad by 1.5 s (speed capped at 1.5 rad/s), overshoot <= 0.01 rad, pinch point fixed."""
    q_d = euler_to_quat(*rpy)
    tgt = target(HOME, q_d)
    errors, drift = [], []
    for _ in range(2500):
        sim.control_step(tgt)
        s = sim.state()
        errors.append(_angle_error(q_d, s.quat_world))
        drift.append(np.linalg.norm(s.p_world - HOME))
    errors_arr = np.asarray(errors)
    first = int(np.argmax(errors_arr < 0.01))
    assert errors_arr[first] < 0.01 and first < 1500
    assert errors_arr[first:].max() < 0.015  # bounded overshoot once there
    assert errors_arr[-1] < 1e-4
    assert max(drift) < 2e-3


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_large_rotation_takes_the_short_way(sim: Simulation, sign: float) -> None:
    """Yaw to +-(pi - 0.05): the yaw angle moves monotonically towards the target's side."""
    goal = sign * (math.pi - 0.05)
    q_d = euler_to_quat(0.0, 0.0, goal)
    tgt = target(HOME, q_d)
    yaws = []
    for _ in range(3500):
        sim.control_step(tgt)
        q = sim.state().quat_world
        yaws.append(2.0 * math.atan2(q[3], q[0]))
    yaw = np.unwrap(np.asarray(yaws))
    assert np.all(sign * np.diff(yaw) > -1e-6), "rotation reversed direction"
    assert yaw[-1] == pytest.approx(goal, abs=1e-3)


def test_double_cover_quaternion_gives_the_same_command(sim: Simulation) -> None:
    """q and -q are the same orientation."""
    s = sim.state()
    q = euler_to_quat(0.4, -0.3, 1.2)
    sim.controller.reset(s)
    a = sim.controller.compute(s, target(HOME, q)).ctrl
    sim.controller.reset(s)
    b = sim.controller.compute(s, target(HOME, -q)).ctrl
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_at_target_only_gravity_is_compensated(model: mujoco.MjModel, sim: Simulation) -> None:
    ctrl = np.asarray(sim.controller.compute(sim.state(), target(HOME)).ctrl)
    weight = model.body_subtreemass[model.body("gripper_root").id] * 9.81
    slides = [model.actuator(n).id for n in ("act_transX", "act_transY", "act_transZ")]
    np.testing.assert_allclose(ctrl[slides], [0.0, 0.0, weight], atol=1e-9)
    balls = [model.actuator(n).id for n in ("act_rotX", "act_rotY", "act_rotZ")]
    assert np.abs(ctrl[balls]).max() < 1e-3  # gripper's centre of mass is nearly on the axis


def test_saturation_holds(sim: Simulation, model: mujoco.MjModel) -> None:
    far = target(HOME + np.array([5.0, -5.0, 5.0]), euler_to_quat(3.0, 1.0, -2.0))
    ctrl = np.asarray(sim.controller.compute(sim.state(), far).ctrl)
    lo, hi = model.actuator_ctrlrange.T
    assert np.all(ctrl >= lo - 1e-12) and np.all(ctrl <= hi + 1e-12)


def test_same_inputs_same_outputs(model: mujoco.MjModel, sim: Simulation) -> None:
    a = make_controller("pd", model)
    b = make_controller("pd", model)
    s = sim.state()
    a.reset(s)
    b.reset(s)
    tgt = target(HOME + 0.05, euler_to_quat(0.3, -0.2, 0.1), jaw=0.03)
    for _ in range(5):
        assert a.compute(s, tgt).ctrl == b.compute(s, tgt).ctrl


@pytest.mark.parametrize("field", ["p", "quat", "v", "w"])
def test_nan_target_raises(field: str) -> None:
    kwargs = {"p": HOME.copy(), "quat": IDENTITY.copy(), "v": np.zeros(3), "w": np.zeros(3)}
    kwargs[field][0] = np.nan
    p, quat = kwargs.pop("p"), kwargs.pop("quat")
    names = {"p": "p_world", "quat": "quat_world", "v": "v_world", "w": "omega_body"}
    with pytest.raises(ValueError, match=names[field]):
        target(p, quat, **kwargs)


def test_target_arrays_are_private_and_read_only() -> None:
    p = HOME.copy()
    tgt = target(p)
    p[0] = 1.0
    assert tgt.p_world[0] == HOME[0]
    with pytest.raises(ValueError):
        tgt.p_world[0] = 0.0


def test_non_finite_state_raises(sim: Simulation) -> None:
    s = sim.state()._replace(p_world=np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="non-finite"):
        sim.controller.compute(s, target(HOME))


def test_registry_errors_list_known_names(model: mujoco.MjModel) -> None:
    with pytest.raises(UnknownController, match="known: admittance, diffik, impedance, mpc, pd"):
        make_controller("nope", model)
    with pytest.raises(ValueError, match="kp_pos"):
        make_controller("pd", model, kp_pos=-1.0)
    with pytest.raises(ValueError, match="bad parameter"):
        make_controller("pd", model, not_a_gain=1.0)


def test_control_period_must_divide_physics_step(model: mujoco.MjModel) -> None:
    with pytest.raises(ValueError, match="whole multiple"):
        Simulation(model, make_controller("pd", model, control_dt=0.0015))
    assert Simulation(model, make_controller("pd", model, control_dt=0.005)).decimation == 5


def test_config_is_frozen() -> None:
    with pytest.raises(AttributeError):
        PDConfig().kp_pos = 1.0  # type: ignore[misc]
