"""Statistics of a sweep: which arms (controller x planner) differ, and by how much.

- Success: Wilson 95 % intervals per arm (:func:`wilson_interval`, ``scipy.stats.binomtest``);
  pairwise Boschloo exact tests (two-sided, more powerful than Fisher's for 2x2 tables with fixed
  group sizes), Holm-corrected over all pairs compared at one clearance.
- Peak force and time to insert (for held insertion: from first contact to seated): the median
  with a 95 % bootstrap interval (percentile method, fixed seed, ``scipy.stats.bootstrap``) per
  arm; pairwise two-sided Mann-Whitney U tests, Holm-corrected likewise.

Every p-value reported is the Holm-adjusted one; a pair "differs" in a metric when it is below
``ALPHA``. Nothing is tested with fewer than two samples per side (the entry is then None).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from peg_ctrl.errors import ConfigError

__all__ = [
    "ALPHA",
    "holm",
    "wilson_interval",
    "success_test",
    "location_test",
    "median_ci",
    "episodes_frame",
    "PairComparison",
    "compare_arms",
]

ALPHA = 0.05
_BOOTSTRAP_RESAMPLES = 2000


def holm(p_values: Sequence[float | None]) -> list[float | None]:
    """Holm-Bonferroni adjusted p-values (step-down, monotone, capped at 1); None stays None.

    The ``i``-th smallest of ``m`` p-values is multiplied by ``m - i`` and the running maximum
    taken (SciPy's ``false_discovery_control`` offers only the Benjamini-Hochberg/Yekutieli
    procedures, which control a different error rate).
    """
    tested = [i for i, p in enumerate(p_values) if p is not None]
    adjusted: list[float | None] = [None] * len(p_values)
    if not tested:
        return adjusted
    p = np.array([p_values[i] for i in tested], dtype=float)
    order = np.argsort(p, kind="stable")
    m = len(p)
    scaled = np.minimum(1.0, (m - np.arange(m)) * p[order])
    for rank, value in zip(order, np.maximum.accumulate(scaled), strict=True):
        adjusted[tested[rank]] = float(value)
    return adjusted


def wilson_interval(successes: int, n: int, *, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval (low, high) of a success rate, as fractions in [0, 1].

    ``successes`` of ``n`` episodes; ``confidence`` level in (0, 1). With no episodes the
    interval is the whole range (0, 1).

    Raises:
        ConfigError: ``successes`` is not in [0, n] or ``confidence`` not in (0, 1).
    """
    from scipy.stats import binomtest

    if not 0 <= successes <= n:
        raise ConfigError(f"successes must be in [0, n={n}], got {successes}")
    if not 0.0 < confidence < 1.0:
        raise ConfigError(f"confidence must be in (0, 1), got {confidence}")
    if n == 0:
        return (0.0, 1.0)
    ci = binomtest(int(successes), int(n)).proportion_ci(confidence_level=confidence, method="wilson")
    return (float(ci.low), float(ci.high))


def success_test(wins_a: int, n_a: int, wins_b: int, n_b: int) -> float | None:
    """Two-sided Boschloo exact test p-value for two success counts (None if a side is empty)."""
    from scipy.stats import boschloo_exact

    if n_a < 1 or n_b < 1:
        return None
    if wins_a * n_b == wins_b * n_a:  # equal rates: nothing to test (and the test returns nan)
        return 1.0
    table = [[wins_a, wins_b], [n_a - wins_a, n_b - wins_b]]
    p = float(boschloo_exact(table, alternative="two-sided").pvalue)
    return min(1.0, p) if math.isfinite(p) else 1.0


def location_test(a: Sequence[float], b: Sequence[float]) -> float | None:
    """Two-sided Mann-Whitney U p-value (None with fewer than two values on a side)."""
    from scipy.stats import mannwhitneyu

    if len(a) < 2 or len(b) < 2:
        return None
    if len(set(a) | set(b)) == 1:  # all equal: no difference to find
        return 1.0
    return float(mannwhitneyu(a, b, alternative="two-sided").pvalue)


def median_ci(values: Sequence[float], *, seed: int = 0) -> tuple[float | None, float | None, float | None]:
    """(median, low, high): the median and its 95 % percentile-bootstrap interval (2000
    resamples drawn from ``default_rng(seed)``), in the unit of ``values``; non-finite and None
    values are left out."""
    from scipy.stats import bootstrap

    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if len(x) == 0:
        return None, None, None
    med = float(np.median(x))
    if len(x) < 2 or np.all(x == x[0]):  # no spread: SciPy would warn and return nan
        return med, med, med
    ci = bootstrap(
        (x,),
        np.median,
        n_resamples=_BOOTSTRAP_RESAMPLES,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(seed),
    ).confidence_interval
    return med, float(ci.low), float(ci.high)


