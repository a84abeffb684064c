"""The episode force-profile plot: panels for grip and insertion, labelled phases that fit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from peg_ctrl.run.episode_log import TRACE_COLUMNS
from peg_ctrl.run.plots import GRASP_HEADROOM, _phase_strip, force_profile_figure, plot_force_profile, pyplot

PHASES = [
    {"phase": "start", "t_start": 0.0, "t_end": 0.0},
    {"phase": "approach", "t_start": 0.0, "t_end": 0.8},
    {"phase": "descend", "t_start": 0.8, "t_end": 0.86},  # too narrow for its name
    {"phase": "grasp", "t_start": 0.86, "t_end": 3.0},
    {"phase": "lift", "t_start": 3.0, "t_end": None},  # still running at the end
]


def _trace(path: Path, n: int = 4000, *, block: float = 0.0, grip: float = 0.0) -> Path:
    data = np.zeros((n, len(TRACE_COLUMNS)))
    data[:, 0] = np.arange(1, n + 1) * 1e-3
    data[:, TRACE_COLUMNS.index("grip_force_n")] = grip
    data[2000:, TRACE_COLUMNS.index("gripper-peg")] = 0.15  # the carried peg's weight [N]
    data[:, TRACE_COLUMNS.index("block-peg")] = block
    data[:, TRACE_COLUMNS.index("peg_depth_m")] = -0.05
    np.savez(path, columns=np.array(TRACE_COLUMNS), data=data)
    return path


def test_force_profile_is_written(tmp_path: Path) -> None:
    from PIL import Image

    out = plot_force_profile(_trace(tmp_path / "forces.npz", block=12.0), PHASES, tmp_path / "a" / "fp.png")
    assert out == tmp_path / "a" / "fp.png"
    width, height = Image.open(out).size
    assert width == 1100 and height > 600  # 10 in at 110 dpi; a phase strip and three panels


@pytest.mark.parametrize("n", [0, 1])
def test_force_profile_of_an_empty_or_one_row_trace(tmp_path: Path, n: int) -> None:
    assert plot_force_profile(_trace(tmp_path / "forces.npz", n), PHASES, tmp_path / "fp.png").is_file()


def test_phase_names_are_shortened_or_left_out_where_they_do_not_fit() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 0.5), layout="constrained")
    ax.set_xlim(0.0, 10.0)
    spans = [("approach", 0.0, 2.0), ("descend", 2.0, 2.35), ("grasp", 2.35, 2.37), ("rotate", 2.37, 10.0)]
    assert _phase_strip(fig, ax, spans) == ["approach", "des.", "rotate"]
    plt.close(fig)


def _axis_labelled(fig: Any, ylabel: str) -> Any:
    (ax,) = [ax for ax in fig.axes if ax.get_ylabel() == ylabel]
    return ax


def test_a_grip_held_throughout_is_drawn_below_the_top_edge(tmp_path: Path) -> None:
    """A held insertion's grip is one value from the first sample to the last: its line lies
    inside the grasp axis, under the legend, as does the load's highest value on its own axis."""
    fig = force_profile_figure(_trace(tmp_path / "forces.npz", grip=44.4), PHASES)
    try:
        grip_ax, load_ax = _axis_labelled(fig, "grip [N]"), _axis_labelled(fig, "load [N]")
        (line,) = grip_ax.get_lines()
        assert np.all(line.get_ydata() == 44.4)
        assert grip_ax.get_ylim() == pytest.approx((0.0, GRASP_HEADROOM * 44.4))
        assert load_ax.get_ylim() == pytest.approx((0.0, GRASP_HEADROOM * 0.15))
        # In display coordinates: the line is at 1/1.4 of the axis's height, below the legend.
        y_line = grip_ax.transData.transform((1.0, 44.4))[1]
        box = grip_ax.get_window_extent()
        assert (y_line - box.y0) / box.height == pytest.approx(1.0 / GRASP_HEADROOM)
        legend = grip_ax.get_legend().get_window_extent()
        assert y_line < legend.y0
    finally:
        pyplot().close(fig)


def test_a_grasp_panel_without_force_still_starts_at_zero(tmp_path: Path) -> None:
    fig = force_profile_figure(_trace(tmp_path / "forces.npz", n=10), PHASES)
    try:
        assert _axis_labelled(fig, "grip [N]").get_ylim()[0] == 0.0
        assert _axis_labelled(fig, "load [N]").get_ylim()[0] == 0.0
    finally:
        pyplot().close(fig)
