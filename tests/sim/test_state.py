"""State reading: poses, jaw separation and contacts grouped by body pair."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.state import StateReader

from ..conftest import HOME, target


def test_control_state_at_home(sim: Tracker) -> None:
    s = sim.state()
    np.testing.assert_allclose(s.p_world, HOME)
    np.testing.assert_allclose(s.quat_world, [1, 0, 0, 0])
    assert s.jaw_sep_m == pytest.approx(0.085, abs=0.5e-3)
    assert s.p_world.shape == (3,) and s.quat_world.shape == (4,) and s.omega_body.shape == (3,)


def test_resting_peg_contact_balances_its_weight(sim: Tracker, model: mujoco.MjModel) -> None:
    sim.hold(target(HOME), 0.5)
    full = StateReader(model).sim_state(sim.data)
    table = full.contact("table", "peg")
    assert table is not None and table.pair == ("peg", "table")
    weight = model.body("peg").mass[0] * 9.81
    # Force on the peg from the table: straight up, equal to the weight.
    np.testing.assert_allclose(table.force_world, [0.0, 0.0, weight], atol=1e-3 * weight)
    assert table.magnitude == pytest.approx(weight, rel=1e-3)
    assert abs(table.position_world[2]) < 1e-3  # on the table surface
    assert full.contact("gripper", "peg") is None
    assert full.p_world_peg[2] == pytest.approx(0.01, abs=0.3e-3)


def test_contact_dict_has_the_log_fields(sim: Tracker, model: mujoco.MjModel) -> None:
    sim.hold(target(HOME), 0.1)
    (c,) = StateReader(model).sim_state(sim.data).contacts
    d = c.to_dict()
    assert set(d) == {"pair", "force", "magnitude", "position", "count", "max_penetration_m"}
    assert d["pair"] == "peg-table"


def test_grip_is_the_pads_squeeze_that_the_net_force_cancels() -> None:
    """A peg held in the closed hand: the pads squeeze it with tens of newtons from both sides,
    while the net gripper-peg force is only the peg's weight."""
    from peg_ctrl.run.episode import build_loop, episode_config_from_mapping
    from peg_ctrl.sim.state import BLOCK_PEG, PAIRS

    loop = build_loop(episode_config_from_mapping({"task": {"name": "held_insertion"}}))
    loop.reset(np.random.default_rng(0))
    loop.step()
    grip = loop.sensors.grip(loop.sensors.raw)
    net = loop.sensors.forces(loop.sensors.raw)[:, PAIRS.index(("gripper", "peg"))]
    weight = float(loop.model.body_mass[loop.model.body("peg").id]) * 9.81
    assert grip.shape == (loop.decimation,)
    assert np.all(grip > 10.0)
    assert np.allclose(net, weight, rtol=0.2)  # the net force carries the weight, nothing more
    assert loop.sensors.forces(loop.sensors.raw)[:, BLOCK_PEG].max() == 0.0
