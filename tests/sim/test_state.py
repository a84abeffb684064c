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


def _contacts_with_arrays(reader: StateReader, data: mujoco.MjData) -> list[tuple]:
    """The per-pair contact sums as the arrays compute them (the reference for contacts())."""
    from peg_ctrl.sim.state import BODY_GROUPS

    model, sums = reader.model, {}
    wrench = np.zeros(6)
    for i in range(data.ncon):
        con = data.contact[i]
        if con.efc_address < 0:
            continue
        group = reader._body_group
        g1 = BODY_GROUPS[group[model.geom_bodyid[con.geom1]]]
        g2 = BODY_GROUPS[group[model.geom_bodyid[con.geom2]]]
        if g1 == g2:
            continue
        mujoco.mj_contactForce(model, data, i, wrench)
        f_world = con.frame.reshape(3, 3).T @ wrench[:3]
        pair, f = ((g1, g2), -f_world) if g1 < g2 else ((g2, g1), f_world)
        entry = sums.setdefault(pair, [np.zeros(3), np.zeros(3), 0.0, 0, 0.0])
        mag = float(np.linalg.norm(f))
        entry[0] += f
        entry[1] += mag * con.pos
        entry[2] += mag
        entry[3] += 1
        entry[4] = max(entry[4], con.includemargin - float(con.dist))
    return [
        (pair, f, float(np.linalg.norm(f)), p / total, n, max(pen, 0.0))
        for pair, (f, p, total, n, pen) in sorted(sums.items())
        if total >= reader.contact_threshold_n
    ]


def test_contacts_and_the_sensor_reduction_are_the_arrays_to_the_last_bits() -> None:
    """The held peg pressed onto the block: SensorBlock.reduce() gives the very numbers the array
    code gives; the plain-float contacts() the same to within a few units in the last place
    (numpy's matrix product and norm may sum in another order, with SIMD or fused operations)."""
    from peg_ctrl.run.episode import build_loop, episode_config_from_mapping

    cfg = {"task": {"name": "held_insertion", "strategy": "force"}, "physics": {"profile": "precision"}}
    loop = build_loop(episode_config_from_mapping(cfg))
    loop.reset(np.random.default_rng(0))
    sensors, touched = loop.sensors, 0
    for _ in range(1200):
        loop.step()
        forces, pens = sensors.reduce()
        block = sensors.block_force
        assert (forces, pens) == sensors._reduce_arrays() and block == sensors.block_force
        contacts = loop.reader.contacts(loop.data)
        reference = _contacts_with_arrays(loop.reader, loop.data)
        assert [(c.pair, c.count, c.max_penetration_m) for c in contacts] == [
            (r[0], r[4], r[5]) for r in reference
        ]
        for c, (_, f, mag, p, _, _) in zip(contacts, reference, strict=True):
            # relative to the vector's size: a small component is a difference of large terms
            np.testing.assert_allclose(c.force_world, f, rtol=0.0, atol=1e-13 * mag)
            np.testing.assert_allclose(c.position_world, p, rtol=0.0, atol=1e-15)
            assert c.magnitude == pytest.approx(mag, rel=1e-13)
        touched += block[-1] > 0.0 and pens[0] > 0.0
    assert touched > 100  # the peg pressed on the block for a good part of it
    sensors.raw[0, 0] = np.nan  # a diverging step: numpy's NaN propagation, kept
    forces, pens = sensors.reduce()
    assert all(np.isnan(forces)) and np.array_equal(forces, sensors._reduce_arrays()[0], equal_nan=True)
