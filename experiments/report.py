"""Summary statistics, plots and the Markdown report of a sweep (also ``peg-sim plot DIR``)."""

from __future__ import annotations

import csv
import math
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.stats import ALPHA, compare_arms, median_ci

__all__ = ["wilson_interval", "summarise", "write_report", "read_rows"]


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval of a success rate."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def _float(value: Any) -> float | None:
    if value in (None, ""):
        return None
    return float(value)


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per controller x planner x clearance: rates, intervals, force and time statistics."""
    groups: dict[tuple[str, str, float], list[dict[str, Any]]] = defaultdict(list)
    order: list[tuple[str, str, float]] = []
    for row in rows:
        key = (row["controller"], row["planner"], float(row["clearance_m"]))
        if key not in groups:
            order.append(key)
        groups[key].append(row)
    out = []
    for key in order:
        group = groups[key]
        n = len(group)
        wins = sum(r["status"] == "success" for r in group)
        lo, hi = wilson_interval(wins, n)
        forces = np.array([_float(r["peak_contact_force_n"]) for r in group], dtype=float)
        times = [
            t
            for t in (_float(r["time_to_insert_s"]) for r in group if r["status"] == "success")
            if t is not None
        ]
        reasons = Counter(r["reason"] for r in group if r["status"] != "success")
        force_ci = median_ci(forces.tolist())
        time_ci = median_ci(times)
        out.append(
            {
                "controller": key[0],
                "planner": key[1],
                "clearance_m": key[2],
                "episodes": n,
                "successes": wins,
                "success_rate": wins / n,
                "success_ci95_low": lo,
                "success_ci95_high": hi,
                "peak_force_median_n": float(np.median(forces)),
                "peak_force_median_ci95_low_n": force_ci[1],
                "peak_force_median_ci95_high_n": force_ci[2],
                "peak_force_p95_n": float(np.percentile(forces, 95)),
                "time_to_insert_median_s": float(np.median(times)) if times else None,
                "time_to_insert_median_ci95_low_s": time_ci[1],
                "time_to_insert_median_ci95_high_s": time_ci[2],
                "failure_reasons": ";".join(f"{k}:{v}" for k, v in sorted(reasons.items())),
            }
        )
    return out


def read_rows(out_dir: Path) -> list[dict[str, Any]]:
    with open(Path(out_dir) / "episodes.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _plots(out_dir: Path, rows: list[dict[str, Any]], summary: list[dict[str, Any]]) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    made: list[tuple[str, str]] = []
    controllers = list(dict.fromkeys(r["controller"] for r in rows))
    colours = {c: f"C{i}" for i, c in enumerate(controllers)}

    # 1. Force profiles around the release, median and 10-90 % band per controller.
    grid = np.linspace(-1.0, 2.0, 301)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), dpi=110, sharex=True)
    for ctrl in controllers:
        for ax, column in zip(axes, ("block-peg", "peg-table"), strict=True):
            curves = []
            for r in rows:
                if r["controller"] != ctrl:
                    continue
                curve = _aligned_force(out_dir / Path(r["log_path"]).parent, column, grid)
                if curve is not None:
                    curves.append(curve)
            if not curves:
                continue
            stack = np.vstack(curves)
            ax.plot(grid, np.median(stack, axis=0), color=colours[ctrl], label=f"{ctrl} (n={len(curves)})")
            ax.fill_between(
                grid,
                np.percentile(stack, 10, axis=0),
                np.percentile(stack, 90, axis=0),
                color=colours[ctrl],
                alpha=0.2,
            )
    for ax, title in zip(axes, ("peg-block contact force", "peg-table contact force"), strict=True):
        ax.set_title(title + " (median, 10-90 %)")
        ax.set_xlabel("time from the start of the insert (or else release) phase [s]")
        ax.set_ylabel("net force [N]")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "force_profiles.png")
    plt.close(fig)
    made.append(("Force profiles", "force_profiles.png"))

    # 2. Success rate vs clearance with Wilson intervals.
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for ctrl in controllers:
        pts = sorted((s["clearance_m"], s) for s in summary if s["controller"] == ctrl)
        x = np.array([p[0] for p in pts]) * 1e3
        y = np.array([p[1]["success_rate"] for p in pts])
        lo = np.clip(y - np.array([p[1]["success_ci95_low"] for p in pts]), 0.0, None)
        hi = np.clip(np.array([p[1]["success_ci95_high"] for p in pts]) - y, 0.0, None)
        ax.errorbar(x, y, yerr=[lo, hi], marker="o", capsize=3, color=colours[ctrl], label=ctrl)
    ax.set_xscale("log")
    ax.set_xlabel("radial hole clearance [mm]")
    ax.set_ylabel("success rate (95 % Wilson interval)")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "success_vs_clearance.png")
    plt.close(fig)
    made.append(("Success rate vs clearance", "success_vs_clearance.png"))

    # 3. Peak peg-block force per controller.
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    data = [[float(r["peak_contact_force_n"]) for r in rows if r["controller"] == c] for c in controllers]
    ax.boxplot(data, showfliers=True)
    ax.set_xticks(range(1, len(controllers) + 1), controllers, rotation=20)
    ax.set_ylabel("peak peg-block contact force [N]")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "peak_force.png")
    plt.close(fig)
    made.append(("Peak contact force", "peak_force.png"))

    # 4. Failure reasons by phase.
    failures = Counter((r["reason"], r["phase"]) for r in rows if r["status"] != "success")
    fig, ax = plt.subplots(figsize=(7, 3.5), dpi=110)
    if failures:
        labels = [f"{reason}\n({phase})" for reason, phase in failures]
        ax.bar(range(len(failures)), list(failures.values()), color="C3")
        ax.set_xticks(range(len(failures)), labels, fontsize=8)
    else:
        ax.text(0.5, 0.5, "no failures", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel("episodes")
    ax.set_title("Failure reasons by phase")
    fig.tight_layout()
    fig.savefig(out_dir / "failures.png")
    plt.close(fig)
    made.append(("Failure reasons by phase", "failures.png"))
    return made


def _aligned_force(episode_dir: Path, column: str, grid: np.ndarray) -> np.ndarray | None:
    """The episode's force ``column`` on ``grid``, time measured from the release phase start."""
    import json

    summary = episode_dir / "summary.json"
    trace = episode_dir / "forces.npz"
    if not (summary.is_file() and trace.is_file()):
        return None
    phases = json.loads(summary.read_text()).get("phases", [])
    starts = [p["t_start"] for p in phases if p["phase"] in ("insert", "release")]
    if not starts:
        return None
    with np.load(trace) as npz:
        columns = [str(c) for c in npz["columns"]]
        data = npz["data"]
    if column not in columns or len(data) == 0:
        return None
    t = data[:, columns.index("t")] - starts[0]
    return np.interp(grid, t, data[:, columns.index(column)], left=np.nan, right=np.nan)


