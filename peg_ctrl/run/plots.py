"""Plots of an episode: its contact forces against time, in stacked panels, phases shaded.

:func:`plot_force_profile` draws, sharing one time axis:

- a strip naming the task's phases (a name is shortened, or left out, where its span is too
  narrow to hold it);
- the grasp, on its own scale: the grip (the finger pads' squeeze on the peg) and the net
  gripper-peg contact force, the load the grasp carries (a fraction of a newton while the peg is
  carried, next to tens of newtons in the hole). Both axes run from zero to 1.4 times their
  highest value, so that a grip held at one value throughout (a held insertion) is a line below
  the legend, not one hidden on the axis's top edge;
- the insertion: the peg-block contact force;
- every other contact pair that carried a force (the peg on the table, the fingers on the block
  or the table), if any did;
- the height of the peg's lower end above the hole's mouth (negative: below it).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from peg_ctrl.io import atomic_path

__all__ = ["force_profile_figure", "plot_force_profile", "PHASE_COLOURS", "pyplot", "save_figure"]

#: Phase name -> colour of its span (the strip at the top; the panels shade it lighter).
PHASE_COLOURS = {
    "approach": "#c7c7c7",
    "descend": "#aec7e8",
    "grasp": "#98df8a",
    "lift": "#ffbb78",
    "rotate": "#c5b0d5",
    "align": "#9edae5",
    "insert": "#ff9896",
    "release": "#dbdb8d",
    "settle": "#f7b6d2",
    "push": "#ff9896",  # held insertion
    "search": "#98df8a",
    "slide": "#98df8a",
    "straighten": "#c5b0d5",
}
_UNKNOWN_PHASE = "#e0e0e0"
_GRIP, _INSERT = "gripper-peg", "block-peg"
#: The grasp panel's axes reach this factor times their highest value (room for the legend).
GRASP_HEADROOM = 1.4


def pyplot() -> Any:
    """``matplotlib.pyplot`` with the headless Agg backend (every plot of the package is a file)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path, **savefig: Any) -> Path:
    """Write ``fig`` to ``path`` atomically (a whole image or none: :func:`~peg_ctrl.io.atomic_path`)
    and close it, also when writing fails; ``savefig`` goes to ``Figure.savefig``."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, **savefig)
    finally:
        pyplot().close(fig)
    return path


def plot_force_profile(trace_npz: Path, phases: Sequence[dict[str, Any]], out: Path) -> Path:
    """Draw an episode's force profile (:func:`force_profile_figure`) as a PNG and return its path.

    Args:
        trace_npz: the episode's ``forces.npz`` (columns
            :data:`~peg_ctrl.run.episode_log.TRACE_COLUMNS`: time [s], forces [N], depth [m]).
        phases: the phase records (``phase``, ``t_start`` [s], ``t_end`` [s] or None while the
            phase was still running at the end), as in ``summary.json``.
        out: the PNG to write (its directory is created).
    """
    fig = force_profile_figure(trace_npz, phases)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, out)


def force_profile_figure(trace_npz: Path, phases: Sequence[dict[str, Any]]) -> Any:
    """The force profile's matplotlib ``Figure`` (arguments as for :func:`plot_force_profile`),
    open: the caller saves or closes it."""
    trace = _Trace(trace_npz)
    spans = _phase_spans(phases, trace.t_last)
    others = [
        c
        for c in trace.columns
        if "-" in c and c not in (_GRIP, _INSERT) and (v := trace.column(c)) is not None and np.any(v > 0)
    ]
    depth = trace.column("peg_depth_m")
    panels = ["grip", "insert", *(["others"] if others else []), *(["height"] if depth is not None else [])]
    heights = {"grip": 1.0, "insert": 1.3, "others": 0.8, "height": 0.9}
    fig, axes = pyplot().subplots(
        len(panels) + 1,
        1,
        figsize=(10, 1.9 * len(panels) + 1.2),
        dpi=110,
        sharex=True,
        height_ratios=[0.28, *(heights[p] for p in panels)],
        layout="constrained",
    )
    strip, panel_axes = axes[0], dict(zip(panels, axes[1:], strict=True))
    _grip_panel(panel_axes["grip"], trace)
    _insert_panel(panel_axes["insert"], trace)
    if others:
        _others_panel(panel_axes["others"], trace, others)
    if depth is not None:
        _height_panel(panel_axes["height"], trace.t, depth)
    for ax in panel_axes.values():
        ax.grid(alpha=0.3)
        ax.margins(x=0)
        for name, start, end in spans:
            ax.axvspan(start, end, color=PHASE_COLOURS.get(name, _UNKNOWN_PHASE), alpha=0.3, lw=0, zorder=0)
    panel_axes["insert"].set_ylim(bottom=0.0)
    axes[-1].set_xlabel("time [s]")
    axes[-1].set_xlim(0.0, trace.t_last)
    _phase_strip(fig, strip, spans)
    fig.suptitle("Contact forces by phase", fontsize=11)
    return fig


class _Trace:
    """An episode's ``forces.npz``: its columns by name, and time."""

    def __init__(self, trace_npz: Path) -> None:
        with np.load(trace_npz) as npz:
            self.columns = [str(c) for c in npz["columns"]]
            self.data = np.asarray(npz["data"], dtype=float)
        self.t = self.data[:, self.columns.index("t")] if len(self.data) else np.zeros(0)
        self.t_last = float(self.t[-1]) if len(self.t) else 1.0

    def column(self, name: str) -> np.ndarray | None:
        """The column ``name``, or None when the trace has no such column or no rows."""
        return self.data[:, self.columns.index(name)] if name in self.columns and len(self.data) else None

    def draw(self, ax: Any, name: str, label: str, colour: str, lw: float = 0.9) -> None:
        """Plot column ``name`` against time on ``ax``, if there is one."""
        values = self.column(name)
        if values is not None:
            ax.plot(self.t, values, lw=lw, color=colour, label=label)


