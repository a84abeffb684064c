"""The contact force an episode reports, measured so that it is the contact's and not the solver's.

A physics step's contact force is what the constraint solver returned for that step. Where a
contact appears under a slide, MuJoCo's convex soft contact answers with a one-step spike that
throws the peg off (docs/physics.md, "Cross-check against Drake"), and a single step's value is
then the solver's more than the contact's. The force *sustained* over a window is the momentum
the contact gave the peg in that window divided by its length: a short spike counts for what it
did, not for its height.

:func:`sustained_peak` is the largest mean of a force trace over any window of the given length;
:class:`SustainedPeak` computes the same over a trace that arrives in pieces (an episode's
physics steps, one control period at a time), bit for bit.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

__all__ = ["sustained_peak", "SustainedPeak", "window_steps", "SUSTAIN_WINDOW"]

#: The window of the force the studies report [s]: the window at which MuJoCo, with the peg's
#: friction given 5 ms, agrees with Drake's lagged contact in every situation of the cross-check
#: (docs/physics.md, "Cross-check against Drake"); a 100 Hz wrist sensor's sample.
SUSTAIN_WINDOW = 0.010


def window_steps(window: float, dt: float) -> int:
    """Physics steps in a window of ``window`` [s] at a step of ``dt`` [s] (at least 1)."""
    if not (math.isfinite(window) and window > 0.0):
        raise ValueError(f"window must be finite and > 0 s, got {window!r}")
    return max(1, round(window / dt))


def sustained_peak(force: NDArray[np.float64], dt: float, window: float) -> float:
    """The largest mean [N] of ``force`` (n,) [N], sampled every ``dt`` [s], over ``window`` [s]
    of consecutive steps; a trace shorter than the window counts as padded with zeros."""
    meter = SustainedPeak(dt, window)
    meter.extend(np.asarray(force, dtype=float).tolist())
    return meter.peak


class SustainedPeak:
    """:func:`sustained_peak` over a trace given piece by piece: :meth:`extend` with each piece's
    forces [N]; :attr:`peak` is the largest window mean so far [N]."""

    def __init__(self, dt: float, window: float) -> None:
        self.n = window_steps(window, dt)
        self.reset()

    def reset(self) -> None:
        self._window: deque[float] = deque([0.0] * self.n, maxlen=self.n)
        self.peak = 0.0

    def extend(self, forces: Iterable[float]) -> None:
        """Add each force [N], one physics step after another."""
        # An exact sum of each window (no running sum to drift), so the peak does not depend
        # on how the trace was cut into pieces.
        window, peak, n = self._window, self.peak, self.n
        for f in forces:
            window.append(f)
            if f > 0.0 or peak == 0.0:
                mean = math.fsum(window) / n
                if mean > peak:
                    peak = mean
        self.peak = peak
