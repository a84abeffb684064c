"""The report's section on the planner's choices, the touch count and the belief figure."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from peg_ctrl.experiments.report.skills import belief_figure, main, skill_section, touch_count

_COLUMNS = np.array(["t", "phase", "block-peg"])


def _episode(root: Path, key: str, forces: list[float], skills: list[dict] | None) -> dict[str, str]:
    folder = root / "episodes" / key
    folder.mkdir(parents=True)
    t = 0.01 * np.arange(len(forces))
    np.savez(folder / "forces.npz", columns=_COLUMNS, data=np.column_stack([t, np.zeros_like(t), forces]))
    (folder / "summary.json").write_text(json.dumps({"skills": skills or []}))
    return {
        "arm": "mpc/plan" if skills else "mpc/locate",
        "log_path": f"episodes/{key}/log.jsonl",
        "status": "success",
        "sim_time_s": "5.0",
        "wall_time_s": "10.0",
        "scene.friction": "0.3",
    }


def test_a_touch_begins_only_after_the_peg_was_clear_of_the_block_long_enough(tmp_path: Path) -> None:
    # contact, 20 ms clear (the same touch), contact, 100 ms clear (a new one), contact
    forces = [1, 1, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0]
    _episode(tmp_path, "a", forces, None)
    assert touch_count(tmp_path / "episodes" / "a" / "forces.npz") == 2
    assert touch_count(tmp_path / "episodes" / "a" / "forces.npz", gap=0.01) == 3


def test_the_section_names_each_cell_s_order_and_the_planner_s_compute(tmp_path: Path) -> None:
    skills = [
        {"skill": "face", "t_start": 0.5, "t_end": 1.0, "decision_s": 0.002},
        {"skill": "mouth", "t_start": 1.0, "t_end": 3.0, "decision_s": 0.004},
        {"skill": "descent", "t_start": 3.0, "decision_s": 0.001},
    ]
    rows = [_episode(tmp_path, "p", [0, 1, 0], skills), _episode(tmp_path, "l", [1, 0], None)]
    text = "\n".join(skill_section(tmp_path, rows, ["scene.friction"]))
    assert (
        "| mpc/plan | friction 0.3 | 1 (1) | face>mouth>descent (1) | 3 | "
        "mouth 44 %, descent 44 %, face 11 % |" in text
    )
    assert "| mpc/plan | 3 | 2.00 |" in text and "0.070 %" in text  # 7 ms of 10 s
    assert "| mpc/locate | 1 | 1 |" in text
    assert skill_section(tmp_path, rows[1:], ["scene.friction"]) == []  # no skills, no section


def test_the_belief_figure_is_drawn_and_a_bad_episode_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spread = {"relative_mm": 3.0, "end_mm": 2.0, "tilt_mrad": 30.0, "face_um": 80.0}
    summary = {
        "strategy": "plan",
        "status": "success",
        "belief": [
            {"t": 0.0, "skill": "prior", **spread},
            {"t": 2.0, "skill": "rock_free", **{k: v / 10 for k, v in spread.items()}},
        ],
        "skills": [{"skill": "rock", "t_start": 0.4}],
    }
    out = belief_figure(summary, tmp_path / "b.png")
    assert out.stat().st_size > 10_000
    with pytest.raises(ValueError, match="no belief readings"):
        belief_figure({"belief": []}, tmp_path / "c.png")
    assert main([str(tmp_path / "nowhere"), "--out", str(tmp_path / "d.png")]) == 2
    assert "summary.json not found" in capsys.readouterr().err
