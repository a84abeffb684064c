"""The one closed loop. It owns time.

Every control period::

    observe (gripper state as sensed: SensorNoise) → task.target → controller.compute → data.ctrl
    → ``decimation`` physics steps, each followed by one copy of ``data.sensordata`` (in C)
    → contact forces and penetrations of every physics step at once (numpy, preallocated)
    → observe the peg → monitors (divergence, contact force spike, grasp slip) → task.evaluate
    → recorders

Per physics step the loop does only what must happen per step: step the physics and keep its
contact sensors, so peak forces, the contact impulse, the force-spike check and the force trace
are at the full physics rate. Everything the control law, the task and the monitors need runs
once per control period, and so are the sensors: :meth:`Loop.sensed` is one reading per
control period, which the task, the controller (and an agent, see :mod:`peg_ctrl.gym.env`)
share. Autonomous episodes, teleoperation and the benchmark are thin drivers
of :class:`Loop`; no other code steps the physics in a loop (jaw calibration and the
benchmark's raw-physics replay aside). The control period must be a whole multiple of the
physics timestep.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from typing import NamedTuple, Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import GripperTarget
from peg_ctrl.controllers.base import Controller, ControlOutput
from peg_ctrl.environment import start_perturbation
from peg_ctrl.errors import DivergenceError, EpisodeFailure
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.ft_model import FTSensorModel, FTSensorStream
from peg_ctrl.sim.scene import HOME_KEY, SLIDE_JOINTS, SceneConfig, contact_sensor_name
from peg_ctrl.sim.state import BLOCK_PEG, ControlState, PegObservation, SensorBlock, StateReader
from peg_ctrl.tasks.base import Evaluation, Observation, Task, belief_task, check_capabilities
from peg_ctrl.tasks.monitors import ContactHistory, ContactMonitor, DivergenceMonitor, GraspMonitor
from peg_ctrl.timing import control_decimation

__all__ = ["Loop", "LoopOutcome", "StepInfo", "Recorder", "SensorNoise", "LoopTimer", "PhantomGuard"]


class SensorNoise:
    """The gripper state as its sensors report it, one reading per control period ``dt`` [s]:
    zero-mean Gaussian noise of standard deviation ``position`` [m] on the position and
    ``velocity`` [m/s] (and [rad/s]) on the velocities (drawn when either is on), a rotation of
    standard deviation ``orientation`` [rad] about each of the gripper's axes on its orientation
    (drawn when it is on), and the wrist force/torque reading through the sensor model ``ft``
    (:class:`~peg_ctrl.sim.ft_model.FTSensorStream`: noise per channel, latency, bias drift);
    everything drawn from ``rng``, in that order.

    With ``position_error_time`` > 0 the position's error is a robot's: a smooth, slowly varying
    error (independent Gaussian knots every ``position_error_time`` [s], joined by half-cosines,
    scaled so that its standard deviation over time is ``position``: a repeatability that holds
    over a touch), plus white noise ``position_white`` [m]; the linear velocity is differenced
    from the sensed positions, as a robot's is (``velocity`` stays on the angular velocity).

    :meth:`reset` at the start of an episode with the true state (it fills the F/T delay line,
    and draws the robot's error from its stationary distribution).
    """

    def __init__(
        self,
        *,
        position: float,
        velocity: float,
        ft: FTSensorModel,
        dt: float,
        rng: np.random.Generator,
        orientation: float = 0.0,
        position_error_time: float = 0.0,
        position_white: float = 0.0,
    ) -> None:
        self.position, self.velocity, self.orientation = position, velocity, orientation
        self.rng = rng
        self.ft = FTSensorStream(ft, dt=dt, rng=rng)
        self._kinematic = position > 0 or velocity > 0
        self._robot = position_error_time > 0
        self._dt, self._white = dt, position_white
        self._step = dt / position_error_time if self._robot else 0.0  # of the way between knots
        # the half-cosine blend of two independent knots has 3/4 of a knot's variance on average
        self._knot_sigma = position / math.sqrt(0.75)
        self._knots = np.zeros((2, 3))
        self._phase = 0.0
        self._last: NDArray[np.float64] | None = None  # the last sensed position (robot model)

    def reset(self, s: ControlState) -> None:
        if self._robot:
            self._knots = self.rng.normal(0.0, self._knot_sigma, (2, 3))
            self._phase = float(self.rng.uniform())
            self._last = None
        self.ft.reset(s.ft_wrench)

    def _robot_pose(self, s: ControlState) -> ControlState:
        """The position with a robot's slowly varying error and white noise; the velocity differenced."""
        rng = self.rng
        self._phase += self._step
        while self._phase >= 1.0:
            self._knots = np.stack([self._knots[1], rng.normal(0.0, self._knot_sigma, 3)])
            self._phase -= 1.0
        w = 0.5 * (1.0 - math.cos(math.pi * self._phase))
        error = (1.0 - w) * self._knots[0] + w * self._knots[1]
        p = s.p_world + error + rng.normal(0.0, self._white, 3)
        v = s.v_world if self._last is None else (p - self._last) / self._dt
        self._last = p
        return s._replace(p_world=p, v_world=v, omega_body=s.omega_body + rng.normal(0.0, self.velocity, 3))

    def apply(self, s: ControlState) -> ControlState:
        if self._robot:
            s = self._robot_pose(s)
        elif self._kinematic:
            rng = self.rng
            s = s._replace(
                p_world=s.p_world + rng.normal(0.0, self.position, 3),
                v_world=s.v_world + rng.normal(0.0, self.velocity, 3),
                omega_body=s.omega_body + rng.normal(0.0, self.velocity, 3),
            )
        if self.orientation > 0:
            q = s.quat_world.copy()
            mujoco.mju_quatIntegrate(q, self.rng.normal(0.0, self.orientation, 3), 1.0)  # gripper frame
            s = s._replace(quat_world=q)
        return s._replace(ft_wrench=self.ft.apply(s.ft_wrench))


class StepInfo(NamedTuple):
    """One control step, for recorders: ``step`` physics steps done, time ``t`` [s] after it.

    ``forces`` and ``penetrations`` are the largest of the control period's physics steps; the
    sensors of every physics step are in ``sensors`` (valid during ``record`` only).
    """

    step: int
    t: float
    phase: str
    gripper: ControlState  # as sensed when the step started
    target: GripperTarget
    output: ControlOutput
    peg: PegObservation  # after the step
    forces: list[float]  # peak net contact force per pair of state.PAIRS [N]
    penetrations: list[float]  # peak per state.PEG_PARTNERS [m]
    sensors: SensorBlock  # the period's physics steps, one row each
    peg_qpos: NDArray[np.float64]  # (decimation, 7) the peg's pose after each physics step


# A contact sensor's data (mjtConDataField bits) and reduction: the number of matching contacts
# and the distance of the closest one.
_FOUND_DIST = (1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)) | (
    1 << int(mujoco.mjtConDataField.mjCONDATA_DIST)
)
_MINDIST = 1
_AUTORESET = int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)


