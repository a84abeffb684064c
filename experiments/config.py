"""Experiment files: controllers x strategies x planners x clearances x grid x seeds.

An experiment file (YAML, TOML or JSON) loads into :class:`ExperimentConfig`; every error names
its field (``controllers[1].kp_pos: ...``). Example::

    name: quick
    controllers:
      - {name: pd}
      - {name: mpc, horizon: 15}
    planners: [ruckig]
    clearances: [0.001, 0.0002]     # radial hole clearance [m]
    seeds: 20                       # seeds 0..19 (or a list)
    randomization: {enabled: true, peg_xy: 0.015, peg_yaw: 0.2}
    domain: {peg_mass_scale: [0.8, 1.2], friction_scale: [0.8, 1.2], gain_scale: [0.9, 1.1]}
    task: {force_guarded_insert: false}
    physics: {profile: precision}   # seed (default) or precision, see docs/physics.md

A contact study (see ``experiments/configs/contact.yaml``) names a task family and sweeps its
strategies and disturbances as well::

    task: {name: held_insertion, position_noise: 0.0}
    strategies: [straight, spiral, tilt]   # task.strategy, crossed with the controllers (a name,
                                            # or {name: spiral, spiral_pitch: 0.001})
    scene: {assets: {chamfer: 0.001}}       # the base scene (clearances still sweep clearance)
    grid:                                   # any dotted episode-config keys, crossed
      task.lateral_error: [0.0005, 0.0015, 0.003]
      task.tilt_error: [0.0, 0.02618]
      sensor:                               # a linked axis: its keys move together
        domain.ft_sensor: [ideal, forge]
        task.position_noise: [0.0, 0.0005]
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from peg_ctrl.config import ConfigError, apply_overrides, is_selectable, load, read_mapping, to_dict
from peg_ctrl.controllers.base import ControllerConfig
from peg_ctrl.planners import PLANNERS
from peg_ctrl.run.episode import (
    DomainConfig,
    EpisodeConfig,
    RandomizationConfig,
    episode_config_from_mapping,
)
from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.physics import PhysicsConfig
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tasks.base import TaskSpec
from peg_ctrl.tasks.pick_and_place import SuccessConfig, TaskConfig
from peg_ctrl.tasks.strategies import StrategyConfig, strategy_name

__all__ = [
    "ExperimentConfig",
    "Job",
    "load_experiment",
    "expand",
    "arms",
    "episode_count",
    "episode_key",
    "cells",
    "apply_experiment_overrides",
]


@dataclasses.dataclass(frozen=True)
class ExperimentConfig:
    name: str
    controllers: tuple[ControllerConfig, ...]
    planners: tuple[str, ...] = ("ruckig",)
    clearances: tuple[float, ...] = (0.001,)  # radial hole clearance [m]; negative: interference
    seeds: tuple[int, ...] = tuple(range(20))
    max_steps: int | None = None  # physics steps; None: 20 s of sim whatever the profile's step
    randomization: RandomizationConfig = RandomizationConfig(enabled=True)
    domain: DomainConfig = DomainConfig()
    task: TaskSpec = TaskConfig()
    success: SuccessConfig = SuccessConfig()
    physics: PhysicsConfig = PhysicsConfig()
    # task.strategy values to cross (names, or mappings with their fields); empty: the task's own.
    # A bare name that the task's own strategy has keeps the task's fields for it.
    strategies: tuple[StrategyConfig, ...] = ()
    # Which strategies each controller (by its label: its name, unless it appears twice) meets;
    # a controller not listed meets every one of ``strategies``.
    arms: dict[str, Any] = dataclasses.field(default_factory=dict)
    scene: SceneConfig = SceneConfig()  # the base scene; ``clearances`` replaces its clearance
    grid: dict[str, Any] = dataclasses.field(default_factory=dict)  # dotted key -> values, or linked axes

    def __post_init__(self) -> None:
        if not self.name or "/" in self.name:
            raise ConfigError(f"name must be a non-empty string without '/', got {self.name!r}")
        if not self.controllers:
            raise ConfigError("controllers: at least one controller is needed")
        for i, p in enumerate(self.planners):
            if p not in PLANNERS:
                raise ConfigError(
                    f"planners[{i}]: unknown planner {p!r}; known: {', '.join(sorted(PLANNERS))}"
                )
        if not self.clearances:
            raise ConfigError("clearances: at least one clearance is needed")
        for i, c in enumerate(self.clearances):
            try:
                AssetParams(clearance=c)
            except ValueError as exc:
                raise ConfigError(f"clearances[{i}]: {exc}") from None
        if not self.seeds or any(s < 0 for s in self.seeds):
            raise ConfigError(f"seeds: need at least one seed, all >= 0, got {list(self.seeds)[:5]}")
        if len(set(self.seeds)) != len(self.seeds):
            raise ConfigError("seeds: repeated seeds")
        if self.max_steps is not None and self.max_steps < 1:
            raise ConfigError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.strategies:
            if not strategy_name(self.task):
                raise ConfigError(
                    f"strategies: task {self.task.name!r} has no strategy; use task: {{name: held_insertion}}"
                )
            names = self.strategy_names
            if len(set(names)) != len(names):
                raise ConfigError(f"strategies: repeated strategies {names}")
        self._check_arms()
        for key, values in self.grid.items():
            _check_axis(key, values)
        # Every grid cell must make a valid episode config (and the scene must suit the physics).
        base = _episode(
            self,
            self.controllers[0],
            self.strategies[0] if self.strategies else None,
            self.planners[0],
            self.clearances[0],
        )
        for cell in cells(self):
            _apply_cell(base, cell)

    def _check_arms(self) -> None:
        labels = [_controller_label(c, self.controllers) for c in self.controllers]
        for label, chosen in self.arms.items():
            if label not in labels:
                raise ConfigError(
                    f"arms.{label}: no such controller; the controllers are {', '.join(labels)}"
                )
            if not self.strategies:
                raise ConfigError(f"arms.{label}: arms choose among strategies; list them in strategies")
            if not isinstance(chosen, list) or not chosen:
                raise ConfigError(f"arms.{label}: expected a non-empty list of strategies, got {chosen!r}")
            for name in chosen:
                if name not in self.strategy_names:
                    raise ConfigError(
                        f"arms.{label}: {name!r} is not one of the experiment's strategies "
                        f"({', '.join(self.strategy_names)})"
                    )

    @property
    def strategy_names(self) -> list[str]:
        """The names of ``strategies``, in order."""
        return [s.name for s in self.strategies]

    def strategies_for(self, label: str) -> tuple[StrategyConfig, ...]:
        """The strategies the controller labelled ``label`` meets, in ``strategies``' order."""
        chosen = self.arms.get(label)
        return tuple(s for s in self.strategies if chosen is None or s.name in chosen)


