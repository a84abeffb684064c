"""The one loop: timing, ordering, failures and how a run ends."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers import make_controller
from peg_ctrl.controllers.base import ControlOutput
from peg_ctrl.errors import ConfigError, DivergenceError
from peg_ctrl.run.loop import Loop, StepInfo
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.state import BLOCK_PEG, PAIRS, ControlState
from peg_ctrl.tasks.monitors import ContactMonitor
from peg_ctrl.tasks.tracking import TrackingTask

HOME = GripperTarget(p_world=np.array([-0.2, 0.0, 0.2]), quat_world=np.array([1.0, 0, 0, 0]), jaw_sep_m=0.085)


class Log:
    def __init__(self) -> None:
        self.steps: list[int] = []

    def record(self, loop: Loop, info: StepInfo) -> None:
        self.steps.append(info.step)


def make(model: mujoco.MjModel, task=None, **kw) -> Loop:  # type: ignore[no-untyped-def]
    kw.setdefault("control_dt", 0.001)  # one physics step per control step
    return Loop(
        model=model,
        controller=make_controller("pd", model, **kw),
        task=task or TrackingTask(HOME),
        scene=SceneConfig(),
    )


def test_control_period_must_be_a_whole_multiple_of_the_timestep(model: mujoco.MjModel) -> None:
    assert make(model, control_dt=0.005).decimation == 5
    with pytest.raises(ConfigError, match="not a whole multiple"):
        make(model, control_dt=0.0015)


def test_a_sequence_runs_to_its_end_and_every_step_is_recorded(model: mujoco.MjModel) -> None:
    log = Log()
    loop = make(model, TrackingTask(sequence=[HOME] * 7), control_dt=0.002)
    loop.recorders = [log]
    loop.reset(np.random.default_rng(0))
    outcome = loop.run(max_steps=1000)
    assert outcome.status == "success" and loop.steps == 14
    assert log.steps == [2, 4, 6, 8, 10, 12, 14]
    assert loop.data.time == pytest.approx(0.014)


def test_the_step_limit_ends_a_run_as_a_timeout(model: mujoco.MjModel) -> None:
    loop = make(model)
    loop.reset(np.random.default_rng(0))
    outcome = loop.run(max_steps=25)
    assert (outcome.status, outcome.reason, loop.steps) == ("failure", "timeout", 25)
    assert loop.task.records[-1].outcome == "timeout"


def test_a_monitor_failure_ends_the_run_and_its_step_is_still_recorded(model: mujoco.MjModel) -> None:
    log = Log()
    drop = model.key("home").qpos.copy()
    loop = make(model, TrackingTask(HOME, qpos=drop))
    loop.contact = ContactMonitor(force_spike=1e-6)  # the resting peg touches the table at once
    loop.recorders = [log]
    loop.reset(np.random.default_rng(0))
    outcome = loop.run(max_steps=100)
    assert (outcome.status, outcome.reason) == ("failure", "force_spike")
    assert log.steps == list(range(1, loop.steps + 1))  # the failing step included
    assert loop.steps < 100


class Exploding:
    name = "exploding"
    control_dt = 0.001

    def reset(self, state: ControlState) -> None:
        pass

    def compute(self, state: ControlState, target: GripperTarget) -> ControlOutput:
        raise DivergenceError("non-finite control")


def test_a_diverging_controller_is_a_diverged_episode(model: mujoco.MjModel) -> None:
    loop = Loop(model=model, controller=Exploding(), task=TrackingTask(HOME), scene=SceneConfig())
    loop.reset(np.random.default_rng(0))
    outcome = loop.run(max_steps=10)
    assert (outcome.status, outcome.reason) == ("failure", "diverged")
    assert "non-finite control" in outcome.detail


def test_ctrl_c_ends_the_run_as_interrupted(model: mujoco.MjModel) -> None:
    class Interrupt:
        def record(self, loop: Loop, info: StepInfo) -> None:
            if info.step == 3:
                raise KeyboardInterrupt

    loop = make(model)
    loop.recorders = [Interrupt()]
    loop.reset(np.random.default_rng(0))
    outcome = loop.run(max_steps=100)
    assert outcome.status == "interrupted" and loop.steps == 3
    assert loop.task.records[-1].outcome == "interrupted"


def test_reset_restores_the_same_state(model: mujoco.MjModel) -> None:
    loop = make(model)
    loop.reset(np.random.default_rng(0))
    q0 = loop.data.qpos.copy()
    loop.advance(0.05)
    assert not np.array_equal(q0, loop.data.qpos)
    loop.reset(np.random.default_rng(0))
    np.testing.assert_array_equal(q0, loop.data.qpos)
    assert loop.steps == 0 and loop.data.time == 0.0


def test_monitors_and_trace_see_every_physics_step_between_control_steps(model: mujoco.MjModel) -> None:
    """At 200 Hz (5 physics steps per control step) the peak forces, the contact impulse and the
    sensor rows are those of every physics step: the same as single steps with the same controls."""
    drop = model.key("home").qpos.copy()
    loop = make(model, TrackingTask(HOME, qpos=drop), control_dt=0.005)
    assert loop.decimation == 5
    ctrls: list[np.ndarray] = []
    rows: list[np.ndarray] = []

    class Keep:
        def record(self, loop: Loop, info: StepInfo) -> None:
            ctrls.append(np.array(info.output.ctrl))
            rows.append(info.sensors.raw.copy())

    loop.recorders = [Keep()]
    loop.reset(np.random.default_rng(0))
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, loop.data)
    loop.run(max_steps=400)
    peaks = [0.0] * len(PAIRS)
    impulse = 0.0
    reader = loop.reader
    for ctrl in ctrls:
        data.ctrl[:] = ctrl
        for _ in range(5):
            mujoco.mj_step(model, data)
            forces, _ = reader.pair_forces(data)
            peaks = [max(a, b) for a, b in zip(peaks, forces, strict=True)]
            if loop.history.first_contact is not None and data.time >= loop.history.first_contact - 1e-9:
                impulse += forces[BLOCK_PEG] * model.opt.timestep
    np.testing.assert_array_equal(data.qpos, loop.data.qpos)
    assert max(peaks) > 0.1  # the peg rests on the table (its weight, 0.18 N)
    assert loop.contact.peak_any == pytest.approx(max(peaks), rel=1e-12)
    assert loop.history.impulse == pytest.approx(impulse, rel=1e-9, abs=1e-12)
    assert np.concatenate(rows).shape == (400, model.nsensordata)
