"""The episode force-profile plot: panels for grip and insertion, labelled phases that fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from peg_ctrl.run.episode_log import TRACE_COLUMNS
from peg_ctrl.run.plots import _phase_strip, plot_force_profile

PHASES = [
    {"phase": "start", "t_start": 0.0, "t_end": 0.0},
    {"phase": "approach", "t_start": 0.0, "t_end": 0.8},
    {"phase": "descend", "t_start": 0.8, "t_end": 0.86},  # too narrow for its name
    {"phase": "grasp", "t_start": 0.86, "t_end": 3.0},
    {"phase": "lift", "t_start": 3.0, "t_end": None},  # still running at the end
]


def _trace(path: Path, n: int = 4000, *, block: float = 0.0) -> Path:
    data = np.zeros((n, len(TRACE_COLUMNS)))
    data[:, 0] = np.arange(1, n + 1) * 1e-3
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
