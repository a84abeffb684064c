"""The F/T sensor model: noise per channel, latency, bias drift, presets and validation."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from peg_ctrl.errors import ConfigError, UnknownComponent
from peg_ctrl.sim.ft_model import FT_PRESETS, DelayLine, FTSensorModel, FTSensorStream, ft_preset

WRENCH = np.array([1.0, -2.0, 3.0, 0.1, -0.2, 0.3])


def _readings(model: FTSensorModel, true: np.ndarray, *, dt: float = 0.001, seed: int = 0) -> np.ndarray:
    """What a fresh stream reports for the true wrenches ``true`` (n, 6), started at ``true[0]``."""
    stream = FTSensorStream(model, dt=dt, rng=np.random.default_rng(seed))
    stream.reset(true[0])
    return np.array([stream.apply(w) for w in true])


def _delayed(true: np.ndarray, lag_periods: float) -> np.ndarray:
    """Independent reference: each channel of ``true`` (one row per period) ``lag_periods``
    late, linearly interpolated, the first row before the start."""
    n = np.arange(len(true), dtype=float)
    return np.stack([np.interp(n - lag_periods, n, true[:, c]) for c in range(6)], axis=1)


def test_white_noise_has_the_configured_sigma_on_each_channel() -> None:
    model = FTSensorModel(force_noise=0.1, torque_noise=0.005)
    n = 20_000
    noise = _readings(model, np.tile(WRENCH, (n, 1))) - WRENCH
    # 20,000 readings: the standard deviation's relative standard error is 1/sqrt(2n) = 0.5 %;
    # 3 % is six of them.
    sigma = np.array([0.1] * 3 + [0.005] * 3)
    np.testing.assert_allclose(noise.std(axis=0), sigma, rtol=0.03)
    assert (np.abs(noise.mean(axis=0)) < 4 * sigma / math.sqrt(n)).all()  # zero mean, to 4 SE
    # Independent channels: no correlation between any two of them.
    corr = np.corrcoef(noise.T) - np.eye(6)
    assert np.abs(corr).max() < 0.04


@pytest.mark.parametrize(
    ("model", "untouched"),
    [
        (FTSensorModel(force_noise=0.5), slice(3, 6)),
        (FTSensorModel(torque_noise=0.05), slice(0, 3)),
        (FTSensorModel(bias_drift=0.5), slice(3, 6)),
    ],
    ids=["force-noise", "torque-noise", "bias-drift"],
)
def test_forces_and_torques_get_only_their_own_noise(model: FTSensorModel, untouched: slice) -> None:
    readings = _readings(model, np.tile(WRENCH, (500, 1)))
    np.testing.assert_array_equal(readings[:, untouched], np.tile(WRENCH[untouched], (500, 1)))
    noisy = slice(0, 3) if untouched.start == 3 else slice(3, 6)
    assert (readings[1:, noisy] != WRENCH[noisy]).all()


def test_a_step_in_the_wrench_is_reported_exactly_the_latency_later() -> None:
    dt = 0.001
    true = np.zeros((40, 6))
    true[10:] = WRENCH  # the step, at reading 10
    # 0.01 / 0.001 is 10.000000000000002 in floating point: still exactly 10 readings late.
    readings = _readings(FTSensorModel(latency=0.01), true, dt=dt)
    np.testing.assert_array_equal(readings[:20], 0.0)
    np.testing.assert_array_equal(readings[20:], np.tile(WRENCH, (20, 1)))


@pytest.mark.parametrize("periods", [0.0, 0.4, 1.0, 2.25, 3.0, 7.5])
def test_latency_matches_linear_interpolation_of_the_past_readings(periods: float) -> None:
    dt = 0.005
    true = np.random.default_rng(1).normal(size=(60, 6)).cumsum(axis=0)
    readings = _readings(FTSensorModel(latency=periods * dt), true, dt=dt)
    np.testing.assert_allclose(readings, _delayed(true, periods), rtol=0, atol=1e-12)


def test_a_non_whole_latency_interpolates_a_step() -> None:
    dt = 0.002
    true = np.zeros((12, 6))
    true[4:] = WRENCH
    readings = _readings(FTSensorModel(latency=2.25 * dt), true, dt=dt)
    np.testing.assert_array_equal(readings[:6], 0.0)  # reading 5 reports 2.75: before the step
    np.testing.assert_array_equal(readings[6], 0.75 * WRENCH)  # 3.75: a quarter before reading 4
    np.testing.assert_array_equal(readings[7:], np.tile(WRENCH, (5, 1)))


def test_the_delay_line_starts_with_the_first_reading() -> None:
    stream = FTSensorStream(FTSensorModel(latency=0.05), dt=0.01, rng=np.random.default_rng(0))
    stream.reset(WRENCH)
    first = [stream.apply(np.zeros(6)) for _ in range(5)]
    np.testing.assert_array_equal(first, np.tile(WRENCH, (5, 1)))
    np.testing.assert_array_equal(stream.apply(np.zeros(6)), 0.0)
    stream.reset(-WRENCH)  # a new episode forgets the old one
    np.testing.assert_array_equal(stream.apply(np.zeros(6)), -WRENCH)


def test_the_bias_random_walk_grows_with_the_square_root_of_time() -> None:
    drift, dt, streams = 0.2, 0.01, 2000
    rng = np.random.default_rng(7)
    checkpoints = {25: [], 100: []}  # readings: 0.25 s and 1 s
    for _ in range(streams):
        stream = FTSensorStream(FTSensorModel(bias_drift=drift), dt=dt, rng=rng)
        stream.reset(WRENCH)
        for i in range(1, 101):
            reading = stream.apply(WRENCH)
            if i in checkpoints:
                checkpoints[i].append(reading[:3] - WRENCH[:3])
                np.testing.assert_allclose(reading[:3] - WRENCH[:3], stream.bias, atol=1e-12)
        np.testing.assert_array_equal(reading[3:], WRENCH[3:])  # no bias on the torques
    for i, biases in checkpoints.items():
        b = np.asarray(biases).ravel()  # 6000 independent samples (3 channels per stream)
        # The sample variance of 6000 normal samples has a relative standard error of
        # sqrt(2 / 5999) = 1.8 %; 6 % is 3.3 of them (p ~ 0.001 to fail by chance).
        assert b.var() == pytest.approx(drift**2 * i * dt, rel=0.06), i
        assert abs(b.mean()) < 4 * drift * math.sqrt(i * dt / b.size)


def test_an_ideal_model_returns_the_input_and_draws_nothing() -> None:
    rng = np.random.default_rng(3)
    before = rng.bit_generator.state
    stream = FTSensorStream(FTSensorModel(), dt=0.001, rng=rng)
    stream.reset(WRENCH)
    wrench = WRENCH.copy()
    for _ in range(10):
        assert stream.apply(wrench) is wrench
    np.testing.assert_array_equal(wrench, WRENCH)
    assert rng.bit_generator.state == before


def test_latency_alone_draws_nothing_and_leaves_the_input_alone() -> None:
    rng = np.random.default_rng(3)
    before = rng.bit_generator.state
    stream = FTSensorStream(FTSensorModel(latency=0.0025), dt=0.001, rng=rng)
    stream.reset(WRENCH)
    wrench = 2.0 * WRENCH
    out = stream.apply(wrench)
    assert out is not wrench
    np.testing.assert_array_equal(wrench, 2.0 * WRENCH)
    assert rng.bit_generator.state == before


def test_the_same_seed_gives_the_same_readings() -> None:
    true = np.random.default_rng(2).normal(size=(200, 6))
    wrist = FT_PRESETS["wrist"]
    a, b = _readings(wrist, true, dt=0.005, seed=11), _readings(wrist, true, dt=0.005, seed=11)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, _readings(wrist, true, dt=0.005, seed=12))


def test_the_presets() -> None:
    assert FT_PRESETS == {
        "ideal": FTSensorModel(force_noise=0.0, torque_noise=0.0, latency=0.0, bias_drift=0.0),
        "wrist": FTSensorModel(
            force_noise=0.1, torque_noise=0.005, latency=0.01, bias_drift=0.01, rate=100.0
        ),
        "mini45": FTSensorModel(
            force_noise=0.05, torque_noise=0.0005, latency=0.001, bias_drift=0.01, rate=2000.0
        ),
        "forge": FTSensorModel(force_noise=1.0, torque_noise=0.01, latency=0.0, bias_drift=0.0, rate=1000.0),
    }
    assert [name for name, m in FT_PRESETS.items() if m.noisy] == ["wrist", "mini45", "forge"]
    assert ft_preset("forge") is FT_PRESETS["forge"]


def test_an_unknown_preset_lists_the_known_ones() -> None:
    message = "x.ft: unknown F/T sensor preset 'nope'; known: forge, ideal, mini45, wrist"
    with pytest.raises(UnknownComponent, match=f"^{re.escape(message)}$"):
        ft_preset("nope", where="x.ft")


@pytest.mark.parametrize(
    ("field", "unit"),
    [
        ("force_noise", "N"),
        ("torque_noise", "N m"),
        ("latency", "s"),
        ("bias_drift", "N/sqrt(s)"),
        ("rate", "Hz"),
    ],
)
@pytest.mark.parametrize("value", [-0.1, math.nan, math.inf])
def test_a_bad_value_is_refused_naming_the_field_and_the_range(field: str, unit: str, value: float) -> None:
    message = f"{field} must be finite and >= 0 {unit}, got {value!r}"
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        FTSensorModel(**{field: value})


@pytest.mark.parametrize("dt", [0.0, -0.001, math.nan])
def test_a_bad_reading_period_is_refused(dt: float) -> None:
    with pytest.raises(ConfigError, match=r"^dt must be finite and > 0 s"):
        FTSensorStream(FT_PRESETS["wrist"], dt=dt, rng=np.random.default_rng(0))


# -- the sensor's own rate: a sample held between ticks of its clock ----------------------------


def test_a_100_hz_sensor_read_at_1_khz_holds_each_sample_for_ten_periods() -> None:
    true = np.random.default_rng(3).normal(size=(200, 6))
    model = FTSensorModel(force_noise=0.1, torque_noise=0.005, rate=100.0)
    readings = _readings(model, true, dt=0.001, seed=4)
    blocks = readings.reshape(20, 10, 6)
    np.testing.assert_array_equal(blocks, np.repeat(blocks[:, :1], 10, axis=1))  # held
    noise = blocks[:, 0, :3] - true[::10, :3]  # each sample is the wrench at its tick plus noise
    assert np.all(np.abs(noise) < 0.5) and 0.05 < noise.std() < 0.2
    assert len(np.unique(readings[:, 0])) == 20


def test_held_noise_averages_ten_times_fewer_samples() -> None:
    """The point of the rate: a second of 1 kHz readings from a 100 Hz sensor averages 100
    independent samples, not 1000, so its mean is sqrt(10) times noisier."""
    true = np.zeros((1000, 6))
    means = {
        rate: np.std(
            [
                _readings(FTSensorModel(force_noise=1.0, rate=rate), true, dt=0.001, seed=s)[:, 2].mean()
                for s in range(200)
            ]
        )
        for rate in (0.0, 100.0)
    }
    assert means[0.0] == pytest.approx(1.0 / math.sqrt(1000), rel=0.15)
    assert means[100.0] == pytest.approx(1.0 / math.sqrt(100), rel=0.15)


@pytest.mark.parametrize("rate", [1000.0, 5000.0])
def test_a_rate_at_or_above_the_control_rate_reads_as_no_rate(rate: float) -> None:
    true = np.random.default_rng(5).normal(size=(100, 6))
    wrist = FT_PRESETS["wrist"]
    fast = dataclasses.replace(wrist, rate=rate)
    np.testing.assert_array_equal(
        _readings(fast, true, dt=0.001, seed=6),
        _readings(dataclasses.replace(wrist, rate=0.0), true, dt=0.001, seed=6),
    )


def test_a_held_sample_is_late_by_its_latency_and_carries_the_bias_of_its_tick() -> None:
    true = np.zeros((40, 6))
    true[:, 2] = np.arange(40.0)  # a ramp: the reading tells which period it was sampled in
    model = FTSensorModel(latency=0.003, rate=250.0)  # a sample every 4 periods, 3 periods late
    readings = _readings(model, true, dt=0.001, seed=0)[:, 2]
    expected = np.maximum(0.0, np.floor(np.arange(40) / 4) * 4 - 3)
    np.testing.assert_array_equal(readings, expected)


def test_a_rate_that_is_not_a_whole_number_of_periods_samples_at_the_first_period_after_each_tick() -> None:
    true = np.zeros((30, 6))
    true[:, 0] = np.arange(30.0)
    readings = _readings(FTSensorModel(rate=400.0), true, dt=0.001, seed=0)[:, 0]  # ticks every 2.5 periods
    assert sorted(set(readings.tolist())) == [0, 3, 5, 8, 10, 13, 15, 18, 20, 23, 25, 28]


# -- the delay line the stream and the wrench predictor share -----------------------------------


@pytest.mark.parametrize("periods", [0.0, 0.4, 3.0, 7.5])
def test_the_delay_line_delays_any_width_like_the_reference(periods: float) -> None:
    dt = 0.002
    signal = np.random.default_rng(2).normal(size=(40, 2)).cumsum(axis=0)
    line = DelayLine(latency=periods * dt, dt=dt, width=2)
    line.reset(signal[0])
    out = np.array([line.push(x) for x in signal])
    n = np.arange(len(signal), dtype=float)
    expected = np.stack([np.interp(n - periods, n, signal[:, c]) for c in range(2)], axis=1)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)


def test_the_delay_line_can_forget_some_channels() -> None:
    """``reset(value, where)``: those channels have been ``value`` for ever, the others keep
    their history."""
    line = DelayLine(latency=0.003, dt=0.001, width=3)
    line.reset(np.zeros(3))
    for k in range(1, 4):
        line.push(np.full(3, float(k)))  # 1, 2, 3
    line.reset(np.array([9.0, 9.0, 9.0]), np.array([False, True, False]))
    np.testing.assert_array_equal(line.push(np.full(3, 4.0)), [1.0, 9.0, 1.0])
    np.testing.assert_array_equal(line.push(np.full(3, 5.0)), [2.0, 9.0, 2.0])


@pytest.mark.parametrize("latency", [-0.001, math.nan, math.inf])
def test_a_bad_latency_is_refused(latency: float) -> None:
    with pytest.raises(ConfigError, match=r"^latency must be finite and >= 0 s"):
        DelayLine(latency=latency, dt=0.001, width=6)
