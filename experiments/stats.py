"""Statistics of a sweep: which arms (controller x planner) differ, and by how much.

- Success: Wilson 95 % intervals per arm; pairwise Boschloo exact tests (two-sided, more
  powerful than Fisher's for 2x2 tables with fixed group sizes), Holm-corrected over all pairs
  compared at one clearance.
- Peak force and time to insert (for held insertion: from first contact to seated): the median
  with a 95 % bootstrap interval (percentile method, fixed seed) per arm; pairwise two-sided
  Mann-Whitney U tests, Holm-corrected likewise.

Every p-value reported is the Holm-adjusted one; a pair "differs" in a metric when it is below
``ALPHA``. Nothing is tested with fewer than two samples per side (the entry is then None).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "ALPHA",
    "holm",
    "success_test",
    "location_test",
    "median_ci",
    "PairComparison",
    "compare_arms",
]

ALPHA = 0.05
_BOOTSTRAP_RESAMPLES = 2000


def holm(p_values: Sequence[float | None]) -> list[float | None]:
    """Holm-Bonferroni adjusted p-values (step-down, monotone, capped at 1); None stays None."""
    indexed = [(p, i) for i, p in enumerate(p_values) if p is not None]
    m = len(indexed)
    adjusted: list[float | None] = [None] * len(p_values)
    running = 0.0
    for rank, (p, i) in enumerate(sorted(indexed)):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return adjusted


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
    """(median, low, high): the median and its 95 % percentile-bootstrap interval."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if len(x) == 0:
        return None, None, None
    med = float(np.median(x))
    if len(x) < 2 or np.all(x == x[0]):
        return med, med, med
    rng = np.random.default_rng(seed)
    samples = rng.choice(x, size=(_BOOTSTRAP_RESAMPLES, len(x)), replace=True)
    medians = np.median(samples, axis=1)
    lo, hi = np.percentile(medians, [2.5, 97.5])
    return med, float(lo), float(hi)


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


@dataclasses.dataclass
class _Arm:
    wins: int
    n: int
    forces: list[float]
    times: list[float]


def compare_arms(rows: Sequence[dict[str, object]]) -> list[PairComparison]:
    """Every pair of arms (``controller`` + ``planner`` of episodes.csv rows) at each clearance."""
    arms: dict[tuple[float, str], _Arm] = {}
    for row in rows:
        key = (float(str(row["clearance_m"])), _arm(row))
        arm = arms.setdefault(key, _Arm(0, 0, [], []))
        arm.n += 1
        ok = row["status"] == "success"
        arm.wins += ok
        force = _number(row.get("peak_contact_force_n"))
        if force is not None:
            arm.forces.append(force)
        # Time from the first contact to seated where the episode has it (held insertion: its
        # start and approach take the same time in every arm), else the time to insert.
        t = _number(row.get("contact_to_seat_s")) if row.get("task") == "held_insertion" else None
        t = t if t is not None else _number(row.get("time_to_insert_s"))
        if ok and t is not None:
            arm.times.append(t)
    out = []
    for clearance in sorted({c for c, _ in arms}, reverse=True):
        names = [name for c, name in arms if c == clearance]
        pairs = [
            (a, b, arms[(clearance, a)], arms[(clearance, b)]) for a, b in itertools.combinations(names, 2)
        ]
        # One Holm family per metric and clearance.
        p_success = holm([success_test(x.wins, x.n, y.wins, y.n) for _, _, x, y in pairs])
        p_force = holm([location_test(x.forces, y.forces) for _, _, x, y in pairs])
        p_time = holm([location_test(x.times, y.times) for _, _, x, y in pairs])
        for i, (a, b, x, y) in enumerate(pairs):
            out.append(
                PairComparison(
                    clearance_m=clearance,
                    arm_a=a,
                    arm_b=b,
                    success_a=f"{x.wins}/{x.n}",
                    success_b=f"{y.wins}/{y.n}",
                    p_success=p_success[i],
                    force_median_a=_median(x.forces),
                    force_median_b=_median(y.forces),
                    p_force=p_force[i],
                    time_median_a=_median(x.times),
                    time_median_b=_median(y.times),
                    p_time=p_time[i],
                )
            )
    return out


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def _arm(row: dict[str, object]) -> str:
    return f"{row.get('arm') or row['controller']}+{row['planner']}"


def _number(value: object) -> float | None:
    if value in (None, ""):
        return None
    x = float(str(value))
    return x if math.isfinite(x) else None
