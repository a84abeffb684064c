"""The wrist's contact wrench: free space reads nothing, a push reads the push, a tare removes a bias."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.controllers import make_controller
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.sensing import WrenchPredictor, WristModel, WristSensor, lowpass_alpha

from ..conftest import HOME, target


def test_lowpass_alpha() -> None:
    assert lowpass_alpha(20.0, 0.001) == pytest.approx(1.0 - np.exp(-2.0 * np.pi * 0.02))
    assert 0.0 < lowpass_alpha(5.0, 0.001) < lowpass_alpha(20.0, 0.001) < 1.0


def test_free_space_reads_no_contact(model: mujoco.MjModel) -> None:
    tracker = Tracker(model, make_controller("pd", model, control_dt=0.001))
    tracker.hold(target(HOME, euler_to_quat(0.3, -0.2, 0.5)), 1.5)
    f, tau = WristModel(model).contact_wrench(tracker.state(), np.array([0.0, -0.07, -0.01]), np.zeros(3))
    assert np.linalg.norm(f) < 0.05 and np.linalg.norm(tau) < 0.01


def test_a_push_below_the_sensor_reads_as_the_push(model: mujoco.MjModel) -> None:
    """5 N applied to the hand below the sensor: the contact force on the hand is that force,
    and its moment about the point it is applied at (the body's centre of mass) is zero."""
    tracker = Tracker(model, make_controller("pd", model, control_dt=0.001))
    tracker.hold(target(HOME), 0.5)
    body = model.body("2f85/base").id
    tracker.data.xfrc_applied[body, :3] = [3.0, 0.0, -4.0]
    tracker.hold(target(HOME), 1.0)
    state = tracker.state()
    wrist = WristModel(model)
    f, _ = wrist.contact_wrench(state, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(f, [3.0, 0.0, -4.0], atol=0.15)
    com_body = np.empty(3)  # where xfrc_applied acts, in the gripper frame from the pinch point
    q_inv = np.array([state.quat_world[0], *(-state.quat_world[1:])])
    mujoco.mju_rotVecQuat(com_body, tracker.data.xipos[body] - state.p_world, q_inv)
    _, tau = wrist.contact_wrench(state, com_body, np.zeros(3))
    assert np.linalg.norm(tau) < 0.01


def test_the_tare_removes_a_bias_and_moment_about_moves_the_point(model: mujoco.MjModel) -> None:
    tracker = Tracker(model, make_controller("pd", model, control_dt=0.001))
    tracker.hold(target(HOME), 0.5)
    state = tracker.state()
    biased = state._replace(ft_wrench=state.ft_wrench + np.array([0.3, 0.0, 0.2, 0.004, 0.0, 0.0]))
    sensor = WristSensor(model, centre_body=np.array([0.0, -0.07, -0.01]), dt=0.001, tare_time=0.05)
    sensor.reset(biased)
    for _ in range(50):
        sensor.accumulate_tare(biased)
    f, tau = sensor.raw(biased)
    assert np.linalg.norm(f) < 1e-9 and np.linalg.norm(tau) < 1e-9
    f, tau = sensor.raw(state)  # the bias is gone: the unbiased reading is its negative
    assert np.linalg.norm(f) == pytest.approx(np.linalg.norm([0.3, 0.0, 0.2]), rel=0.05)
    sensor.force[:] = [0.0, 0.0, 2.0]
    sensor.moment[:] = 0.0
    # The same force about a point 10 mm away along the gripper's x has a moment r x F.
    moved = sensor.moment_about(state, np.array([0.01, -0.07, -0.01]))
    offset = np.empty(3)
    mujoco.mju_rotVecQuat(offset, np.array([-0.01, 0.0, 0.0]), state.quat_world)
    np.testing.assert_allclose(moved, np.cross(offset, [0.0, 0.0, 2.0]), atol=1e-12)


def test_a_known_acceleration_is_compensated(model: mujoco.MjModel) -> None:
    """``accel_ref``: the hand's own inertia along an acceleration the caller knows is not contact."""
    tracker = Tracker(model, make_controller("pd", model, control_dt=0.001))
    tracker.hold(target(HOME), 0.5)
    state = tracker.state()
    sensor = WristSensor(model, centre_body=np.array([0.0, -0.07, -0.01]), dt=0.001)
    f_rest, _ = sensor.raw(state)
    accel = np.array([0.5, 0.0, -1.0])
    f, _ = sensor.raw(state, accel_ref=accel)
    np.testing.assert_allclose(f - f_rest, sensor.wrist.mass * accel, atol=1e-12)
    f_update, _ = sensor.update(state, accel_ref=accel)
    np.testing.assert_allclose(f_update, lowpass_alpha(20.0, 0.001) * f, atol=1e-12)


def test_the_fast_moment_is_the_moment_through_the_force_filter(model: mujoco.MjModel) -> None:
    tracker = Tracker(model, make_controller("pd", model, control_dt=0.001))
    tracker.hold(target(HOME), 0.5)
    pushed = tracker.state()
    pushed = pushed._replace(ft_wrench=pushed.ft_wrench + np.array([0.0, 0.0, 0.0, 0.02, 0.0, 0.0]))
    centre = np.array([0.0, -0.07, -0.01])
    fast = WristSensor(model, centre_body=centre, dt=0.001, force_hz=20.0, moment_hz=5.0, fast_moment=True)
    plain = WristSensor(model, centre_body=centre, dt=0.001, force_hz=20.0, moment_hz=5.0)
    _, tau = fast.raw(pushed)
    for sensor in (fast, plain):
        sensor.update(pushed)
    np.testing.assert_allclose(fast.moment_fast, lowpass_alpha(20.0, 0.001) * tau, atol=1e-15)
    np.testing.assert_allclose(fast.moment, lowpass_alpha(5.0, 0.001) * tau, atol=1e-15)
    np.testing.assert_array_equal(fast.moment, plain.moment)
    assert np.all(plain.moment_fast == 0.0)


# -- the wrench predictor -------------------------------------------------------------------------


def _late_filtered(true: np.ndarray, lag: int, alpha: np.ndarray) -> np.ndarray:
    """Independent reference: the rows of ``true`` ``lag`` periods late (the first row before
    the start), through a first-order low-pass of gain ``alpha`` started at the first row."""
    out, state = [], true[0].copy()
    for n in range(len(true)):
        state = state + alpha * (true[max(0, n - lag)] - state)
        out.append(state)
    return np.array(out)


def test_the_predictor_recovers_the_wrench_a_late_filtered_reading_hides() -> None:
    """On a linear contact (w = w_rest - K s), the prediction from the late, filtered reading and
    the command is the wrench now, exactly, for any motion of the command."""
    dt, lag = 0.001, 10
    stiffness = np.array([4000.0, 2.0])
    alpha = np.array([lowpass_alpha(20.0, dt), lowpass_alpha(5.0, dt)])
    w_rest = np.array([-0.5, 0.01])
    t = np.arange(400) * dt
    command = np.stack([2e-4 * np.sin(40.0 * t), 0.05 * t], axis=1)  # an oscillation, a ramp
    true = w_rest - stiffness * command  # the wrench that each command makes
    reading = _late_filtered(true, lag, alpha)
    predictor = WrenchPredictor(stiffness=stiffness, latency=lag * dt, dt=dt, alpha=alpha)
    predictor.reset(command[0])
    predicted = np.array([predictor.predict(r, s) for r, s in zip(reading, command, strict=True)])
    np.testing.assert_allclose(predicted, true, rtol=0, atol=1e-12)
    # The reading itself trails the ramp by K v (latency + the filter's time constant): 4 mN m.
    tau = (1.0 - alpha[1]) / alpha[1] * dt
    assert reading[-1, 1] - true[-1, 1] == pytest.approx(2.0 * 0.05 * (lag * dt + tau), rel=1e-3)


def test_a_restarted_axis_has_no_correction_and_a_wrong_latency_a_bounded_one() -> None:
    dt = 0.001
    stiffness = np.array([4000.0])
    alpha = np.array([lowpass_alpha(20.0, dt)])
    predictor = WrenchPredictor(stiffness=stiffness, latency=0.01, dt=dt, alpha=alpha)
    predictor.reset(np.zeros(1))
    for k in range(50):  # the command ramps down at 1 mm/s
        out = predictor.predict(np.zeros(1), np.array([-1e-6 * k]))
    # The reading lags the command by the latency and the filter's time constant (~18 ms).
    lag = 0.01 + (1.0 - alpha[0]) / alpha[0] * dt
    assert out[0] == pytest.approx(4000.0 * 1e-3 * lag, rel=0.05)
    predictor.restart(np.array([True]), np.array([-5e-5]))
    np.testing.assert_array_equal(predictor.predict(np.zeros(1), np.array([-5e-5])), 0.0)


def test_the_predictor_checks_its_shapes() -> None:
    with pytest.raises(ValueError, match=r"alpha \(2,\) and stiffness \(3,\) differ in shape"):
        WrenchPredictor(stiffness=np.ones(3), latency=0.01, dt=0.001, alpha=np.ones(2))


def test_the_wrench_in_floats_is_the_array_formula_to_the_bit(model: mujoco.MjModel) -> None:
    """WristModel.contact_wrench runs in plain floats; the numbers are the array formula's."""
    from peg_ctrl.sim.rotations import cross, rotate
    from peg_ctrl.sim.state import ControlState, ft_world

    wrist = WristModel(model)
    rng = np.random.default_rng(4)
    for _ in range(500):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        ft, centre, accel = rng.normal(size=6) * 5.0, rng.normal(size=3) * 0.05, rng.normal(size=3)
        state = ControlState(0.0, np.zeros(3), q, np.zeros(3), np.zeros(3), 0.085, ft)
        f_world, t_world = ft_world(state)
        inertia = wrist.mass * (accel - wrist.gravity)
        f_ext = inertia - f_world
        site, com, c = rotate(q, wrist.site_body), rotate(q, wrist.com_body), rotate(q, centre)
        tau = -t_world + cross(com - site, inertia) + cross(site - c, f_ext)
        f, t = wrist.contact_wrench(state, centre, accel)
        assert f.tobytes() == f_ext.tobytes() and t.tobytes() == tau.tobytes()
