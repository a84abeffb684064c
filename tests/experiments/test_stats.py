"""Sweep statistics: Holm correction, Wilson and bootstrap intervals (SciPy, checked against the
formulas), exact success tests, rank tests, the episodes table."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest, boschloo_exact, mannwhitneyu

from peg_ctrl.config import ConfigError
from peg_ctrl.experiments.stats import (
    ALPHA,
    compare_arms,
    episodes_frame,
    holm,
    location_test,
    median_ci,
    success_test,
    wilson_interval,
)


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


def _timed_rows(task: str, strategy: str) -> list[dict[str, str]]:
    return [
        {
            "controller": arm,
            "planner": "ruckig",
            "clearance_m": "0.0001",
            "status": "success",
            "task": task,
            "strategy": strategy,
            "peak_contact_force_n": "10",
            "time_to_insert_s": str(5.0 + 0.01 * i),  # the same in both arms
            "contact_to_seat_s": str(seat + 0.01 * i),
        }
        for arm, seat in (("a", 1.0), ("b", 3.0))
        for i in range(10)
    ]


def test_held_insertion_times_are_from_first_contact() -> None:
    """A task that inserts with a strategy (the held insertion) compares the time from first
    contact to seated, not from the start; whatever the task is called."""
    for task in ("held_insertion", "another_held_task"):
        (pair,) = compare_arms(_timed_rows(task, "spiral"))
        assert pair.time_median_a == pytest.approx(1.045) and pair.time_median_b == pytest.approx(3.045)
        assert pair.p_time is not None and pair.p_time < ALPHA


def test_a_task_without_a_strategy_compares_the_time_to_insert() -> None:
    (pair,) = compare_arms(_timed_rows("pick_and_place", ""))
    assert pair.time_median_a == pytest.approx(5.045) and pair.time_median_b == pytest.approx(5.045)
    assert pair.p_time == pytest.approx(1.0)


# -- SciPy in place of the hand-written intervals: the same numbers -------------------------------
def _wilson_by_hand(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """The score interval as the report used to compute it (Wilson 1927)."""
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


@pytest.mark.parametrize("k, n", [(0, 10), (1, 10), (19, 20), (20, 20), (30, 60), (59, 60), (3, 7)])
def test_wilson_interval_is_scipys_and_matches_the_formula(k: int, n: int) -> None:
    lo, hi = wilson_interval(k, n)
    assert (lo, hi) == pytest.approx(_wilson_by_hand(k, n), abs=1e-8)
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert (lo, hi) == (ci.low, ci.high)


def test_wilson_interval_edges_and_bad_counts() -> None:
    assert wilson_interval(10, 10)[1] == 1.0 and wilson_interval(0, 10)[0] == 0.0  # exactly
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ConfigError, match=r"successes must be in \[0, n=5\], got 6"):
        wilson_interval(6, 5)
    with pytest.raises(ConfigError, match=r"confidence must be in \(0, 1\), got 1.5"):
        wilson_interval(1, 5, confidence=1.5)


def _median_ci_by_hand(x: np.ndarray, seed: int) -> tuple[float, float]:
    """The percentile bootstrap as the report used to compute it."""
    rng = np.random.default_rng(seed)
    medians = np.median(rng.choice(x, size=(2000, len(x)), replace=True), axis=1)
    lo, hi = np.percentile(medians, [2.5, 97.5])
    return float(lo), float(hi)


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_median_ci_is_scipys_bootstrap_with_the_same_numbers(seed: int) -> None:
    x = np.random.default_rng(100 + seed).exponential(10.0, size=25 + seed)
    med, lo, hi = median_ci(x.tolist(), seed=seed)
    assert med == np.median(x)
    assert (lo, hi) == pytest.approx(_median_ci_by_hand(x, seed), rel=1e-12)


def test_holm_matches_the_step_down_loop() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        p = rng.uniform(0.0, 0.2, size=rng.integers(1, 12)).tolist()
        expected, running = [0.0] * len(p), 0.0
        for rank, i in enumerate(np.argsort(p, kind="stable")):
            running = max(running, min(1.0, (len(p) - rank) * p[i]))
            expected[i] = running
        assert holm(p) == pytest.approx(expected)


def test_episodes_frame_reads_csv_strings_as_numbers() -> None:
    rows = [
        {
            "controller": "pd",
            "arm": "",
            "clearance_m": "0.0001",
            "peak_contact_force_n": "5.5",
            "time_to_insert_s": "",
        },
        {
            "controller": "pd",
            "arm": "pd/spiral",
            "clearance_m": "0.0001",
            "peak_contact_force_n": "7",
            "time_to_insert_s": "3.25",
        },
    ]
    df = episodes_frame(rows)
    assert list(df["arm"]) == ["pd", "pd/spiral"]
    assert df["peak_contact_force_n"].tolist() == [5.5, 7.0]
    assert np.isnan(df["time_to_insert_s"][0]) and df["time_to_insert_s"][1] == 3.25
    assert df["clearance_m"].dtype == float
