"""A wrist force/torque sensor as a real one reads: white noise, latency and a drifting bias.

:class:`FTSensorModel` is the configuration (in the manner of Isaac Lab's ``GaussianNoiseCfg``
and ``NoiseModelWithAdditiveBiasCfg``); :class:`FTSensorStream` applies it to the true wrench
(:attr:`peg_ctrl.sim.state.ControlState.ft_wrench`: forces [N], then torques [N m], sensor
frame), read once per control period. The sensor samples at its own ``rate``; what it reports
at control step ``n`` is its last sample, taken at step ``m <= n``::

    reading_n = sample_m = wrench(t_m - latency) + [b_m, 0] + [e_f, e_t]
    b_n = b_(n-1) + N(0, bias_drift^2 dt)          per force channel and control period, b_0 = 0
    e_f ~ N(0, force_noise^2),  e_t ~ N(0, torque_noise^2)   fresh every sample

A sample is taken at the first control step at or after each tick of the sensor's clock
(``k / rate``, the first at the episode's start) and held until the next; ``rate`` 0, or a rate
at or above the control rate, samples every control period (the newest sample is the one read).

The delayed wrench is interpolated linearly between the two readings around ``t_n - latency``
when the latency is not a whole number of periods, and is the first reading before the stream
started. The bias starts at zero: a constant offset is what a tare removes; the drift after it
is not.

Presets (:data:`FT_PRESETS`), with the sources of their numbers:

``ideal``
    The true wrench, unchanged.
``wrist``
    A dedicated wrist F/T sensor. Robotiq FT 300-S (its instruction manual): noise about 0.1 N
    on force and 0.005 N m on torque, a 100 Hz data stream (``rate``; a sample is held for up to
    0.01 s), and 0.01 s of transport latency on top (the FT 300-S's ROS stream shows gaps of
    2-32 ms, ros-industrial-attic/robotiq #124). The drift is an ATI Mini45's, measured on a
    DAQ (hqhan03/VBTS_test, ``docs/measurement_protocol.md``): Fz zero drift 0.12 N in 4 min,
    0.12 / sqrt(240 s) = 0.008 N/sqrt(s), rounded up to 0.01. (The same measurement's white noise, sigma
    0.02/0.02/0.05 N on Fx/Fy/Fz, is below the FT 300-S's.)
``mini45``
    A lab-grade sensor on a fast DAQ: an ATI Mini45 measured at 2 kHz (hqhan03/VBTS_test,
    ``docs/measurement_protocol.md``): white noise sigma 0.02 / 0.02 / 0.05 N on Fx / Fy / Fz
    (the model has one sigma for the three forces: 0.05 N, the largest), torque about 0.5 mN m,
    the same drift as ``wrist`` (0.008 N/sqrt(s), rounded up), 1 ms of latency (our choice: one
    period of a 1 kHz controller's DAQ read).
``forge``
    The F/T observation noise of FORGE (Isaac Lab, ``source/isaaclab_tasks/isaaclab_tasks/
    direct/forge/forge_env_cfg.py``, ``ForgeObsRandCfg.ft_force``): sigma 1.0 N on each force
    channel at every step, no bias, no delay; 1 kHz, the rate of the Franka arm's external wrench
    estimate that FORGE's real-robot policy reads. FORGE observes no torque; 0.01 N m keeps a real
    sensor's torque/force noise ratio of about 1/100 m. (FORGE also smooths the force with an
    exponential moving average before the noise; this preset does not.)

For scale: an ATI Axia80 delivers its readings over Ethernet within 28 ms (its Ethernet
manual), so latencies of a few control periods are realistic. docs/sensing.md has the table.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import ConfigError, UnknownComponent

__all__ = ["DelayLine", "FTSensorModel", "FTSensorStream", "FT_DOMAIN_FIELDS", "FT_PRESETS", "ft_preset"]

#: The ``domain.`` fields of an episode's config that set an :class:`FTSensorModel`, in its order.
FT_DOMAIN_FIELDS = ("force_noise", "torque_noise", "ft_latency", "ft_bias_drift", "ft_rate")

_Wrench = NDArray[np.float64]

# A latency within this fraction of a whole number of periods is that number (0.01 / 0.001 is
# 10.000000000000002, not 10 periods and a 2e-15 interpolation).
_WHOLE_PERIODS_TOL = 1e-9


@dataclasses.dataclass(frozen=True)
class FTSensorModel:
    """How a wrist force/torque sensor corrupts the true wrench. All zero: an ideal sensor."""

    force_noise: float = 0.0  # sigma of white noise on each force channel, per reading [N]
    torque_noise: float = 0.0  # sigma of white noise on each torque channel, per reading [N m]
    latency: float = 0.0  # the reading arrives this late [s]
    bias_drift: float = 0.0  # random walk of the force bias: sigma = bias_drift * sqrt(t) [N/sqrt(s)]
    rate: float = 0.0  # the sensor's own sample rate [Hz]; 0: one sample per control period

    def __post_init__(self) -> None:
        for field, unit in (
            ("force_noise", "N"),
            ("torque_noise", "N m"),
            ("latency", "s"),
            ("bias_drift", "N/sqrt(s)"),
            ("rate", "Hz"),
        ):
            value = getattr(self, field)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"{field} must be finite and >= 0 {unit}, got {value!r}")

    @property
    def noisy(self) -> bool:
        """Whether the model changes a reading at all (a rate alone does: it holds samples)."""
        return self != IDEAL


IDEAL = FTSensorModel()

FT_PRESETS: dict[str, FTSensorModel] = {
    "ideal": IDEAL,
    "wrist": FTSensorModel(force_noise=0.1, torque_noise=0.005, latency=0.01, bias_drift=0.01, rate=100.0),
    "mini45": FTSensorModel(
        force_noise=0.05, torque_noise=0.0005, latency=0.001, bias_drift=0.01, rate=2000.0
    ),
    "forge": FTSensorModel(force_noise=1.0, torque_noise=0.01, rate=1000.0),
}


def ft_preset(name: str, *, where: str = "") -> FTSensorModel:
    """The preset called ``name``; an unknown name lists the known ones (naming the field
    ``where`` it came from, if given)."""
    try:
        return FT_PRESETS[name]
    except KeyError:
        raise UnknownComponent("F/T sensor preset", name, FT_PRESETS, where=where) from None


class DelayLine:
    """A sampled signal ``latency`` [s] late: one sample of ``width`` channels per period ``dt``
    [s], in a preallocated ring of the last samples.

    A latency that is a whole number of periods returns the sample that many periods back; in
    between, the two samples around it are interpolated linearly. Until :meth:`push` has been
    called that often, the samples before it are the one :meth:`reset` gave. The sensor's
    readings (:class:`FTSensorStream`) and a controller's prediction of them
    (:class:`peg_ctrl.sim.sensing.WrenchPredictor`) are delayed by the same rule.
    """

    def __init__(self, *, latency: float, dt: float, width: int) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f"dt must be finite and > 0 s, got {dt!r}")
        if not (math.isfinite(latency) and latency >= 0):
            raise ConfigError(f"latency must be finite and >= 0 s, got {latency!r}")
        periods = latency / dt
        whole = round(periods)
        if abs(periods - whole) <= _WHOLE_PERIODS_TOL * max(1.0, periods):
            self._lag, self._frac = int(whole), 0.0
        else:
            self._lag, self._frac = math.floor(periods), periods - math.floor(periods)
        # The samples back to lag (and lag + 1 to interpolate); none needed without latency.
        size = self._lag + (2 if self._frac > 0 else 1)
        self._ring = np.zeros((size, width)) if size > 1 else None
        self._head = 0  # row of the newest sample
        self._scratch = np.zeros(width)

    def reset(self, first: NDArray[np.float64], where: NDArray[np.bool_] | None = None) -> None:
        """Fill the line with ``first`` (width,): every sample before the next :meth:`push` was
        ``first``; with ``where`` (width,), on those channels only."""
        if self._ring is None:
            return
        if where is None:
            self._ring[:] = first
            self._head = 0
        else:
            self._ring[:, where] = np.asarray(first)[where]

    def push(self, sample: NDArray[np.float64]) -> NDArray[np.float64]:
        """Add this period's ``sample`` (width,); the signal ``latency`` ago (a new array)."""
        ring = self._ring
        if ring is None:
            return np.array(sample, dtype=np.float64)
        n = len(ring)
        head = self._head = (self._head + 1) % n
        ring[head] = sample
        out = ring[(head - self._lag) % n].copy()
        if self._frac > 0:
            # (1 - f) * sample(lag periods ago) + f * sample(lag + 1 periods ago)
            out *= 1.0 - self._frac
            np.multiply(ring[(head - self._lag - 1) % n], self._frac, out=self._scratch)
            out += self._scratch
        return out


