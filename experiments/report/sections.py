"""The sections of a sweep's ``report.md``, each a list of Markdown lines: the header, the
summary table (its columns from the metrics the episode record declares a summary for), success
per grid cell or condition, which arms differ, where the time goes, what the control costs, and
the plots."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.report.axes import arm_of, contact_tasks, episode_dir
from peg_ctrl.experiments.report.plots import caption
from peg_ctrl.experiments.stats import (
    ALPHA,
    compare_arms,
    compared_time,
    episodes_frame,
    force_metric,
    summary_columns,
    wilson_interval,
)
from peg_ctrl.run.result import COST_FIELDS, summarised

__all__ = [
    "summary_section",
    "cell_section",
    "comparison_section",
    "against_section",
    "phase_section",
    "cost_section",
    "plots_section",
]

_MAX_CELL_COLUMNS = 12  # a larger grid's success table is folded onto its axes


def _interval(lo: float | None, hi: float | None, fmt: str) -> str:
    return "" if lo is None or hi is None else f"[{fmt.format(lo)}, {fmt.format(hi)}]"


def _p(p: float | None) -> str:
    if p is None:
        return "–"
    text = "< 0.001" if p < 0.001 else f"{p:.3f}"
    return f"**{text}**" if p < ALPHA else text


def comparison_section(rows: list[dict[str, Any]]) -> list[str]:
    """Pairwise tests between the arms at each clearance, and which pairs differ."""
    pairs = compare_arms(rows)
    if not pairs:
        return []
    df = episodes_frame(rows)
    tasks = contact_tasks(df)
    seated = f"; for {tasks} the time from the first contact to seated" if tasks else ""
    lines = [
        "## Which arms differ",
        "",
        "Pairs of controller+planner at the same clearance. Success: Boschloo exact test; "
        f"{force_metric(df)[1]} and time to insert (successes only{seated}): Mann-Whitney U. All "
        f"p-values are two-sided and Holm-corrected over the pairs at that clearance; bold: p < {ALPHA}. "
        "Intervals in the summary: Wilson (success), percentile bootstrap of the median (force, time).",
        "",
        "| clearance [mm] | A | B | success A / B | p | force median A / B [N] | p | time median A / B [s] "
        "| p | differ in |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    for c in pairs:
        lines.append(
            f"| {c.clearance_m * 1e3:g} | {c.arm_a} | {c.arm_b} | {c.success_a} / {c.success_b} | "
            f"{_p(c.p_success)} | {_num(c.force_median_a, '{:.1f}')} / {_num(c.force_median_b, '{:.1f}')} | "
            f"{_p(c.p_force)} | {_num(c.time_median_a, '{:.2f}')} / {_num(c.time_median_b, '{:.2f}')} | "
            f"{_p(c.p_time)} | {', '.join(c.differs()) or 'no difference found'} |"
        )
    return [*lines, ""]


def against_section(
    rows: list[dict[str, Any]], arm: str, study: str, rerun: list[str] | None = None
) -> list[str]:
    """``arm`` (brought to a committed study by ``peg-sim compare``) against each of the study's
    arms at each clearance and planner: success with its Wilson interval, medians, and p-values
    Holm-corrected over those pairs; ``rerun``: the study arms rerun in full."""
    pairs = compare_arms(rows, against=arm)
    if not pairs:
        return []
    df = episodes_frame(rows)
    tasks = contact_tasks(df)
    force = force_metric(df)[1]
    time_what = "first contact to seated" if tasks else "time to insert"
    source = (
        f"The new arm's episodes ran here; the other arms' are {study}'s committed episodes (a sample "
        "of each rerun and classed against them: the verification above, `compare.json`)"
    )
    if rerun:
        source += f", except {', '.join(rerun)}: rerun here in full (not reproduced, or missing)"
    lines = [
        f"## {arm} against {study}'s arms",
        "",
        f"{source}. Success: Wilson 95 % interval; p: Boschloo exact test (success), Mann-Whitney U "
        f"({force}; {time_what}, successes only), two-sided, Holm-corrected over the pairs with "
        f"{arm} at that clearance and planner; bold: p < {ALPHA}.",
        "",
        f"| clearance [mm] | arm | success | 95 % interval | {force} median [N] | {time_what} "
        "median [s] | p success | p force | p time |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def row(clearance: float, name: str, k_n: str, force: float | None, time: float | None, ps: str) -> str:
        k, n = (int(x) for x in k_n.split("/"))
        lo, hi = wilson_interval(k, n)
        return (
            f"| {clearance * 1e3:g} | {name} | {k_n} ({k / n:.0%}) | {_interval(lo, hi, '{:.0%}')} | "
            f"{_num(force, '{:.1f}')} | {_num(time, '{:.2f}')} | {ps} |"
        )

    # Arms are arm+planner: the planner is left out when every arm has the same one.
    one_planner = len({n.rsplit("+", 1)[-1] for c in pairs for n in (c.arm_a, c.arm_b)}) == 1

    def name(arm_planner: str) -> str:
        return arm_planner.rsplit("+", 1)[0] if one_planner else arm_planner

    for clearance in dict.fromkeys(c.clearance_m for c in pairs):
        at = [c for c in pairs if c.clearance_m == clearance]
        for mine in dict.fromkeys(c.arm_a for c in at):  # one block per planner of the new arm
            block = [c for c in at if c.arm_a == mine]
            a = block[0]
            lines.append(
                row(clearance, f"**{name(mine)}**", a.success_a, a.force_median_a, a.time_median_a, "| |")
            )
            for c in block:
                ps = f"{_p(c.p_success)} | {_p(c.p_force)} | {_p(c.p_time)}"
                lines.append(
                    row(clearance, name(c.arm_b), c.success_b, c.force_median_b, c.time_median_b, ps)
                )
    return [*lines, ""]


def _num(x: float | None, fmt: str) -> str:
    return "–" if x is None else fmt.format(x)


def cell_section(rows: list[dict[str, Any]]) -> list[str]:
    """Success and median peak force per arm in every grid cell (contact studies)."""
    df = episodes_frame(rows)
    keys = [k for k in df.columns if "." in k]  # the grid's dotted keys
    if not keys:
        return []
    df["won"] = df["status"] == "success"
    cells = list(dict.fromkeys(df[keys].itertuples(index=False, name=None)))
    if len(cells) > _MAX_CELL_COLUMNS:
        return _condition_section(df, keys)
    column, label = force_metric(df)
    by_cell = df.groupby(["arm", *keys], sort=False).agg(
        wins=("won", "sum"), n=("won", "size"), force=(column, "median")
    )
    lines = [
        "## Success per grid cell",
        "",
        f"Successes / episodes, and the median {label} of the peg on the block [N], per arm and cell.",
        "",
        "| arm | "
        + " | ".join(
            ", ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(keys, c, strict=True)) for c in cells
        )
        + " |",
        "|---|" + "---|" * len(cells),
    ]
    for arm in dict.fromkeys(df["arm"]):
        cells_text = []
        for c in cells:
            key = (arm, *c)
            if key in by_cell.index:
                wins, n, force = by_cell.loc[key]
                cells_text.append(f"{int(wins)}/{int(n)}, {force:.1f} N")
            else:
                cells_text.append("0/0, –")
        lines.append(f"| {arm} | " + " | ".join(cells_text) + " |")
    return [*lines, ""]


def _condition_section(df: Any, keys: list[str]) -> list[str]:
    """Success, median peak force and median contact-to-seated per arm at each level of each grid
    key, pooled over the others: the per-cell table of a large grid, folded onto its axes."""
    df["time"] = compared_time(df)
    tasks = contact_tasks(df)
    seated = f"; for a {tasks} from first contact to seated" if tasks else ""
    levels = [(k, v) for k in keys for v in dict.fromkeys(df[k])]
    column, label = force_metric(df)
    lines = [
        "## Success per condition",
        "",
        f"The grid has {len(set(df[keys].itertuples(index=False, name=None)))} cells; each column "
        "pools the episodes at one level of one grid key (every cell per episode: episodes.csv). "
        f"Successes / episodes, median {label} of the peg on the block [N], median time to insert [s] "
        f"(successes{seated}).",
        "",
        "| arm | " + " | ".join(f"{k.split('.')[-1]}={v}" for k, v in levels) + " |",
        "|---|" + "---|" * len(levels),
    ]
    for arm, group in df.groupby("arm", sort=False):
        texts = []
        for key, value in levels:
            at = group[group[key] == value]
            time = at.loc[at["won"], "time"].median()
            texts.append(
                f"{int(at['won'].sum())}/{len(at)}, {at[column].median():.1f} N, "
                + ("–" if np.isnan(time) else f"{time:.1f} s")
            )
        lines.append(f"| {arm} | " + " | ".join(texts) + " |")
    return [*lines, ""]


_UNTIMED_PHASES = ("start", "settle", "hold", "done")  # not part of getting the peg in


def phase_section(out_dir: Path, rows: list[dict[str, Any]]) -> list[str]:
    """Where the time goes: per arm, the median duration of each phase over its successes (read
    from the episodes' summary.json; left out without them)."""
    per_arm: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        if row.get("status") != "success" or not row.get("log_path"):
            continue
        path = episode_dir(out_dir, row["log_path"]) / "summary.json"
        if not path.is_file():
            continue
        phases = json.loads(path.read_text()).get("phases") or []
        times = per_arm.setdefault(arm_of(row), {})
        for ph in phases:
            if ph["phase"] in _UNTIMED_PHASES or ph.get("t_end") is None:
                continue
            times.setdefault(ph["phase"], []).append(float(ph["t_end"]) - float(ph["t_start"]))
    if not per_arm:
        return []
    lines = [
        "## Where the time goes",
        "",
        "Per arm, the median time [s] each phase took over the arm's successes (in the order the "
        "phases run; the first contact is in the first phase that touches: `touch` for probe and "
        "align, `descend` or `push` for the others).",
        "",
        "| arm | successes | phases: median [s] |",
        "|---|---|---|",
    ]
    for arm, times in per_arm.items():
        n = max((len(v) for v in times.values()), default=0)
        text = ", ".join(f"{name} {np.median(v):.2f}" for name, v in times.items())
        lines.append(f"| {arm} | {n} | {text} |")
    return [*lines, ""]


def cost_section(rows: list[dict[str, Any]]) -> list[str]:
    """Wall time of the controller per control step, and of its optimiser per solve, per arm."""
    df = episodes_frame(rows)  # the cost columns as numbers
    if "control_time_p50_s" not in df:
        return []
    for column in COST_FIELDS:
        if column not in df:
            df[column] = np.nan
    if df["control_time_p50_s"].isna().all():
        return []
    lines = [
        "## What the control costs",
        "",
        "Wall time per control step (the controller's whole update) and, for the controllers that "
        "solve an optimisation problem, per solve (a QP, a replan), on one core of the machine that "
        "ran the sweep: the median over the arm's episodes of each episode's p50 and p99, and the "
        "largest p99. Real-time factor: the mean solve time over the solve period (below 1: the "
        "optimiser keeps up with its own rate).",
        "",
        "| arm | control step p50 [µs] | p99 [µs] | solve period [ms] | solve p50 [µs] | solve p99 "
        "[µs] (largest) | real-time factor |",
        "|---|---|---|---|---|---|---|",
    ]
    for arm, group in df.groupby("arm", sort=False):
        us = 1e6 * group[list(COST_FIELDS[:4])].median()
        solve = group["solve_period_s"].dropna()
        if solve.empty:
            solver = "– | – | – | –"
        else:
            largest = 1e6 * group["solve_time_p99_s"].max()
            solver = (
                f"{1e3 * solve.median():g} | {us['solve_time_p50_s']:.0f} | "
                f"{us['solve_time_p99_s']:.0f} ({largest:.0f}) | "
                f"{group['solve_real_time_factor'].median():.2f}"
            )
        lines.append(
            f"| {arm} | {us['control_time_p50_s']:.0f} | {us['control_time_p99_s']:.0f} | {solver} |"
        )
    return [*lines, ""]


def _table(rows: list[dict[str, Any]], columns: list[tuple[str, str]]) -> str:
    head = "| " + " | ".join(title for _, title in columns) + " |"
    rule = "|" + "|".join("---" for _ in columns) + "|"
    lines = [head, rule]
    for row in rows:
        cells = []
        for key, _ in columns:
            value = row[key]
            if isinstance(value, float):
                cells.append(f"{value:.4g}")
            else:
                cells.append(str(value if value is not None else "–"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_section(summary: list[dict[str, Any]]) -> list[str]:
    """Success, the summarised metrics (:func:`~peg_ctrl.run.result.summarised`) and the
    failures per arm, planner and clearance; ``summary``: the rows of
    :func:`~peg_ctrl.experiments.stats.summarise`."""
    columns = [
        ("controller", "arm"),
        ("planner", "planner"),
        ("clearance_mm", "clearance [mm]"),
        ("success", "success"),
        ("ci", "95 % CI"),
    ]
    cells = [
        {
            **s,
            "success": f"{s['successes']}/{s['episodes']} ({100 * s['success_rate']:.0f} %)",
            "ci": f"[{100 * s['success_ci95_low']:.0f}, {100 * s['success_ci95_high']:.0f}] %",
            "clearance_mm": s["clearance_m"] * 1e3,
        }
        for s in summary
    ]
    for field in summarised():
        names = summary_columns(field)
        info = field.metric.summary
        assert info is not None
        label, unit = info.label, field.metric.unit
        decimals = f"{{:.{info.decimals}f}}"
        for stat, name in names.items():
            title = ""
            if stat == "median":
                title = f"{label} median [{unit}]" if unit else f"{label} median"
            elif stat == "ci_low":
                title = "95 % CI"
                for c in cells:
                    c[name] = _interval(c[name], c[names["ci_high"]], decimals)
            elif stat == "p95":
                title = f"{label} p95 [{unit}]" if unit else f"{label} p95"
            elif stat == "within":
                title = f"{label} ≤ {info.within:g} {unit}".rstrip()
                for c in cells:
                    c[name] = "–" if c[name] is None else f"{100 * c[name]:.0f} %"
            elif stat == "rate":
                title = f"{label}"
                for c in cells:
                    c[name] = "–" if c[name] is None else f"{100 * c[name]:.0f} %"
            elif stat == "rate_low":
                title = "95 % CI"
                for c in cells:
                    c[name] = _interval(c[name], c[names["rate_high"]], "{:.0%}")
            if title:
                columns.append((name, title))
    columns.append(("failure_reasons", "failures"))
    return ["## Summary", "", _table(cells, columns), ""]


def plots_section(rows: list[dict[str, Any]], plots: list[tuple[str, str]]) -> list[str]:
    """Each plot with its caption (or why the force plots are missing)."""
    parts: list[str] = []
    if rows and "force_profiles.png" not in {name for _, name in plots}:
        parts += [
            "The episodes' force traces (`episodes/<key>/forces.npz`) are not in this directory, so "
            "the force profiles and force against depth are not drawn.",
            "",
        ]
    for title, name in plots:
        parts += [f"## {title}", "", caption(name, rows), "", f"![{title}]({name})", ""]
    return parts
