"""50 randomized episodes per planner (slow): success rate and per-episode physics bounds."""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest

from peg_ctrl.run.batch import run_batch
from peg_ctrl.run.episode import EpisodeConfig, RandomizationConfig


@pytest.mark.slow
@pytest.mark.parametrize("planner", ["ruckig", "fixed_speed"])
def test_fifty_randomized_episodes(planner: str, tmp_path: Path, record_property) -> None:
    jobs = [
        (
            EpisodeConfig(seed=s, planner=planner, randomization=RandomizationConfig(enabled=True)),
            tmp_path / f"{s:03d}",
        )
        for s in range(50)
    ]
    results = run_batch(jobs, progress=False)
    successes = [r for r in results if r["status"] == "success"]
    failures = {
        r["seed"]: (r["reason"], r["phase"], r["detail"]) for r in results if r["status"] != "success"
    }
    record_property("success_rate", len(successes) / len(results))
    record_property(
        "median_time_to_insert_s", float(statistics.median(r["time_to_insert_s"] for r in successes))
    )
    assert len(successes) >= 48, failures
    for r in results:
        assert r["reason"] != "diverged", r
        assert r["max_penetration_m"] <= 3e-3, r
        assert r["resting_penetration_m"] <= 0.5e-3, r
        assert r["peg_slip_m"] <= 0.5e-3, r
