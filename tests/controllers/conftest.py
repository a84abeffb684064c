"""Fixtures for the controller tests: the state at the home keyframe (no physics stepped)."""

from __future__ import annotations

import mujoco
import pytest

from peg_ctrl.sim.scene import HOME_KEY
from peg_ctrl.sim.state import ControlState, StateReader

NAMES = ("admittance", "diffik", "impedance", "mpc", "pd", "sampling_mpc")


@pytest.fixture(scope="session")
def home_state(model: mujoco.MjModel) -> ControlState:
    """The gripper at rest at the ``home`` keyframe, as the loop would observe it."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(HOME_KEY).id)
    mujoco.mj_forward(model, data)
    return StateReader(model).control_state(data)