class FTSensorStream:
    """One episode's F/T readings through ``model``, one per control period ``dt`` [s], from
    ``rng``.

    Call :meth:`reset` with the first true wrench, then :meth:`apply` once per control period.
    The delay line is a :class:`DelayLine`; an ideal model returns its input untouched and draws
    nothing. The draws per control period: the bias's step (if it drifts), then, when the sensor
    samples, the white noise; a sensor that samples every period draws exactly as one without a
    rate.
    """

    def __init__(self, model: FTSensorModel, *, dt: float, rng: np.random.Generator) -> None:
        self._delay = DelayLine(latency=model.latency, dt=dt, width=6)  # checks dt
        self.model = model
        self.dt = dt
        self.rng = rng
        self._ideal = not model.noisy
        self._bias = np.zeros(3)  # on the force channels [N]
        # One draw per reading: the bias's step (if it drifts), then the white noise of the
        # channels that have any (forces 0-2, torques 3-5), each scaled by its sigma.
        sigma = np.array([model.force_noise] * 3 + [model.torque_noise] * 3)
        noisy = np.flatnonzero(sigma > 0)
        self._lo, self._hi = (int(noisy[0]), int(noisy[-1]) + 1) if noisy.size else (0, 0)
        walk = 3 if model.bias_drift > 0 else 0
        step = model.bias_drift * math.sqrt(dt)  # sigma of one step of the walk [N]
        self._scale = np.concatenate([np.full(walk, step), sigma[self._lo : self._hi]])
        self._z = np.zeros(self._scale.size)
        self._z_bias, self._z_noise = self._z[:walk], self._z[walk:]  # views
        # The sample clock, in control periods: a sample every `_every` periods (0: every one).
        self._every = 1.0 / (model.rate * dt) if model.rate > 0 else 0.0
        self._held = self._every > 1.0 + _WHOLE_PERIODS_TOL
        self._n = 0  # control periods since reset
        self._next = 0.0  # the next tick of the sensor's clock [periods]
        self._sample = np.zeros(6)

    @property
    def bias(self) -> _Wrench:
        """The force bias now (3,) [N] (a copy)."""
        return self._bias.copy()

    def reset(self, first_reading: _Wrench) -> None:
        """Start an episode: the delay line holds ``first_reading`` (6,) (the true wrench at the
        start), the bias is zero."""
        self._delay.reset(first_reading)
        self._bias[:] = 0.0
        self._n, self._next = 0, 0.0

    def apply(self, true_wrench: _Wrench) -> _Wrench:
        """What the sensor reports for the true wrench (6,) of this step: a new (6,) array
        (``true_wrench`` itself for an ideal model)."""
        if self._ideal:
            return true_wrench
        out = self._delay.push(true_wrench)
        if self._held:
            return self._apply_held(out)
        if self._z.size:
            self.rng.standard_normal(out=self._z)
            self._z *= self._scale
            if self._z_bias.size:
                self._bias += self._z_bias
                out[:3] += self._bias
            if self._z_noise.size:
                out[self._lo : self._hi] += self._z_noise
        return out

    def _apply_held(self, delayed: _Wrench) -> _Wrench:
        """A sensor slower than the control loop: the bias walks every period; a new sample
        (``delayed`` plus the bias and fresh noise) at the first period at or after each tick of
        its clock, else the last sample again."""
        n, self._n = self._n, self._n + 1
        bias = self._z_bias
        if bias.size:
            self.rng.standard_normal(out=bias)
            bias *= self._scale[: bias.size]
            self._bias += bias
        if n + _WHOLE_PERIODS_TOL < self._next:
            return self._sample.copy()
        while self._next <= n + _WHOLE_PERIODS_TOL:
            self._next += self._every
        delayed[:3] += self._bias
        noise = self._z_noise
        if noise.size:
            self.rng.standard_normal(out=noise)
            noise *= self._scale[bias.size :]
            delayed[self._lo : self._hi] += noise
        self._sample[:] = delayed
        return delayed
