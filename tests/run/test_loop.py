"""The one loop: timing, ordering, failures and how a run ends."""

from __future__ import annotations

from typing import Any, ClassVar

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers import make_controller
from peg_ctrl.controllers.base import ControlOutput, SolveTiming
from peg_ctrl.controllers.pd import PDConfig, PDController
from peg_ctrl.errors import ConfigError, DivergenceError
from peg_ctrl.run.loop import Loop, SensorNoise, StepInfo
from peg_ctrl.sim.ft_model import FT_PRESETS, FTSensorModel
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.sim.state import BLOCK_PEG, PAIRS, ControlState
from peg_ctrl.tasks.base import Capabilities
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


def test_the_period_that_fails_on_a_force_spike_counts_in_the_sustained_force(model: mujoco.MjModel) -> None:
    qpos = model.key("home").qpos.copy()
    peg = model.joint("peg_free").qposadr[0]
    qpos[peg : peg + 3] = (0.225, 0.0, 0.0605)  # lying on the block's face, 0.5 mm above it
    loop = make(model, TrackingTask(HOME, qpos=qpos))
    loop.contact = ContactMonitor(force_spike=1e-6)  # fails at the first peg-block contact
    loop.reset(np.random.default_rng(0))
    outcome = loop.run(max_steps=200)
    assert (outcome.status, outcome.reason) == ("failure", "force_spike") and "block-peg" in outcome.detail
    assert 0.0 < loop.contact.peak_block_sustained <= loop.contact.peak_block


class Exploding:
    """A controller written against the protocol alone, not :class:`ControllerBase`."""

    name = "exploding"
    control_dt = 0.001
    observes_belief = False

    def reset(self, state: ControlState) -> None:
        pass

    def compute(self, state: ControlState, target: GripperTarget) -> ControlOutput:
        raise DivergenceError("non-finite control")

    def observe_belief(self, belief: object) -> None:
        pass

    def timings(self) -> list[SolveTiming]:
        return []


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


# -- the sensed state ---------------------------------------------------------------------------


def _noisy(model: mujoco.MjModel, ft: FTSensorModel, *, position: float = 0.0, seed: int = 0) -> Loop:
    loop = make(model, TrackingTask(HOME, qpos=model.key("home").qpos.copy()), control_dt=0.002)
    rng = np.random.default_rng(seed)
    loop.noise = SensorNoise(position=position, velocity=0.0, ft=ft, dt=loop.control_dt, rng=rng)
    return loop


def test_the_ft_reading_lags_the_truth_from_the_reset_on(model: mujoco.MjModel) -> None:
    """Two control periods of latency: each step acts on the true wrench of two steps before,
    and the first steps on the true wrench at the reset (the delay line starts with it)."""
    loop = _noisy(model, FTSensorModel(latency=0.004))  # the peg drops: the wrench changes
    truth: list[np.ndarray] = []
    sensed: list[np.ndarray] = []

    class Keep:
        def record(self, loop: Loop, info: StepInfo) -> None:
            sensed.append(info.gripper.ft_wrench)

    loop.recorders = [Keep()]
    loop.reset(np.random.default_rng(0))
    for _ in range(30):
        truth.append(loop.state().ft_wrench)
        loop.step()
    expected = [truth[0], truth[0], *truth[:-2]]
    np.testing.assert_array_equal(sensed, expected)
    assert not np.array_equal(truth[0], truth[-1])


def test_one_reading_per_control_period(model: mujoco.MjModel) -> None:
    loop = _noisy(model, FT_PRESETS["wrist"], position=1e-4)
    loop.reset(np.random.default_rng(0))
    first = loop.sensed()
    assert loop.sensed() is first  # asked twice, read once
    seen: list[ControlState] = []

    class Keep:
        def record(self, loop: Loop, info: StepInfo) -> None:
            seen.append(info.gripper)

    loop.recorders = [Keep()]
    loop.step()
    assert seen == [first]  # the step acted on it
    assert loop.sensed() is not first  # a new period, a new reading
    assert not np.array_equal(loop.sensed().ft_wrench, loop.state().ft_wrench)


