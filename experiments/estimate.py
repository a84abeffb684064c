"""How big a sweep is and how long it will take, before it runs (``peg-sim sweep --dry-run``).

The size is counted from the experiment (arms x planners x clearances x grid cells x seeds)
without expanding its jobs. The wall time is estimated from measured runs: per controller, task
and physics profile, the wall seconds a worker spends per simulated second and the mean
simulated length of an episode. Where the measurements come from, best first:

1. the finished episodes in the sweep's own output directory (a resumed sweep: this machine,
   this experiment);
2. the packaged table ``peg_ctrl/data/sweep_costs.json``, derived from the committed runs (the
   ``contact_hard`` and ``contact`` sweeps' ``episodes.csv`` and the loop benchmark of the
   default task, all on the 2-core reference machine) by :func:`measured_costs`; a source
   whose experiment has the sweep's name is preferred to the others;
3. failing both, the same controller on another task or profile (scaled by the profile's steps
   per simulated second), or the costliest controller measured: said so in the estimate.

Each episode runs at most its time limit (``max_steps``, else 20 s of simulated time), so the
estimate is a range over the measured rates and lengths, and an upper bound with every episode
at its limit. Regenerate the table after committing new runs::

    python -m peg_ctrl.experiments.estimate
"""

from __future__ import annotations

import csv
import dataclasses
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from peg_ctrl.experiments.config import ExperimentConfig, arms, cells
from peg_ctrl.run.episode import EPISODE_TIME
from peg_ctrl.sim.physics import PROFILES

__all__ = [
    "Cost",
    "Axis",
    "SweepSize",
    "Part",
    "Estimate",
    "EPISODE_OVERHEAD_S",
    "sweep_size",
    "estimate",
    "load_costs",
    "costs_from_rows",
    "measured_costs",
]

COSTS_FILE = "sweep_costs.json"
# The committed runs the packaged table is derived from (paths in a source checkout).
_SWEEPS = {
    "contact_hard": "docs/contact_hard/episodes.csv",
    "contact": "docs/contact/episodes.csv",
}
_BENCH = ("bench", "docs/performance/bench_default.json")
# The tasks peg-sim bench names (peg_ctrl.tools.profile_check.TASKS) by the task's own name.
_BENCH_TASKS = {"default": "pick_and_place", "contact": "held_insertion"}
_MACHINE = "the 2-core reference machine"

Key = tuple[str, str, str]  # task, physics profile, controller name

#: A worker's seconds per episode outside its simulation loop (building the episode, writing its
#: records, handing it over), which ``wall_time_s`` does not count. The committed contact_hard
#: run took 2139 s of episodes on 2 workers for 4108 s of loops: 0.42 s per episode.
EPISODE_OVERHEAD_S = 0.4


@dataclasses.dataclass(frozen=True)
class Cost:
    """What one controller's episodes cost on one task and physics profile, as measured."""

    source: str  # where: a key of the table's sources, or "here"
    task: str
    physics: str
    controller: str
    episodes: int
    wall_per_sim: float  # wall seconds of a worker per simulated second
    sim_s: float  # mean simulated length of an episode [s]

    @property
    def key(self) -> Key:
        return (self.task, self.physics, self.controller)


def costs_from_rows(
    rows: Iterable[Mapping[str, Any]], source: str, *, controller_field: str = "controller"
) -> list[Cost]:
    """:class:`Cost` per (task, physics, controller) of episode records (``summary.json`` or
    ``episodes.csv`` rows, whose controller's name is ``controller_name``): total wall time over
    total simulated time, and the mean simulated length."""
    totals: dict[Key, list[float]] = {}
    for row in rows:
        try:
            wall, sim = float(row["wall_time_s"]), float(row["sim_time_s"])
            key = (str(row["task"]), str(row["physics"]), str(row[controller_field]))
        except (KeyError, TypeError, ValueError):
            continue
        if sim > 0 and wall > 0:
            total = totals.setdefault(key, [0, 0.0, 0.0])
            total[0] += 1
            total[1] += wall
            total[2] += sim
    return [
        Cost(source, *key, episodes=int(n), wall_per_sim=wall / sim, sim_s=sim / n)
        for key, (n, wall, sim) in sorted(totals.items())
    ]


def _costs_from_bench(bench: Mapping[str, Any], source: str) -> list[Cost]:
    """:class:`Cost` of each whole episode that ``peg-sim bench`` timed through the loop."""
    found = []
    for entry in bench["episodes"]:
        dt = PROFILES[entry["profile"]].timestep
        found.append(
            Cost(
                source,
                _BENCH_TASKS[entry["task"]],
                entry["profile"],
                entry["controller"],
                episodes=1,
                wall_per_sim=entry["loop_us_per_step"]["median"] * 1e-6 / dt,
                sim_s=entry["physics_steps"] * dt,
            )
        )
    return found


