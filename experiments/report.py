"""Summary statistics, plots and the Markdown report of a sweep (also ``peg-sim plot DIR``).

Every table and plot is drawn from ``episodes.csv`` alone, except the two that need the
episodes' force traces (``episodes/<key>/forces.npz``): the aligned force profiles and force
against depth, which are left out (and the report says so) when the traces are not there.
"""

from __future__ import annotations

import csv
import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.stats import ALPHA, compare_arms, episodes_frame, median_ci, wilson_interval
from peg_ctrl.io import atomic_write_text
from peg_ctrl.run.episode import COST_FIELDS
from peg_ctrl.run.plots import pyplot, save_figure
from peg_ctrl.tasks.monitors import FIRST_CONTACT_N

__all__ = [
    "wilson_interval",
    "summarise",
    "write_report",
    "read_rows",
    "episodes_csv_problem",
    "arm_of",
    "swept_conditions",
]

# Swept episode fields with a readable axis: column -> (label, factor from the column's unit).
_CONDITION_LABELS = {
    "clearance_m": ("radial hole clearance [mm]", 1e3),
    "task.lateral_error": ("lateral error at first contact [mm]", 1e3),
    "task.tilt_error": ("peg tilt in the grasp [deg]", 180.0 / math.pi),
    "task.position_noise": ("noise on the observed hole position [mm]", 1e3),
    "scene.friction": ("friction coefficient", 1.0),
    "domain.ft_sensor": ("force/torque sensor model", 1.0),
    "peg_mass_scale": ("peg mass scale (drawn per seed)", 1.0),
    "friction_scale": ("friction scale (drawn per seed)", 1.0),
    "gain_scale": ("controller gain scale (drawn per seed)", 1.0),
}
_DOMAIN_COLUMNS = ("peg_mass_scale", "friction_scale", "gain_scale")
_MAX_CELL_COLUMNS = 12  # a larger grid's success table is folded onto its axes
_MAX_LEVELS = 6  # a condition with more distinct values than this is drawn in quartile bins
_SEATED, _FAILED = "#2ca02c", "#d62728"
_CAPTIONS = {
    "force_profiles.png": "Per arm, the median (line) and 10-90 % band of the contact force against "
    "time, aligned at the first peg-block contact (held insertion) or at the start of the insert "
    "(else release) phase (dotted line).",
    "success_vs_clearance.png": "Success rate with 95 % Wilson intervals at each clearance, pooled "
    "over the other conditions; one row of panels per strategy, one colour per controller.",
    "success_vs_disturbance.png": "Success rate with 95 % Wilson intervals against each condition "
    "the experiment varies, pooled over the others; one row of panels per strategy, one colour per "
    "controller. A condition drawn per seed (mass, friction, gain scale) is grouped in quartile "
    "bins, plotted at the bin's median.",
    "peak_force.png": "The peak peg-block force of every episode (dots: green inserted, red failed), "
    "its distribution (violin) and box (median, quartiles, whiskers to 1.5 IQR) per arm.",
    "failures.png": "Episodes per arm: inserted, or the failure reason and the phase the episode ended in.",
    "force_vs_depth.png": "Peg-block force against the depth of the peg's lower end, from the first "
    "contact, for up to 12 episodes per arm.",
}


def _float(value: Any) -> float | None:
    if value in (None, ""):
        return None
    return float(value)