def episodes_frame(rows: Sequence[dict[str, Any]] | Any) -> Any:
    """``episodes.csv`` rows (dicts of strings or numbers, or a DataFrame) as a pandas DataFrame
    with the numeric metric columns as floats (blank: NaN) and an ``arm`` column (the row's
    ``arm``, else its ``controller``)."""
    import pandas as pd

    df = rows.copy() if isinstance(rows, pd.DataFrame) else pd.DataFrame(list(rows))
    arm = df["arm"] if "arm" in df else pd.Series("", index=df.index)
    df["arm"] = [
        str(a) if isinstance(a, str) and a else str(c) for a, c in zip(arm, df["controller"], strict=True)
    ]
    for column in _NUMERIC:
        if column in df:
            df[column] = pd.to_numeric(df[column].replace("", np.nan), errors="coerce").astype(float)
    return df


# Metric columns of episodes.csv read as numbers.
_NUMERIC = (
    "clearance_m",
    "peak_contact_force_n",
    "time_to_insert_s",
    "contact_to_seat_s",
    "contact_impulse_ns",
)


@dataclasses.dataclass(frozen=True)
class PairComparison:
    """Two arms at one clearance: raw effect sizes and Holm-adjusted p-values."""

    clearance_m: float
    arm_a: str
    arm_b: str
    success_a: str  # "k/n"
    success_b: str
    p_success: float | None
    force_median_a: float | None  # [N]
    force_median_b: float | None
    p_force: float | None
    time_median_a: float | None  # [s], successful episodes only
    time_median_b: float | None
    p_time: float | None

    def differs(self) -> list[str]:
        """The metrics in which the pair differs at ``ALPHA``."""
        return [
            name
            for name, p in (("success", self.p_success), ("peak force", self.p_force), ("time", self.p_time))
            if p is not None and p < ALPHA
        ]


def compare_arms(rows: Sequence[dict[str, Any]] | Any) -> list[PairComparison]:
    """Every pair of arms (``arm`` or ``controller``, + ``planner``, of episodes.csv rows or
    their :func:`episodes_frame`) at each clearance, largest clearance first."""
    import pandas as pd

    df = episodes_frame(rows)
    if df.empty:
        return []
    df["pair_arm"] = df["arm"] + "+" + df["planner"].astype(str)
    df["won"] = df["status"] == "success"
    # Time from the first contact to seated where the episode has it (held insertion: its
    # start and approach take the same time in every arm), else the time to insert.
    seat = df.get("contact_to_seat_s", pd.Series(np.nan, index=df.index))
    held = df.get("task", pd.Series("", index=df.index)) == "held_insertion"
    df["compared_time"] = df["time_to_insert_s"].where(~held | seat.isna(), seat)
    out = []
    for clearance, at in sorted(df.groupby("clearance_m", sort=False), key=lambda g: -g[0]):
        arms = {
            name: (
                int(g["won"].sum()),
                len(g),
                _finite(g["peak_contact_force_n"]),
                _finite(g.loc[g["won"], "compared_time"]),
            )
            for name, g in at.groupby("pair_arm", sort=False)
        }
        pairs = [(a, b, arms[a], arms[b]) for a, b in itertools.combinations(arms, 2)]
        # One Holm family per metric and clearance.
        p_success = holm([success_test(x[0], x[1], y[0], y[1]) for _, _, x, y in pairs])
        p_force = holm([location_test(x[2], y[2]) for _, _, x, y in pairs])
        p_time = holm([location_test(x[3], y[3]) for _, _, x, y in pairs])
        for i, (a, b, x, y) in enumerate(pairs):
            out.append(
                PairComparison(
                    clearance_m=float(clearance),
                    arm_a=str(a),
                    arm_b=str(b),
                    success_a=f"{x[0]}/{x[1]}",
                    success_b=f"{y[0]}/{y[1]}",
                    p_success=p_success[i],
                    force_median_a=_median(x[2]),
                    force_median_b=_median(y[2]),
                    p_force=p_force[i],
                    time_median_a=_median(x[3]),
                    time_median_b=_median(y[3]),
                    p_time=p_time[i],
                )
            )
    return out


def _finite(values: Any) -> list[float]:
    return [float(v) for v in values if math.isfinite(v)]


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None
