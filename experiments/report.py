"""Summary statistics, plots and the Markdown report of a sweep (also ``peg-sim plot DIR``)."""

from __future__ import annotations

import csv
import math
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.stats import ALPHA, compare_arms, median_ci
from peg_ctrl.monitors import FIRST_CONTACT_N

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


def arm_of(row: dict[str, Any]) -> str:
    """The row's arm: controller, and strategy when the sweep has them."""
    return str(row.get("arm") or row["controller"])


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per arm (controller/strategy) x planner x clearance: rates, intervals, force and time statistics."""
    groups: dict[tuple[str, str, float], list[dict[str, Any]]] = defaultdict(list)
    order: list[tuple[str, str, float]] = []
    for row in rows:
        key = (arm_of(row), row["planner"], float(row["clearance_m"]))
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
        seat = [
            t
            for t in (_float(r.get("contact_to_seat_s")) for r in group if r["status"] == "success")
            if t is not None
        ]
        impulses = [x for x in (_float(r.get("contact_impulse_ns")) for r in group) if x is not None]
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
                "contact_to_seat_median_s": float(np.median(seat)) if seat else None,
                "impulse_median_ns": float(np.median(impulses)) if impulses else None,
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
    controllers = list(dict.fromkeys(arm_of(r) for r in rows))
    colours = {c: f"C{i}" for i, c in enumerate(controllers)}

    # 1. Force profiles around the release, median and 10-90 % band per controller.
    grid = np.linspace(-1.0, 2.0, 301)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), dpi=110, sharex=True)
    for ctrl in controllers:
        for ax, column in zip(axes, ("block-peg", "peg-table"), strict=True):
            curves = []
            for r in rows:
                if arm_of(r) != ctrl:
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

    # 2. Success rate vs clearance with Wilson intervals (when the sweep has more than one).
    if len({s["clearance_m"] for s in summary}) > 1:
        made.append(_success_vs_clearance(out_dir, summary, controllers, colours))

    # 3. Peak peg-block force per controller.
    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    data = [[float(r["peak_contact_force_n"]) for r in rows if arm_of(r) == c] for c in controllers]
    ax.boxplot(data, showfliers=True)
    ax.set_xticks(range(1, len(controllers) + 1), controllers, rotation=20, ha="right", fontsize=8)
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
    made += _contact_plots(out_dir, rows, controllers, colours)
    return made


def _success_vs_clearance(
    out_dir: Path, summary: list[dict[str, Any]], controllers: list[str], colours: dict[str, str]
) -> tuple[str, str]:
    import matplotlib.pyplot as plt

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
    return ("Success rate vs clearance", "success_vs_clearance.png")


def _condition_success(rows: list[dict[str, Any]], arm: str, column: str) -> list[tuple[float, int, int]]:
    """(value, successes, episodes) per value of ``column`` for one arm, pooled over the rest."""
    counts: dict[float, list[int]] = defaultdict(lambda: [0, 0])
    for r in rows:
        if arm_of(r) == arm and r.get(column) not in (None, ""):
            c = counts[float(r[column])]
            c[0] += r["status"] == "success"
            c[1] += 1
    return [(v, k, n) for v, (k, n) in sorted(counts.items())]


def _contact_plots(
    out_dir: Path, rows: list[dict[str, Any]], arms: list[str], colours: dict[str, str]
) -> list[tuple[str, str]]:
    """Success vs each swept disturbance, and force-vs-depth traces, per arm (contact studies)."""
    import matplotlib.pyplot as plt

    made: list[tuple[str, str]] = []
    conditions = [
        (column, label, scale)
        for column, label, scale in (
            ("task.lateral_error", "lateral error at first contact [mm]", 1e3),
            ("task.tilt_error", "peg tilt in the grasp [deg]", 180.0 / math.pi),
            ("task.position_noise", "noise on the observed hole position [mm]", 1e3),
        )
        if any(r.get(column) not in (None, "") for r in rows)
    ]
    if conditions:
        fig, axes = plt.subplots(
            1, len(conditions), figsize=(6 * len(conditions), 4.2), dpi=110, squeeze=False
        )
        for ax, (column, label, scale) in zip(axes[0], conditions, strict=True):
            for i, arm in enumerate(arms):
                pts = _condition_success(rows, arm, column)
                if not pts:
                    continue
                x = np.array([p[0] for p in pts]) * scale
                x = x + (i - (len(arms) - 1) / 2) * 0.012 * (x.max() - x.min() or 1.0)  # dodge
                y = np.array([k / n for _, k, n in pts])
                ci = np.array([wilson_interval(k, n) for _, k, n in pts])
                ax.errorbar(
                    x,
                    y,
                    yerr=[np.clip(y - ci[:, 0], 0.0, None), np.clip(ci[:, 1] - y, 0.0, None)],  # round-off
                    marker="o",
                    capsize=3,
                    color=colours[arm],
                    label=arm,
                )
            ax.set_xlabel(label)
            ax.set_ylabel("success rate (95 % Wilson interval)")
            ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3)
        axes[0][0].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out_dir / "success_vs_disturbance.png")
        plt.close(fig)
        made.append(("Success vs disturbance", "success_vs_disturbance.png"))

    # Force against depth, a few episodes per arm.
    held = [r for r in rows if r.get("task") == "held_insertion"]
    if held:
        cols = min(3, len(arms))
        nrows = math.ceil(len(arms) / cols)
        fig, axes = plt.subplots(nrows, cols, figsize=(5.2 * cols, 3.6 * nrows), dpi=110, squeeze=False)
        for ax, arm in zip(axes.flat, arms, strict=False):
            picked = [r for r in held if arm_of(r) == arm][:: max(1, len(held) // (len(arms) * 12))][:12]
            for r in picked:
                trace = _trace(out_dir / Path(r["log_path"]).parent)
                if trace is None:
                    continue
                depth, force = trace
                ok = r["status"] == "success"
                ax.plot(depth * 1e3, force, lw=0.7, alpha=0.7, color="C2" if ok else "C3")
            ax.set_title(f"{arm} (green: seated, red: not)", fontsize=9)
            ax.set_xlabel("depth of the peg's lower end [mm]")
            ax.set_ylabel("peg-block force [N]")
            ax.grid(alpha=0.3)
        for ax in list(axes.flat)[len(arms) :]:
            ax.set_visible(False)
        fig.tight_layout()
        fig.savefig(out_dir / "force_vs_depth.png")
        plt.close(fig)
        made.append(("Force against depth", "force_vs_depth.png"))
    return made


def _trace(episode_dir: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(depth [m], peg-block force [N]) of an episode's force trace, from its first contact."""
    trace = episode_dir / "forces.npz"
    if not trace.is_file():
        return None
    with np.load(trace) as npz:
        columns = [str(c) for c in npz["columns"]]
        data = npz["data"]
    if "peg_depth_m" not in columns or len(data) == 0:
        return None
    force = data[:, columns.index("block-peg")]
    touched = np.flatnonzero(force > FIRST_CONTACT_N)
    if len(touched) == 0:
        return None
    start = int(touched[0])
    return data[start:, columns.index("peg_depth_m")], force[start:]


