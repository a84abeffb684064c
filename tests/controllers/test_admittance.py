"""Admittance: its config (with the inner PD's), its law at a fixed state, and closed loop
(through :class:`peg_ctrl.run.tracker.Tracker`, a driver of the episode loop)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget, euler_to_quat
from peg_ctrl.controllers.admittance import AdmittanceConfig, AdmittanceController
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.sensing import WristSensor
from peg_ctrl.sim.state import ControlState

from ..conftest import HOME, target


def test_scaled_scales_its_gains_and_the_inner_pd() -> None:
    cfg = AdmittanceConfig(stiffness=200.0, inner=PDConfig(kp_pos=1000.0))
    scaled = cfg.scaled(0.9)
    assert AdmittanceConfig.GAINS == ("stiffness", "rot_stiffness")
    assert scaled.stiffness == 200.0 * 0.9
    assert scaled.inner == cfg.inner.scaled(0.9)
    assert scaled.inner.kp_pos == 1000.0 * 0.9
    assert (scaled.mass, scaled.deadband, scaled.max_offset) == (cfg.mass, cfg.deadband, cfg.max_offset)
    assert cfg.scaled(1.0) == cfg


def test_inner_pd_is_configured_and_runs_at_our_period(model: mujoco.MjModel) -> None:
    cfg = AdmittanceConfig(control_dt=0.002, inner=PDConfig(kp_pos=1000.0, k_rot=5.0))
    c = AdmittanceController(model, cfg)
    assert c.control_dt == 0.002
    assert c.inner.config == dataclasses.replace(cfg.inner, control_dt=0.002)


def _at_rest_wrench(c: AdmittanceController, state: ControlState, push_world: np.ndarray) -> np.ndarray:
    """The sensor reading for the gripper at rest under its weight and an external push [N]."""
    wrist = c.loop.sensor.wrist
    f_world = -wrist.mass * wrist.gravity - push_world  # what external_force() inverts
    f_site = np.empty(3)
    q = state.quat_world
    mujoco.mju_rotVecQuat(f_site, f_world, np.array([q[0], -q[1], -q[2], -q[3]]))
    return np.array([f_site[0], -f_site[1], -f_site[2], 0.0, 0.0, 0.0])


def test_without_contact_it_is_the_inner_pd(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = AdmittanceController(model)
    pd = PDController(model, c.inner.config)
    state = home_state._replace(ft_wrench=_at_rest_wrench(c, home_state, np.zeros(3)))
    c.reset(state)
    pd.reset(state)
    tgt = target(state.p_world + [0.01, 0.0, -0.02], jaw=0.03)
    for _ in range(5):
        assert c.compute(state, tgt).ctrl == pd.compute(state, tgt).ctrl
    assert np.all(c.offset == 0.0)


def test_yields_along_a_push_like_a_spring(model: mujoco.MjModel, home_state: ControlState) -> None:
    """A steady 5 N push: the offset settles at (|F| - deadband) / K along F."""
    c = AdmittanceController(model)
    push = np.array([4.0, 0.0, -3.0])
    state = home_state._replace(ft_wrench=_at_rest_wrench(c, home_state, push))
    c.reset(state)
    tgt = target(state.p_world)
    for _ in range(3000):  # 3 s of the virtual dynamics (critically damped, 12 rad/s)
        c.compute(state, tgt)
    expected = (5.0 - c.config.deadband) / c.config.stiffness * push / 5.0
    np.testing.assert_allclose(c.offset, expected, atol=1e-6)
    c.reset(state)
    assert np.all(c.offset == 0.0) and np.all(c.force_filtered == 0.0)


def test_offset_is_capped(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = AdmittanceController(model, AdmittanceConfig(max_offset=0.005))
    state = home_state._replace(ft_wrench=_at_rest_wrench(c, home_state, np.array([0.0, 50.0, 0.0])))
    c.reset(state)
    for _ in range(2000):
        c.compute(state, target(state.p_world))
    assert np.linalg.norm(c.offset) == pytest.approx(0.005, rel=1e-12)


def test_scaled_config_builds_a_working_controller(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = AdmittanceController(model, AdmittanceConfig().scaled(1.1))
    c.reset(home_state)
    ctrl = c.compute(home_state, target(home_state.p_world + [0.01, 0.0, 0.0])).ctrl
    assert len(ctrl) == model.nu and np.all(np.isfinite(ctrl))


# -- closed loop -------------------------------------------------------------------------------


def test_closed_loop_yields_along_an_applied_force(model: mujoco.MjModel) -> None:
    controller = AdmittanceController(model)
    tracker = Tracker(model, controller)
    goal = target(HOME)
    tracker.hold(goal, 0.5)
    body = model.body("2f85/base").id  # below the sensor, as a contact on the gripper would be
    tracker.data.xfrc_applied[body, :3] = [4.0, 0.0, -3.0]  # a 5 N push from outside
    tracker.hold(goal, 1.5)
    offset = controller.offset
    assert offset[0] > 1e-3 and offset[2] < -1e-3 and abs(offset[1]) < 1e-4
    # Spring-like: steady offset ~ (|F| - deadband) / K along F.
    expected = (5.0 - controller.config.deadband) / controller.config.stiffness
    assert np.linalg.norm(offset) == pytest.approx(expected, rel=0.15)
    tracker.data.xfrc_applied[body] = 0.0
    tracker.hold(goal, 1.5)
    assert np.linalg.norm(controller.offset) < 1e-4


def test_closed_loop_sees_no_force_in_free_space(model: mujoco.MjModel) -> None:
    controller = AdmittanceController(model)
    tracker = Tracker(model, controller)
    tracker.hold(target(HOME, euler_to_quat(1.2, 0.0, 0.4)), 2.0)
    assert np.linalg.norm(controller.external_force(tracker.state(), np.zeros(3))) < 0.05


def test_closed_loop_sees_no_torque_in_free_space(model: mujoco.MjModel) -> None:
    """The gripper's own weight is taken out of the torque as well (centre of mass from the model)."""
    controller = AdmittanceController(model, AdmittanceConfig(compliance_center=(0.0, 0.0, -0.07)))
    tracker = Tracker(model, controller)
    tracker.hold(target(HOME, euler_to_quat(0.4, 0.3, 0.4)), 2.0)
    _, torque = controller.external_wrench(tracker.state(), np.zeros(3))
    assert np.linalg.norm(torque) < 0.01


