"""The strategy registry: names, selection, errors, and a strategy registered from outside the package."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget
from peg_ctrl.config import ConfigError, apply_overrides, to_dict
from peg_ctrl.errors import UnknownComponent
from peg_ctrl.planners.base import Waypoint
from peg_ctrl.run.episode import episode_config_from_mapping, run_episode
from peg_ctrl.tasks.base import Observation
from peg_ctrl.tasks.phases import DONE, Motion, PhaseSpec, Timeout
from peg_ctrl.tasks.strategies import (
    STRATEGIES,
    HeldInsertion,
    Strategy,
    StrategyConfig,
    register_strategy,
    strategy_name,
)
from peg_ctrl.tasks.strategies.motions import Hold


@dataclasses.dataclass(frozen=True)
class PlungeConfig(StrategyConfig):
    """A toy: over the observed hole, then a position-controlled plunge to the seated depth."""

    name: ClassVar[str] = "plunge"
    phases: ClassVar[tuple[str, ...]] = ("hover", "plunge")
    speed: float = 0.02  # [m/s]

    def build(self, task: HeldInsertion) -> PlungeStrategy:
        return PlungeStrategy(task, self)


class PlungeStrategy(Strategy):
    first = "hover"
    cfg: PlungeConfig

    def phase_table(self) -> dict[str, PhaseSpec]:
        return {
            "hover": PhaseSpec(self._hover, self._moved, "plunge", Timeout(0.5, True)),
            "plunge": PhaseSpec(self._plunge, lambda obs: None, DONE, Timeout(1.0, True)),
        }

    def _tip_at(self, z: float) -> Waypoint:
        t = self.task
        q = np.asarray(t.goal.quat_world)
        return Waypoint.of(t.pinch_for(np.array([*t.observed_hole, z]), q), q, 0.0)

    def _hover(self, obs: Observation) -> Motion:
        return self.task.move(self._tip_at(self.task.block_top + 0.001))

    def _moved(self, obs: Observation) -> str | None:
        return "ok" if self.task.machine.motion_over(obs.t) else None

    def _plunge(self, obs: Observation) -> Motion:
        t = self.task
        return t.move(self._tip_at(t.block_top - t.min_depth - 0.001), t.limits.scaled(self.cfg.speed / 0.25))


@pytest.fixture
def plunge() -> object:
    register_strategy(PlungeConfig)
    yield PlungeConfig
    STRATEGIES.pop("plunge", None)


def test_the_built_in_strategies_are_registered_by_name() -> None:
    assert list(STRATEGIES) == [
        "straight",
        "force",
        "spiral",
        "tilt",
        "align",
        "probe",
        "locate",
        "plan",
        "handover",
    ]
    for name, cls in STRATEGIES.items():
        assert cls.name == name and cls.phases and "settle" not in cls.phases
        assert StrategyConfig.select(name) == cls()


def test_a_strategy_is_a_name_or_a_mapping_and_saves_back() -> None:
    cfg = episode_config_from_mapping({"task": {"name": "held_insertion", "strategy": "spiral"}})
    assert strategy_name(cfg.task) == "spiral"
    sets = ["task.strategy=spiral", "task.strategy.spiral_pitch=0.001"]
    cfg = episode_config_from_mapping(apply_overrides({"task": {"name": "held_insertion"}}, sets))
    assert cfg.task.strategy == STRATEGIES["spiral"](spiral_pitch=0.001)  # type: ignore[attr-defined, call-arg]


def test_a_saved_strategy_loads_again() -> None:
    data = {"task": {"name": "held_insertion", "strategy": {"name": "spiral", "spiral_pitch": 0.001}}}
    cfg = episode_config_from_mapping(data)
    saved = to_dict(cfg)
    assert saved["task"]["strategy"]["name"] == "spiral"
    assert episode_config_from_mapping(saved) == cfg
    assert strategy_name(episode_config_from_mapping({}).task) == ""  # pick-and-place has none


@pytest.mark.parametrize(
    ("config", "error", "message"),
    [
        ("nope", UnknownComponent, "task.strategy: unknown strategy 'nope'; known: align, force,"),
        ({"name": "tilt", "tilt_angle": 0.7}, ConfigError, r"task.strategy.tilt_angle must be in \(0, 0.5\)"),
        ({"name": "align", "wiggle": 1}, ConfigError, "task.strategy.wiggle: unknown field; known: align_"),
        (3, ConfigError, "task.strategy: expected a strategy name or a mapping, got 3"),
        (
            {"name": "probe", "insert_free": 1},
            ConfigError,
            "task.strategy.insert_free: expected true or false, got 1",
        ),
        (
            {"name": "probe", "land_force": True},
            ConfigError,
            "task.strategy.land_force: expected a number, got True",
        ),
    ],
)
def test_bad_strategies_are_named(config: object, error: type[Exception], message: str) -> None:
    with pytest.raises(error, match=message):
        episode_config_from_mapping({"task": {"name": "held_insertion", "strategy": config}})


def test_registration_checks_the_config_class(plunge: object) -> None:
    with pytest.raises(ConfigError, match="expected a StrategyConfig subclass"):
        register_strategy(dict)  # type: ignore[arg-type]

    @dataclasses.dataclass(frozen=True)
    class Clash(StrategyConfig):
        name: ClassVar[str] = "plunge"
        phases: ClassVar[tuple[str, ...]] = ("hover",)

    with pytest.raises(ConfigError, match="the name 'plunge' is taken by PlungeConfig"):
        register_strategy(Clash)

    @dataclasses.dataclass(frozen=True)
    class Settles(StrategyConfig):
        name: ClassVar[str] = "settles"
        phases: ClassVar[tuple[str, ...]] = ("settle", "push")

    with pytest.raises(ConfigError, match="'settle' and 'done' are the task's own"):
        register_strategy(Settles)


def test_a_strategy_registered_from_outside_runs_an_episode(plunge: object, tmp_path: Path) -> None:
    """The toy plunges a centred peg (no lateral error, no tilt) into a 0.1 mm clearance hole."""
    data = {
        "task": {"name": "held_insertion", "strategy": {"name": "plunge"}, "lateral_error": 0.0},
        "physics": {"profile": "precision"},
        "scene": {"assets": {"clearance": 0.0001, "chamfer": 0.001}, "friction": 0.3},
        "controller": {"name": "impedance", "compliance_center": [0.0, -0.07, -0.01]},
        "max_steps": 12000,
    }
    r = run_episode(episode_config_from_mapping(data), tmp_path / "ep", plot=False, progress=False)
    assert r.strategy == "plunge"
    assert r.status == "success", r.detail
    assert [p["phase"] for p in r.phases][:4] == ["start", "settle", "hover", "plunge"]
    assert r.insertion_depth_m >= 0.04
    with np.load(r.trace_path) as npz:  # the trace indexes the task's phases, the toy's among them
        phase = npz["data"][:, [str(c) for c in npz["columns"]].index("phase")]
    assert set(np.unique(phase).astype(int)) >= {0, 1, 2}


def test_hold_is_a_constant_target() -> None:
    target = GripperTarget.trusted(np.zeros(3), (1.0, 0.0, 0.0, 0.0), np.zeros(3), np.zeros(3), 0.0)
    assert Hold(target).sample(3.0) is target


def test_no_module_of_the_strategies_is_over_450_lines() -> None:
    """The strategies are scripts of skills, each a module of its own: none grows past 450 lines."""
    from pathlib import Path

    import peg_ctrl.tasks.strategies as package

    root = Path(package.__file__).parent
    sizes = {p.relative_to(root).as_posix(): len(p.read_text().splitlines()) for p in root.rglob("*.py")}
    assert {"plan.py", "probe.py", "locate.py", "skills/models.py"} <= set(sizes)
    assert max(sizes.values()) <= 450, {k: v for k, v in sizes.items() if v > 450}