_NOT_IN_GRID = ("controller", "seed", "planner", "task.strategy", "task.name", "scene.assets.clearance")


def _check_axis(key: Any, values: Any) -> None:
    """One grid axis: a dotted key with a list of values, or a linked axis (a plain name with a
    mapping of dotted keys to lists of one length, which move together)."""
    if not isinstance(key, str) or not key:
        raise ConfigError(f"grid: keys must be dotted field names, got {key!r}")
    if isinstance(values, dict) and "." not in key:
        if not values:
            raise ConfigError(f"grid.{key}: a linked axis needs at least one dotted key")
        lengths = {len(v) if isinstance(v, list) else -1 for v in values.values()}
        for sub, sub_values in values.items():
            if not isinstance(sub, str) or "." not in sub:
                raise ConfigError(
                    f"grid.{key}: keys of a linked axis must be dotted field names, got {sub!r}"
                )
            _check_values(f"{key}.{sub}", sub, sub_values)
        if len(lengths) != 1:
            raise ConfigError(
                f"grid.{key}: the lists of a linked axis must have one length, got "
                + ", ".join(f"{sub}: {len(v)}" for sub, v in values.items())
            )
        levels = list(zip(*values.values(), strict=True))
        if len({json.dumps(level, sort_keys=True) for level in levels}) != len(levels):
            raise ConfigError(f"grid.{key}: repeated levels {levels!r}")
        return
    if "." not in key and key not in _NOT_IN_GRID:
        raise ConfigError(
            f"grid.{key}: expected a dotted field name with a list of values, or a linked axis "
            f"(a name with a mapping of dotted keys to lists), got {values!r}"
        )
    _check_values(key, key, values)
    if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
        raise ConfigError(f"grid.{key}: repeated values {values!r}")


def _check_values(where: str, key: str, values: Any) -> None:
    if not isinstance(values, list) or not values:
        raise ConfigError(f"grid.{where}: expected a non-empty list of values, got {values!r}")
    if key.split(".")[0] in _NOT_IN_GRID or key in _NOT_IN_GRID:
        raise ConfigError(f"grid.{where}: sweep this with controllers/strategies/planners/clearances/seeds")


