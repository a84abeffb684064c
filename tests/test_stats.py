"""Sweep statistics: Holm correction, exact success tests, rank tests, bootstrap intervals."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import boschloo_exact, mannwhitneyu

from peg_ctrl.experiments.stats import ALPHA, compare_arms, holm, location_test, median_ci, success_test


def test_holm_matches_the_textbook_example() -> None:
    # p = 0.01, 0.04, 0.03, 0.005 -> sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 = 0.02, 0.03, 0.06, 0.04
    # -> monotone: 0.02, 0.03, 0.06, 0.06.
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.01, None, 0.04]) == [pytest.approx(0.02), None, pytest.approx(0.04)]  # None: untested
    assert holm([0.6, 0.7]) == [1.0, 1.0]  # capped
    assert holm([]) == []


def test_success_test_is_boschloo_and_separates_clear_differences() -> None:
    p = success_test(20, 20, 8, 20)
    assert p == pytest.approx(boschloo_exact([[20, 8], [0, 12]]).pvalue)
    assert p < 0.001
    assert success_test(10, 20, 11, 20) > 0.5
    assert success_test(5, 10, 10, 20) == 1.0  # equal rates
    assert success_test(0, 0, 3, 5) is None


def test_location_test_is_mann_whitney() -> None:
    a, b = [1.0, 2.0, 3.0, 4.0, 5.0], [6.0, 7.0, 8.0, 9.0, 10.0]
    assert location_test(a, b) == pytest.approx(mannwhitneyu(a, b, alternative="two-sided").pvalue)
    assert location_test(a, b) < ALPHA
    assert location_test([1.0], b) is None
    assert location_test([2.0, 2.0], [2.0, 2.0, 2.0]) == 1.0


def test_median_ci_covers_the_true_median() -> None:
    rng = np.random.default_rng(1)
    covered = 0
    for k in range(200):
        x = rng.exponential(1.0, size=40)  # true median ln 2
        med, lo, hi = median_ci(x.tolist(), seed=k)
        assert lo <= med <= hi
        covered += lo <= np.log(2) <= hi
    assert 0.88 <= covered / 200 <= 0.99  # nominal 95 %
    assert median_ci([]) == (None, None, None)
    assert median_ci([3.0, 3.0]) == (3.0, 3.0, 3.0)
    assert median_ci([1.0, 2.0, 3.0], seed=5) == median_ci([1.0, 2.0, 3.0], seed=5)  # reproducible


def _rows(
    controller: str, wins: int, n: int, force: float, clearance: float = 1e-4
) -> list[dict[str, object]]:
    return [
        {
            "controller": controller,
            "planner": "ruckig",
            "clearance_m": clearance,
            "status": "success" if i < wins else "failure",
            "peak_contact_force_n": force + 0.1 * i,
            "time_to_insert_s": 1.0 + 0.01 * (i % 3) if i < wins else "",
        }
        for i in range(n)
    ]


def test_compare_arms_finds_the_pair_that_differs() -> None:
    rows = _rows("a", 20, 20, 5.0) + _rows("b", 19, 20, 5.0) + _rows("c", 6, 20, 40.0)
    pairs = {(c.arm_a, c.arm_b): c for c in compare_arms(rows)}
    assert set(pairs) == {("a+ruckig", "b+ruckig"), ("a+ruckig", "c+ruckig"), ("b+ruckig", "c+ruckig")}
    assert pairs[("a+ruckig", "b+ruckig")].differs() == []
    assert pairs[("a+ruckig", "c+ruckig")].differs() == ["success", "peak force"]
    ab = pairs[("a+ruckig", "b+ruckig")]
    assert ab.success_a == "20/20" and ab.success_b == "19/20"
    assert ab.force_median_a == pytest.approx(5.95)
    # Holm over the three pairs: every adjusted p is at least the raw one.
    raw = success_test(20, 20, 6, 20)
    assert pairs[("a+ruckig", "c+ruckig")].p_success >= raw


def test_compare_arms_only_compares_within_a_clearance() -> None:
    rows = _rows("a", 10, 10, 1.0, 1e-3) + _rows("b", 0, 10, 1.0, 1e-4)
    assert compare_arms(rows) == []


def test_held_insertion_times_are_from_first_contact() -> None:
    """Held insertion compares the time from first contact to seated, not from the start."""
    rows = [
        {
            "controller": arm,
            "planner": "ruckig",
            "clearance_m": "0.0001",
            "status": "success",
            "task": "held_insertion",
            "peak_contact_force_n": "10",
            "time_to_insert_s": str(5.0 + 0.01 * i),  # the same in both arms
            "contact_to_seat_s": str(seat + 0.01 * i),
        }
        for arm, seat in (("a", 1.0), ("b", 3.0))
        for i in range(10)
    ]
    (pair,) = compare_arms(rows)
    assert pair.time_median_a == pytest.approx(1.045) and pair.time_median_b == pytest.approx(3.045)
    assert pair.p_time is not None and pair.p_time < ALPHA
