"""Every controller completes the autonomous task on 30 randomized seeds (slow)."""

from __future__ import annotations

from pathlib import Path

import pytest

from peg_ctrl.controllers import REGISTRY
from peg_ctrl.run.batch import run_batch
from peg_ctrl.run.episode import EpisodeConfig, RandomizationConfig


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_thirty_randomized_episodes(name: str, tmp_path: Path, record_property) -> None:
    jobs = [
        (
            EpisodeConfig(
                controller=REGISTRY[name](), seed=s, randomization=RandomizationConfig(enabled=True)
            ),
            tmp_path / f"{s:03d}",
        )
        for s in range(30)
    ]
    results = run_batch(jobs, progress=False)
    wins = sum(r["status"] == "success" for r in results)
    record_property("success_rate", wins / len(results))
    record_property("peak_contact_force_n_max", float(max(r["peak_contact_force_n"] for r in results)))
    assert wins >= 27, {r["seed"]: (r["reason"], r["phase"]) for r in results if r["status"] != "success"}
    assert all(r["reason"] != "diverged" for r in results)