def _levels(key: str, values: Any) -> list[dict[str, Any]]:
    """An axis's levels, each as dotted key -> value (a linked axis sets all its keys at once)."""
    if isinstance(values, dict):
        return [dict(zip(values, level, strict=True)) for level in zip(*values.values(), strict=True)]
    return [{key: value} for value in values]


def cells(exp: ExperimentConfig) -> list[dict[str, Any]]:
    """The grid's cells (dotted key -> value), crossed in file order; one empty cell without a grid."""
    out: list[dict[str, Any]] = [{}]
    for key, values in exp.grid.items():
        out = [{**cell, **level} for cell in out for level in _levels(key, values)]
    return out


@dataclasses.dataclass(frozen=True)
class Job:
    """One episode of a sweep: its key, the varied values and its full config."""

    key: str
    controller: str
    controller_label: str
    planner: str
    clearance: float
    seed: int
    config: EpisodeConfig
    strategy: str = ""
    cell: dict[str, Any] = dataclasses.field(default_factory=dict)  # the grid values

    @property
    def arm(self) -> str:
        """What the sweep compares: the controller, and the strategy when there is one."""
        return f"{self.controller_label}/{self.strategy}" if self.strategy else self.controller_label


def _controller_label(spec: ControllerConfig, all_specs: tuple[ControllerConfig, ...]) -> str:
    """The controller's name; when the same name appears more than once, with the fields in which
    those configs differ (``sampling_mpc(hypotheses=1)``, ``sampling_mpc(hypotheses=4)``)."""
    same = [to_dict(s) for s in all_specs if s.name == spec.name]
    if len(same) == 1:
        return spec.name
    mine = to_dict(spec)
    differ = {k: v for k, v in mine.items() if any(other.get(k) != v for other in same)}
    if not differ:
        return spec.name
    inner = ",".join(f"{k}={v}" for k, v in sorted(differ.items()))
    return f"{spec.name}({inner})"


def apply_experiment_overrides(data: dict[str, Any], assignments: list[str]) -> dict[str, Any]:
    """``--set KEY=VALUE`` on an experiment's plain data; a key the grid sweeps is fixed to the
    value instead (its grid axis is dropped), so ``--set task.lateral_error=0.002`` works on a
    file that sweeps the lateral error."""
    result = apply_overrides(data, assignments)
    grid = result.get("grid")
    if isinstance(grid, dict):
        for item in assignments:
            key = item.partition("=")[0].strip()
            grid.pop(key, None)
            for name, axis in list(grid.items()):
                if isinstance(axis, dict) and key in axis:
                    _fix_linked(grid, name, axis, key, _dig(result, key))
    return result


def _dig(data: dict[str, Any], key: str) -> Any:
    node: Any = data
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return node


def _fix_linked(grid: dict[str, Any], name: str, axis: dict[str, Any], key: str, value: Any) -> None:
    """``--set`` on a key of a linked axis: keep the level where that key has the value (its
    other keys move with it), or drop the axis when no level has it."""
    values = axis[key]
    if isinstance(values, list) and value in values:
        i = values.index(value)
        grid[name] = {k: [v[i]] for k, v in axis.items() if k != key and isinstance(v, list)}
        if not grid[name]:
            grid.pop(name)
    else:
        grid.pop(name)


def load_experiment(path: Path) -> ExperimentConfig:
    """Read and validate an experiment file; errors name the field."""
    data = read_mapping(Path(path))
    return experiment_from_mapping(data, default_name=Path(path).stem)


def experiment_from_mapping(data: dict[str, Any], *, default_name: str = "experiment") -> ExperimentConfig:
    """Validate plain data into an :class:`ExperimentConfig`; ``seeds: N`` means seeds 0..N-1."""
    data = dict(data)
    data.setdefault("name", default_name)
    if "controllers" not in data:
        raise ConfigError("controllers: missing field (a list like [{name: pd}, {name: mpc}])")
    if not isinstance(data["controllers"], list):
        raise ConfigError(f"controllers: expected a list, got {data['controllers']!r}")
    seeds = data.get("seeds", 20)
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        if seeds < 1:
            raise ConfigError(f"seeds: must be >= 1, got {seeds}")
        data["seeds"] = list(range(seeds))
    return load(ExperimentConfig, data)