def arm_of(row: dict[str, Any]) -> str:
    """The row's arm: controller, and strategy when the sweep has them."""
    return str(row.get("arm") or row["controller"])


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per arm (controller/strategy) x planner x clearance, in order of first appearance: success
    rate with its 95 % Wilson interval, peak peg-block force [N] median (bootstrap 95 % interval)
    and p95 and share within 10 N, time to insert [s] median (interval), contact to seated [s]
    median and p95, impulse [N s] median
    and the failure reasons."""
    if not rows:
        return []
    df = episodes_frame(rows)
    df["won"] = df["status"] == "success"
    out = []
    for (arm, planner, clearance), group in df.groupby(["arm", "planner", "clearance_m"], sort=False):
        n = len(group)
        wins = int(group["won"].sum())
        lo, hi = wilson_interval(wins, n)
        forces = group["peak_contact_force_n"].to_numpy(dtype=float)
        won = group[group["won"]]
        times = won["time_to_insert_s"].dropna().tolist()
        seat = won["contact_to_seat_s"].dropna().tolist() if "contact_to_seat_s" in won else []
        impulses = group["contact_impulse_ns"].dropna().tolist() if "contact_impulse_ns" in group else []
        reasons = group.loc[~group["won"], "reason"].value_counts().sort_index()
        force_ci = median_ci(forces.tolist())
        time_ci = median_ci(times)
        out.append(
            {
                "controller": str(arm),
                "planner": str(planner),
                "clearance_m": float(clearance),
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
                "contact_to_seat_p95_s": float(np.percentile(seat, 95)) if seat else None,
                "peak_force_within_10n": float(np.mean(forces <= 10.0)),
                "impulse_median_ns": float(np.median(impulses)) if impulses else None,
                "failure_reasons": ";".join(f"{k}:{v}" for k, v in reasons.items()),
            }
        )
    return out


def read_rows(out_dir: Path) -> list[dict[str, Any]]:
    """The rows of ``out_dir/episodes.csv`` (values as strings)."""
    with open(Path(out_dir) / "episodes.csv", newline="") as fh:
        return list(csv.DictReader(fh))


# Columns the report cannot be drawn without, and the ones it reads as numbers.
_REQUIRED_COLUMNS = (
    "key",
    "controller",
    "planner",
    "clearance_m",
    "status",
    "reason",
    "peak_contact_force_n",
    "time_to_insert_s",
)
_NUMBER_COLUMNS = ("clearance_m", "peak_contact_force_n", "time_to_insert_s", "contact_to_seat_s")
_STATUSES = ("success", "failure")


def episodes_csv_problem(path: Path) -> str | None:
    """What makes ``path`` (an ``episodes.csv``) unusable for a report, in a few words, or None.

    Found: a missing, unreadable, empty or non-text file; NUL bytes (a torn write); a file cut
    off (its last line has no line end, or a row has fewer fields than the header); a row with
    more fields; a column the report needs missing; a status other than success or failure; a
    metric that is not a number.
    """
    import io

    try:
        text = Path(path).read_bytes().decode("utf-8")
    except FileNotFoundError:
        return "does not exist"
    except OSError as exc:
        return f"cannot be read: {exc.strerror or exc}"
    except UnicodeDecodeError as exc:
        return f"is not text (byte {exc.start} is not UTF-8)"
    if not text:
        return "is empty"
    if "\0" in text:  # a torn write after a crash leaves zero-filled blocks
        line = text.count("\n", 0, text.index("\0")) + 1
        return f"is damaged: line {line} holds NUL bytes"
    if not text.endswith("\n"):
        last = text.count("\n") + 1
        return f"is cut off: its last line ({last}) has no line end"
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader)
        missing = [name for name in _REQUIRED_COLUMNS if name not in header]
        if missing:
            return f"has no column {', '.join(missing)} (line 1)"
        numbers = [(header.index(name), name) for name in _NUMBER_COLUMNS if name in header]
        status = header.index("status")
        for fields in reader:
            line = reader.line_num
            if len(fields) < len(header):
                return f"is cut off or damaged: line {line} has {len(fields)} of {len(header)} fields"
            if len(fields) > len(header):
                return f"is damaged: line {line} has {len(fields)} fields, the header {len(header)}"
            if fields[status] not in _STATUSES:
                return f"is damaged: line {line} has status {fields[status]!r} (not success or failure)"
            for i, name in numbers:
                try:
                    float(fields[i] or 0.0)
                except ValueError:
                    return f"is damaged: line {line} has {name} {fields[i]!r} (not a number)"
    except csv.Error as exc:
        return f"is damaged: line {reader.line_num}: {exc}"
    return None


def swept_conditions(df: Any) -> list[str]:
    """The columns of an :func:`~peg_ctrl.experiments.stats.episodes_frame` that the experiment
    varies and that success can be plotted against: the clearance, every grid key (dotted
    column) and the per-seed domain draws, each when it takes more than one value."""
    candidates = ["clearance_m", *[c for c in df.columns if "." in c], *_DOMAIN_COLUMNS]
    found: list[str] = []
    for column in candidates:
        if column not in df or df[column].astype(str).nunique() < 2:
            continue
        numeric = _numeric(df[column]).notna().all()
        if not numeric and "." not in column:
            continue  # a named grid value (a sensor preset) is a condition; other text is not
        if any(_same_levels(df, column, seen) for seen in found):
            continue  # moves with an earlier condition (a linked grid axis): one plot says it
        found.append(column)
    return found


def _same_levels(df: Any, a: str, b: str) -> bool:
    """Whether each value of column ``a`` goes with one value of ``b`` and back."""
    pairs = df[[a, b]].astype(str).drop_duplicates()
    return bool(pairs[a].is_unique and pairs[b].is_unique)


def _numeric(series: Any) -> Any:
    import pandas as pd

    return pd.to_numeric(series.replace("", np.nan), errors="coerce").astype(float)


def _split_arm(arm: str) -> tuple[str, str]:
    controller, _, strategy = arm.partition("/")
    return controller, strategy


def _controller_colours(arms: list[str]) -> dict[str, Any]:
    """One colour per controller (strategies of one controller share it), from tab10/tab20."""
    import matplotlib

    controllers = list(dict.fromkeys(_split_arm(a)[0] for a in arms))
    cmap = matplotlib.colormaps["tab10" if len(controllers) <= 10 else "tab20"]
    return {c: cmap(i % cmap.N) for i, c in enumerate(controllers)}


def _plots(out_dir: Path, rows: list[dict[str, Any]], summary: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """Draw the report's plots into ``out_dir``; returns (title, file name) of each one drawn."""
    pyplot()  # the headless backend, before any figure

    df = episodes_frame(rows)
    df["won"] = df["status"] == "success"
    arms = list(dict.fromkeys(df["arm"]))
    made: list[tuple[str, str]] = []
    traced = _has_traces(out_dir, df)
    if traced:
        made.append(_force_profiles(out_dir, df, arms))
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
    if traced and "task" in df and (df["task"] == "held_insertion").any():
        made.append(_force_vs_depth(out_dir, df, arms))
    return made


