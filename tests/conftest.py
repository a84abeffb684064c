"""Shared fixtures: the default scene compiled once per test session."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from controllers import make_controller
from peg_ctrl.commands import GripperTarget
from peg_ctrl.scene import build_model
from peg_ctrl.sim import Simulation

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
HOME = np.array([-0.2, 0.0, 0.2])


@pytest.fixture(scope="session")
def model() -> mujoco.MjModel:
    return build_model()


@pytest.fixture()
def sim(model: mujoco.MjModel) -> Simulation:
    return Simulation(model, make_controller("pd", model))


def target(p, quat=IDENTITY, *, jaw: float = 0.085, v=(0.0, 0.0, 0.0), w=(0.0, 0.0, 0.0)) -> GripperTarget:
    return GripperTarget(
        p_world=np.asarray(p, dtype=float),
        quat_world=np.asarray(quat, dtype=float),
        jaw_sep_m=jaw,
        v_world=np.asarray(v, dtype=float),
        omega_body=np.asarray(w, dtype=float),
    )
