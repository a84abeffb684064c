"""Controllers for the peg-in-hole gripper, selected by name from one registry.

Every controller drives the same actuators (3 slide forces, 3 ball-joint torques, the jaw)
through the :class:`~controllers.base.Controller` protocol.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import mujoco

from controllers.admittance import AdmittanceConfig, AdmittanceController
from controllers.base import Controller, ControlOutput, Diagnostics
from controllers.diffik import DiffIKConfig, DiffIKController
from controllers.impedance import ImpedanceConfig, ImpedanceController
from controllers.mpc import MPCConfig, MPCController
from controllers.pd import PDConfig, PDController

__all__ = [
    "Controller",
    "ControlOutput",
    "Diagnostics",
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
    "make_controller",
]

# name -> (config class, factory(model, config) -> controller)
REGISTRY: dict[str, tuple[type, Callable[..., Controller]]] = {
    "pd": (PDConfig, PDController),
    "impedance": (ImpedanceConfig, ImpedanceController),
    "admittance": (AdmittanceConfig, AdmittanceController),
    "diffik": (DiffIKConfig, DiffIKController),
    "mpc": (MPCConfig, MPCController),
}


class UnknownController(ValueError):
    """A controller name that is not registered; the message lists the known names."""

    def __init__(self, name: str) -> None:
        super().__init__(f"unknown controller {name!r}; known: {', '.join(sorted(REGISTRY))}")


def make_controller(name: str, model: mujoco.MjModel, **params: Any) -> Controller:
    """Build the controller registered as ``name`` with its config fields overridden by ``params``."""
    if name not in REGISTRY:
        raise UnknownController(name)
    config_cls, factory = REGISTRY[name]
    try:
        config = config_cls(**params)
    except TypeError as exc:
        raise ValueError(f"bad parameter for controller {name!r}: {exc}") from None
    return factory(model, config)
