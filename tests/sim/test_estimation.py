"""The wrist sensor as an estimator: the tare measures each channel's noise, the filtered wrench's
sigma is that noise through the filter, the bias follows a drift only while the hand is free,
and the detection's thresholds in units of that sigma hold on noise."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from numpy.typing import NDArray

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.sim.rotations import yaw_quat
from peg_ctrl.sim.sensing import Detector, WristModel, WristSensor, lowpass_alpha, within
from peg_ctrl.sim.state import ControlState

DT = 0.001
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
SIGMA = np.array([0.02, 0.05, 0.1, 1e-3, 2e-3, 4e-3])  # per sensor channel: force [N], torque [N m]
BIAS = np.array([0.3, -0.2, 0.5, 0.004, -0.003, 0.002])  # the sensor's zero offset, sensor frame


def _state(t: float, ft: NDArray[np.float64], quat: NDArray[np.float64] = IDENTITY) -> ControlState:
    """The hand at rest at the origin, the sensor reading ``ft`` (6,) (sensor frame)."""
    return ControlState(t, np.zeros(3), np.asarray(quat, dtype=float), np.zeros(3), np.zeros(3), 0.085, ft)


def _sensor(model: mujoco.MjModel, centre: NDArray[np.float64] | None = None, **kw: object) -> WristSensor:
    """A sensor taking moments about ``centre`` (default: the sensor site itself, so that the
    force's noise does not leak into the moment's)."""
    site = WristModel(model).site_body
    return WristSensor(model, centre_body=site if centre is None else centre, dt=DT, **kw)


def _readings(rng: np.random.Generator, n: int, sigma: NDArray[np.float64] = SIGMA) -> NDArray[np.float64]:
    return BIAS + sigma * rng.standard_normal((n, 6))


def _tare(sensor: WristSensor, readings: NDArray[np.float64], quat: NDArray[np.float64] = IDENTITY) -> None:
    for k, ft in enumerate(readings):
        sensor.accumulate_tare(_state(k * DT, ft, quat))


# -- the tare and the noise ---------------------------------------------------------------------------


def test_the_tare_measures_each_channels_noise_and_mean(model: mujoco.MjModel) -> None:
    """Welford over the tare: the sample standard deviation of each channel (the sensor frame's
    y and z flip sign into the gripper frame, which leaves a spread as it is), within a few per
    cent of the true sigma over 4000 readings; the mean reading tares to zero."""
    readings = _readings(np.random.default_rng(7), 4000)
    sensor = _sensor(model)
    sensor.accumulate_tare(_state(0.0, readings[0]))
    assert np.all(sensor.noise_force == 0.0) and np.all(sensor.noise_moment == 0.0)  # one reading: no spread
    _tare(sensor, readings[1:])
    np.testing.assert_allclose(sensor.noise_force, readings[:, :3].std(axis=0, ddof=1), rtol=1e-9)
    np.testing.assert_allclose(sensor.noise_moment, readings[:, 3:].std(axis=0, ddof=1), rtol=1e-9)
    np.testing.assert_allclose(sensor.noise_force, SIGMA[:3], rtol=0.04)
    np.testing.assert_allclose(sensor.noise_moment, SIGMA[3:], rtol=0.04)
    f, tau = sensor.raw(_state(0.0, readings.mean(axis=0)))
    np.testing.assert_allclose(f, 0.0, atol=1e-12)
    np.testing.assert_allclose(tau, 0.0, atol=1e-12)


def test_the_force_noise_is_in_world_axes_and_the_moment_noise_in_the_grippers(
    model: mujoco.MjModel,
) -> None:
    """The hand turned 90 degrees about world z: the sensor's x and y force channels swap in world
    axes. The moment's noise is measured in the gripper frame (where its bias is kept), so it
    does not swap."""
    readings = _readings(np.random.default_rng(11), 4000)
    sensor = _sensor(model)
    _tare(sensor, readings, yaw_quat(0.5 * math.pi))
    std = readings.std(axis=0, ddof=1)
    np.testing.assert_allclose(sensor.noise_force, std[[1, 0, 2]], rtol=1e-6)
    np.testing.assert_allclose(sensor.noise_moment, std[3:], rtol=1e-6)


def test_sigma_is_the_resolution_without_noise_and_adds_to_it_in_quadrature(model: mujoco.MjModel) -> None:
    sensor = _sensor(model, force_hz=20.0, moment_hz=5.0)
    np.testing.assert_array_equal(sensor.sigma_force, [0.05] * 3)  # no tare yet: the floor
    np.testing.assert_array_equal(sensor.sigma_moment, [5e-4] * 3)
    _tare(sensor, np.tile(BIAS, (100, 1)))  # a noise-free sensor
    np.testing.assert_allclose(sensor.noise_force, 0.0, atol=1e-12)
    np.testing.assert_allclose(sensor.sigma_force, [0.05] * 3, rtol=1e-9)
    np.testing.assert_allclose(sensor.sigma_moment, [5e-4] * 3, rtol=1e-9)
    sensor.noise_force = np.array([0.0, 0.2, 2.0])
    a = lowpass_alpha(20.0, DT)
    np.testing.assert_allclose(
        sensor.sigma_force, np.hypot(sensor.noise_force * math.sqrt(a / (2 - a)), 0.05)
    )


def test_sigma_is_the_measured_spread_of_the_filtered_wrench(model: mujoco.MjModel) -> None:
    """White noise through the filters: the filtered wrench's standard deviation over 20 s is the
    sensor's ``sigma_force`` / ``sigma_moment`` (no resolution floor) within 15 %."""
    rng = np.random.default_rng(3)
    sensor = _sensor(model, force_hz=20.0, moment_hz=5.0, resolution=(0.0, 0.0))
    _tare(sensor, _readings(rng, 4000))
    out = []
    for k, ft in enumerate(_readings(rng, 20000)):
        f, tau = sensor.update(_state(4.0 + k * DT, ft))
        out.append(np.concatenate([f, tau]))
    filtered = np.array(out)[500:]  # past the moment filter's start (15 time constants)
    std = filtered.std(axis=0)
    np.testing.assert_allclose(std[:3], sensor.sigma_force, rtol=0.15)
    np.testing.assert_allclose(std[3:], sensor.sigma_moment, rtol=0.15)
    # and the filter does reduce the noise: to sqrt(alpha / (2 - alpha)) of a reading's, ~0.25 at 20 Hz
    assert np.all(std[:3] < 0.3 * SIGMA[:3]) and np.all(std[3:] < 0.15 * SIGMA[3:])