def measured_costs(root: Path) -> dict[str, Any]:
    """The packaged table's content, derived from the committed runs in the source tree ``root``."""
    sources = {
        name: f"the committed {name} sweep ({path}: 2 workers on {_MACHINE})"
        for name, path in _SWEEPS.items()
    }
    costs: list[Cost] = []
    for name, path in _SWEEPS.items():
        with open(root / path, newline="") as fh:
            costs += costs_from_rows(csv.DictReader(fh), name, controller_field="controller_name")
    name, path = _BENCH
    sources[name] = f"one episode per controller timed by peg-sim bench ({path}: CPU time on {_MACHINE})"
    costs += _costs_from_bench(json.loads((root / path).read_text()), name)

    def rounded(cost: Cost) -> dict[str, Any]:
        data = dataclasses.asdict(cost)
        data["wall_per_sim"] = float(f"{cost.wall_per_sim:.4g}")
        data["sim_s"] = float(f"{cost.sim_s:.4g}")
        return data

    return {
        "about": "Wall seconds of a sweep worker per simulated second, and the mean simulated length "
        "of an episode, per task, physics profile and controller; for peg-sim sweep --dry-run. "
        "Derived from the committed runs by python -m peg_ctrl.experiments.estimate.",
        "sources": sources,
        "costs": [rounded(c) for c in costs],
    }


def load_costs() -> tuple[list[Cost], dict[str, str]]:
    """The packaged table: its costs and its sources' descriptions."""
    from importlib import resources

    data = json.loads((resources.files("peg_ctrl.data") / COSTS_FILE).read_text(encoding="utf-8"))
    return [Cost(**c) for c in data["costs"]], dict(data["sources"])


# -- the size ----------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Axis:
    """A grid axis: its name, the keys it sets (one, or a linked axis's) and its levels."""

    name: str
    keys: tuple[str, ...]
    levels: tuple[tuple[Any, ...], ...]


@dataclasses.dataclass(frozen=True)
class SweepSize:
    """How many episodes an experiment has, and what they are made of."""

    name: str
    arms: tuple[str, ...]
    planners: tuple[str, ...]
    clearances: tuple[float, ...]
    axes: tuple[Axis, ...]
    cells: int
    seeds: tuple[int, ...]
    max_steps: int | None
    counts: dict[Key, int]  # episodes per (task, physics, controller)

    @property
    def episodes(self) -> int:
        return sum(self.counts.values())

    def factors(self) -> list[tuple[int, str]]:
        """The product that makes :attr:`episodes`: (count, what), planners and clearances only
        when there is more than one."""
        found = [(len(self.arms), "arms")]
        if len(self.planners) > 1:
            found.append((len(self.planners), "planners"))
        if len(self.clearances) > 1:
            found.append((len(self.clearances), "clearances"))
        found += [(self.cells, "cells"), (len(self.seeds), "seeds")]
        return found

    def limit_s(self, physics: str) -> float:
        """An episode's time limit [s of simulated time] with the ``physics`` profile."""
        dt = PROFILES[physics].timestep
        steps = self.max_steps if self.max_steps is not None else round(EPISODE_TIME / dt)
        return steps * dt


def sweep_size(exp: ExperimentConfig) -> SweepSize:
    """``exp``'s size and breakdown, counted without expanding its jobs."""
    axes = []
    for name, values in exp.grid.items():
        if isinstance(values, dict):  # a linked axis
            axes.append(Axis(name, tuple(values), tuple(zip(*values.values(), strict=True))))
        else:
            axes.append(Axis(name, (name,), tuple((v,) for v in values)))
    grid = cells(exp)
    per_cell = len(exp.planners) * len(exp.clearances) * len(exp.seeds)
    counts: dict[Key, int] = {}
    for _, controller in arms(exp):
        for cell in grid:
            key = (exp.task.name, str(cell.get("physics.profile", exp.physics.profile)), controller)
            counts[key] = counts.get(key, 0) + per_cell
    return SweepSize(
        name=exp.name,
        arms=tuple(label for label, _ in arms(exp)),
        planners=exp.planners,
        clearances=exp.clearances,
        axes=tuple(axes),
        cells=len(grid),
        seeds=exp.seeds,
        max_steps=exp.max_steps,
        counts=counts,
    )


