"""A sweep's size and estimated wall time, counted and estimated without running it."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import pytest

from peg_ctrl.experiments.config import episode_count, expand, experiment_from_mapping, load_experiment
from peg_ctrl.experiments.estimate import (
    COSTS_FILE,
    EPISODE_OVERHEAD_S,
    Cost,
    estimate,
    load_costs,
    measured_costs,
    sweep_size,
)

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "experiments" / "configs"


@pytest.mark.parametrize("name", ["contact_hard", "contact_real", "clearance"])
def test_the_size_is_the_number_of_jobs(name: str) -> None:
    exp = load_experiment(CONFIGS / f"{name}.yaml")
    jobs = expand(exp)
    size = sweep_size(exp)
    assert size.episodes == episode_count(exp) == len(jobs)
    assert size.arms == tuple(dict.fromkeys(j.arm for j in jobs))
    product = 1
    for n, _ in size.factors():
        product *= n
    assert product == len(jobs)
    per_controller: dict[str, int] = {}
    for job in jobs:
        per_controller[job.controller] = per_controller.get(job.controller, 0) + 1
    assert {key[2]: n for key, n in size.counts.items()} == per_controller


def test_a_linked_axis_is_one_axis_of_tuples() -> None:
    size = sweep_size(load_experiment(CONFIGS / "contact_real.yaml"))
    (sensor,) = [a for a in size.axes if a.name == "sensor"]
    assert sensor.keys == ("domain.ft_sensor", "task.position_noise")
    assert sensor.levels[0] == ("wrist", 0.0005)
    assert size.cells == 2 * 2 * 2 * len(sensor.levels)


def test_the_packaged_costs_are_derived_from_the_committed_runs() -> None:
    packaged = json.loads((ROOT / "peg_ctrl" / "data" / COSTS_FILE).read_text())
    assert packaged == json.loads(json.dumps(measured_costs(ROOT))), (
        "the committed runs changed: regenerate the table with python -m peg_ctrl.experiments.estimate"
    )


def test_the_estimate_of_a_committed_sweep_is_its_measured_time() -> None:
    """contact_hard's estimate (from its own committed run) is that run's episode time over 2
    workers, plus the set-up time per episode."""
    exp = load_experiment(CONFIGS / "contact_hard.yaml")
    est = estimate(sweep_size(exp), workers=2, cores=2)
    with open(ROOT / "docs" / "contact_hard" / "episodes.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    measured = (sum(float(r["wall_time_s"]) for r in rows) + EPISODE_OVERHEAD_S * len(rows)) / 2
    assert est.episodes == 400 and est.parallel == 2
    assert est.low_s == est.high_s == pytest.approx(measured, rel=1e-3)
    assert est.high_s == pytest.approx(851, rel=0.02)  # its episodes' wall time, over 2 workers
    assert est.high_s < est.worst_s  # episodes up to their 20 s limit
    assert {p.sources for p in est.parts} == {("contact_hard",)}
    assert list(est.sources) == ["contact_hard"]


def test_another_experiment_gets_the_range_of_the_measured_runs() -> None:
    exp = load_experiment(CONFIGS / "contact_real.yaml")
    est = estimate(sweep_size(exp), workers=2, cores=2)
    impedance = next(p for p in est.parts if p.controller == "impedance")
    assert impedance.sources == ("contact", "contact_hard")
    assert impedance.wall_per_sim[0] < impedance.wall_per_sim[1]
    assert est.low_s < est.high_s < est.worst_s


def test_workers_beyond_the_cores_or_the_episodes_do_not_count() -> None:
    size = sweep_size(load_experiment(CONFIGS / "contact_hard.yaml"))
    one = estimate(size, workers=1, cores=2)
    assert estimate(size, workers=2, cores=2).high_s == pytest.approx(one.high_s / 2)
    assert estimate(size, workers=8, cores=2).parallel == 2
    assert estimate(size, workers=8, cores=None).parallel == 8  # a cluster: all of them
    tiny = experiment_from_mapping({"name": "t", "controllers": [{"name": "pd"}], "seeds": 3})
    assert estimate(sweep_size(tiny), workers=8, cores=8).parallel == 3


def test_an_unmeasured_controller_task_or_profile_borrows_and_says_so() -> None:
    costs = [
        Cost("a", "held_insertion", "precision", "pd", 10, 0.6, 12.0),
        Cost("a", "held_insertion", "precision", "mpc", 10, 1.0, 13.0),
    ]
    exp = experiment_from_mapping(
        {
            "name": "t",
            "controllers": [{"name": "pd"}, {"name": "impedance"}],
            "seeds": 2,
            "task": {"name": "held_insertion"},
            "physics": {"profile": "seed"},
        }
    )
    est = estimate(sweep_size(exp), workers=1, table=(costs, {"a": "source a"}))
    pd, impedance = est.parts
    # pd is measured on the precision profile: scaled to seed's steps (1 ms against 0.5 ms).
    assert pd.wall_per_sim == (0.3, 0.3) and pd.sim_s == (12.0, 12.0)
    assert pd.note == "not measured: as pd on held_insertion/precision per seed step"
    assert impedance.wall_per_sim == (0.5, 0.5)  # the costliest measured
    assert impedance.note.startswith("not measured: as the costliest measured, mpc on ")
    assert est.sources == {"a": "source a"}


def test_finished_episodes_are_not_work_and_their_costs_come_first() -> None:
    exp = experiment_from_mapping(
        {"name": "t", "controllers": [{"name": "pd"}], "seeds": 4, "max_steps": 2000}
    )
    done = {
        f"k{i}": {
            "status": "success",
            "task": "pick_and_place",
            "physics": "seed",
            "controller": "pd",
            "wall_time_s": 1.0,
            "sim_time_s": 2.0,
        }
        for i in range(3)
    }
    est = estimate(sweep_size(exp), workers=1, done=done)
    (part,) = est.parts
    assert est.episodes == part.episodes == 1
    assert part.sources == ("here",) and part.wall_per_sim == (0.5, 0.5)
    assert part.sim_s == (2.0, 2.0) and part.limit_s == pytest.approx(2.0)  # 2000 steps of 1 ms
    assert est.high_s == pytest.approx(0.5 * 2.0 + EPISODE_OVERHEAD_S)
    assert est.sources == {}  # nothing from the packaged table


def test_an_episode_is_no_longer_than_its_time_limit() -> None:
    exp = load_experiment(CONFIGS / "contact_hard.yaml")
    short = dataclasses.replace(exp, max_steps=200)  # 0.1 s of precision physics
    est = estimate(sweep_size(short), workers=2, cores=2)
    assert all(p.limit_s == pytest.approx(0.1) and p.sim_s == (0.1, 0.1) for p in est.parts)
    assert est.high_s == pytest.approx(est.worst_s)


def test_the_packaged_table_loads() -> None:
    costs, sources = load_costs()
    assert {c.source for c in costs} == set(sources)
    assert all(c.wall_per_sim > 0 and c.sim_s > 0 and c.episodes > 0 for c in costs)