def _interval(lo: float | None, hi: float | None, fmt: str) -> str:
    return "" if lo is None or hi is None else f"[{fmt.format(lo)}, {fmt.format(hi)}]"


def _p(p: float | None) -> str:
    if p is None:
        return "–"
    text = "< 0.001" if p < 0.001 else f"{p:.3f}"
    return f"**{text}**" if p < ALPHA else text


def _comparison_section(rows: list[dict[str, Any]]) -> list[str]:
    """Pairwise tests between the arms at each clearance, and which pairs differ."""
    pairs = compare_arms(rows)
    if not pairs:
        return []
    lines = [
        "## Which arms differ",
        "",
        "Pairs of controller+planner at the same clearance. Success: Boschloo exact test; peak "
        "peg-block force and time to insert (successes only): Mann-Whitney U. All p-values are "
        f"two-sided and Holm-corrected over the pairs at that clearance; bold: p < {ALPHA}. Intervals "
        "in the summary: Wilson (success), percentile bootstrap of the median (force, time).",
        "",
        "| clearance [mm] | A | B | success A / B | p | force median A / B [N] | p | time median A / B [s] "
        "| p | differ in |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def num(x: float | None, fmt: str) -> str:
        return "–" if x is None else fmt.format(x)

    for c in pairs:
        lines.append(
            f"| {c.clearance_m * 1e3:g} | {c.arm_a} | {c.arm_b} | {c.success_a} / {c.success_b} | "
            f"{_p(c.p_success)} | {num(c.force_median_a, '{:.1f}')} / {num(c.force_median_b, '{:.1f}')} | "
            f"{_p(c.p_force)} | {num(c.time_median_a, '{:.2f}')} / {num(c.time_median_b, '{:.2f}')} | "
            f"{_p(c.p_time)} | {', '.join(c.differs()) or 'no difference found'} |"
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


def write_report(out_dir: Path, *, elapsed_s: float | None = None) -> Path:
    """Draw the plots and write ``report.md`` from the saved ``episodes.csv``."""
    import json

    out_dir = Path(out_dir)
    rows = read_rows(out_dir)
    summary = summarise(rows)
    plots = _plots(out_dir, rows, summary) if rows else []
    exp = (
        json.loads((out_dir / "experiment.json").read_text())
        if (out_dir / "experiment.json").is_file()
        else {}
    )
    for s in summary:
        s["success"] = f"{s['successes']}/{s['episodes']} ({100 * s['success_rate']:.0f} %)"
        s["ci"] = f"[{100 * s['success_ci95_low']:.0f}, {100 * s['success_ci95_high']:.0f}] %"
        s["clearance_mm"] = s["clearance_m"] * 1e3
        s["force_ci"] = _interval(
            s["peak_force_median_ci95_low_n"], s["peak_force_median_ci95_high_n"], "{:.1f}"
        )
        s["time_ci"] = _interval(
            s["time_to_insert_median_ci95_low_s"], s["time_to_insert_median_ci95_high_s"], "{:.2f}"
        )
    clearances = ", ".join(f"{c * 1e3:g} mm" for c in exp.get("clearances", []))
    parts = [
        f"# Experiment report: {exp.get('name', out_dir.name)}",
        "",
        f"{len(rows)} episodes: controllers {', '.join(dict.fromkeys(r['controller'] for r in rows))}; "
        f"planners {', '.join(exp.get('planners', []))}; clearances "
        f"{clearances}; {len(exp.get('seeds', []))} seeds; physics profile "
        f"`{exp.get('physics', {}).get('profile', 'seed')}`."
        + (f" Run time {elapsed_s:.0f} s." if elapsed_s is not None else ""),
        "",
        "## Summary",
        "",
        _table(
            summary,
            [
                ("controller", "controller"),
                ("planner", "planner"),
                ("clearance_mm", "clearance [mm]"),
                ("success", "success"),
                ("ci", "95 % CI"),
                ("peak_force_median_n", "peak force median [N]"),
                ("force_ci", "95 % CI"),
                ("peak_force_p95_n", "peak force p95 [N]"),
                ("time_to_insert_median_s", "time to insert [s]"),
                ("time_ci", "95 % CI"),
                ("failure_reasons", "failures"),
            ],
        ),
        "",
        *_comparison_section(rows),
    ]
    for title, name in plots:
        parts += [f"## {title}", "", f"![{title}]({name})", ""]
    path = out_dir / "report.md"
    path.write_text("\n".join(parts))
    return path