def test_rotational_admittance_turns_like_a_spring(model: mujoco.MjModel) -> None:
    cfg = AdmittanceConfig(rotational=True, rot_stiffness=4.0)
    controller = AdmittanceController(model, cfg)
    tracker = Tracker(model, controller)
    goal = target(HOME)
    tracker.hold(goal, 0.5)
    body = model.body("2f85/base").id
    tracker.data.xfrc_applied[body, 3:] = [0.0, 0.2, 0.0]  # a pure torque about world y [N m]
    tracker.hold(goal, 2.0)
    expected = (0.2 - cfg.torque_deadband) / cfg.rot_stiffness
    assert controller.rotation[1] == pytest.approx(expected, rel=0.15)
    assert abs(controller.rotation[0]) < 0.1 * expected and abs(controller.rotation[2]) < 0.1 * expected


# -- moment-controlled axes ----------------------------------------------------------------------


def _tared_on_moment_axes(
    model: mujoco.MjModel, home_state: ControlState, **changes: float
) -> tuple[AdmittanceController, ControlState, GripperTarget]:
    """An admittance about a centre 70 mm below the pinch point (``moment_damping`` 1 and
    ``changes``), tared over 50 ms at rest, free of contact; the rest state and a target that
    flags the tilt axes moment-controlled at zero moment."""
    cfg = AdmittanceConfig(compliance_center=(0.0, 0.0, -0.07), moment_damping=1.0, tare_time=0.05)
    c = AdmittanceController(model, dataclasses.replace(cfg, **changes))
    rest = home_state._replace(ft_wrench=_at_rest_wrench(c, home_state, np.zeros(3)))
    c.reset(rest)
    free = target(rest.p_world).with_wrench((0.0, 0.0, 0.0), axes=(False,) * 3 + (True, True, False))
    for i in range(50):
        c.compute(rest._replace(t=0.001 * i), free)
    return c, rest, free


