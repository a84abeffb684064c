"""The loop benchmark: its efficiency and the loop's own work per control step."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

import peg_ctrl.tools.bench as bench


def test_efficiency_and_own_work_of_a_tiny_run(monkeypatch: pytest.MonkeyPatch) -> None:
    episode_config = bench._episode_config

    def short(*args: Any) -> Any:  # 400 physics steps of the held insertion (it times out)
        return dataclasses.replace(episode_config(*args), max_steps=400)

    monkeypatch.setattr(bench, "_episode_config", short)
    entry = bench.bench_episode("pd", task="contact", profile="precision", repeats=1, control_dt=0.001)
    assert entry["physics_steps"] == 400 and entry["physics_steps_per_control_step"] == 2
    assert 0.0 < entry["efficiency"] <= 1.0
    assert entry["loop_own_us_per_control_step"] > 0.0
    # The split adds up: loop = raw physics + controller + the loop's own work, per control step.
    k = entry["physics_steps_per_control_step"]
    loop_us = entry["loop_us_per_step"]["median"] * k
    raw_us = entry["raw_us_per_step"]["median"] * k
    controller_us = entry["components_us_per_step"]["controller"] * k
    assert entry["loop_own_us_per_control_step"] == pytest.approx(loop_us - raw_us - controller_us)
    assert entry["efficiency"] == pytest.approx(raw_us / loop_us)


def test_summary_medians_over_repeats() -> None:
    times = bench._Timings(
        loop_cpu=[0.30, 0.20, 0.25],
        loop_wall=[0.30, 0.20, 0.25],
        raw_cpu=[0.15, 0.12, 0.10],
        raw_wall=[0.15, 0.12, 0.10],
        steps=[1000, 1000, 1000],
        sections=[dict.fromkeys(bench.LoopTimer.SECTIONS, 10.0)] * 3,
    )
    summary = times.summary(2, 3)
    assert summary["efficiency"] == pytest.approx(0.5)  # the median of 0.5, 0.6 and 0.4
    # (loop - raw) per physics step 150, 80 and 150 us, less 10 us of controller, times 2
    assert summary["loop_own_us_per_control_step"] == pytest.approx(280.0)