def _aligned_force(episode_dir: Path, column: str, grid: np.ndarray) -> np.ndarray | None:
    """The episode's force ``column`` on ``grid``, time measured from the release phase start."""
    import json

    summary = episode_dir / "summary.json"
    trace = episode_dir / "forces.npz"
    if not (summary.is_file() and trace.is_file()):
        return None
    record = json.loads(summary.read_text())
    phases = record.get("phases", [])
    if record.get("task") == "held_insertion":  # aligned at the first peg-block contact
        starts = [record["first_contact_s"]] if record.get("first_contact_s") is not None else []
    else:
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
        "peg-block force and time to insert (successes only; for held insertion the time from the "
        "first contact to seated): Mann-Whitney U. All p-values are "
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


def _cell_section(rows: list[dict[str, Any]]) -> list[str]:
    """Success and median peak force per arm in every grid cell (contact studies)."""
    keys = [k for k in (rows[0] if rows else {}) if "." in k]  # the grid's dotted keys
    if not keys:
        return []
    cells = list(dict.fromkeys(tuple(r[k] for k in keys) for r in rows))
    arms = list(dict.fromkeys(arm_of(r) for r in rows))
    lines = [
        "## Success per grid cell",
        "",
        "Successes / episodes, and the median peak peg-block force [N], per arm and cell.",
        "",
        "| arm | "
        + " | ".join(
            ", ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(keys, c, strict=True)) for c in cells
        )
        + " |",
        "|---|" + "---|" * len(cells),
    ]
    for arm in arms:
        cells_text = []
        for c in cells:
            group = [r for r in rows if arm_of(r) == arm and tuple(r[k] for k in keys) == c]
            wins = sum(r["status"] == "success" for r in group)
            forces = [float(r["peak_contact_force_n"]) for r in group]
            med = f"{np.median(forces):.1f} N" if forces else "–"
            cells_text.append(f"{wins}/{len(group)}, {med}")
        lines.append(f"| {arm} | " + " | ".join(cells_text) + " |")
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
        f"{len(rows)} episodes: arms {', '.join(dict.fromkeys(arm_of(r) for r in rows))}; "
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
                ("controller", "arm"),
                ("planner", "planner"),
                ("clearance_mm", "clearance [mm]"),
                ("success", "success"),
                ("ci", "95 % CI"),
                ("peak_force_median_n", "peak force median [N]"),
                ("force_ci", "95 % CI"),
                ("peak_force_p95_n", "peak force p95 [N]"),
                ("time_to_insert_median_s", "time to insert [s]"),
                ("time_ci", "95 % CI"),
                ("contact_to_seat_median_s", "contact to seated [s]"),
                ("impulse_median_ns", "impulse median [N s]"),
                ("failure_reasons", "failures"),
            ],
        ),
        "",
        *_cell_section(rows),
        *_comparison_section(rows),
    ]
    for title, name in plots:
        parts += [f"## {title}", "", f"![{title}]({name})", ""]
    path = out_dir / "report.md"
    path.write_text("\n".join(parts))
    return path
