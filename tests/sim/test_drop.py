"""Drop tests: the peg comes to rest, barely penetrates, never tunnels and never gains energy."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.state import StateReader

from ..conftest import target

PARK = (0.5, 0.5, 0.4)  # gripper out of the way [m]


def _drop(sim: Tracker, peg_pose: list[float], duration_s: float = 2.0) -> dict[str, float]:
    """Release the peg from ``peg_pose`` (7,) and record speed, penetration and energy."""
    model, data = sim.model, sim.data
    model.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    try:
        sim.reset()
        adr = model.joint("peg_free").qposadr[0]
        q = data.qpos.copy()
        q[adr : adr + 7] = peg_pose
        q[model.joint("gripper_transX").qposadr[0] : model.joint("gripper_transX").qposadr[0] + 3] = PARK
        sim.reset(q)
        reader = StateReader(model)
        peg_body = model.body("peg").id
        dof = model.joint("peg_free").dofadr[0]
        hold = target(PARK)
        energy, speed, pen = [], [], []
        for _ in range(int(duration_s / model.opt.timestep)):
            sim.control_step(hold)
            mujoco.mj_energyPos(model, data)
            mujoco.mj_energyVel(model, data)
            v = data.qvel[dof : dof + 3]
            w = data.qvel[dof + 3 : dof + 6]
            m = model.body_mass[peg_body]
            inertia = model.body_inertia[peg_body]
            kinetic = 0.5 * m * float(v @ v) + 0.5 * float(inertia @ (w * w))
            potential = m * -model.opt.gravity[2] * data.xipos[peg_body][2]
            energy.append(kinetic + potential)
            speed.append(float(np.linalg.norm(v)))
            peg_contacts = [c for c in reader.contacts(data) if "peg" in c.pair]
            pen.append(max((c.max_penetration_m for c in peg_contacts), default=0.0))
        return {
            "energy": np.asarray(energy),
            "speed": np.asarray(speed),
            "penetration": np.asarray(pen),
            "z": float(data.qpos[adr + 2]),
        }
    finally:
        model.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_ENERGY)


def _check_rest(result: dict, record_property) -> None:
    speed, pen, energy = result["speed"], result["penetration"], result["energy"]
    steps_to_rest = int(np.argmax(speed < 1e-3))
    record_property("peak_penetration_mm", float(pen.max() * 1e3))
    record_property("resting_penetration_mm", float(pen[-1] * 1e3))
    assert speed[-1] < 1e-3, "peg still moving after 2 s"
    assert np.all(speed[steps_to_rest + 200 :] < 1e-3), "peg did not stay at rest"
    assert pen[-1] <= 0.5e-3, f"resting penetration {pen[-1] * 1e3:.3f} mm"
    assert pen.max() <= 3e-3, f"peak penetration {pen.max() * 1e3:.3f} mm"
    # Mechanical energy of the peg never rises above its initial value (1 uJ numerical slack).
    assert energy.max() <= energy[0] + 1e-6
    assert energy[-1] < energy[0]


def test_peg_dropped_on_the_table_comes_to_rest(sim: Tracker, record_property) -> None:
    r = 0.01
    result = _drop(sim, [-0.2, 0.0, r + 0.05, np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0])
    _check_rest(result, record_property)
    assert result["z"] == pytest.approx(r, abs=0.5e-3)


def test_upright_peg_dropped_into_the_hole_reaches_the_bottom(sim: Tracker, record_property) -> None:
    cfg = SceneConfig()
    hx, hy = cfg.hole_xy
    half = 0.5 * cfg.assets.peg_length
    top = cfg.assets.block_size[2]
    result = _drop(sim, [hx, hy, top + half + 0.01, 1.0, 0.0, 0.0, 0.0])
    _check_rest(result, record_property)
    # Through-hole onto the table: the peg stands on it, inside the block.
    assert result["z"] == pytest.approx(half, abs=0.5e-3)