# -- the bias ------------------------------------------------------------------------------------------


def test_the_bias_follows_a_slow_drift_only_while_free(model: mujoco.MjModel) -> None:
    """The zero drifts 0.2 N and 2 mN m over 5 s. Free, the bias follows with the lag of a
    first-order tracker on a ramp (rate x ``bias_time``); not free, it stays, and the filtered
    wrench reads the whole drift."""
    bias_time, duration = 0.5, 5.0
    drift = np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.002])  # sensor channels z: +z in the gripper frame too
    sensors = {free: _sensor(model, bias_time=bias_time) for free in (True, False)}
    for sensor in sensors.values():
        _tare(sensor, np.tile(BIAS, (200, 1)))
    f0, m0 = sensors[True].force_bias.copy(), sensors[True].moment_bias_body.copy()
    n = round(duration / DT)
    for k in range(1, n + 1):
        state = _state(k * DT, BIAS + drift * k / n)
        for free, sensor in sensors.items():
            sensor.update(state, free=free)
    a = DT / bias_time
    lag = (drift / duration) * DT * (1.0 - a) / a  # the discrete tracker's steady lag on the ramp
    free, held = sensors[True], sensors[False]
    assert free.force_bias[2] - f0[2] == pytest.approx(drift[2] - lag[2], rel=1e-3)
    assert free.moment_bias_body[2] - m0[2] == pytest.approx(drift[5] - lag[5], rel=1e-3)
    assert free.force[2] == pytest.approx(lag[2], rel=0.02)  # what the tracker has not caught up
    np.testing.assert_allclose(free.force_bias[:2] - f0[:2], 0.0, atol=1e-12)
    np.testing.assert_array_equal(held.force_bias, f0)
    np.testing.assert_array_equal(held.moment_bias_body, m0)
    assert held.force[2] == pytest.approx(drift[2], abs=1e-3)
    assert held.moment[2] == pytest.approx(drift[5], abs=1e-4)