def test_a_moment_axis_turns_the_command_until_the_moment_is_gone(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """A sensed moment about x on a moment-controlled axis turns the command about the centre at
    M / D_m (capped), and only about that axis; a pose target leaves the turn at zero."""
    c, rest, free = _tared_on_moment_axes(model, home_state, max_turn_rate=0.02)
    torque = np.array([0.0, 0.0, 0.0, 0.03, 0.0, 0.0])  # a contact's moment about x at the sensor
    state = rest._replace(t=0.05, ft_wrench=rest.ft_wrench - torque)
    for _ in range(2000):  # 2 s: the 5 Hz moment filter settles, the turn runs at its rate
        c.compute(state, free)
    assert abs(c.turn[0]) == pytest.approx(0.02 * 2.0, rel=0.1)  # capped at 0.02 rad/s
    assert abs(c.turn[1]) < 1e-9 and abs(c.turn[2]) < 1e-9
    c.compute(state, target(state.p_world))
    assert np.all(c.turn == 0.0)  # no longer moment-controlled: the task re-anchors


def test_a_moment_axis_turns_slower_after_its_moment_reverses(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """``reversal_backoff``: once the moment has crossed from beyond +band to beyond -band, the
    axis turns at M / (2 D_m); the other axis, which did not reverse, at M / D_m."""
    c, rest, free = _tared_on_moment_axes(model, home_state, reversal_backoff=2.0)

    def turn_rate(moment: tuple[float, float], steps: int) -> np.ndarray:
        torque = np.array([0.0, 0.0, 0.0, *moment, 0.0])
        state = rest._replace(t=0.05, ft_wrench=rest.ft_wrench - torque)
        for _ in range(steps):  # the 5 Hz moment filter settles
            before = c.turn.copy()
            c.compute(state, free)
        return (c.turn - before) / 0.001

    rate = turn_rate((0.01, 0.01), 1500)
    np.testing.assert_allclose(np.abs(rate[:2]), [0.01, 0.01], rtol=0.01)
    rate = turn_rate((-0.01, 0.01), 1500)
    np.testing.assert_allclose(np.abs(rate[:2]), [0.005, 0.01], rtol=0.01)
    np.testing.assert_array_equal(c.loop.backoff.scale, [2.0, 1.0, 1.0])


def test_the_tare_is_the_wrist_sensors(model: mujoco.MjModel, home_state: ControlState) -> None:
    """One tare: the admittance's is a :class:`WristSensor`'s, bit for bit the same as a sensor of
    the same settings fed the same readings, and it removes a bias the model does not know."""
    cfg = AdmittanceConfig(compliance_center=(0.0, 0.0, -0.07), tare_time=0.05)
    c = AdmittanceController(model, cfg)
    bias = np.array([0.4, -0.3, 0.2, 0.01, -0.02, 0.005])  # sensor frame [N, N m]
    rest = home_state._replace(ft_wrench=_at_rest_wrench(c, home_state, np.zeros(3)) + bias)
    sensor = WristSensor(
        model,
        centre_body=np.array(cfg.compliance_center),
        dt=cfg.control_dt,
        force_hz=cfg.filter_hz,
        moment_hz=cfg.moment_filter_hz,
        tare_time=cfg.tare_time,
        fast_moment=True,
    )
    c.reset(rest)
    sensor.reset(rest)
    hold = target(rest.p_world)
    rng = np.random.default_rng(0)
    for i in range(60):  # 50 readings in the tare, 10 after it; a little noise for the estimate
        state = rest._replace(t=0.001 * i, ft_wrench=rest.ft_wrench + rng.normal(0.0, 0.01, 6))
        c.compute(state, hold)
        sensor.update(state, accel_ref=np.zeros(3))
    assert np.all(c.loop.sensor.noise_force > 0.0)  # the tare ran
    for name in ("force_bias", "moment_bias_body", "noise_force", "noise_moment", "force", "moment_fast"):
        np.testing.assert_array_equal(getattr(c.loop.sensor, name), getattr(sensor, name), err_msg=name)
    assert not [name for name in vars(c.loop) if "tare" in name or "bias" in name]  # none of its own
    push = np.array([2.0, 0.0, -3.0])
    pushed = rest._replace(t=0.06, ft_wrench=_at_rest_wrench(c, rest, push) + bias)
    np.testing.assert_allclose(c.external_force(pushed, np.zeros(3)), push, atol=0.02)