def _phase_spans(phases: Sequence[dict[str, Any]], t_last: float) -> list[tuple[str, float, float]]:
    """(name, start, end) of each phase that started; one still running ends at ``t_last``."""
    return [
        (
            str(rec["phase"]),
            float(rec["t_start"]),
            float(rec["t_end"] if rec.get("t_end") is not None else t_last),
        )
        for rec in phases
        if rec.get("t_start") is not None
    ]


def _grip_panel(grip_ax: Any, trace: _Trace) -> None:
    """The pads' squeeze (left axis) and the net gripper-peg force, the load (right axis)."""
    load_ax = grip_ax.twinx()  # the net load is a fraction of a newton next to tens of the squeeze
    trace.draw(grip_ax, "grip_force_n", "grip: the pads' squeeze (left axis)", "C1", lw=1.1)
    trace.draw(load_ax, _GRIP, "net gripper-peg force: the load carried (right axis)", "C2")
    grip_ax.set_ylabel("grip [N]", color="C1")
    load_ax.set_ylabel("load [N]", color="C2")
    _from_zero(grip_ax, trace.column("grip_force_n"))
    _from_zero(load_ax, trace.column(_GRIP))
    grip_ax.set_title("grasp", fontsize=8, loc="left")
    handles = grip_ax.get_lines() + load_ax.get_lines()
    if handles:
        grip_ax.legend(handles, [h.get_label() for h in handles], loc="upper left", fontsize=7, ncol=2)


def _from_zero(ax: Any, values: np.ndarray | None) -> None:
    """The y axis from zero to :data:`GRASP_HEADROOM` times the highest of ``values``
    (autoscaling would put a constant line on the top edge), or from zero as autoscaled when
    there is no positive value."""
    top = float(np.max(values)) if values is not None and len(values) else 0.0
    if np.isfinite(top) and top > 0.0:
        ax.set_ylim(0.0, GRASP_HEADROOM * top)
    else:
        ax.set_ylim(bottom=0.0)


def _insert_panel(ax: Any, trace: _Trace) -> None:
    """The peg-block contact force, or a note that there was none."""
    trace.draw(ax, _INSERT, "peg-block", "C3")
    ax.set_ylabel("insertion [N]")
    ax.set_title("peg-block contact force", fontsize=8, loc="left")
    insert = trace.column(_INSERT)
    if insert is None or not np.any(insert > 0):
        ax.text(
            0.5,
            0.5,
            "the peg never touched the block",
            transform=ax.transAxes,
            ha="center",
            va="center",
            fontsize=9,
            color="0.35",
        )


def _others_panel(ax: Any, trace: _Trace, others: list[str]) -> None:
    """Every other contact pair that carried force."""
    for k, name in enumerate(others):
        trace.draw(ax, name, name, f"C{(k + 4) % 10}", lw=0.8)
    ax.set_ylabel("other [N]")
    ax.set_title("other contacts", fontsize=8, loc="left")
    ax.legend(loc="upper left", fontsize=7, ncol=len(others))


def _height_panel(ax: Any, t: np.ndarray, depth: np.ndarray) -> None:
    """The peg's lower end above the hole's mouth (negative depth) [mm]."""
    ax.plot(t, -depth * 1e3, lw=1.0, color="C0")
    ax.axhline(0.0, color="0.3", lw=0.7, ls="--")
    ax.set_ylabel("height [mm]")
    ax.set_title("height of the peg's lower end above the hole's mouth (dashed)", fontsize=8, loc="left")


def _phase_strip(fig: Any, ax: Any, spans: list[tuple[str, float, float]]) -> list[str]:
    """Coloured spans with the phase names inside them; a name that does not fit its span is
    shortened to three letters, and left out if even that does not fit. Returns the labels
    drawn, in order."""
    ax.set_yticks([])
    ax.set_ylim(0.0, 1.0)
    for side in ("top", "right", "left"):
        ax.spines[side].set_visible(False)
    ax.tick_params(axis="x", which="both", length=0)
    for name, start, end in spans:
        ax.axvspan(start, end, color=PHASE_COLOURS.get(name, _UNKNOWN_PHASE), lw=0.5, ec="white")
    fig.canvas.draw()  # the final layout, to measure the labels against their spans
    renderer = fig.canvas.get_renderer()
    drawn = []
    for name, start, end in spans:
        (x0, _), (x1, _) = ax.transData.transform([(start, 0.0), (end, 0.0)])
        for text in (name, name[:3] + "."):
            label = ax.text(
                0.5 * (start + end), 0.5, text, ha="center", va="center", fontsize=8, clip_on=True
            )
            if label.get_window_extent(renderer).width <= 0.92 * (x1 - x0):
                drawn.append(text)
                break
            label.remove()
    return drawn
