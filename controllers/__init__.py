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
    "REGISTRY",
    "UnknownController",
    "controller_names",
    "make_controller",
]

#: Controller name -> its config class (whose ``build(model)`` makes the controller).
REGISTRY: dict[str, type[ControllerConfig]] = {
    cfg.name: cfg for cfg in (PDConfig, ImpedanceConfig, AdmittanceConfig, DiffIKConfig, MPCConfig)
}

#: Kept for callers that catch it by its old name.
UnknownController = UnknownComponent


def controller_names() -> list[str]:
    """The registered controller names, sorted."""
    return sorted(REGISTRY)


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
