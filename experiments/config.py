"""Experiment files: controllers x planners x clearances x seeds, with randomization settings.

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
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

from peg_ctrl.assets import AssetParams
from peg_ctrl.config import ConfigError, load, read_mapping, to_dict
from peg_ctrl.controllers.base import ControllerConfig
from peg_ctrl.episode import (
    DomainConfig,
    EpisodeConfig,
    RandomizationConfig,
    episode_config_from_mapping,
)
from peg_ctrl.physics import PhysicsConfig
from peg_ctrl.planners import PLANNERS
from peg_ctrl.scene import SceneConfig
from peg_ctrl.tasks.pick_and_place import SuccessConfig, TaskConfig

__all__ = ["ExperimentConfig", "Job", "load_experiment", "expand"]


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
    task: TaskConfig = TaskConfig()
    success: SuccessConfig = SuccessConfig()
    physics: PhysicsConfig = PhysicsConfig()

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


def _changed_fields(spec: ControllerConfig) -> dict[str, Any]:
    """The fields of ``spec`` that differ from its class's defaults."""
    default = to_dict(type(spec)())
    return {k: v for k, v in to_dict(spec).items() if default.get(k) != v}


def _controller_label(spec: ControllerConfig, all_specs: tuple[ControllerConfig, ...]) -> str:
    """The controller's name, with its changed fields when the same name appears more than once."""
    changed = _changed_fields(spec)
    if sum(s.name == spec.name for s in all_specs) == 1 or not changed:
        return spec.name
    inner = ",".join(f"{k}={v}" for k, v in sorted(changed.items()))
    return f"{spec.name}({inner})"


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


def expand(exp: ExperimentConfig) -> list[Job]:
    """Every episode of the experiment, in a fixed order (controller, planner, clearance, seed)."""
    jobs = []
    for spec in exp.controllers:
        label = _controller_label(spec, exp.controllers)
        for planner in exp.planners:
            for clearance in exp.clearances:
                scene = SceneConfig(assets=AssetParams(clearance=clearance))
                for seed in exp.seeds:
                    cfg = EpisodeConfig(
                        controller=spec,
                        planner=planner,
                        seed=seed,
                        max_steps=exp.max_steps,
                        task=exp.task,
                        success=exp.success,
                        randomization=exp.randomization,
                        domain=exp.domain,
                        scene=scene,
                        physics=exp.physics,
                    )
                    blob = json.dumps(to_dict(cfg), sort_keys=True).encode()
                    key = hashlib.sha256(blob).hexdigest()[:16]
                    jobs.append(Job(key, spec.name, label, planner, clearance, seed, cfg))
    return jobs


def job_config_mapping(job: Job) -> dict[str, Any]:
    """Plain data for a worker process (rebuilt there with full validation)."""
    return to_dict(job.config)


def job_config(data: dict[str, Any]) -> EpisodeConfig:
    return episode_config_from_mapping(data)
