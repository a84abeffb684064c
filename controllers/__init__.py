"""Controllers for the peg-in-hole gripper, selected by name from one registry.

Every controller drives the same actuators (3 slide forces, 3 ball-joint torques, the jaw)
through the :class:`~peg_ctrl.controllers.base.Controller` protocol. Each is a config class (a
:class:`~peg_ctrl.controllers.base.ControllerConfig`, naming the controller) and a controller
class built from it (a :class:`~peg_ctrl.controllers.base.ControllerBase`, writing only its
control law). :data:`REGISTRY` maps each config class's ``name`` to the class.
"""

from __future__ import annotations

from typing import Any

import mujoco

from peg_ctrl.controllers.admittance import AdmittanceConfig, AdmittanceController
from peg_ctrl.controllers.base import (
    Controller,
    ControllerBase,
    ControllerConfig,
    ControlOutput,
    Diagnostics,
    Effort,
)
from peg_ctrl.controllers.diffik import DiffIKConfig, DiffIKController
from peg_ctrl.controllers.impedance import ImpedanceConfig, ImpedanceController
from peg_ctrl.controllers.mpc import MPCConfig, MPCController
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.controllers.sampling_mpc import SamplingMPCConfig, SamplingMPCController
from peg_ctrl.errors import ConfigError, UnknownComponent

__all__ = [
    "Controller",
    "ControllerBase",
    "ControllerConfig",
    "ControlOutput",
    "Diagnostics",
    "Effort",
    "PDConfig",
    "PDController",
    "AdmittanceConfig",
    "AdmittanceController",
    "DiffIKConfig",
    "DiffIKController",
    "MPCConfig",
    "MPCController",
    "ImpedanceConfig",
    "ImpedanceController",
    "SamplingMPCConfig",
    "SamplingMPCController",
    "REGISTRY",
    "UnknownController",
    "controller_names",
    "make_controller",
    "register_controller",
]

#: Controller name -> its config class (whose ``build(model)`` makes the controller).
REGISTRY: dict[str, type[ControllerConfig]] = {
    cfg.name: cfg
    for cfg in (PDConfig, ImpedanceConfig, AdmittanceConfig, DiffIKConfig, MPCConfig, SamplingMPCConfig)
}

#: Kept for callers that catch it by its old name.
UnknownController = UnknownComponent


def controller_names() -> list[str]:
    """The registered controller names, sorted."""
    return sorted(REGISTRY)


def register_controller(config_cls: type[ControllerConfig], *, replace: bool = False) -> None:
    """Add a controller to :data:`REGISTRY` under its config's ``name``, so that configs,
    experiment files and ``gymnasium.make`` can name it.

    Sweep workers are new processes that import the main module again: register at the top
    level of your script or in a module the workers import (Ray workers need it importable).

    Raises:
        ConfigError: ``config_cls`` is not a :class:`ControllerConfig` subclass with a ``name``,
            or the name is taken (unless ``replace``).
    """
    if not (isinstance(config_cls, type) and issubclass(config_cls, ControllerConfig)):
        raise ConfigError(f"register_controller: expected a ControllerConfig subclass, got {config_cls!r}")
    name = getattr(config_cls, "name", None)
    if not isinstance(name, str) or not name:
        raise ConfigError(f"register_controller: {config_cls.__name__} has no name (set name: ClassVar[str])")
    if name in REGISTRY and REGISTRY[name] is not config_cls and not replace:
        raise ConfigError(
            f"register_controller: the name {name!r} is taken by {REGISTRY[name].__name__}; "
            "pass replace=True to replace it"
        )
    REGISTRY[name] = config_cls


def make_controller(
    config_or_name: ControllerConfig | str, model: mujoco.MjModel, **params: Any
) -> Controller:
    """Build a controller for ``model`` from its config, or from its name and config fields.

    ``make_controller("pd", model, kp_pos=2000.0)`` is
    ``ControllerConfig.select({"name": "pd", "kp_pos": 2000.0}).build(model)``.

    Raises:
        UnknownComponent: for a name not in :data:`REGISTRY` (the message lists the known ones).
        ConfigError: for a bad field name or value (named ``controller.<field>``), or fields
            passed together with a config.
    """
    if isinstance(config_or_name, ControllerConfig):
        if params:
            raise ConfigError(
                f"controller: pass fields in the config, not as arguments: {', '.join(sorted(params))}"
            )
        return config_or_name.build(model)
    return ControllerConfig.select({"name": config_or_name, **params}).build(model)