def test_free_follows_no_bias_before_a_tare(model: mujoco.MjModel) -> None:
    sensor = _sensor(model)
    for k in range(100):
        sensor.update(_state(k * DT, BIAS), free=True)
    np.testing.assert_array_equal(sensor.force_bias, 0.0)
    np.testing.assert_array_equal(sensor.moment_bias_body, 0.0)


def test_the_timed_tare_takes_the_first_readings_only(model: mujoco.MjModel) -> None:
    """``tare_time`` 0.05 s: the first 50 readings (t = 0 .. 0.049) tare, later ones are filtered."""
    readings = _readings(np.random.default_rng(5), 50)
    sensor = _sensor(model, tare_time=0.05)
    for k, ft in enumerate(readings):
        sensor.update(_state(k * DT, ft))
    bias = sensor.force_bias.copy()
    np.testing.assert_allclose(sensor.noise_force, readings[:, :3].std(axis=0, ddof=1), rtol=1e-9)
    sensor.update(_state(0.05, BIAS + 1.0))
    np.testing.assert_array_equal(sensor.force_bias, bias)


def test_moving_the_centre_keeps_the_tare_and_the_filtered_moment(model: mujoco.MjModel) -> None:
    """A sensor tared about A and moved to B agrees with one tared about B from the start: the
    same bias, the same reading, and (the filters settled on a steady push) the same moment."""
    quat = euler_to_quat(0.3, -0.2, 0.5)
    a, b = np.array([0.0, -0.07, -0.01]), np.array([0.01, 0.02, 0.12])
    moved, fixed = _sensor(model, a), _sensor(model, b)
    readings = _readings(np.random.default_rng(2), 300)
    for sensor in (moved, fixed):
        _tare(sensor, readings, quat)
    pushed = _state(1.0, BIAS + np.array([1.5, -0.5, 3.0, 0.01, 0.02, -0.005]), quat)
    for k in range(2000):
        for sensor in (moved, fixed):
            sensor.update(pushed._replace(t=1.0 + k * DT))
    expected = moved.moment_about(pushed, b)
    assert np.linalg.norm(expected - moved.moment) > 0.05  # the point matters: a 0.1 N m difference
    moved.move_centre(b, pushed)
    np.testing.assert_array_equal(moved.centre_body, b)
    np.testing.assert_allclose(moved.moment, expected, atol=1e-15)
    np.testing.assert_allclose(moved.moment_bias_body, fixed.moment_bias_body, atol=1e-12)
    np.testing.assert_allclose(moved.moment, fixed.moment, atol=1e-9)
    np.testing.assert_allclose(moved.force, fixed.force, atol=1e-12)
    for x, y in zip(moved.raw(pushed), fixed.raw(pushed), strict=True):
        np.testing.assert_allclose(x, y, atol=1e-12)


# -- the detector ----------------------------------------------------------------------------------------


def test_the_detector_needs_k_on_above_k_off() -> None:
    with pytest.raises(ValueError, match="k_on must exceed k_off, got 2.0 and 2.0"):
        Detector(k_on=2.0, k_off=2.0)