def test_the_same_force_and_torque_noise_is_the_old_single_sigma_draw_for_draw(model: mujoco.MjModel) -> None:
    """force_noise = torque_noise = sigma reads exactly as domain.force_noise = sigma did when
    it covered all six channels (the reference below is that formula)."""
    sigma, position = 0.3, 2e-4
    loop = _noisy(model, FTSensorModel(force_noise=sigma, torque_noise=sigma), position=position, seed=5)
    loop.reset(np.random.default_rng(0))
    state = loop.state()
    rng = np.random.default_rng(5)
    for _ in range(20):
        expected = state._replace(
            p_world=state.p_world + rng.normal(0.0, position, 3),
            v_world=state.v_world + rng.normal(0.0, 0.0, 3),
            omega_body=state.omega_body + rng.normal(0.0, 0.0, 3),
            ft_wrench=state.ft_wrench + rng.normal(0.0, sigma, 6),
        )
        got = loop.noise.apply(state)  # type: ignore[union-attr]
        for name in ("p_world", "v_world", "omega_body", "ft_wrench"):
            np.testing.assert_array_equal(getattr(got, name), getattr(expected, name), err_msg=name)


def test_the_orientation_reads_a_rotation_of_sigma_about_each_gripper_axis(model: mujoco.MjModel) -> None:
    """Each reading turns the true orientation by a rotation drawn with standard deviation
    ``orientation`` about each axis; nothing else in the reading moves. (An isotropic rotation
    reads the same in the gripper's frame and the world's: the frame is the draw-order test's.)"""
    sigma = 2e-4
    rng = np.random.default_rng(3)
    noise = SensorNoise(position=0.0, velocity=0.0, orientation=sigma, ft=FTSensorModel(), dt=0.001, rng=rng)
    loop = make(model)
    loop.reset(np.random.default_rng(0))
    state = loop.state()
    noise.reset(state)
    q_true = state.quat_world
    errors = []
    for _ in range(4000):
        got = noise.apply(state)
        assert np.linalg.norm(got.quat_world) == pytest.approx(1.0, abs=1e-12)
        for name in ("p_world", "v_world", "omega_body", "ft_wrench"):
            np.testing.assert_array_equal(getattr(got, name), getattr(state, name), err_msg=name)
        dq = np.empty(4)
        mujoco.mju_negQuat(dq, q_true)
        mujoco.mju_mulQuat(dq, dq, got.quat_world)  # the error in the gripper frame
        w = np.empty(3)
        mujoco.mju_quat2Vel(w, dq, 1.0)
        errors.append(w)
    e = np.array(errors)
    np.testing.assert_allclose(e.std(axis=0), sigma, rtol=0.06)
    np.testing.assert_allclose(e.mean(axis=0), 0.0, atol=4 * sigma / np.sqrt(len(e)))


def test_orientation_noise_draws_after_the_velocities_and_only_when_on(model: mujoco.MjModel) -> None:
    """With ``orientation`` 0 a reading draws position, velocities and the F/T noise, in that
    order, as before the field existed (the reference below is that formula); with it on, three
    draws for the orientation come between the velocities and the F/T sensor's."""
    position, velocity, force = 1e-4, 1e-3, 0.3
    ft = FTSensorModel(force_noise=force, torque_noise=force)
    loop = make(model)
    loop.reset(np.random.default_rng(0))
    state = loop.state()
    off = SensorNoise(position=position, velocity=velocity, ft=ft, dt=0.001, rng=np.random.default_rng(9))
    on = SensorNoise(
        position=position, velocity=velocity, ft=ft, dt=0.001, rng=np.random.default_rng(9), orientation=1e-4
    )
    rng = np.random.default_rng(9)
    ref = np.random.default_rng(9)
    for _ in range(20):
        expected = state._replace(
            p_world=state.p_world + rng.normal(0.0, position, 3),
            v_world=state.v_world + rng.normal(0.0, velocity, 3),
            omega_body=state.omega_body + rng.normal(0.0, velocity, 3),
            ft_wrench=state.ft_wrench + rng.normal(0.0, force, 6),
        )
        got = off.apply(state)
        for name in ("p_world", "quat_world", "v_world", "omega_body", "ft_wrench"):
            np.testing.assert_array_equal(getattr(got, name), getattr(expected, name), err_msg=name)
        p, v, w = (ref.normal(0.0, s, 3) for s in (position, velocity, velocity))
        turn = ref.normal(0.0, 1e-4, 3)
        wrench = state.ft_wrench + ref.normal(0.0, force, 6)
        turned = state.quat_world.copy()
        mujoco.mju_quatIntegrate(turned, turn, 1.0)
        got = on.apply(state)
        np.testing.assert_array_equal(got.p_world, state.p_world + p)
        np.testing.assert_array_equal(got.v_world, state.v_world + v)
        np.testing.assert_array_equal(got.omega_body, state.omega_body + w)
        np.testing.assert_array_equal(got.quat_world, turned)
        np.testing.assert_array_equal(got.ft_wrench, wrench)


