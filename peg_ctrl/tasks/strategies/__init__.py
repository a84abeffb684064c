"""Insertion strategies for the held peg, selected by name from one registry.

Each strategy is one module: a frozen config dataclass (a
:class:`~peg_ctrl.tasks.strategies.base.StrategyConfig` with a registered ``name`` and its own
parameters) and the strategy it builds (a :class:`~peg_ctrl.tasks.strategies.base.Strategy`:
its rows of the held insertion's phase table). :data:`STRATEGIES` maps each config's ``name`` to
its class; :func:`register_strategy` adds one from outside the package.
"""

from __future__ import annotations

from peg_ctrl.errors import ConfigError
from peg_ctrl.tasks.base import TaskSpec
from peg_ctrl.tasks.strategies.align import AlignConfig, AlignStrategy
from peg_ctrl.tasks.strategies.base import (
    DEFAULT_STRATEGY,
    HeldInsertion,
    PushIn,
    Strategy,
    StrategyConfig,
    TaskDisturbance,
)
from peg_ctrl.tasks.strategies.force import ForceConfig, ForceStrategy
from peg_ctrl.tasks.strategies.handover import HandoverConfig, HandoverStrategy
from peg_ctrl.tasks.strategies.locate import LocateConfig, LocateStrategy
from peg_ctrl.tasks.strategies.plan import PlanConfig, PlanStrategy
from peg_ctrl.tasks.strategies.probe import ProbeConfig, ProbeStrategy
from peg_ctrl.tasks.strategies.spiral import SpiralConfig, SpiralStrategy
from peg_ctrl.tasks.strategies.straight import StraightConfig, StraightStrategy
from peg_ctrl.tasks.strategies.tilt import TiltConfig, TiltStrategy

__all__ = [
    "DEFAULT_STRATEGY",
    "STRATEGIES",
    "HeldInsertion",
    "PushIn",
    "Strategy",
    "StrategyConfig",
    "TaskDisturbance",
    "AlignConfig",
    "AlignStrategy",
    "ForceConfig",
    "ForceStrategy",
    "HandoverConfig",
    "HandoverStrategy",
    "LocateConfig",
    "LocateStrategy",
    "PlanConfig",
    "PlanStrategy",
    "ProbeConfig",
    "ProbeStrategy",
    "SpiralConfig",
    "SpiralStrategy",
    "StraightConfig",
    "StraightStrategy",
    "TiltConfig",
    "TiltStrategy",
    "register_strategy",
    "strategy_name",
    "strategy_names",
]

#: Strategy name -> its config class (whose ``build(task)`` makes the strategy).
STRATEGIES: dict[str, type[StrategyConfig]] = {
    cfg.name: cfg
    for cfg in (
        StraightConfig,
        ForceConfig,
        SpiralConfig,
        TiltConfig,
        AlignConfig,
        ProbeConfig,
        LocateConfig,
        PlanConfig,
        HandoverConfig,
    )
}


def strategy_names() -> list[str]:
    """The registered strategy names, in registration order."""
    return list(STRATEGIES)


def strategy_name(task: TaskSpec) -> str:
    """The name of the strategy a task config runs ("" for a task without strategies)."""
    return task.strategy_name


def register_strategy(config_cls: type[StrategyConfig], *, replace: bool = False) -> None:
    """Add a strategy to :data:`STRATEGIES` under its config's ``name``, so that configs and
    experiment files (``task.strategy``, ``strategies:``) can name it.

    Sweep workers are new processes that import the main module again: register at the top
    level of your script or in a module the workers import.

    Raises:
        ConfigError: ``config_cls`` is not a :class:`StrategyConfig` subclass with a ``name`` and
            ``phases``, or the name is taken (unless ``replace``).
    """
    if not (isinstance(config_cls, type) and issubclass(config_cls, StrategyConfig)):
        raise ConfigError(f"register_strategy: expected a StrategyConfig subclass, got {config_cls!r}")
    name = getattr(config_cls, "name", None)
    if not isinstance(name, str) or not name or "/" in name:
        raise ConfigError(
            f"register_strategy: {config_cls.__name__}.name must be a non-empty string without '/', "
            f"got {name!r}"
        )
    phases = getattr(config_cls, "phases", None)
    if not (isinstance(phases, tuple) and phases and all(isinstance(p, str) and p for p in phases)):
        raise ConfigError(
            f"register_strategy: {config_cls.__name__}.phases must be a non-empty tuple of phase names"
        )
    if "settle" in phases or "done" in phases:
        raise ConfigError(
            f"register_strategy: {config_cls.__name__}.phases: 'settle' and 'done' are the task's own"
        )
    if name in STRATEGIES and STRATEGIES[name] is not config_cls and not replace:
        raise ConfigError(
            f"register_strategy: the name {name!r} is taken by {STRATEGIES[name].__name__}; "
            "pass replace=True to replace it"
        )
    STRATEGIES[name] = config_cls
