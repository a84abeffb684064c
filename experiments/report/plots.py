"""The report's plots: success against each swept condition, the peak force and the outcomes per
arm, and (from the force traces, :mod:`~peg_ctrl.experiments.report.traces`) the force profiles
and the force against depth."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.report.axes import (
    CONDITION_LABELS,
    contact_tasks,
    controller_colours,
    split_arm,
    swept_conditions,
)
from peg_ctrl.experiments.report.traces import force_profiles, force_vs_depth, has_traces
from peg_ctrl.experiments.stats import episodes_frame, force_metric, inserts_from_contact, success_by_level
from peg_ctrl.run.plots import pyplot, save_figure

__all__ = ["draw_plots", "caption"]

_MAX_LEVELS = 6  # a condition with more distinct values than this is drawn in quartile bins
_SEATED, _FAILED = "#2ca02c", "#d62728"
_CAPTIONS = {
    "force_profiles.png": "Per arm, the median (line) and 10-90 % band of the contact force against "
    "time, aligned at {start}the start of the insert (else release) phase (dotted line).",
    "success_vs_clearance.png": "Success rate with 95 % Wilson intervals at each clearance, pooled "
    "over the other conditions; one row of panels per strategy, one colour per controller.",
    "success_vs_disturbance.png": "Success rate with 95 % Wilson intervals against each condition "
    "the experiment varies, pooled over the others; one row of panels per strategy, one colour per "
    "controller. A condition drawn per seed (mass, friction, gain scale) is grouped in quartile "
    "bins, plotted at the bin's median.",
    "peak_force.png": "The peak peg-block force of every episode (the force sustained over 10 ms; "
    "the solver's one-step peak in a run that did not record it; dots: green inserted, red failed), "
    "its distribution (violin) and box (median, quartiles, whiskers to 1.5 IQR) per arm.",
    "failures.png": "Episodes per arm: inserted, or the failure reason and the phase the episode ended in.",
    "force_vs_depth.png": "Peg-block force against the depth of the peg's lower end, from the first "
    "contact, for up to 12 episodes per arm.",
}


def caption(name: str, rows: list[dict[str, Any]]) -> str:
    """The caption of the plot ``name`` of a report on ``rows`` ("" for an unknown one)."""
    tasks = contact_tasks(episodes_frame(rows)) if rows else ""
    start = f"the first peg-block contact ({tasks}) or at " if tasks else ""
    return _CAPTIONS.get(name, "").format(start=start)


def draw_plots(
    out_dir: Path, rows: list[dict[str, Any]], *, traced_arms: list[str] | None = None
) -> list[tuple[str, str]]:
    """Draw the report's plots into ``out_dir``; returns (title, file name) of each one drawn.
    ``traced_arms``: the arms whose force traces are drawn (default every arm; a comparison's
    new arm, whose episodes alone ran in full, ``peg-sim compare``)."""
    pyplot()  # the headless backend, before any figure

    df = episodes_frame(rows)
    df["won"] = df["status"] == "success"
    arms = list(dict.fromkeys(df["arm"]))
    made: list[tuple[str, str]] = []
    shown = arms if traced_arms is None else [a for a in arms if a in traced_arms]
    df_traced = df[df["arm"].isin(shown)]
    traced = bool(shown) and has_traces(out_dir, df_traced)
    if traced:
        made.append(force_profiles(out_dir, df_traced, shown))
    conditions = swept_conditions(df)
    if "clearance_m" in conditions:
        made.append(
            _success_curves(out_dir, df, arms, ["clearance_m"], "success_vs_clearance.png", log_x=True)
        )
    others = [c for c in conditions if c != "clearance_m"]
    if others:
        made.append(_success_curves(out_dir, df, arms, others, "success_vs_disturbance.png"))
    made.append(_peak_force(out_dir, df, arms))
    made.append(_outcomes(out_dir, df, arms))
    if traced and inserts_from_contact(df_traced).any():
        made.append(force_vs_depth(out_dir, df_traced, shown))
    return made


def _success_curves(
    out_dir: Path, df: Any, arms: list[str], conditions: list[str], name: str, *, log_x: bool = False
) -> tuple[str, str]:
    """Success rate with 95 % Wilson intervals against each swept condition (columns), one row
    of panels per strategy, one line per controller; pooled over the other conditions."""
    import matplotlib.pyplot as plt

    strategies = list(dict.fromkeys(split_arm(a)[1] for a in arms))
    colours = controller_colours(arms)
    fig, axes = plt.subplots(
        len(strategies),
        len(conditions),
        figsize=(4.6 * len(conditions) + 0.4, 2.9 * len(strategies) + 0.9),
        dpi=110,
        sharey=True,
        squeeze=False,
        layout="constrained",
    )
    for j, column in enumerate(conditions):
        label, scale = CONDITION_LABELS.get(column, (column, 1.0))
        table = success_by_level(df, column, max_levels=_MAX_LEVELS)
        for i, strategy in enumerate(strategies):
            ax = axes[i][j]
            members = [a for a in arms if split_arm(a)[1] == strategy]
            for k, arm in enumerate(members):
                pts = table[table["arm"] == arm]
                if pts.empty:
                    continue
                x = pts["x"].to_numpy() * scale
                offset = (k - (len(members) - 1) / 2) * 0.012
                x = x * (1.0 + 2 * offset) if log_x else x + offset * (np.ptp(x) or 1.0)  # dodge
                y = pts["rate"].to_numpy()
                err = [np.clip(y - pts["low"], 0.0, None), np.clip(pts["high"] - y, 0.0, None)]
                controller = split_arm(arm)[0]
                ax.errorbar(
                    x, y, yerr=err, marker="o", ms=4, capsize=3, color=colours[controller], label=controller
                )
            if table.attrs["labels"]:
                ax.set_xticks(range(len(table.attrs["labels"])), table.attrs["labels"])
                ax.set_xlim(-0.5, len(table.attrs["labels"]) - 0.5)
            if log_x:  # ticks at the swept values, written plainly
                ax.set_xscale("log")
                levels = np.unique(table["x"].to_numpy() * scale)
                ax.set_xticks(levels, [f"{v:g}" for v in levels])
                ax.minorticks_off()
            ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3, which="both")
            if strategy:
                ax.set_title(f"strategy: {strategy}", fontsize=9)
            if i == len(strategies) - 1:
                ax.set_xlabel(label + (" (quartile bins)" if table.attrs.get("binned") else ""))
    handles: dict[str, Any] = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles), loc="outside upper center", ncol=min(6, len(handles)))
    fig.supylabel("success rate (95 % Wilson interval)")
    save_figure(fig, out_dir / name)
    title = "Success rate vs clearance" if name == "success_vs_clearance.png" else "Success vs disturbance"
    return (title, name)


def _peak_force(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Per arm: the distribution of the peak peg-block force the report compares
    (:func:`~peg_ctrl.experiments.stats.force_metric`; violin, box, and every episode as a dot,
    green inserted, red not)."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    column, label = force_metric(df)
    colours = controller_colours(arms)
    rng = np.random.default_rng(0)  # the dots' horizontal jitter only
    fig, ax = plt.subplots(figsize=(max(6.0, 0.8 * len(arms) + 2.0), 4.6), dpi=110, layout="constrained")
    for i, arm in enumerate(arms):
        group = df[df["arm"] == arm]
        y = group[column].to_numpy(dtype=float)
        ok = group["won"].to_numpy()
        keep = np.isfinite(y)
        y, ok = y[keep], ok[keep]
        if len(y) == 0:
            continue
        if len(y) >= 2 and np.ptp(y) > 0:
            violin: Any = ax.violinplot([y], positions=[i], widths=0.8, showextrema=False)
            for body in violin["bodies"]:
                body.set_facecolor(colours[split_arm(arm)[0]])
                body.set_alpha(0.3)
        ax.boxplot(
            [y],
            positions=[i],
            widths=0.22,
            showfliers=False,
            medianprops={"color": "k"},
            boxprops={"color": "0.2"},
            whiskerprops={"color": "0.2"},
            capprops={"color": "0.2"},
        )
        jitter = rng.uniform(-0.2, 0.2, len(y))
        ax.scatter(i + jitter, y, s=7, c=np.where(ok, _SEATED, _FAILED), alpha=0.6, lw=0, zorder=3)
    ax.set_xticks(range(len(arms)), arms, rotation=25, ha="right", fontsize=8)
    ax.set_xlim(-0.6, len(arms) - 0.4)
    ax.set_ylabel(f"{label} of the peg on the block [N]")
    ax.set_title(f"The {label} per arm (every episode a dot)", fontsize=10)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(
        handles=[
            Line2D([], [], marker="o", ls="", color=_SEATED, label="inserted"),
            Line2D([], [], marker="o", ls="", color=_FAILED, label="failed"),
        ],
        fontsize=8,
        loc="upper right",
    )
    save_figure(fig, out_dir / "peak_force.png")
    return ("Peak contact force", "peak_force.png")


def _outcomes(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Per arm: episodes inserted and failed, the failures by reason and the phase they ended in."""
    import matplotlib
    import matplotlib.pyplot as plt

    outcome = np.where(df["won"], "inserted", df["reason"].astype(str) + " (" + df["phase"].astype(str) + ")")
    counts = df.assign(outcome=outcome).groupby(["arm", "outcome"]).size().unstack(fill_value=0)
    counts = counts.reindex(index=arms, fill_value=0)
    kinds = ["inserted"] if "inserted" in counts else []
    kinds += sorted(c for c in counts.columns if c != "inserted")
    tab20 = matplotlib.colormaps["tab20"]
    palette = [tab20(i) for i in range(20) if i not in (4, 5)]  # no green: green is "inserted"
    fig, ax = plt.subplots(figsize=(8.5, 0.42 * len(arms) + 1.6), dpi=110, layout="constrained")
    left = np.zeros(len(arms))
    for k, kind in enumerate(kinds):
        values = counts[kind].to_numpy(dtype=float)
        colour = _SEATED if kind == "inserted" else palette[(k - 1) % len(palette)]
        ax.barh(range(len(arms)), values, left=left, color=colour, label=kind, height=0.7)
        left += values
    ax.set_yticks(range(len(arms)), arms, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("episodes")
    ax.set_title("Outcome per arm: inserted, or the failure reason (phase it ended in)", fontsize=10)
    ax.grid(alpha=0.3, axis="x")
    fig.legend(fontsize=7, loc="outside right upper")
    save_figure(fig, out_dir / "failures.png")
    return ("Outcome per arm", "failures.png")
