"""Statistics of a sweep: which arms (controller x planner) differ, and by how much.

- Success: Wilson 95 % intervals per arm (:func:`wilson_interval`, ``scipy.stats.binomtest``);
  pairwise Boschloo exact tests (two-sided, more powerful than Fisher's for 2x2 tables with fixed
  group sizes), Holm-corrected over all pairs compared at one clearance.
- Peak force and time to insert (for a task that inserts with a strategy from its first contact,
  the held insertion: from first contact to seated): the median with a 95 % bootstrap interval
  (percentile method, fixed seed, ``scipy.stats.bootstrap``) per arm; pairwise two-sided
  Mann-Whitney U tests, Holm-corrected likewise.
- The summary of a sweep (:func:`summarise`, ``summary.csv``): per arm, planner and clearance,
  the success rate and every metric the episode record declares a summary for
  (:mod:`peg_ctrl.run.result`).

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
from peg_ctrl.run.result import MetricField, flag_columns, numeric_columns, summarised

__all__ = [
    "ALPHA",
    "holm",
    "wilson_interval",
    "success_test",
    "location_test",
    "median_ci",
    "episodes_frame",
    "number_columns",
    "numbers",
    "inserts_from_contact",
    "compared_time",
    "summarise",
    "summary_columns",
    "metric_summary",
    "success_by_level",
    "PairComparison",
    "compare_arms",
    "force_metric",
    "FORCE_10MS",
    "SOLVER_PEAK",
]

ALPHA = 0.05
_BOOTSTRAP_RESAMPLES = 2000


#: The force the report compares, and the solver's one-step peak it replaced (runs made before the
#: 10 ms force was recorded have only the latter; docs/physics.md, "Cross-check against Drake").
FORCE_10MS = "peak_force_10ms_n"
SOLVER_PEAK = "peak_contact_force_n"


def force_metric(df: Any) -> tuple[str, str]:
    """The force column a comparison of ``df``'s episodes uses, and its name in the report: the
    force sustained over 10 ms where every episode recorded it, else the solver's one-step peak
    (an older run, or one mixed with one): never the one for some episodes, the other for others."""
    if FORCE_10MS in df.columns and len(df) and bool(np.isfinite(numbers(df[FORCE_10MS])).all()):
        return FORCE_10MS, "peak force (10 ms)"
    return SOLVER_PEAK, "solver peak (one step)"


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
    with the clearance and the episode record's number columns as floats (blank: NaN), its flag
    columns as 1.0/0.0 (blank: NaN), and an ``arm`` column (the row's ``arm``, else its
    ``controller``)."""
    import pandas as pd

    df = rows.copy() if isinstance(rows, pd.DataFrame) else pd.DataFrame(list(rows))
    arm = df["arm"] if "arm" in df else pd.Series("", index=df.index)
    df["arm"] = [
        str(a) if isinstance(a, str) and a else str(c) for a, c in zip(arm, df["controller"], strict=True)
    ]
    for column in number_columns():
        if column in df:
            df[column] = numbers(df[column])
    for column in flag_columns():
        if column in df:
            flags = {"true": 1.0, "false": 0.0, "1": 1.0, "0": 0.0}
            df[column] = [flags.get(str(v).lower(), np.nan) for v in df[column]]
    return df


def number_columns() -> tuple[str, ...]:
    """The columns of ``episodes.csv`` that hold numbers: the clearance and the episode record's
    number fields (:func:`~peg_ctrl.run.result.numeric_columns`)."""
    return ("clearance_m", *numeric_columns())


def numbers(series: Any) -> Any:
    """A column as floats: a blank or a text that is not a number is NaN."""
    import pandas as pd

    return pd.to_numeric(series.replace("", np.nan), errors="coerce").astype(float)


def inserts_from_contact(df: Any) -> Any:
    """Per row of an :func:`episodes_frame`, whether its task inserts with a strategy from the
    first contact on (its ``strategy`` is not blank: the held insertion starts at the hole, so
    its start and approach take the same time in every arm); such an episode's insertion is timed
    and aligned from its first contact."""
    import pandas as pd

    strategy = df["strategy"] if "strategy" in df else pd.Series("", index=df.index)
    return strategy.fillna("").astype(str) != ""


