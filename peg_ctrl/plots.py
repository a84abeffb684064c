"""Plots of an episode: contact force per body-group pair against time, phases shaded."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_force_profile"]

_PHASE_COLOURS = {
    "approach": "#f2f2f2",
    "descend": "#e6eef7",
    "grasp": "#e8f4e8",
    "lift": "#fff6e0",
    "rotate": "#f6e8f4",
    "align": "#e7f6f6",
    "insert": "#fbe9e7",
    "release": "#eeeeee",
    "settle": "#f7f7e8",
    "push": "#fbe9e7",  # held insertion
    "search": "#eef7e0",
    "slide": "#eef7e0",
    "straighten": "#f6e8f4",
}


def plot_force_profile(trace_npz: Path, phases: Sequence[dict[str, Any]], out: Path) -> Path:
    """Contact force magnitude per pair vs time, with each phase shaded and labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with np.load(trace_npz) as npz:
        columns = [str(c) for c in npz["columns"]]
        trace = npz["data"]
    fig, ax = plt.subplots(figsize=(10, 4.5), dpi=110)
    if len(trace):
        t = trace[:, columns.index("t")]
        for k, name in enumerate(columns):
            if "-" not in name:
                continue
            values = trace[:, k]
            if np.any(values > 0):
                ax.plot(t, values, lw=1.0, label=name)
        top = max(1e-3, float(np.nanmax(trace[:, [i for i, c in enumerate(columns) if "-" in c]])))
    else:
        top = 1.0
    for rec in phases:
        if rec.get("phase") in _PHASE_COLOURS and rec.get("t_end") is not None:
            ax.axvspan(rec["t_start"], rec["t_end"], color=_PHASE_COLOURS[rec["phase"]], zorder=0)
            ax.text(
                0.5 * (rec["t_start"] + rec["t_end"]),
                top * 1.02,
                rec["phase"],
                ha="center",
                va="bottom",
                fontsize=7,
                rotation=90,
            )
    ax.set_ylim(0, top * 1.25)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("net contact force [N]")
    ax.set_title("Contact force per body pair")
    ax.legend(loc="upper left", fontsize=8, ncol=3)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out