class PhantomGuard:
    """Steps the physics, recomputing a step's collisions without multiccd when the collider
    returns a phantom peg-block contact (deeper than ``depth`` [m]; see
    :attr:`peg_ctrl.sim.physics.PhysicsProfile.phantom_depth`).

    :meth:`step` is one guarded step: ``mj_step1`` + ``mj_step2`` is bit-identical to
    ``mj_step`` (not available for RK4), so a step without a phantom is exactly the plain one.
    ``count`` is the number of recomputed steps.

    A control period's steps are cheaper checked afterwards (:meth:`begin`, plain ``mj_step``,
    :meth:`end`): the scene's peg-block contact sensor holds the smallest distance among exactly
    the contacts each step's collision returned (``found``, ``dist``; computed in its
    ``mj_step2``), and with MuJoCo's auto-reset off a step gone bad leaves a new warning and
    nothing else. A period with neither was the guarded one, step for step; one with either
    is put back to its start, to be rerun with :meth:`step`. A model without that sensor
    (``sensor`` None) is guarded step by step.
    """

    STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # what a step starts from, in full

    def __init__(self, model: mujoco.MjModel, depth: float) -> None:
        if model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
            raise ValueError("the phantom-contact guard needs a split step; RK4 has none")
        self.depth = depth
        peg, block = model.body("peg").id, model.body("block").id
        self._peg = set(np.flatnonzero(model.geom_bodyid == peg).tolist())
        self._block = set(np.flatnonzero(model.geom_bodyid == block).tolist())
        self.count = 0
        #: sensordata address of the peg-block contact sensor's (found, dist), or None.
        self.sensor: int | None = None
        name = contact_sensor_name("dist", "block", "peg")
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, name)
        body = int(mujoco.mjtObj.mjOBJ_BODY)
        if (
            sid >= 0
            and {
                (int(model.sensor_objtype[sid]), int(model.sensor_objid[sid])),
                (int(model.sensor_reftype[sid]), int(model.sensor_refid[sid])),
            }
            == {(body, peg), (body, block)}  # exactly the contacts _phantom looks at
            and model.sensor_intprm[sid][:3].tolist() == [_FOUND_DIST, _MINDIST, 1]
        ):
            self.sensor = int(model.sensor_adr[sid])
        self._start = np.empty(mujoco.mj_stateSize(model, self.STATE))
        self._opt = model.opt  # the guard is this model's
        self._flags = 0
        self._warnings: list[int] = []
        self._lastinfo: list[int] = []
        self._data: mujoco.MjData | None = None  # the data whose warning counters are viewed

    def step(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """One guarded physics step."""
        mujoco.mj_step1(model, data)
        if data.ncon and self._phantom(data):
            flags = model.opt.disableflags
            model.opt.disableflags = flags | mujoco.mjtDisableBit.mjDSBL_MULTICCD
            try:
                mujoco.mj_step1(model, data)  # positions and velocities are still this step's
            finally:
                model.opt.disableflags = flags
            self.count += 1
        mujoco.mj_step2(model, data)

    def begin(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Before a period of plain steps: keep its start; MuJoCo's auto-reset off."""
        mujoco.mj_getState(model, data, self._start, self.STATE)
        if data is not self._data:  # views into data's arrays, fixed for its lifetime
            self._data = data
            self._number, self._lastinfo_view = data.warning.number, data.warning.lastinfo
        self._warnings, self._lastinfo = self._number.tolist(), self._lastinfo_view.tolist()
        opt = self._opt
        self._flags = flags = opt.disableflags
        opt.disableflags = flags | _AUTORESET

    def end(self, model: mujoco.MjModel, data: mujoco.MjData, rows: NDArray[np.float64]) -> bool:
        """After the period's plain steps, whose ``sensordata`` are ``rows`` (one per step):
        restore the auto-reset; if a step had a phantom or went bad, put the period back to
        its start (state and warnings) and return True: it is to be rerun with :meth:`step`."""
        self._opt.disableflags = self._flags
        assert self.sensor is not None
        adr, limit = self.sensor, -self.depth
        # (found, dist) of each step; a NaN distance is not trusted either
        clean = all(found == 0.0 or dist >= limit for found, dist in rows[:, adr : adr + 2].tolist())
        if clean and self._number.tolist() == self._warnings:
            return False
        mujoco.mj_setState(model, data, self._start, self.STATE)
        self._number[:] = self._warnings
        self._lastinfo_view[:] = self._lastinfo
        return True

    def _phantom(self, data: mujoco.MjData) -> bool:
        # Plain Python over a handful of contacts: numpy's per-call cost would dominate.
        contact = data.contact
        limit = -self.depth
        dist = contact.dist.tolist()
        if min(dist) >= limit:  # nothing that deep (the usual case); a NaN first goes on below
            return False
        deep = [i for i, d in enumerate(dist) if d < limit]
        if not deep:
            return False
        geoms = contact.geom.tolist()
        peg, block = self._peg, self._block
        for i in deep:
            a, b = geoms[i]
            if (a in peg and b in block) or (b in peg and a in block):
                return True
        return False


class LoopTimer:
    """Optional per-section CPU timing of :meth:`Loop.step` (for ``peg-sim bench``): seconds
    summed over steps in ``task`` (target and evaluate), ``controller``, ``physics`` (the
    physics steps and their sensor copies), ``monitors`` (sensor reduction, observation and
    checks) and ``recording`` (the recorders)."""

    SECTIONS = ("task", "controller", "physics", "monitors", "recording")

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(self.SECTIONS, 0.0)
        self.steps = 0  # control steps timed

    def add(self, task: float, controller: float, physics: float, monitors: float, recording: float) -> None:
        sec = self.seconds
        sec["task"] += task
        sec["controller"] += controller
        sec["physics"] += physics
        sec["monitors"] += monitors
        sec["recording"] += recording
        self.steps += 1


def _no_clock() -> float:
    return 0.0


class Recorder(Protocol):
    """Receives every control step (including the one on which the episode failed)."""

    def record(self, loop: Loop, info: StepInfo) -> None: ...


class LoopOutcome(NamedTuple):
    """How :meth:`Loop.run` ended: ``status`` is "success", "failure" or "interrupted"."""

    status: str
    reason: str
    detail: str
    evaluation: Evaluation | None  # the task's last verdict (None before the first step)


@dataclasses.dataclass
class Loop:
    """Model, data, controller, task, monitors and recorders, stepped together."""

    model: mujoco.MjModel
    controller: Controller
    task: Task
    scene: SceneConfig
    contact: ContactMonitor = dataclasses.field(default_factory=ContactMonitor)
    history: ContactHistory = dataclasses.field(default_factory=ContactHistory)
    grasp: GraspMonitor | None = None
    noise: SensorNoise | None = None
    recorders: Sequence[Recorder] = ()
    contact_threshold_n: float = 0.01  # contacts below this are left out of logs [N]
    phantom_depth: float | None = None  # see PhantomGuard; None: plain mj_step

    def __post_init__(self) -> None:
        check_capabilities(self.task)
        self.data = mujoco.MjData(self.model)
        self.reader = StateReader(self.model, contact_threshold_n=self.contact_threshold_n)
        self.decimation = control_decimation(self.controller.control_dt, self.model.opt.timestep)
        self.divergence = DivergenceMonitor()
        self.sensors = self.reader.sensor_block(self.decimation)
        self.peg_qpos = np.zeros((self.decimation, 7))
        self._timestep = float(self.model.opt.timestep)
        self._peg_q = self.data.qpos[self.reader.peg_qpos_slice]  # a view into data
        self.timer: LoopTimer | None = None
        self._half_length = 0.5 * self.scene.assets.peg_length
        self._home = self.model.key(HOME_KEY).id
        self.steps = 0  # physics steps since reset
        self.last: Evaluation | None = None
        self.output: ControlOutput | None = None  # the controller's last output
        self.peg: PegObservation | None = None
        self.guard = PhantomGuard(self.model, self.phantom_depth) if self.phantom_depth is not None else None
        # A controller that plans on a model of the world hears the task's belief (peg_ctrl.sim.belief).
        self._observe = self.controller.observe_belief if self.controller.observes_belief else None
        self._belief: Belief | None = None
        self.compute_times: list[float] = []  # the controller's wall time per control step [s]
        self._sensed: ControlState | None = None  # this control period's reading (sensed())

    @property
    def control_dt(self) -> float:
        """Control period [s]."""
        return self.decimation * float(self.model.opt.timestep)

    def state(self) -> ControlState:
        """The gripper's state now, noise-free."""
        return self.reader.control_state(self.data)

    def sensed(self) -> ControlState:
        """The gripper's state now as the sensors report it (:class:`SensorNoise`; the true
        state without noise). One reading per control period: until the next :meth:`step`
        steps the physics, it is the same reading, the one the step will act on."""
        if self._sensed is None:
            state = self.reader.control_state(self.data)
            self._sensed = self.noise.apply(state) if self.noise is not None else state
        return self._sensed

    def reset(self, rng: np.random.Generator) -> Observation:
        """Home keyframe, the task's initial state from ``rng``, one ``mj_forward``; resets the
        controller, monitors, task and sensor noise (its F/T delay line holds this true
        reading). Returns the first (noise-free) observation."""
        data = self.data
        mujoco.mj_resetDataKeyframe(self.model, data, self._home)
        self.task.reset(self.model, data, rng)
        # PEG_CTRL_START_PERTURBATION: the gripper's start moved along x by a last-bit amount, to
        # measure how far such a difference carries (peg_ctrl.experiments.reproduction)
        data.qpos[self.model.joint(SLIDE_JOINTS[0]).qposadr[0]] += start_perturbation()
        mujoco.mj_forward(self.model, data)
        state = self.reader.control_state(data)
        if self.noise is not None:
            self.noise.reset(state)
        self._sensed = None
        self.controller.reset(state)
        self._belief = None
        self.compute_times = []
        forces, _ = self.reader.pair_forces(data)
        self.peg = self.reader.peg(data, forces[BLOCK_PEG], self._half_length)
        obs = Observation(float(data.time), state, self.peg)
        self.task.start(obs)
        self.contact.reset()
        self.history.reset()
        if self.grasp is not None:
            self.grasp.reset()
        self.divergence.reset(data)
        self.sensors.raw[:] = 0.0
        if self.guard is not None:
            self.guard.count = 0
        self.steps = 0
        self.last = None
        return obs

    def step(self) -> Evaluation:
        """One control period; raises :class:`EpisodeFailure` if a monitor or the task fails."""
        timer = self.timer
        clock = time.thread_time if timer is not None else _no_clock
        data = self.data
        assert self.peg is not None, "reset() first"
        t0 = clock()
        state = self.sensed()
        target = self.task.target(Observation(data.time, state, self.peg))
        t1 = clock()
        out = self._compute(state, target)
        t2 = clock()
        self._physics(out)
        t3 = clock()
        forces, pens, failure = self._monitor(state)
        t4 = clock()
        if failure is None:
            failure = self._evaluate(state)
        t5 = clock()
        info = StepInfo(
            self.steps,
            data.time,
            self.task.phase,
            state,
            target,
            out,
            self.peg,  # type: ignore[arg-type]
            forces,
            pens,
            self.sensors,
            self.peg_qpos,
        )
        for recorder in self.recorders:
            recorder.record(self, info)
        if timer is not None:
            timer.add(t1 - t0 + t5 - t4, t2 - t1, t3 - t2, t4 - t3, clock() - t5)
        if failure is not None:
            raise failure
        assert self.last is not None
        return self.last

    def _compute(self, state: ControlState, target: GripperTarget) -> ControlOutput:
        if self._observe is not None:
            believing = belief_task(self.task)  # the task may be replaced between steps (gym)
            belief = believing.belief if believing is not None else None
            if belief is not self._belief:
                self._belief = belief
                self._observe(belief)
        try:
            out = self.controller.compute(state, target)
        except DivergenceError as exc:
            raise EpisodeFailure("diverged", f"controller rejected the state: {exc}") from None
        self.output = out
        self.compute_times.append(out.diagnostics.solve_time_s)
        return out

    def _physics(self, out: ControlOutput) -> None:
        """Apply ``out`` and run the control period's physics steps, keeping their sensors."""
        model, data = self.model, self.data
        data.ctrl[:] = out.ctrl
        guard = self.guard
        if guard is None:
            self._steps(mujoco.mj_step)
        elif guard.sensor is None:
            self._steps(guard.step)
        else:  # plain steps checked afterwards, rerun guarded if need be (see PhantomGuard)
            guard.begin(model, data)
            try:
                self._steps(mujoco.mj_step)
            finally:
                rerun = guard.end(model, data, self.sensors.raw)
            if rerun:
                self._steps(guard.step)
        self.steps += self.decimation
        self._sensed = None  # a new period: a new reading

    def _steps(self, step: Callable[[mujoco.MjModel, mujoco.MjData], None]) -> None:
        """The period's physics steps by ``step``, each followed by a copy of its sensors and
        of the peg's pose."""
        model, data = self.model, self.data
        raw, sd, peg_log, peg_q = self.sensors.raw, data.sensordata, self.peg_qpos, self._peg_q
        for i in range(self.decimation):
            step(model, data)
            raw[i] = sd
            peg_log[i] = peg_q

    def _monitor(self, state: ControlState) -> tuple[list[float], list[float], EpisodeFailure | None]:
        """Reduce the period's sensors, observe the peg and run the monitors."""
        data, sensors = self.data, self.sensors
        forces, pens = sensors.reduce()
        block = sensors.block_force
        peg = self.peg = self.reader.peg(data, block[-1], self._half_length)
        try:
            self.divergence.check(data, state.t)
            self.history.update(data.time, self._timestep, block, peg)
            self.contact.sustain(block, self._timestep)  # first: a period that fails still counts
            self.contact.check(forces, pens)
            if self.grasp is not None and self.task.grasped:
                self.grasp.check(data, state, peg)
        except EpisodeFailure as exc:
            return forces, pens, exc
        return forces, pens, None

    def _evaluate(self, state: ControlState) -> EpisodeFailure | None:
        assert self.peg is not None
        try:
            self.last = self.task.evaluate(Observation(self.data.time, state, self.peg))
        except EpisodeFailure as exc:
            return exc
        return None

    def advance(self, seconds: float) -> Evaluation | None:
        """Step for ``seconds`` [s] of simulated time (whole control periods, at least one), or
        until the task is done. Failures propagate as :class:`EpisodeFailure`."""
        evaluation = None
        for _ in range(max(1, round(seconds / self.control_dt))):
            evaluation = self.step()
            if evaluation.done:
                break
        return evaluation

    def run(self, max_steps: int) -> LoopOutcome:
        """Step until the task is done, a failure, ``max_steps`` physics steps, or Ctrl-C."""
        status, reason, detail = "failure", "timeout", "step limit reached"
        try:
            while self.steps < max_steps:
                evaluation = self.step()
                if evaluation.done:
                    status = "success" if evaluation.success else "failure"
                    reason, detail = evaluation.reason, evaluation.detail
                    break
        except EpisodeFailure as failure:
            reason, detail = failure.reason, failure.detail
            self.task.finish(float(self.data.time), failure.reason)
        except KeyboardInterrupt:
            self.task.finish(float(self.data.time), "interrupted")
            return LoopOutcome("interrupted", "interrupted", "Ctrl-C", self.last)
        if status != "success" and self.steps >= max_steps:
            self.task.finish(float(self.data.time), "timeout")
        return LoopOutcome(status, reason, detail, self.last)