def compared_time(df: Any) -> Any:
    """Per row of an :func:`episodes_frame`, the time its insertion is compared by [s]: from the
    first contact to seated where the episode has it and inserts from its first contact
    (:func:`inserts_from_contact`), else the time to insert."""
    import pandas as pd

    seat = df["contact_to_seat_s"] if "contact_to_seat_s" in df else pd.Series(np.nan, index=df.index)
    return df["time_to_insert_s"].where(~inserts_from_contact(df) | seat.isna(), seat)


def summarise(rows: Sequence[dict[str, Any]] | Any) -> list[dict[str, Any]]:
    """Per arm (controller/strategy) x planner x clearance, in order of first appearance: the
    episodes, the success rate with its 95 % Wilson interval, each metric the episode record
    declares a :class:`~peg_ctrl.run.result.Summary` for (its median, bootstrap interval, p95,
    share within a bound, rate, over all episodes or the successes), and the failure reasons.

    Columns (``summary.csv``): ``controller`` (the arm), ``planner``, ``clearance_m``,
    ``episodes``, ``successes``, ``success_rate``, ``success_ci95_low``/``_high``, the metrics'
    (named as :class:`~peg_ctrl.run.result.Summary` says) and ``failure_reasons``.
    """
    if len(rows) == 0:
        return []
    df = episodes_frame(rows)
    df["won"] = df["status"] == "success"
    metrics = summarised()
    out = []
    for (arm, planner, clearance), group in df.groupby(["arm", "planner", "clearance_m"], sort=False):
        n = len(group)
        wins = int(group["won"].sum())
        lo, hi = wilson_interval(wins, n)
        row: dict[str, Any] = {
            "controller": str(arm),
            "planner": str(planner),
            "clearance_m": float(clearance),
            "episodes": n,
            "successes": wins,
            "success_rate": wins / n,
            "success_ci95_low": lo,
            "success_ci95_high": hi,
        }
        for field in metrics:
            row.update(metric_summary(group, field))
        reasons = group.loc[~group["won"], "reason"].value_counts().sort_index()
        row["failure_reasons"] = ";".join(f"{k}:{v}" for k, v in reasons.items())
        out.append(row)
    return out


def summary_columns(field: MetricField) -> dict[str, str]:
    """The columns of ``summary.csv`` that ``field``'s :class:`~peg_ctrl.run.result.Summary`
    makes, by the statistic each holds (``median``, ``ci_low``, ``ci_high``, ``p95``,
    ``within``, ``rate``, ``rate_low``, ``rate_high``)."""
    summary = field.metric.summary
    assert summary is not None
    stem, unit = field.stem, f"_{field.suffix}" if field.suffix else ""
    names: dict[str, str] = {}
    for stat in summary.stats:
        if stat == "median":
            names["median"] = f"{stem}_median{unit}"
        elif stat == "ci":
            names["ci_low"] = f"{stem}_median_ci95_low{unit}"
            names["ci_high"] = f"{stem}_median_ci95_high{unit}"
        elif stat == "p95":
            names["p95"] = f"{stem}_p95{unit}"
        else:  # rate
            names.update(
                rate=f"{stem}_rate", rate_low=f"{stem}_rate_ci95_low", rate_high=f"{stem}_rate_ci95_high"
            )
    if summary.within is not None:
        names["within"] = f"{stem}_within_{summary.within:g}{field.suffix}"
    return names


