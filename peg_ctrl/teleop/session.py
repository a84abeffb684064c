"""A teleoperation session: the loop with a :class:`TeleopTask`, its logs, resets and summary.

The session is driven by :meth:`TeleopSession.advance` (simulated seconds) from a window or a
script (:class:`~peg_ctrl.teleop.scripted.ScriptedOperator`). It writes what ``peg-sim run``
writes: ``summary.json`` (every field of :class:`~peg_ctrl.run.episode.EpisodeResult`, plus the
session's own), ``config.json`` (the simulation's part of an episode config: controller, seed,
randomization, scene, physics; the key mapping's settings are in the log's ``teleop_start``
record), ``log.jsonl``, the full-rate force trace ``forces.npz`` and the states at every control
step ``states.npz`` (for ``peg-sim replay``).

One clock runs through the whole session: a reset (``Z``) restores the start state but not the
simulated time, so the logs, the force trace and the states stay in time order.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from peg_ctrl.commands import JAW_SEP_MAX_M, quat_to_euler
from peg_ctrl.config import to_dict
from peg_ctrl.controllers import ControllerConfig
from peg_ctrl.controllers.base import Controller
from peg_ctrl.environment import environment_id
from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.io import atomic_write_text, to_json
from peg_ctrl.run.episode import (
    EpisodeConfig,
    RandomizationConfig,
    compiled_model,
    contact_fields,
    contact_to_seat,
    loop_fields,
)
from peg_ctrl.run.episode_log import EpisodeLogger
from peg_ctrl.run.loop import Loop, StepInfo
from peg_ctrl.run.recorders import StateRecorder, TraceRecorder, step_record
from peg_ctrl.sim.physics import SEED, PhysicsConfig
from peg_ctrl.sim.physics import profile as physics_profile
from peg_ctrl.sim.scene import HOME_KEY, SceneConfig
from peg_ctrl.sim.state import ControlState, PegObservation, StateReader
from peg_ctrl.tasks.monitors import ContactMonitor, InsertionMeasure
from peg_ctrl.teleop.mapper import TeleopConfig, TeleopMapper
from peg_ctrl.teleop.task import TeleopTask, crossed

__all__ = ["TeleopSession"]

# The fields of an episode config that describe a teleop session's simulation (config.json).
_SIMULATION_FIELDS = ("controller", "seed", "randomization", "domain", "scene", "physics")


class TeleopSession:
    """Simulation, controller, key mapping, insertion checks and logging for one teleop episode.

    ``controller`` is a registered name or a controller config; ``scene`` and ``physics`` (default
    the seed profile) build the model. They are checked as an episode config's are
    (:class:`~peg_ctrl.run.episode.EpisodeConfig`) before anything is written.
    """

    def __init__(
        self,
        out_dir: Path,
        *,
        controller: str | ControllerConfig = "pd",
        seed: int = 0,
        randomize: bool = False,
        config: TeleopConfig | None = None,
        scene: SceneConfig | None = None,
        physics: PhysicsConfig | None = None,
    ) -> None:
        self.cfg = config or TeleopConfig()
        self.scene = scene or SceneConfig()
        ctrl_cfg = ControllerConfig.select(controller)  # a name or a config
        # Validated as an episode's config is (a scene field the profile sets is refused).
        episode = EpisodeConfig(
            controller=ctrl_cfg,
            seed=seed,
            randomization=RandomizationConfig(enabled=randomize),
            scene=self.scene,
            physics=physics or PhysicsConfig(),
        )
        self.physics = episode.physics.profile  # the profile's name, as in an episode's summary
        self.friction_time = episode.physics.friction_time  # the peg's, when set (physics.friction_time)
        self.model = compiled_model(self.scene, episode.physics.resolved())
        self.controller_name = ctrl_cfg.name
        self.seed = seed
        self.randomize = randomize
        self.out_dir = Path(out_dir)
        ctrl = ctrl_cfg.build(self.model)
        # The step limit is SPEC §5's, in steps of the seed profile; a finer step gets the same time.
        self.max_steps = round(self.cfg.max_steps * SEED.timestep / self.model.opt.timestep)
        self.logger = EpisodeLogger(self.out_dir)
        resolved = {k: v for k, v in to_dict(episode).items() if k in _SIMULATION_FIELDS}
        atomic_write_text(self.out_dir / "config.json", _json(resolved))
        self.mapper = self._home_mapper()
        self.task = TeleopTask(
            self.mapper, scene=self.scene, config=self.cfg, randomize=randomize, decimation=episode.decimation
        )
        self.trace = TraceRecorder(self.logger, self.task.phases)
        self.states = StateRecorder(self.out_dir / "states.npz", self.model.nq)
        self.loop = self._loop(ctrl)
        self.data = self.loop.data
        self.attempt = 1
        self.finished = False
        self.end_reason = ""
        self._inserted_logged = False  # the "inserted" event of this attempt is in the log
        self.summary: dict[str, Any] = {}
        self.wall0 = time.perf_counter()
        self.loop.reset(np.random.default_rng(seed))
        self.states.start(self.data)
        start = {
            "seed": seed,
            "randomize": randomize,
            "controller": self.controller_name,
            "physics": self.physics,
        }
        self.logger.record({"event": "teleop_start", **start, "teleop": to_dict(self.cfg)})

    def _loop(self, controller: Controller) -> Loop:
        """The loop: no force-spike failure (the operator may push), the session as a recorder."""
        return Loop(
            model=self.model,
            controller=controller,
            task=self.task,
            scene=self.scene,
            contact=ContactMonitor(force_spike=None),
            recorders=[self.trace, self.states, self],
            phantom_depth=physics_profile(self.physics).phantom_depth,
        )

    def _home_mapper(self) -> TeleopMapper:
        """The key mapper, at the home pose with the jaw open (the task resets it every attempt)."""
        home = mujoco.MjData(self.model)
        mujoco.mj_resetDataKeyframe(self.model, home, self.model.key(HOME_KEY).id)
        s = StateReader(self.model).control_state(home)
        return TeleopMapper(self.cfg, p_world=s.p_world, quat_world=s.quat_world, jaw_sep_m=JAW_SEP_MAX_M)

    # -- state --------------------------------------------------------------------------------
    @property
    def step_count(self) -> int:
        """Physics steps over all attempts."""
        return self.task.step_count

    @property
    def inserted(self) -> bool:
        return self.task.inserted

    def state(self) -> ControlState:
        return self.loop.state()

    def peg(self) -> PegObservation:
        assert self.loop.peg is not None
        return self.loop.peg

    # -- driving ------------------------------------------------------------------------------
    def advance(self, sim_seconds: float) -> None:
        """Run the loop for ``sim_seconds`` of simulated time (whole control steps, at least one)."""
        for _ in range(max(1, round(sim_seconds / self.loop.control_dt))):
            if self.finished:
                return
            if self.mapper.quit_requested:
                self.finish("quit")
                return
            if self.mapper.reset_requested:
                self._reset()
                if self.finished:
                    return
            try:
                self.loop.step()
            except EpisodeFailure as failure:  # e.g. diverged: end with the records so far
                self.finish(failure.reason, detail=failure.detail)
                return
            if self.step_count >= self.max_steps:
                self.finish("timeout")

    def _reset(self) -> None:
        """Restore the start state (re-randomised from seed + attempt if enabled), SPEC §5; the
        clock runs on."""
        self.mapper.reset_requested = False
        if self.attempt >= self.cfg.max_attempts:
            self.finish("attempts_exhausted")
            return
        self.attempt += 1
        seed = self.seed + self.attempt - 1 if self.randomize else self.seed
        t = float(self.data.time)
        self.loop.reset(np.random.default_rng(seed))
        self.data.time = t  # the session's clock runs on (the reset zeroed it)
        self.task.records[-1].t_start = t
        self.states.start(self.data)
        self._inserted_logged = False
        self.logger.record({"event": "reset", "step": self.step_count, "attempt": self.attempt})

    # -- recording (the session is one of the loop's recorders) ---------------------------------
    def record(self, loop: Loop, info: StepInfo) -> None:
        cfg = self.cfg
        before = self.step_count - loop.decimation
        if crossed(before, self.step_count, cfg.log_every):
            self.logger.record({**_teleop_step(loop, info), "step": self.step_count, **self._log_extra()})
        if crossed(before, self.step_count, cfg.save_every):
            self.logger.record({"event": "save", "step": self.step_count})
        if self.task.inserted and not self._inserted_logged:
            self._inserted_logged = True
            self.logger.record({"event": "inserted", "step": self.step_count, "t": round(info.t, 6)})

    def _log_extra(self) -> dict[str, Any]:
        m = self.mapper
        return {"phase": "teleop", "attempt": self.attempt, "speed": m.speed, "keys": sorted(m.held)}

    def finish(self, reason: str, *, detail: str = "") -> dict[str, Any]:
        """End the session (``reason``: quit, timeout, script_done, ...): flush the force trace and
        write ``summary.json`` with every field ``peg-sim run`` writes, plus ``attempts``, ``end``
        (= ``reason``), ``peg_radial_m`` and ``peg_bottom_z_m``. Calling it again returns the same
        summary.

        ``total_timesteps`` and ``sim_time_s`` count every attempt, and every time [s] is on the
        session's clock; the contact metrics are the last attempt's (a reset restarts the
        monitors and the contact history); ``phases`` holds one record per attempt.
        ``peg_slip_m`` is None: the operator may let go at any time, so slip is not monitored.
        """
        if self.finished:
            return self.summary
        self.finished = True
        self.end_reason = reason
        check = self.task.insertion.measure(self.peg())
        inserted = self.task.inserted or self.task.insertion.criterion(check)
        self.task.finish(float(self.data.time), reason)
        self.summary = self._summary(reason, detail, check, inserted)
        summary = self.out_dir / "summary.json"
        try:
            self.trace.flush()
            # The record first: packing the trace and the states cannot lose it.
            atomic_write_text(summary, _json(self.summary))
            self.summary["trace_path"] = str(self.logger.npz_path)
            self.logger.close({"event": "end", **self.summary})
            self.states.close()
            atomic_write_text(summary, _json(self.summary))
        finally:
            self.logger.abort()
        return self.summary

    def _summary(self, reason: str, detail: str, check: InsertionMeasure, inserted: bool) -> dict[str, Any]:
        """The fields of ``peg-sim run``'s summary, and teleop's own (see :meth:`finish`)."""
        if inserted:
            status = "success"
        else:
            status = "interrupted" if reason == "interrupted" else "failure"
        fields = contact_fields(self.loop, check, seated=inserted, assets=self.scene.assets)
        tti = self.task.time_to_insert
        return {
            "status": status,
            "reason": "" if status == "success" else reason,
            "phase": "teleop",
            "controller": self.controller_name,
            "planner": "teleop",
            "physics": self.physics,
            "friction_time_s": self.friction_time,
            "task": self.task.name,
            "strategy": "",
            "seed": self.seed,
            "total_timesteps": self.step_count,
            "sim_time_s": float(self.data.time),
            "wall_time_s": time.perf_counter() - self.wall0,
            **fields,
            "peg_slip_m": None,
            "time_to_insert_s": tti,
            # None unless the peg touched the block before the insertion was detected (the
            # operator may lower it in without touching, then let it fall against the bore).
            "contact_to_seat_s": contact_to_seat(fields["first_contact_s"], tti),
            "detail": detail or f"session ended: {reason}",
            "log_path": str(self.logger.log_path),
            "trace_path": str(self.logger.trace_path),
            "plot_path": None,
            "video_path": None,
            "phases": [r.to_dict() for r in self.task.records],
            "belief": [],  # a person decides: no task belief, no skills chosen
            "skills": [],
            "attempts": self.attempt,
            "end": reason,
            "peg_radial_m": check.radial_m,
            "peg_bottom_z_m": check.bottom_z_m,
            **loop_fields(self.loop),
            "environment": environment_id(),
        }

    # -- overlay ------------------------------------------------------------------------------
    def overlay_lines(self) -> tuple[str, str]:
        """Status panel text (titles, values) for the window."""
        s = self.state()
        m = self.mapper
        cmd_rpy = np.degrees(quat_to_euler(m.quat_world))
        act_rpy = np.degrees(quat_to_euler(s.quat_world))
        checked = self.task.last_check is not None
        status = "INSERTED" if self.inserted else ("searching" if checked else "not inserted")
        titles = "Speed\nJaw\nCmd xyz\nAct xyz\nCmd rpy\nAct rpy\nInsertion\nAttempt\nSim time"
        values = (
            f"{m.speed:.2f}x{'  (fine)' if m.fine else ''}\n"
            f"{s.jaw_sep_m * 1e3:.1f} mm (cmd {m.jaw_sep_m * 1e3:.1f} mm)\n"
            f"{m.p_world[0]:+.3f} {m.p_world[1]:+.3f} {m.p_world[2]:+.3f} m\n"
            f"{s.p_world[0]:+.3f} {s.p_world[1]:+.3f} {s.p_world[2]:+.3f} m\n"
            f"{cmd_rpy[0]:+6.1f} {cmd_rpy[1]:+6.1f} {cmd_rpy[2]:+6.1f} deg\n"
            f"{act_rpy[0]:+6.1f} {act_rpy[1]:+6.1f} {act_rpy[2]:+6.1f} deg\n"
            f"{status}\n"
            f"{self.attempt} / {self.cfg.max_attempts}\n"
            f"{self.data.time:.2f} s"
        )
        return titles, values


def _teleop_step(loop: Loop, info: StepInfo) -> dict[str, Any]:
    entry = step_record(loop, info)
    del entry["controller"]
    return entry


def _json(data: dict[str, Any]) -> str:
    return to_json(data, indent=2) + "\n"
