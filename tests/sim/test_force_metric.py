"""The force the studies report: the largest mean peg-block force over a window."""

from __future__ import annotations

import numpy as np
import pytest

from peg_ctrl.sim.force_metric import SUSTAIN_WINDOW, SustainedPeak, sustained_peak, window_steps


def test_a_one_step_spike_counts_for_its_momentum_over_the_window() -> None:
    dt = 0.5e-3
    force = np.zeros(200)
    force[50] = 40.0  # a 40 N spike of one step: 20 mN s
    assert sustained_peak(force, dt, SUSTAIN_WINDOW) == pytest.approx(40.0 * dt / SUSTAIN_WINDOW)  # 2 N


def test_a_steady_force_is_its_own_sustained_force() -> None:
    assert sustained_peak(np.full(100, 3.5), 1e-3, 0.01) == pytest.approx(3.5, abs=1e-15)


def test_it_is_the_largest_moving_mean_of_the_trace() -> None:
    rng = np.random.default_rng(0)
    force = rng.exponential(2.0, 1000) * (rng.random(1000) < 0.1)
    n = window_steps(0.01, 0.5e-3)
    means = np.convolve(force, np.ones(n) / n, mode="full")[: len(force)]  # zeros before the start
    assert sustained_peak(force, 0.5e-3, 0.01) == pytest.approx(means.max(), rel=1e-12)


def test_a_trace_in_pieces_gives_the_same_peak_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    force = rng.exponential(5.0, 3000) * (rng.random(3000) < 0.2)
    meter = SustainedPeak(0.5e-3, SUSTAIN_WINDOW)
    cuts = np.sort(rng.choice(np.arange(1, 3000), 150, replace=False))
    for piece in np.split(force, cuts):
        meter.extend(piece.tolist())
    assert meter.peak == sustained_peak(force, 0.5e-3, SUSTAIN_WINDOW)
    meter.reset()
    assert meter.peak == 0.0


def test_a_window_shorter_than_a_step_is_one_step() -> None:
    assert window_steps(1e-4, 1e-3) == 1
    assert window_steps(SUSTAIN_WINDOW, 0.5e-3) == 20


@pytest.mark.parametrize("window", [0.0, -0.01, float("nan"), float("inf")])
def test_a_bad_window_is_refused(window: float) -> None:
    with pytest.raises(ValueError, match="window must be finite and > 0 s"):
        SustainedPeak(1e-3, window)