def metric_summary(group: Any, field: MetricField) -> dict[str, float | None]:
    """``field``'s statistics over one group of :func:`episodes_frame` rows (its successes
    only, if its summary says so), by their :func:`summary_columns` names; None where there is
    no finite value."""
    summary = field.metric.summary
    assert summary is not None
    names = summary_columns(field)
    if field.name in group:
        picked = group.loc[group["won"], field.name] if summary.successes else group[field.name]
        x = np.asarray([v for v in picked.tolist() if v is not None and math.isfinite(v)], dtype=float)
    else:  # an older episodes.csv without the column
        x = np.zeros(0)
    stats: dict[str, float | None] = dict.fromkeys(names)
    if len(x):
        if "ci_low" in names:
            stats["median"], stats["ci_low"], stats["ci_high"] = median_ci(x.tolist())
        elif "median" in names:
            stats["median"] = float(np.median(x))
        if "p95" in names:
            stats["p95"] = float(np.percentile(x, 95))
        if "within" in names:
            stats["within"] = float(np.mean(x <= summary.within))
        if "rate" in names:
            k = int(np.count_nonzero(x))
            stats["rate"] = k / len(x)
            stats["rate_low"], stats["rate_high"] = wilson_interval(k, len(x))
    return {names[k]: v for k, v in stats.items()}


def success_by_level(df: Any, column: str, *, max_levels: int = 6) -> Any:
    """Per arm and level of ``column`` of an :func:`episodes_frame` with a ``won`` column: x
    (the level, or the median of a quartile bin when there are more than ``max_levels`` numeric
    levels), successes ``k`` of ``n``, ``rate`` and its Wilson interval ``low``/``high``. Named
    levels (a sensor preset) are at x = 0, 1, ... in the order they first appear, their names in
    ``attrs["labels"]``; ``attrs["binned"]`` says whether the levels were binned."""
    import pandas as pd

    values = numbers(df[column])
    labels: list[str] = []
    if values.isna().any():  # named levels: at 0, 1, ... in the file's order
        labels = list(dict.fromkeys(df[column].astype(str)))
        values = df[column].astype(str).map({v: float(i) for i, v in enumerate(labels)})
    binned = not labels and values.nunique() > max_levels
    if binned:
        bins = pd.qcut(values, q=4, duplicates="drop")
        x = values.groupby(bins, observed=True).transform("median")
    else:
        x = values
    table = df.assign(x=x).groupby(["arm", "x"], sort=True)["won"].agg(k="sum", n="count").reset_index()
    ci = [wilson_interval(int(k), int(n)) for k, n in zip(table["k"], table["n"], strict=True)]
    table["rate"] = table["k"] / table["n"]
    table["low"] = [c[0] for c in ci]
    table["high"] = [c[1] for c in ci]
    table.attrs["binned"] = binned
    table.attrs["labels"] = labels
    return table


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


def compare_arms(rows: Sequence[dict[str, Any]] | Any, *, against: str | None = None) -> list[PairComparison]:
    """Every pair of arms (``arm`` or ``controller``, + ``planner``, of episodes.csv rows or
    their :func:`episodes_frame`) at each clearance, largest clearance first; with ``against``
    (an arm), only that arm (as A) against each other one with the same planner, the Holm family
    those pairs."""
    df = episodes_frame(rows)
    if df.empty:
        return []
    df["pair_arm"] = df["arm"] + "+" + df["planner"].astype(str)
    df["won"] = df["status"] == "success"
    df["compared_time"] = compared_time(df)
    force, _ = force_metric(df)
    out = []
    for clearance, at in sorted(df.groupby("clearance_m", sort=False), key=lambda g: -g[0]):
        arms = {
            name: (
                int(g["won"].sum()),
                len(g),
                _finite(g[force]),
                _finite(g.loc[g["won"], "compared_time"]),
            )
            for name, g in at.groupby("pair_arm", sort=False)
        }
        if against is None:
            pairs = [(a, b, arms[a], arms[b]) for a, b in itertools.combinations(arms, 2)]
        else:
            # ... each of its planners against the other arms with the same planner.
            mine = [a for a in arms if a.rsplit("+", 1)[0] == against]
            pairs = [
                (a, b, arms[a], arms[b])
                for a in mine
                for b in arms
                if b not in mine and b.rsplit("+", 1)[1] == a.rsplit("+", 1)[1]
            ]
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