def _episode_dir(out_dir: Path, log_path: Any) -> Path:
    return out_dir / Path(str(log_path)).parent


def _has_traces(out_dir: Path, df: Any) -> bool:
    """Whether the sweep's episode directories (with their force traces) are present."""
    if "log_path" not in df:
        return False
    return any((_episode_dir(out_dir, p) / "forces.npz").is_file() for p in df["log_path"])


def _force_profiles(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Per arm, one panel: the peg-block (and peg-table, if ever touched) force against the time
    from the first contact (held insertion) or the insert/release phase, median and 10-90 %."""
    import matplotlib.pyplot as plt

    grid = np.linspace(-1.0, 2.0, 301)
    columns = {"block-peg": ("peg-block", "C0"), "peg-table": ("peg-table", "C1")}
    curves: dict[str, dict[str, list[np.ndarray]]] = {a: {c: [] for c in columns} for a in arms}
    for arm, log_path in zip(df["arm"], df["log_path"], strict=True):
        aligned = _aligned_forces(_episode_dir(out_dir, log_path), tuple(columns), grid)
        for column, curve in (aligned or {}).items():
            curves[arm][column].append(curve)
    touched = [c for c in columns if any(np.nanmax(x, initial=0.0) > 0 for a in arms for x in curves[a][c])]
    ncols = min(4, len(arms))
    nrows = math.ceil(len(arms) / ncols)
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(3.4 * ncols + 0.6, 2.5 * nrows + 0.8),
        dpi=110,
        sharex=True,
        sharey=True,
        squeeze=False,
        layout="constrained",
    )
    for ax, arm in zip(axes.flat, arms, strict=False):
        n = 0
        for column in touched or ["block-peg"]:
            label, colour = columns[column]
            if not curves[arm][column]:
                continue
            stack = np.vstack(curves[arm][column])
            n = len(stack)
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # depths no episode reached: NaN
                ax.fill_between(
                    grid,
                    np.nanpercentile(stack, 10, axis=0),
                    np.nanpercentile(stack, 90, axis=0),
                    color=colour,
                    alpha=0.25,
                    lw=0,
                )
                ax.plot(grid, np.nanmedian(stack, axis=0), color=colour, lw=1.2, label=label)
        ax.axvline(0.0, color="0.4", lw=0.8, ls=":")
        ax.set_title(f"{arm} (n={n})", fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(arms) :]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    if handles:
        fig.legend(
            handles, [f"{x} force: median, 10-90 %" for x in labels], loc="outside upper center", ncol=2
        )
    fig.supxlabel("time from the first peg-block contact (held insertion) or the insert/release phase [s]")
    fig.supylabel("net contact force [N]")
    save_figure(fig, out_dir / "force_profiles.png")
    return ("Force profiles", "force_profiles.png")


def _success_curves(
    out_dir: Path, df: Any, arms: list[str], conditions: list[str], name: str, *, log_x: bool = False
) -> tuple[str, str]:
    """Success rate with 95 % Wilson intervals against each swept condition (columns), one row
    of panels per strategy, one line per controller; pooled over the other conditions."""
    import matplotlib.pyplot as plt

    strategies = list(dict.fromkeys(_split_arm(a)[1] for a in arms))
    colours = _controller_colours(arms)
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
        label, scale = _CONDITION_LABELS.get(column, (column, 1.0))
        table = _success_table(df, column)
        for i, strategy in enumerate(strategies):
            ax = axes[i][j]
            members = [a for a in arms if _split_arm(a)[1] == strategy]
            for k, arm in enumerate(members):
                pts = table[table["arm"] == arm]
                if pts.empty:
                    continue
                x = pts["x"].to_numpy() * scale
                offset = (k - (len(members) - 1) / 2) * 0.012
                x = x * (1.0 + 2 * offset) if log_x else x + offset * (np.ptp(x) or 1.0)  # dodge
                y = pts["rate"].to_numpy()
                err = [np.clip(y - pts["low"], 0.0, None), np.clip(pts["high"] - y, 0.0, None)]
                controller = _split_arm(arm)[0]
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


def _success_table(df: Any, column: str) -> Any:
    """Per arm and level of ``column``: x (the level, or the median of a quartile bin), successes
    ``k`` of ``n``, ``rate`` and its Wilson interval ``low``/``high``."""
    import pandas as pd

    values = _numeric(df[column])
    labels: list[str] = []
    if values.isna().any():  # named levels (a sensor preset): at 0, 1, ... in the file's order
        labels = list(dict.fromkeys(df[column].astype(str)))
        values = df[column].astype(str).map({v: float(i) for i, v in enumerate(labels)})
    binned = not labels and values.nunique() > _MAX_LEVELS
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


def _peak_force(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Per arm: the distribution of the peak peg-block force (violin, box, and every episode as
    a dot, green inserted, red not)."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    colours = _controller_colours(arms)
    rng = np.random.default_rng(0)  # the dots' horizontal jitter only
    fig, ax = plt.subplots(figsize=(max(6.0, 0.8 * len(arms) + 2.0), 4.6), dpi=110, layout="constrained")
    for i, arm in enumerate(arms):
        group = df[df["arm"] == arm]
        y = group["peak_contact_force_n"].to_numpy(dtype=float)
        ok = group["won"].to_numpy()
        keep = np.isfinite(y)
        y, ok = y[keep], ok[keep]
        if len(y) == 0:
            continue
        if len(y) >= 2 and np.ptp(y) > 0:
            violin: Any = ax.violinplot([y], positions=[i], widths=0.8, showextrema=False)
            for body in violin["bodies"]:
                body.set_facecolor(colours[_split_arm(arm)[0]])
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
    ax.set_ylabel("peak peg-block contact force [N]")
    ax.set_title("Peak peg-block force per arm (every episode a dot)", fontsize=10)
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


def _force_vs_depth(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Peg-block force against the depth of the peg's lower end, up to 12 episodes per arm."""
    import matplotlib.pyplot as plt

    held = df[df["task"] == "held_insertion"]
    cols = min(3, len(arms))
    nrows = math.ceil(len(arms) / cols)
    fig, axes = plt.subplots(
        nrows, cols, figsize=(5.2 * cols, 3.4 * nrows + 0.4), dpi=110, squeeze=False, layout="constrained"
    )
    step = max(1, len(held) // (len(arms) * 12))
    for ax, arm in zip(axes.flat, arms, strict=False):
        picked = held[held["arm"] == arm].iloc[::step].head(12)
        for log_path, ok in zip(picked["log_path"], picked["won"], strict=True):
            trace = _trace(_episode_dir(out_dir, log_path))
            if trace is None:
                continue
            depth, force = trace
            ax.plot(depth * 1e3, force, lw=0.7, alpha=0.7, color=_SEATED if ok else _FAILED)
        ax.set_title(f"{arm} (green: seated, red: not)", fontsize=9)
        ax.set_xlabel("depth of the peg's lower end [mm]")
        ax.set_ylabel("peg-block force [N]")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(arms) :]:
        ax.set_visible(False)
    save_figure(fig, out_dir / "force_vs_depth.png")
    return ("Force against depth", "force_vs_depth.png")


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


def _aligned_forces(
    episode_dir: Path, columns: tuple[str, ...], grid: np.ndarray
) -> dict[str, np.ndarray] | None:
    """The episode's force ``columns`` [N] on ``grid`` [s], time measured from its first
    peg-block contact (held insertion) or the start of its insert (else release) phase."""
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
        names = [str(c) for c in npz["columns"]]
        data = npz["data"]
    if len(data) == 0:
        return None
    t = data[:, names.index("t")] - starts[0]
    return {
        c: np.interp(grid, t, data[:, names.index(c)], left=np.nan, right=np.nan)
        for c in columns
        if c in names
    }


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
    df = episodes_frame(rows)
    keys = [k for k in df.columns if "." in k]  # the grid's dotted keys
    if not keys:
        return []
    df["won"] = df["status"] == "success"
    cells = list(dict.fromkeys(df[keys].itertuples(index=False, name=None)))
    if len(cells) > _MAX_CELL_COLUMNS:
        return _condition_section(df, keys)
    by_cell = df.groupby(["arm", *keys], sort=False).agg(
        wins=("won", "sum"), n=("won", "size"), force=("peak_contact_force_n", "median")
    )
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
    import pandas as pd

    column = (
        "contact_to_seat_s" if df.get("contact_to_seat_s", pd.Series()).notna().any() else "time_to_insert_s"
    )
    df["time"] = pd.to_numeric(df[column].replace("", np.nan), errors="coerce")
    levels = [(k, v) for k in keys for v in dict.fromkeys(df[k])]
    lines = [
        "## Success per condition",
        "",
        f"The grid has {len(set(df[keys].itertuples(index=False, name=None)))} cells; each column "
        "pools the episodes at one level of one grid key (every cell per episode: episodes.csv). "
        "Successes / episodes, median peak peg-block force [N], median time to insert [s] "
        "(successes; for a held insertion from first contact to seated).",
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
                f"{int(at['won'].sum())}/{len(at)}, {at['peak_contact_force_n'].median():.1f} N, "
                + ("–" if np.isnan(time) else f"{time:.1f} s")
            )
        lines.append(f"| {arm} | " + " | ".join(texts) + " |")
    return [*lines, ""]


_UNTIMED_PHASES = ("start", "settle", "hold", "done")  # not part of getting the peg in


def _phase_section(out_dir: Path, rows: list[dict[str, Any]]) -> list[str]:
    """Where the time goes: per arm, the median duration of each phase over its successes (read
    from the episodes' summary.json; left out without them)."""
    per_arm: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        if row.get("status") != "success" or not row.get("log_path"):
            continue
        path = _episode_dir(out_dir, row["log_path"]) / "summary.json"
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


def _cost_section(rows: list[dict[str, Any]]) -> list[str]:
    """Wall time of the controller per control step, and of its optimiser per solve, per arm."""
    import pandas as pd

    df = episodes_frame(rows)
    if "control_time_p50_s" not in df:
        return []
    for column in COST_FIELDS:
        values = df[column].replace("", np.nan) if column in df else np.nan
        df[column] = pd.to_numeric(values, errors="coerce")
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


def write_report(out_dir: Path, *, elapsed_s: float | None = None) -> Path:
    """Draw the plots and write ``report.md`` from the saved ``episodes.csv``; returns its path."""
    out_dir = Path(out_dir)
    rows = read_rows(out_dir)
    summary = summarise(rows)
    plots = _plots(out_dir, rows, summary) if rows else []
    exp = (
        json.loads((out_dir / "experiment.json").read_text())
        if (out_dir / "experiment.json").is_file()
        else {}
    )
    parts = [
        *_header_section(exp, out_dir.name, rows, elapsed_s),
        *_summary_section(summary),
        *_cell_section(rows),
        *_comparison_section(rows),
        *_phase_section(out_dir, rows),
        *_cost_section(rows),
        *_plots_section(rows, plots),
    ]
    path = out_dir / "report.md"
    atomic_write_text(path, "\n".join(parts))
    return path


def _header_section(
    exp: dict[str, Any], default_name: str, rows: list[dict[str, Any]], elapsed_s: float | None
) -> list[str]:
    """The title and one line of what was run."""
    clearances = ", ".join(f"{c * 1e3:g} mm" for c in exp.get("clearances", []))
    return [
        f"# Experiment report: {exp.get('name', default_name)}",
        "",
        f"{len(rows)} episodes: arms {', '.join(dict.fromkeys(arm_of(r) for r in rows))}; "
        f"planners {', '.join(exp.get('planners', []))}; clearances "
        f"{clearances}; {len(exp.get('seeds', []))} seeds; physics profile "
        f"`{exp.get('physics', {}).get('profile', 'seed')}`."
        + (f" Run time {elapsed_s:.0f} s." if elapsed_s is not None else ""),
        "",
    ]


def _summary_section(summary: list[dict[str, Any]]) -> list[str]:
    """Success, peak force, time to insert and failures per arm, planner and clearance."""
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
        s["within"] = f"{100 * s['peak_force_within_10n']:.0f} %"
    columns = [
        ("controller", "arm"),
        ("planner", "planner"),
        ("clearance_mm", "clearance [mm]"),
        ("success", "success"),
        ("ci", "95 % CI"),
        ("peak_force_median_n", "peak force median [N]"),
        ("force_ci", "95 % CI"),
        ("peak_force_p95_n", "peak force p95 [N]"),
        ("within", "peak ≤ 10 N"),
        ("time_to_insert_median_s", "time to insert [s]"),
        ("time_ci", "95 % CI"),
        ("contact_to_seat_median_s", "contact to seated median [s]"),
        ("contact_to_seat_p95_s", "p95 [s]"),
        ("impulse_median_ns", "impulse median [N s]"),
        ("failure_reasons", "failures"),
    ]
    return ["## Summary", "", _table(summary, columns), ""]


def _plots_section(rows: list[dict[str, Any]], plots: list[tuple[str, str]]) -> list[str]:
    """Each plot with its caption (or why the force plots are missing)."""
    parts: list[str] = []
    if rows and "force_profiles.png" not in {name for _, name in plots}:
        parts += [
            "The episodes' force traces (`episodes/<key>/forces.npz`) are not in this directory, so "
            "the force profiles and force against depth are not drawn.",
            "",
        ]
    for title, name in plots:
        parts += [f"## {title}", "", _CAPTIONS.get(name, ""), "", f"![{title}]({name})", ""]
    return parts