def test_the_detector_switches_on_above_k_on_after_the_hold_and_off_below_k_off() -> None:
    det = Detector(k_on=4.0, k_off=2.0, hold=0.01)
    sigma, level = 0.5, 1.0  # on above 3.0, off below 2.0
    assert det.update(0.000, 3.0, sigma, level) is False  # at the threshold: not above it
    assert det.update(0.001, 3.1, sigma, level) is False  # rising since 0.001
    assert det.update(0.006, 3.1, sigma, level) is False
    assert det.update(0.008, 2.9, sigma, level) is False  # a dip: the hold starts over
    assert det.update(0.009, 3.1, sigma, level) is False
    assert det.update(0.018, 3.1, sigma, level) is False  # 9 ms above
    assert det.update(0.019, 3.1, sigma, level) is True  # 10 ms
    assert det.since == pytest.approx(0.019)
    assert det.update(0.020, 2.5, sigma, level) is True  # between the thresholds: stays on
    assert det.update(0.021, 2.0, sigma, level) is True  # at k_off: not below it
    assert det.update(0.022, 1.99, sigma, level) is False
    assert det.since is None
    assert det.update(0.023, 3.1, sigma, level) is False  # off again: a new hold


def test_the_detector_without_hold_fires_on_the_first_sample_above() -> None:
    det = Detector(k_on=3.0, k_off=1.0)
    assert det.update(0.0, 0.31, 0.1) is True and det.since == 0.0
    det.reset()
    assert (det.on, det.since) == (False, None)


def test_the_detector_rarely_fires_on_filtered_noise(model: mujoco.MjModel) -> None:
    """20 s of Gaussian noise through the task's force filter (30 Hz), tested as the task does
    against the sensor's own ``sigma_force``. Every switch-on is an up-crossing, so a sample
    above ``k_on`` sigma: on average at most ``n Q(k_on)`` of them (0.6 at 4 sigma, 124 at 2.5).
    The task's test (4 sigma held 10 ms, 11 samples above in a row) never fires; without a hold,
    2.5 sigma fires within its bound; a hold divides the switch-ons by the run it needs."""
    rng = np.random.default_rng(1)
    sigma = np.array([0.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    sensor = _sensor(model, force_hz=30.0, resolution=(0.0, 0.0))
    _tare(sensor, _readings(rng, 2000, sigma))
    n, hold = 20000, 0.01
    detectors = {
        "task": Detector(k_on=4.0, k_off=2.0, hold=hold),
        "loose": Detector(k_on=2.5, k_off=1.0),
        "held": Detector(k_on=2.5, k_off=1.0, hold=hold),
    }
    rises = dict.fromkeys(detectors, 0)
    above = 0  # samples above 2.5 sigma
    for k, ft in enumerate(_readings(rng, n, sigma)):
        t = 2.0 + k * DT
        f, _ = sensor.update(_state(t, ft))
        s = float(sensor.sigma_force[2])
        above += bool(f[2] > 2.5 * s)
        for name, det in detectors.items():
            was = det.on
            rises[name] += det.update(t, float(f[2]), s) and not was
    assert float(sensor.sigma_force[2]) == pytest.approx(0.5 * math.sqrt(0.172 / 1.828), rel=0.03)
    assert rises["task"] == 0
    tail = n * 0.5 * math.erfc(2.5 / math.sqrt(2.0))  # n Q(2.5) = 124
    assert 1 <= rises["loose"] <= min(above, tail)
    assert rises["held"] <= above / (round(hold / DT) + 1) and rises["held"] < rises["loose"]


# -- within ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "sigma", "tolerance", "k", "expected"),
    [
        (0.9, 0.1, 1.0, 3.0, True),  # inside the tolerance, the noise narrower
        (-1.0, 0.1, 1.0, 3.0, False),  # |value| at the tolerance: not within (strict)
        (1.2, 0.5, 1.0, 3.0, True),  # outside the tolerance, inside 3 sigma of a wider noise
        (1.6, 0.5, 1.0, 3.0, False),  # outside both
        (1.2, 0.5, 1.0, 2.0, False),  # k = 2: 2 sigma = the tolerance
        (-1.9, 0.5, 0.0, 4.0, True),  # no tolerance: the noise alone
    ],
)
def test_within(value: float, sigma: float, tolerance: float, k: float, expected: bool) -> None:
    assert within(value, sigma, tolerance, k) is expected
