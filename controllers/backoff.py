"""Reversal backoff: an accommodation law that slows down each time its error reverses.

An accommodation law turns its command at a rate proportional to the error it regulates
(``rate = error / D``). On a contact that behaves like a relay — a held peg pressed on a face
reads the same moment about its tip, the normal force times the lever to the rim it stands on,
until its end lies flat, and the opposite moment once it has turned past — a late reading (the
sensor's latency, the moment filter's lag) lets the command run past the point where the error
changes sign, by about ``rate x delay``; the law then turns back at the same rate, and the peg
rocks from rim to rim for ever (a relay with a delay always limit-cycles). Slowing the law by
``factor`` at every reversal shrinks each overshoot by the same factor, so the rocking dies out
geometrically, whatever the delay is; an axis that never reverses (a peg turning on its rim
towards flat) keeps its full rate. A reversal is the error crossing from beyond ``+band`` to
beyond ``-band`` (or the other way), the band widened to 3 standard deviations of the error's
noise where that is wider, so that noise around zero is no reversal.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.controllers.base import InvalidField

__all__ = ["ReversalBackoff", "MAX_BACKOFF", "check_backoff"]

_Vec = NDArray[np.float64]

MAX_BACKOFF = 64.0  # the backoff slows an axis at most this much (six reversals at factor 2)


class ReversalBackoff:
    """Per axis, how much an accommodation law is slowed: ``scale`` (n,), 1 until the error on
    that axis first reverses, times ``factor`` at every reversal (at most :data:`MAX_BACKOFF`).

    Args:
        factor: growth of the scale per reversal (>= 1; 1: never slows).
        band: half-width of the band the error must cross [its unit, e.g. N m].
        size: the number of axes.
    """

    def __init__(self, *, factor: float, band: float, size: int) -> None:
        if not factor >= 1.0:
            raise ValueError(f"factor must be >= 1, got {factor!r}")
        self.factor = factor
        self.band = band
        self.scale = np.ones(size)
        self._side = np.zeros(size)  # the side of the band the error was last seen beyond

    def reset(self, where: NDArray[np.bool_] | None = None) -> None:
        """Full rate again (on the axes ``where``, or all): their regulation starts afresh."""
        if where is None:
            self.scale[:] = 1.0
            self._side[:] = 0.0
        else:
            self.scale[where] = 1.0
            self._side[where] = 0.0

    def update(self, error: _Vec, active: NDArray[np.bool_], sigma: _Vec | float = 0.0) -> _Vec:
        """Count the reversals of ``error`` (n,) on the ``active`` axes (n,), ``sigma`` its
        noise's standard deviation; the scale (n,)."""
        band = np.maximum(self.band, 3.0 * np.asarray(sigma))
        side = np.where(error > band, 1.0, np.where(error < -band, -1.0, 0.0))
        reversed_ = active & (side != 0.0) & (self._side != 0.0) & (side != self._side)
        if self.factor > 1.0 and reversed_.any():
            self.scale[reversed_] = np.minimum(self.scale[reversed_] * self.factor, MAX_BACKOFF)
        self._side = np.where(active & (side != 0.0), side, self._side)
        return self.scale


def check_backoff(component: str, value: float) -> None:
    """A config's ``reversal_backoff`` must be >= 1: a backoff slows down, never speeds up."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 1.0):
        raise InvalidField(component, "reversal_backoff", f"must be >= 1 (1: never), got {value!r}")
