"""The reference PD controller: its config, its control law at a fixed state, and step responses
(closed loop, through :class:`peg_ctrl.run.tracker.Tracker`, a driver of the episode loop)."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.scene import SLIDE_JOINTS
from peg_ctrl.sim.state import ControlState

from ..conftest import HOME, target

SLIDES = ("act_transX", "act_transY", "act_transZ")
BALLS = ("act_rotX", "act_rotY", "act_rotZ")


def test_config_is_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        PDConfig().kp_pos = 1.0  # type: ignore[misc]


def test_scaled_scales_every_gain() -> None:
    cfg = PDConfig(kp_pos=1000.0)
    scaled = cfg.scaled(0.9)
    assert set(PDConfig.GAINS) == {"kp_pos", "kd_pos", "k_rot", "k_omega"}
    for field in PDConfig.GAINS:
        assert getattr(scaled, field) == getattr(cfg, field) * 0.9
    assert dataclasses.replace(scaled, **{f: getattr(cfg, f) for f in PDConfig.GAINS}) == cfg
    assert cfg.scaled(1.0) == cfg


def test_scaled_config_builds_a_working_controller(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = PDController(model, PDConfig().scaled(1.1))
    c.reset(home_state)
    ctrl = c.compute(home_state, target(HOME + [0.01, 0.0, 0.0])).ctrl
    assert len(ctrl) == model.nu and np.all(np.isfinite(ctrl))


def test_double_cover_quaternion_gives_the_same_command(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """q and -q are the same orientation."""
    c = PDController(model)
    q = euler_to_quat(0.4, -0.3, 1.2)
    c.reset(home_state)
    a = c.compute(home_state, target(HOME, q)).ctrl
    c.reset(home_state)
    b = c.compute(home_state, target(HOME, -q)).ctrl
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_at_target_only_gravity_is_compensated(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = PDController(model)
    c.reset(home_state)
    ctrl = np.asarray(c.compute(home_state, target(HOME)).ctrl)
    weight = model.body_subtreemass[model.body("gripper_root").id] * 9.81
    slides = [model.actuator(n).id for n in SLIDES]
    np.testing.assert_allclose(ctrl[slides], [0.0, 0.0, weight], atol=1e-9)
    balls = [model.actuator(n).id for n in BALLS]
    assert np.abs(ctrl[balls]).max() < 1e-3  # gripper's centre of mass is nearly on the axis


def test_far_target_is_approached_at_the_velocity_cap(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """Without feed-forward, |F| = (max b + Kd) v_max along the error for a far target at rest."""
    cfg = PDConfig(model_feedforward=False)
    c = PDController(model, cfg)
    c.reset(home_state)
    ctrl = np.asarray(c.compute(home_state, target(HOME + [0.3, 0.0, -0.4])).ctrl)
    force = ctrl[[model.actuator(n).id for n in SLIDES]]
    b_max = max(model.dof_damping[model.joint(n).dofadr[0]] for n in SLIDE_JOINTS)
    expected = (b_max + cfg.kd_pos) * cfg.v_max
    np.testing.assert_allclose(force, expected * np.array([0.6, 0.0, -0.8]), rtol=1e-12, atol=1e-12)


def test_saturation_holds(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = PDController(model, PDConfig(v_max=100.0, omega_max=100.0))
    c.reset(home_state)
    far = target(HOME + np.array([5.0, -5.0, 5.0]), euler_to_quat(3.0, 1.0, -2.0))
    ctrl = np.asarray(c.compute(home_state, far).ctrl)
    lo, hi = model.actuator_ctrlrange.T
    assert np.all(ctrl >= lo) and np.all(ctrl <= hi)
    slides = [model.actuator(n).id for n in SLIDES]
    np.testing.assert_array_equal(np.abs(ctrl[slides]), hi[slides])  # this far, every slide saturates


def test_same_inputs_same_outputs(model: mujoco.MjModel, home_state: ControlState) -> None:
    a, b = PDController(model), PDController(model)
    a.reset(home_state)
    b.reset(home_state)
    tgt = target(HOME + 0.05, euler_to_quat(0.3, -0.2, 0.1), jaw=0.03)
    for _ in range(5):
        assert a.compute(home_state, tgt).ctrl == b.compute(home_state, tgt).ctrl


def test_reset_restarts_the_omega_filter(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = PDController(model)
    spinning = home_state._replace(omega_body=np.array([0.5, 0.0, 0.0]))
    tgt = target(HOME)
    c.reset(home_state)
    first = c.compute(spinning, tgt).ctrl
    c.compute(spinning, tgt)
    c.reset(home_state)
    assert c.compute(spinning, tgt).ctrl == first


# -- closed loop -------------------------------------------------------------------------------


@pytest.fixture()
def tracker(model: mujoco.MjModel) -> Tracker:
    return Tracker(model, PDController(model))


def _angle_error(q_d: np.ndarray, q: np.ndarray) -> float:
    err = np.zeros(3)
    mujoco.mju_subQuat(err, q_d, q)
    return float(np.linalg.norm(err))


# ~2 s of physics each: two in the default suite, every axis and sign with the slow tests.
FAST_SLIDES = {(0, 0.1), (2, -0.1)}


@pytest.mark.parametrize(
    ("axis", "step"),
    [
        pytest.param(
            axis,
            step,
            id=f"{step}-{'xyz'[axis]}",
            marks=() if (axis, step) in FAST_SLIDES else pytest.mark.slow,
        )
        for step in (0.1, -0.1)
        for axis in (0, 1, 2)
    ],
)
def test_slide_step_response(tracker: Tracker, axis: int, step: float) -> None:
    """10 cm step: within 1 mm by 0.5 s, overshoot <= 0.5 mm, within 0.01 mm at 2 s."""
    goal = HOME.copy()
    goal[axis] += step
    tgt = target(goal)
    positions = []
    for _ in range(2000):
        tracker.control_step(tgt)
        positions.append(tracker.state().p_world.copy())
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


FAST_ROTATIONS = ("yaw 0.5", "roll 95deg", "pitch 90 + yaw 45")  # ~3 s each; the rest are slow


@pytest.mark.parametrize(
    "rpy",
    [
        pytest.param(rpy, id=name, marks=() if name in FAST_ROTATIONS else pytest.mark.slow)
        for name, rpy in ROTATIONS.items()
    ],
)
def test_rotation_step_response(tracker: Tracker, rpy: tuple[float, float, float]) -> None:
    """Within 0.01 rad by 1.5 s (speed capped at 1.5 rad/s), overshoot <= 0.01 rad, pinch point fixed."""
    q_d = euler_to_quat(*rpy)
    tgt = target(HOME, q_d)
    errors, drift = [], []
    for _ in range(2500):
        tracker.control_step(tgt)
        s = tracker.state()
        errors.append(_angle_error(q_d, s.quat_world))
        drift.append(np.linalg.norm(s.p_world - HOME))
    errors_arr = np.asarray(errors)
    first = int(np.argmax(errors_arr < 0.01))
    assert errors_arr[first] < 0.01 and first < 1500
    assert errors_arr[first:].max() < 0.015  # bounded overshoot once there
    assert errors_arr[-1] < 1e-4
    assert max(drift) < 2e-3


@pytest.mark.parametrize("sign", [1.0, pytest.param(-1.0, marks=pytest.mark.slow)])  # ~3 s each
def test_large_rotation_takes_the_short_way(tracker: Tracker, sign: float) -> None:
    """Yaw to +-(pi - 0.05): the yaw angle moves monotonically towards the target's side."""
    goal = sign * (math.pi - 0.05)
    q_d = euler_to_quat(0.0, 0.0, goal)
    tgt = target(HOME, q_d)
    yaws = []
    for _ in range(3500):
        tracker.control_step(tgt)
        q = tracker.state().quat_world
        yaws.append(2.0 * math.atan2(q[3], q[0]))
    yaw = np.unwrap(np.asarray(yaws))
    assert np.all(sign * np.diff(yaw) > -1e-6), "rotation reversed direction"
    assert yaw[-1] == pytest.approx(goal, abs=1e-3)


def test_a_force_controlled_axis_pushes_with_the_commanded_force(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """z force-controlled at -3 N: the position error along z is ignored, x still tracked."""
    c = PDController(model)
    c.reset(home_state)
    far = target(HOME + [0.001, 0.0, -0.05]).with_force([0.0, 0.0, -3.0])
    ctrl = np.asarray(c.compute(home_state, far).ctrl)
    weight = model.body_subtreemass[model.body("gripper_root").id] * 9.81
    slides = [model.actuator(n).id for n in SLIDES]
    np.testing.assert_allclose(ctrl[slides], [PDConfig().kp_pos * 0.001, 0.0, weight - 3.0], atol=1e-9)
