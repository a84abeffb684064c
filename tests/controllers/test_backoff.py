"""The reversal backoff: it counts reversals of an error across a band, and nothing else."""

from __future__ import annotations

import numpy as np
import pytest

from peg_ctrl.controllers.backoff import MAX_BACKOFF, ReversalBackoff


def _feed(
    backoff: ReversalBackoff, errors: list[list[float]], active: np.ndarray | None = None
) -> np.ndarray:
    for e in errors:
        scale = backoff.update(np.array(e), np.ones(len(e), dtype=bool) if active is None else active)
    return scale


def test_each_reversal_across_the_band_multiplies_the_scale() -> None:
    b = ReversalBackoff(factor=2.0, band=0.004, size=2)
    np.testing.assert_array_equal(_feed(b, [[0.02, 0.0], [0.01, 0.0]]), [1.0, 1.0])  # one side only
    np.testing.assert_array_equal(_feed(b, [[-0.005, 0.0]]), [2.0, 1.0])  # crossed to beyond -band
    np.testing.assert_array_equal(_feed(b, [[0.003, 0.0], [-0.003, 0.0]]), [2.0, 1.0])  # inside: none
    np.testing.assert_array_equal(_feed(b, [[0.006, 0.0], [-0.006, 0.0]]), [8.0, 1.0])


def test_noise_wider_than_the_band_widens_it() -> None:
    b = ReversalBackoff(factor=2.0, band=0.004, size=1)
    one = np.ones(1, dtype=bool)
    for e in (0.02, -0.01, 0.01, -0.01):  # then beyond the band, within 3 sigma of 5 mN m noise
        scale = b.update(np.array([e]), one, sigma=0.005)
    np.testing.assert_array_equal(scale, [1.0])
    b.update(np.array([-0.02]), one, sigma=0.005)
    np.testing.assert_array_equal(b.scale, [2.0])


def test_inactive_axes_do_not_count_and_a_reset_restarts_an_axis() -> None:
    b = ReversalBackoff(factor=2.0, band=0.004, size=2)
    _feed(b, [[0.01, 0.01], [-0.01, -0.01]], active=np.array([True, False]))
    np.testing.assert_array_equal(b.scale, [2.0, 1.0])
    b.reset(np.array([True, False]))
    np.testing.assert_array_equal(_feed(b, [[0.01, 0.01]]), [1.0, 1.0])  # no side remembered


def test_the_scale_is_capped_and_factor_one_never_slows() -> None:
    b = ReversalBackoff(factor=2.0, band=0.004, size=1)
    assert _feed(b, [[0.01], [-0.01]] * 20)[0] == MAX_BACKOFF
    never = ReversalBackoff(factor=1.0, band=0.004, size=1)
    assert _feed(never, [[0.01], [-0.01]] * 5)[0] == 1.0
    with pytest.raises(ValueError, match="factor must be >= 1, got 0.5"):
        ReversalBackoff(factor=0.5, band=0.004, size=1)
