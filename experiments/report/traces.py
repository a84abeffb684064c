"""The report's plots drawn from the episodes' force traces (``episodes/<key>/forces.npz``): the
aligned force profiles and the force against depth. Both are left out when the traces are not
in the sweep's directory."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.experiments.report.axes import contact_tasks, episode_dir
from peg_ctrl.experiments.stats import inserts_from_contact
from peg_ctrl.run.plots import save_figure
from peg_ctrl.tasks.monitors import FIRST_CONTACT_N

__all__ = ["has_traces", "force_profiles", "force_vs_depth"]

_SEATED, _FAILED = "#2ca02c", "#d62728"


def has_traces(out_dir: Path, df: Any) -> bool:
    """Whether the sweep's episode directories (with their force traces) are present."""
    if "log_path" not in df:
        return False
    return any((episode_dir(out_dir, p) / "forces.npz").is_file() for p in df["log_path"])


def force_profiles(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Per arm, one panel: the peg-block (and peg-table, if ever touched) force against the time
    from the first contact (a task that inserts from it, see
    :func:`~peg_ctrl.experiments.stats.inserts_from_contact`) or the insert/release phase,
    median and 10-90 %."""
    import matplotlib.pyplot as plt

    grid = np.linspace(-1.0, 2.0, 301)
    columns = {"block-peg": ("peg-block", "C0"), "peg-table": ("peg-table", "C1")}
    curves: dict[str, dict[str, list[np.ndarray]]] = {a: {c: [] for c in columns} for a in arms}
    for arm, log_path in zip(df["arm"], df["log_path"], strict=True):
        aligned = _aligned_forces(episode_dir(out_dir, log_path), tuple(columns), grid)
        for column, curve in (aligned or {}).items():
            curves[arm][column].append(curve)
    touched = [c for c in columns if any(np.nanmax(x, initial=0.0) > 0 for a in arms for x in curves[a][c])]
    ncols = min(4, len(arms))
    nrows = math.ceil(len(arms) / ncols)
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(max(3.4 * ncols + 0.6, 7.0), 2.5 * nrows + 0.8),  # wide enough for the axis label
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
    fig.supxlabel(_time_axis(df))
    fig.supylabel("net contact force [N]")
    save_figure(fig, out_dir / "force_profiles.png")
    return ("Force profiles", "force_profiles.png")


def _time_axis(df: Any) -> str:
    """The force profiles' time axis: what its zero is, naming the tasks aligned at the contact."""
    tasks = contact_tasks(df)
    start = f"the first peg-block contact ({tasks}) or " if tasks else ""
    return f"time from {start}the insert/release phase [s]"


def force_vs_depth(out_dir: Path, df: Any, arms: list[str]) -> tuple[str, str]:
    """Peg-block force against the depth of the peg's lower end, up to 12 episodes per arm (of
    the episodes that insert from the first contact)."""
    import matplotlib.pyplot as plt

    contact = df[inserts_from_contact(df)]
    cols = min(3, len(arms))
    nrows = math.ceil(len(arms) / cols)
    fig, axes = plt.subplots(
        nrows, cols, figsize=(5.2 * cols, 3.4 * nrows + 0.4), dpi=110, squeeze=False, layout="constrained"
    )
    step = max(1, len(contact) // (len(arms) * 12))
    for ax, arm in zip(axes.flat, arms, strict=False):
        picked = contact[contact["arm"] == arm].iloc[::step].head(12)
        for log_path, ok in zip(picked["log_path"], picked["won"], strict=True):
            trace = _trace(episode_dir(out_dir, log_path))
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
    peg-block contact (an episode with an insertion strategy, see
    :func:`~peg_ctrl.experiments.stats.inserts_from_contact`) or the start of its insert (else
    release) phase."""
    summary = episode_dir / "summary.json"
    trace = episode_dir / "forces.npz"
    if not (summary.is_file() and trace.is_file()):
        return None
    record = json.loads(summary.read_text())
    phases = record.get("phases", [])
    if record.get("strategy"):  # it inserts from the first peg-block contact: aligned there
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