# -- the estimate ------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Part:
    """The estimate for the episodes of one controller on one task and physics profile."""

    task: str
    physics: str
    controller: str
    episodes: int  # still to run
    wall_per_sim: tuple[float, float]  # the measured range [s/s]
    sim_s: tuple[float, float]  # the measured range of mean lengths, within the limit [s]
    limit_s: float
    sources: tuple[str, ...]  # where the numbers come from: "here", or the table's sources
    note: str = ""  # how they were borrowed when this controller, task and profile has none

    @property
    def low_s(self) -> float:
        """One worker's time for these episodes [s], at the low ends of the measured ranges."""
        return self.episodes * (self.wall_per_sim[0] * self.sim_s[0] + EPISODE_OVERHEAD_S)

    @property
    def high_s(self) -> float:
        """... at their high ends."""
        return self.episodes * (self.wall_per_sim[1] * self.sim_s[1] + EPISODE_OVERHEAD_S)

    @property
    def worst_s(self) -> float:
        """... with every episode running to its time limit."""
        return self.episodes * (self.wall_per_sim[1] * self.limit_s + EPISODE_OVERHEAD_S)


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A sweep's estimated wall time: the sum of its parts over the workers that run at once."""

    episodes: int  # still to run
    parallel: int  # episodes run at once
    parts: tuple[Part, ...]
    sources: dict[str, str]  # the descriptions of the table's sources the parts use

    @property
    def low_s(self) -> float:
        return sum(p.low_s for p in self.parts) / self.parallel

    @property
    def high_s(self) -> float:
        return sum(p.high_s for p in self.parts) / self.parallel

    @property
    def worst_s(self) -> float:
        return sum(p.worst_s for p in self.parts) / self.parallel


def _choose(key: Key, here: list[Cost], table: list[Cost], experiment: str) -> tuple[list[Cost], str, float]:
    """The measurements for ``key``; how they were borrowed ("" when they are its own); and the
    factor that scales their rate to ``key``'s physics profile (its steps per simulated second)."""
    task, physics, controller = key
    mine = [c for c in here if c.key == key]
    if mine:
        return mine, "", 1.0
    exact = [c for c in table if c.key == key]
    if exact:
        return [c for c in exact if c.source == experiment] or exact, "", 1.0

    def scale(c: Cost) -> float:
        return PROFILES[c.physics].timestep / PROFILES[physics].timestep

    similar = [c for c in table if c.controller == controller] or table
    if not similar:
        raise ValueError("no measured costs to estimate from")
    # The same task and profile first, then the costliest after scaling to this profile.
    best = max(similar, key=lambda c: (c.task == task, c.physics == physics, c.wall_per_sim * scale(c)))
    note = "not measured: as " + ("" if best.controller == controller else "the costliest measured, ")
    note += f"{best.controller} on {best.task}/{best.physics}"
    if best.physics != physics:
        note += f" per {physics} step"
    return [best], note, scale(best)


def estimate(
    size: SweepSize,
    *,
    workers: int,
    cores: int | None = None,
    done: Mapping[str, Mapping[str, Any]] | None = None,
    table: tuple[list[Cost], dict[str, str]] | None = None,
) -> Estimate:
    """The wall time of the episodes of ``size`` not in ``done`` (finished episodes' summaries:
    key -> ``summary.json``, whose costs are preferred), on ``workers`` processes of which at
    most ``cores`` run at once (None: all of them). ``table``: default :func:`load_costs`."""
    costs, sources = table if table is not None else load_costs()
    done = done or {}
    here = costs_from_rows(done.values(), "here")
    finished: dict[Key, int] = {}
    for summary in done.values():
        key = (str(summary.get("task")), str(summary.get("physics")), str(summary.get("controller")))
        finished[key] = finished.get(key, 0) + 1
    parts = []
    for key, count in size.counts.items():
        chosen, note, factor = _choose(key, here, costs, size.name)
        limit = size.limit_s(key[1])
        rates = [c.wall_per_sim * factor for c in chosen]
        lengths = [min(c.sim_s, limit) for c in chosen]
        parts.append(
            Part(
                *key,
                episodes=max(0, count - finished.get(key, 0)),
                wall_per_sim=(min(rates), max(rates)),
                sim_s=(min(lengths), max(lengths)),
                limit_s=limit,
                sources=tuple(sorted({c.source for c in chosen})),
                note=note,
            )
        )
    to_run = sum(p.episodes for p in parts)
    parallel = max(1, min(workers, cores if cores is not None else workers, to_run))
    used = {s for p in parts if p.episodes for s in p.sources}
    return Estimate(to_run, parallel, tuple(parts), {k: v for k, v in sources.items() if k in used})


if __name__ == "__main__":  # pragma: no cover - run by hand in a source checkout
    from peg_ctrl.io import atomic_write_text, to_json

    root = Path(__file__).resolve().parents[1]
    target = root / "peg_ctrl" / "data" / COSTS_FILE
    atomic_write_text(target, to_json(measured_costs(root), indent=2) + "\n")
    print(f"wrote {target}")
