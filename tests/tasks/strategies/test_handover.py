"""The handover strategy: an approach, then the controller plans the insertion over the belief."""

from __future__ import annotations

import numpy as np
import pytest

from peg_ctrl.run.episode import build_loop, episode_config_from_mapping


def _config(seed: int) -> object:
    """The plan study's easiest cell (docs/planning.md): a 0.05 mm clearance, friction 0.3, the
    peg 1 mm off in the hand and upright, the hole seen 0.5 mm off, the wrist sensor."""
    inner = {"k_pos": [3000.0] * 3, "k_rot": [2.0] * 3, "damping_compensation": 0.9}
    return episode_config_from_mapping(
        {
            "seed": seed,
            "controller": {"name": "sampling_mpc", "inner": inner, "velocity_filter_hz": 30.0},
            "task": {
                "name": "held_insertion",
                "strategy": "handover",
                "lateral_error": 0.001,
                "position_noise": 0.0005,
                "drawing_tolerance": 0.00015,
            },
            "domain": {"ft_sensor": "wrist", "position_noise": 3e-5, "velocity_noise": 0.001},
            "scene": {"assets": {"chamfer": 0.001, "clearance": 0.00005}, "friction": 0.3},
            "physics": {"profile": "precision"},
        }
    )


def test_the_task_hands_over_after_the_approach() -> None:
    """Until the planning phase the controller tracks (no planner); then the belief carries the
    goal's depth and the controller plans on hypotheses of it."""
    cfg = _config(102)
    loop = build_loop(cfg)  # type: ignore[arg-type]
    loop.reset(np.random.default_rng(102))
    task, controller = loop.task, loop.controller
    while True:
        loop.step()
        if task.phase == "handover":  # type: ignore[attr-defined]
            break
        assert controller.planner is None  # type: ignore[attr-defined]
    for _ in range(50):
        loop.step()
    assert task.belief.plan_depth == pytest.approx(task.min_depth + 0.0005)  # type: ignore[attr-defined]
    planner = controller.planner  # type: ignore[attr-defined]
    assert planner is not None and len(planner.hyp.weights) == 64
    assert len(planner.history) >= 2 and planner.history[-1].spread > 0.0


@pytest.mark.slow  # one held insertion planned over the belief, ~20 s
def test_the_planner_seats_the_peg_with_no_scripted_phase() -> None:
    """Seed 101 of the development seeds: seated in 4.0 s. Not every seed is (103 ends in the
    chamfer after 15 s); the plan study gives the rate."""
    cfg = _config(101)
    loop = build_loop(cfg)  # type: ignore[arg-type]
    loop.reset(np.random.default_rng(101))
    while True:
        ev = loop.step()
        if ev.done:
            break
    assert ev.success, ev.detail
    phases = [r.phase for r in loop.task.machine.records]  # type: ignore[attr-defined]
    assert phases[:4] == ["start", "settle", "approach", "handover"] and set(phases) <= {
        "start",
        "settle",
        "approach",
        "handover",
        "hold",
    }