def _episode(
    exp: ExperimentConfig,
    spec: ControllerConfig,
    strategy: StrategyConfig | None,
    planner: str,
    clearance: float,
) -> EpisodeConfig:
    """The episode config of one arm, planner and clearance, before the grid cell and the seed."""
    task = exp.task
    if strategy is not None:
        keeps_own = strategy_name(task) == strategy.name and strategy == type(strategy)()
        if not keeps_own:
            task = task.with_strategy(strategy)
    scene = dataclasses.replace(exp.scene, assets=dataclasses.replace(exp.scene.assets, clearance=clearance))
    return EpisodeConfig(
        controller=spec,
        planner=planner,
        max_steps=exp.max_steps,
        task=task,
        success=exp.success,
        randomization=exp.randomization,
        domain=exp.domain,
        scene=scene,
        physics=exp.physics,
    )


def _arms(exp: ExperimentConfig) -> list[tuple[ControllerConfig, str, StrategyConfig | None]]:
    """Each controller with its label and each strategy it meets (None: the task's own)."""
    found: list[tuple[ControllerConfig, str, StrategyConfig | None]] = []
    for spec in exp.controllers:
        label = _controller_label(spec, exp.controllers)
        strategies: tuple[StrategyConfig | None, ...] = (
            exp.strategies_for(label) if exp.strategies else (None,)
        )
        found.extend((spec, label, strategy) for strategy in strategies)
    return found


def arms(exp: ExperimentConfig) -> list[tuple[str, str]]:
    """What the sweep compares, in job order: (:attr:`Job.arm`, the controller's name)."""
    own = strategy_name(exp.task)
    return [
        (f"{label}/{name}" if (name := strategy.name if strategy else own) else label, spec.name)
        for spec, label, strategy in _arms(exp)
    ]


def episode_count(exp: ExperimentConfig) -> int:
    """How many episodes :func:`expand` makes, counted without making them."""
    return len(_arms(exp)) * len(exp.planners) * len(exp.clearances) * len(cells(exp)) * len(exp.seeds)


def expand(exp: ExperimentConfig) -> list[Job]:
    """Every episode of the experiment, in a fixed order (controller, strategy, planner,
    clearance, grid cell, seed)."""
    jobs = []
    for spec, label, strategy in _arms(exp):
        for planner in exp.planners:
            for clearance in exp.clearances:
                base = _episode(exp, spec, strategy, planner, clearance)
                name = strategy_name(base.task)
                for cell in cells(exp):
                    cell_cfg = _apply_cell(base, cell)
                    for seed in exp.seeds:
                        cfg = dataclasses.replace(cell_cfg, seed=seed)
                        jobs.append(
                            Job(
                                episode_key(cfg),
                                spec.name,
                                label,
                                planner,
                                clearance,
                                seed,
                                cfg,
                                name,
                                cell,
                            )
                        )
    if len({j.key for j in jobs}) != len(jobs):
        raise ConfigError("the experiment lists the same episode twice (repeated controllers or clearances?)")
    return jobs


def episode_key(cfg: EpisodeConfig) -> str:
    """An episode's identity: 16 hex digits of the SHA-256 of its config as JSON, fields at
    their defaults left out, so that a new field with a default keeps every existing key."""
    blob = json.dumps(_identity(cfg), sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _identity(cfg: Any) -> Any:
    """:func:`to_dict` without the dataclass fields that equal their default (a selectable
    config keeps its name)."""
    if not (dataclasses.is_dataclass(cfg) and not isinstance(cfg, type)):
        return to_dict(cfg)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cfg):
        if not f.init:
            continue
        value = getattr(cfg, f.name)
        if f.default is not dataclasses.MISSING:
            default: Any = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = dataclasses.MISSING
        if default is dataclasses.MISSING or _json(value) != _json(default):
            out[f.name] = _identity(value)
    return {"name": cfg.name, **out} if is_selectable(type(cfg)) else out  # type: ignore[attr-defined]


def _json(value: Any) -> str:
    return json.dumps(to_dict(value), sort_keys=True)


def _apply_cell(base: EpisodeConfig, cell: dict[str, Any]) -> EpisodeConfig:
    if not cell:
        return base
    data = to_dict(base)
    for key, value in cell.items():
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            child = node.get(part)
            if not isinstance(child, dict):
                raise ConfigError(f"grid.{key}: {part} is not a section of the episode config")
            node = child
        if parts[-1] not in node:
            raise ConfigError(f"grid.{key}: no such field in the episode config")
        node[parts[-1]] = value
    try:
        return episode_config_from_mapping(data)
    except ConfigError as exc:
        raise ConfigError(f"grid: {exc}") from None


def job_config_mapping(job: Job) -> dict[str, Any]:
    """Plain data for a worker process (rebuilt there with full validation)."""
    return to_dict(job.config)


def job_config(data: dict[str, Any]) -> EpisodeConfig:
    return episode_config_from_mapping(data)
