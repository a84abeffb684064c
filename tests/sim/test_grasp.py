"""Grasp hold: the peg does not slip in the pads under base acceleration and the 95-degree turn."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.scene import GRIPPER_PREFIX

from ..conftest import target

PEG_XY = (-0.2, 0.0)
GRASP_Z = 0.016  # pinch height over the lying peg's axis (10 mm) [m]
LIFT_Z = 0.15


def _peg_in_pad(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    pad = model.body(GRIPPER_PREFIX + "left_pad").id
    peg = model.body("peg").id
    return data.xmat[pad].reshape(3, 3).T @ (data.xpos[peg] - data.xpos[pad])


def test_grasp_holds_under_acceleration_and_rotation(sim: Tracker, record_property) -> None:
    model, data = sim.model, sim.data
    x, y = PEG_XY
    sim.hold(target([x, y, GRASP_Z]), 1.5)
    sim.hold(target([x, y, GRASP_Z], jaw=0.0), 1.0)
    closed = sim.state().jaw_sep_m
    assert 0.017 < closed < 0.0205  # closed on the 20 mm peg, not on air
    sim.hold(target([x, y, LIFT_Z], jaw=0.0), 1.5)
    assert data.body("peg").xpos[2] > LIFT_Z - 0.03, "peg was not lifted"
    ref = _peg_in_pad(model, data)

    slip = []
    # 1 m/s^2 in x and y for 0.3 s, then -1 m/s^2 back to rest (trajectory with feed-forward).
    p = np.array([x, y, LIFT_Z])
    v = np.zeros(3)
    accel = np.array([1.0, 1.0, 0.0])
    dt = model.opt.timestep
    for k in range(600):
        v = v + (accel if k < 300 else -accel) * dt
        p = p + v * dt
        sim.control_step(target(p, jaw=0.0, v=v))
        slip.append(np.linalg.norm(_peg_in_pad(model, data) - ref))
    # Turn 95 degrees about X in 2 s (smoothstep profile with its angular-velocity feed-forward).
    angle, duration = math.radians(95), 2.0
    n = int(duration / dt)
    for k in range(n + 1000):
        s = min(k / n, 1.0)
        theta = angle * (3 * s * s - 2 * s**3)
        omega = angle * (6 * s - 6 * s * s) / duration if k < n else 0.0
        sim.control_step(target(p, euler_to_quat(theta, 0.0, 0.0), jaw=0.0, w=(omega, 0.0, 0.0)))
        slip.append(np.linalg.norm(_peg_in_pad(model, data) - ref))
    record_property("max_slip_mm", float(max(slip) * 1e3))
    assert max(slip) <= 0.5e-3, f"peg slipped {max(slip) * 1e3:.3f} mm"
    # And the peg really turned with the gripper: its axis is now within 10 degrees of vertical.
    axis = data.body("peg").xmat.reshape(3, 3)[:, 2]
    assert abs(axis[2]) > math.cos(math.radians(10))
