"""Same inputs, bit-identical trajectories."""

from __future__ import annotations

import numpy as np

from peg_ctrl.commands import euler_to_quat
from peg_ctrl.controllers import make_controller
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.scene import build_model

from ..conftest import HOME, target


def _run() -> np.ndarray:
    model = build_model()
    sim = Tracker(model, make_controller("pd", model))
    trace = []
    goals = [
        target(HOME + [0.0, 0.0, -0.18], jaw=0.085),
        target(HOME + [0.0, 0.0, -0.184], jaw=0.0),
        target(HOME + [0.05, 0.02, -0.05], euler_to_quat(1.0, 0.0, 0.2), jaw=0.0),
    ]
    for goal in goals:
        for _ in range(400):
            sim.control_step(goal)
            trace.append(np.concatenate([sim.data.qpos, sim.data.qvel]))
    return np.asarray(trace)


def test_two_runs_are_bit_identical() -> None:
    a, b = _run(), _run()
    assert a.shape == b.shape
    assert np.array_equal(a, b)