class Believing(TrackingTask):
    """Tracks home while its belief changes: ``beliefs[k]`` during control step k (from 1)."""

    capabilities: ClassVar[Capabilities] = Capabilities(belief=True)

    def __init__(self, beliefs: list[object]) -> None:
        super().__init__(sequence=[HOME] * len(beliefs))
        self.beliefs = beliefs
        self.reads = 0

    @property
    def belief(self) -> Any:
        self.reads += 1
        return self.beliefs[self._index - 1]


class Listening(PDController):
    """A PD law that keeps every belief it hears."""

    observes_belief = True

    def __init__(self, model: mujoco.MjModel) -> None:
        super().__init__(model, PDConfig(control_dt=0.001))
        self.heard: list[object] = []

    def observe_belief(self, belief: object) -> None:
        self.heard.append(belief)


def test_the_loop_hands_each_new_belief_to_a_controller_that_observes_beliefs(model: mujoco.MjModel) -> None:
    first, second = object(), object()
    task = Believing([first, first, second, second, second])
    controller = Listening(model)
    loop = Loop(model=model, controller=controller, task=task, scene=SceneConfig())
    loop.reset(np.random.default_rng(0))
    assert loop.run(max_steps=100).status == "success"  # the sequence ran out
    assert controller.heard == [first, second] and controller.heard[0] is first


def test_the_loop_reads_no_belief_for_a_controller_that_does_not_observe_them(model: mujoco.MjModel) -> None:
    task = Believing([object()] * 5)
    loop = make(model, task)
    loop.reset(np.random.default_rng(0))
    loop.run(max_steps=100)
    assert loop.steps == 5 and task.reads == 0
    listening = Listening(model)  # and a task without the capability states no belief
    tracking = TrackingTask(sequence=[HOME] * 5)
    loop = Loop(model=model, controller=listening, task=tracking, scene=SceneConfig())
    loop.reset(np.random.default_rng(0))
    loop.run(max_steps=100)
    assert loop.steps == 5 and listening.heard == []


def test_a_robots_position_error_holds_over_a_touch_and_its_velocity_is_differenced(
    model: mujoco.MjModel,
) -> None:
    """domain.position_error_time > 0: the sensed position's error is a smooth, slowly varying
    error of standard deviation ``position`` (knots every tau), plus white noise; the sensed
    linear velocity is the difference of the sensed positions. A still hand: the error's std
    matches, it holds over a touch (correlated above 0.9 over 50 ms) and an average over 20 ms
    does not average it away (as white noise would), and the velocity's std is the white
    noise's, sqrt(2) * white / dt, within 10 %: the slow error adds almost nothing to it."""
    sigma, tau, white, dt = 1e-4, 0.5, 2e-6, 0.001
    loop = make(model)
    loop.reset(np.random.default_rng(0))
    state = loop.state()
    errors, velocities = [], []
    for seed in range(8):  # independent episodes: the error's level differs between them
        noise = SensorNoise(
            position=sigma,
            velocity=0.0,
            ft=FTSensorModel(),
            dt=dt,
            rng=np.random.default_rng(seed),
            position_error_time=tau,
            position_white=white,
        )
        noise.reset(state)
        readings = [noise.apply(state) for _ in range(20000)]
        errors.append(np.array([r.p_world - state.p_world for r in readings]))
        velocities.append(np.array([r.v_world for r in readings[1:]]))
    e = np.concatenate(errors)
    assert e.std() == pytest.approx(sigma, rel=0.25)
    lag = int(0.1 * tau / dt)
    # about the known zero mean (a sample mean over a few tau would bias it)
    corr = sum(float(np.sum(x[:-lag] * x[lag:])) for x in errors) / sum(
        float(np.sum(x[:-lag] ** 2)) for x in errors
    )
    assert corr > 0.9
    window = np.concatenate([x[: (len(x) // 20) * 20].reshape(-1, 20, 3).mean(axis=1) for x in errors])
    assert window.std() > 0.9 * e.std()  # 20 readings averaged: the repeatability stays
    v = np.concatenate(velocities)
    assert v.std() == pytest.approx(np.sqrt(2.0) * white / dt, rel=0.1)  # white dominates the difference


def test_a_robots_white_position_noise_needs_its_error_time() -> None:
    from peg_ctrl.run.episode import DomainConfig

    with pytest.raises(ConfigError, match="domain.position_white_noise"):
        DomainConfig(position_white_noise=1e-6)
    assert DomainConfig(position_error_time=0.5, position_white_noise=1e-6).noisy
