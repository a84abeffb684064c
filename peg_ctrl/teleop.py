"""Teleoperation: keys -> rate-limited command deltas -> the same command API and controller.

Keymap (SPEC §5), by key name:

=========  ==================================
``4``/``5``  +Y / -Y
``6``/``7``  +X / -X
``8``/``9``  +Z / -Z
``Q``/``E``  roll + / - (about the gripper's own X)
Up/Down    pitch + / - (about the gripper's own Y)
Left/Right yaw + / - (about the gripper's own Z)
``[``/``]``  jaw open / close
``Z``        reset (requested, performed between steps)
Esc        quit
=========  ==================================

Speed (SPEC decision: keys that collide with nothing): ``J`` 0.5x, ``K`` 1x, ``L`` 2x, and ``-``/``=``
step the multiplier down/up within 0.1x-5x. Hold Shift for fine motion (x0.2).

The window is our own GLFW window rendered with MuJoCo's renderer (mouse: left-drag rotates,
right-drag moves, scroll zooms, as in MuJoCo's viewer). MuJoCo's stock viewer uses ``[``/``]``
(cameras), the digits (geom groups), ``-``/``=`` (speed) and other letters for its own
shortcuts and reports key presses but not releases; an own window has no built-in shortcuts and
gets press *and* release events, so a motion stops when its key is released.

:class:`TeleopMapper` is the pure key -> command component (no window, no simulation), so a
scripted input stream (:class:`ScriptedOperator`) can drive teleoperation headlessly.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from peg_ctrl.commands import JAW_SEP_MAX_M, GripperTarget, quat_to_euler
from peg_ctrl.state import ControlState

__all__ = [
    "KEYMAP",
    "SPEED_KEYS",
    "TeleopConfig",
    "TeleopMapper",
    "TeleopSession",
    "ScriptedOperator",
    "InsertionCheck",
]

# key name -> (command index, sign); indices 0-2 x, y, z; 3-5 roll, pitch, yaw; 6 jaw.
KEYMAP: dict[str, tuple[int, float]] = {
    "4": (1, +1.0),
    "5": (1, -1.0),
    "6": (0, +1.0),
    "7": (0, -1.0),
    "8": (2, +1.0),
    "9": (2, -1.0),
    "Q": (3, +1.0),
    "E": (3, -1.0),
    "UP": (4, +1.0),
    "DOWN": (4, -1.0),
    "LEFT": (5, +1.0),
    "RIGHT": (5, -1.0),
    "[": (6, +1.0),
    "]": (6, -1.0),
}
SPEED_KEYS: dict[str, float] = {"J": 0.5, "K": 1.0, "L": 2.0}
SPEED_STEP_KEYS: dict[str, float] = {"-": 1 / 1.25, "=": 1.25}
RESET_KEY = "Z"
QUIT_KEY = "ESCAPE"
SPEED_RANGE = (0.1, 5.0)


@dataclasses.dataclass(frozen=True)
class TeleopConfig:
    """Rates [m/s, rad/s], rate limits [m/s^2, rad/s^2] and deadzones of the key mapping."""

    lin_speed: float = 0.06  # held-key translation speed [m/s]
    rot_speed: float = 0.6  # held-key rotation speed [rad/s]
    jaw_speed: float = 0.04  # held-key jaw speed [m/s]
    lin_accel: float = 0.6  # rate limit on the translation velocity [m/s^2]
    rot_accel: float = 4.0  # [rad/s^2]
    jaw_accel: float = 0.4  # [m/s^2]
    deadzone: float = 0.02  # velocities below this fraction of full speed count as zero
    fine_scale: float = 0.2  # speed factor while Shift is held
    max_steps: int = 50_000  # SPEC §5
    log_every: int = 100
    save_every: int = 1_000
    check_every: int = 500
    max_attempts: int = 5
    insert_radius: float = 0.03  # peg within this of the hole axis (horizontally) [m]
    insert_height: float = 0.04  # peg bottom below block centre + this [m]
    settle_speed: float = 0.05  # peg speed at most this [m/s]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"teleop.{f.name} must be finite and > 0, got {value!r}")
        if not 0 < self.deadzone < 1:
            raise ValueError(f"teleop.deadzone must be in (0, 1), got {self.deadzone}")


class TeleopMapper:
    """Held keys -> a commanded pose and jaw separation, advanced by :meth:`step`.

    Each axis has a velocity that ramps (rate limit) toward full speed while its key is held and
    toward zero when released; a velocity inside the deadzone is zero, so motion stops cleanly.
    """

    def __init__(self, config: TeleopConfig, *, p_world, quat_world, jaw_sep_m: float) -> None:
        self.cfg = config
        self._home = (np.array(p_world, float), np.array(quat_world, float), float(jaw_sep_m))
        self.held: set[str] = set()
        self.fine = False
        self.speed = 1.0
        self.reset_requested = False
        self.quit_requested = False
        self.reset_command()

    # -- events -----------------------------------------------------------------------------
    def press(self, key: str, *, shift: bool = False) -> None:
        key = key.upper()
        self.fine = shift
        if key in KEYMAP:
            self.held.add(key)
        elif key in SPEED_KEYS:
            self.speed = SPEED_KEYS[key]
        elif key in SPEED_STEP_KEYS:
            lo, hi = SPEED_RANGE
            self.speed = round(min(hi, max(lo, self.speed * SPEED_STEP_KEYS[key])), 3)
        elif key == RESET_KEY:
            self.reset_requested = True
        elif key == QUIT_KEY:
            self.quit_requested = True

    def release(self, key: str, *, shift: bool = False) -> None:
        self.held.discard(key.upper())
        self.fine = shift

    def release_all(self) -> None:
        """Forget every held key (e.g. when the window loses focus)."""
        self.held.clear()

    def set_speed(self, multiplier: float) -> None:
        lo, hi = SPEED_RANGE
        if not lo <= multiplier <= hi:
            raise ValueError(f"speed multiplier must be in [{lo}, {hi}], got {multiplier}")
        self.speed = multiplier

    # -- command ----------------------------------------------------------------------------
    def reset_command(self) -> None:
        p, q, jaw = self._home
        self.p_world = p.copy()
        self.quat_world = q.copy()
        self.jaw_sep_m = jaw
        self.velocity = np.zeros(7)  # x, y, z [m/s], body rates [rad/s], jaw [m/s]
        self.held.clear()

    def step(self, dt: float) -> None:
        """Advance the command by ``dt`` seconds of simulated time."""
        cfg = self.cfg
        scale = cfg.fine_scale if self.fine else 1.0
        target = np.zeros(7)
        for key in self.held:
            index, sign = KEYMAP[key]
            target[index] += sign
        full = np.array([cfg.lin_speed] * 3 + [cfg.rot_speed] * 3 + [cfg.jaw_speed]) * scale
        accel = np.array([cfg.lin_accel] * 3 + [cfg.rot_accel] * 3 + [cfg.jaw_accel])
        target = np.clip(target, -1.0, 1.0) * full
        dv = np.clip(target - self.velocity, -accel * dt, accel * dt)
        self.velocity = self.velocity + dv
        dead = np.abs(self.velocity) < cfg.deadzone * full
        self.velocity[dead & (target == 0.0)] = 0.0
        v = self.velocity
        self.p_world = self.p_world + v[:3] * dt
        if np.any(v[3:6]):
            mujoco.mju_quatIntegrate(self.quat_world, v[3:6].copy(), dt)
            self.quat_world /= np.linalg.norm(self.quat_world)
        self.jaw_sep_m = float(min(JAW_SEP_MAX_M, max(0.0, self.jaw_sep_m + v[6] * dt)))

    def target(self) -> GripperTarget:
        return GripperTarget.trusted(
            self.p_world, self.quat_world, self.velocity[:3], self.velocity[3:6], self.jaw_sep_m
        )


@dataclasses.dataclass
class InsertionCheck:
    """SPEC §5 teleop detection: near the hole axis, deep enough, nearly still."""

    radial: float
    bottom_z: float
    speed: float
    inserted: bool


class TeleopSession:
    """Simulation, controller, key mapping, insertion checks and logging for one teleop episode.

    The session is driven by :meth:`advance` (simulated seconds) from a window or a script.
    """

    def __init__(
        self,
        out_dir: Path,
        *,
        controller: str = "pd",
        seed: int = 0,
        randomize: bool = False,
        config: TeleopConfig | None = None,
    ) -> None:
        from controllers import make_controller
        from peg_ctrl.episode import EpisodeConfig, RandomizationConfig, initial_qpos
        from peg_ctrl.episode_log import EpisodeLogger
        from peg_ctrl.scene import build_model
        from peg_ctrl.sim import control_decimation
        from peg_ctrl.state import StateReader

        self.cfg = config or TeleopConfig()
        self.episode_cfg = EpisodeConfig(seed=seed, randomization=RandomizationConfig(enabled=randomize))
        self.scene = self.episode_cfg.scene
        self.model = build_model(self.scene)
        self.data = mujoco.MjData(self.model)
        self.controller = make_controller(controller, self.model)
        self.controller_name = controller
        self.decimation = control_decimation(self.controller.control_dt, self.model.opt.timestep)
        self.reader = StateReader(self.model)
        self._initial_qpos = initial_qpos
        self._seed = seed
        self.randomize = randomize
        self.out_dir = Path(out_dir)
        self.logger = EpisodeLogger(self.out_dir)
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key("home").id)
        self.qpos0 = initial_qpos(self.model, self.episode_cfg)
        self.data.qpos[:] = self.qpos0
        mujoco.mj_forward(self.model, self.data)
        state = self.reader.control_state(self.data)
        self.mapper = TeleopMapper(
            self.cfg, p_world=state.p_world, quat_world=state.quat_world, jaw_sep_m=JAW_SEP_MAX_M
        )
        self.controller.reset(state)
        self.step_count = 0
        self.attempt = 1
        self.inserted = False
        self.last_check: InsertionCheck | None = None
        self.finished = False
        self.end_reason = ""
        self.summary: dict[str, Any] = {}
        self.wall0 = time.perf_counter()
        self._peg_adr = self.model.joint("peg_free").qposadr[0]
        self._peg_dof = self.model.joint("peg_free").dofadr[0]
        self.logger.record(
            {"event": "teleop_start", "seed": seed, "randomize": randomize, "controller": controller}
        )

    # -- simulation -------------------------------------------------------------------------
    def state(self) -> ControlState:
        return self.reader.control_state(self.data)

    def advance(self, sim_seconds: float) -> None:
        """Run the loop for ``sim_seconds`` of simulated time (whole control steps)."""
        dt_control = self.decimation * self.model.opt.timestep
        for _ in range(max(1, int(round(sim_seconds / dt_control)))):
            if self.finished:
                return
            self._control_step(dt_control)

    def _control_step(self, dt: float) -> None:
        m = self.mapper
        if m.quit_requested:
            self.finish("quit")
            return
        if m.reset_requested:
            self._reset()
        m.step(dt)
        state = self.reader.control_state(self.data)
        target = m.target()
        out = self.controller.compute(state, target)
        self.data.ctrl[:] = out.ctrl
        before = self.step_count
        mujoco.mj_step(self.model, self.data, nstep=self.decimation)
        self.step_count += self.decimation
        cfg = self.cfg
        if self.step_count // cfg.log_every != before // cfg.log_every:
            self._log(target, state)
        if self.step_count // cfg.save_every != before // cfg.save_every:
            self.logger.record({"event": "save", "step": self.step_count})
        if self.step_count // cfg.check_every != before // cfg.check_every:
            self.last_check = self.check_insertion()
            if self.last_check.inserted and not self.inserted:
                self.inserted = True
                self.logger.record(
                    {"event": "inserted", "step": self.step_count, "t": round(self.data.time, 6)}
                )
        if self.step_count >= cfg.max_steps:
            self.finish("timeout")

    def _reset(self) -> None:
        """Restore qpos (re-randomised if enabled), zero qvel, one mj_forward (SPEC §5)."""
        m = self.mapper
        m.reset_requested = False
        if self.attempt >= self.cfg.max_attempts:
            self.finish("attempts_exhausted")
            return
        self.attempt += 1
        if self.randomize:
            cfg = dataclasses.replace(self.episode_cfg, seed=self._seed + self.attempt - 1)
            self.qpos0 = self._initial_qpos(self.model, cfg)
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key("home").id)
        self.data.qpos[:] = self.qpos0
        self.data.qvel[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        m.reset_command()
        self.controller.reset(self.reader.control_state(self.data))
        self.inserted = False
        self.logger.record({"event": "reset", "step": self.step_count, "attempt": self.attempt})

    def check_insertion(self) -> InsertionCheck:
        q = self.data.qpos[self._peg_adr : self._peg_adr + 7]
        p = q[:3]
        axis = np.empty(3)
        mujoco.mju_rotVecQuat(axis, np.array([0.0, 0.0, 1.0]), q[3:])
        bottom = p - math.copysign(0.5 * self.scene.assets.peg_length, axis[2]) * axis
        hx, hy = self.scene.hole_xy
        radial = math.hypot(p[0] - hx, p[1] - hy)
        speed = float(np.linalg.norm(self.data.qvel[self._peg_dof : self._peg_dof + 3]))
        block_centre_z = self.scene.block_pos[2]
        inserted = (
            radial <= self.cfg.insert_radius
            and bottom[2] < block_centre_z + self.cfg.insert_height
            and speed <= self.cfg.settle_speed
        )
        return InsertionCheck(radial, float(bottom[2]), speed, inserted)

    def _log(self, target: GripperTarget, state: ControlState) -> None:
        q = self.data.qpos[self._peg_adr : self._peg_adr + 7]
        self.logger.record(
            {
                "event": "step",
                "step": self.step_count,
                "t": round(float(self.data.time), 6),
                "phase": "teleop",
                "attempt": self.attempt,
                "speed": self.mapper.speed,
                "keys": sorted(self.mapper.held),
                "command": {
                    "position": [round(float(v), 6) for v in target.p_world],
                    "quat": [round(float(v), 6) for v in target.quat_world],
                    "omega_body": [round(float(v), 6) for v in target.omega_body],
                    "jaw_sep_m": round(target.jaw_sep_m, 6),
                },
                "gripper": {
                    "position": [round(float(v), 6) for v in state.p_world],
                    "euler": [round(float(v), 6) for v in quat_to_euler(state.quat_world)],
                    "quat": [round(float(v), 6) for v in state.quat_world],
                    "jaw_sep_m": round(state.jaw_sep_m, 6),
                },
                "peg": {
                    "position": [round(float(v), 6) for v in q[:3]],
                    "quat": [round(float(v), 6) for v in q[3:]],
                },
                "contacts": [c.to_dict() for c in self.reader.contacts(self.data)],
            }
        )

    def finish(self, reason: str) -> dict[str, Any]:
        """End the session: write the episode record (same format as autonomous mode)."""
        if self.finished:
            return self.summary
        self.finished = True
        self.end_reason = reason
        check = self.check_insertion()
        self.inserted = self.inserted or check.inserted
        status = "success" if self.inserted else "failure"
        self.summary = {
            "status": status,
            "reason": "" if status == "success" else reason,
            "phase": "teleop",
            "controller": self.controller_name,
            "planner": "teleop",
            "seed": self._seed,
            "total_timesteps": self.step_count,
            "sim_time_s": float(self.data.time),
            "wall_time_s": time.perf_counter() - self.wall0,
            "attempts": self.attempt,
            "end": reason,
            "peg_radial_m": check.radial,
            "peg_bottom_z_m": check.bottom_z,
            "log_path": str(self.logger.log_path),
            "trace_path": str(self.logger.npz_path),
        }
        self.logger.close({"event": "end", **self.summary})
        import json

        (self.out_dir / "summary.json").write_text(json.dumps(self.summary, indent=2) + "\n")
        return self.summary

    # -- overlay ----------------------------------------------------------------------------
    def overlay_lines(self) -> tuple[str, str]:
        """Status panel text (titles, values) for the window."""
        s = self.state()
        m = self.mapper
        cmd_rpy = np.degrees(quat_to_euler(m.quat_world))
        act_rpy = np.degrees(quat_to_euler(s.quat_world))
        check = self.last_check
        status = "INSERTED" if self.inserted else ("not inserted" if check is None else "searching")
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


HELP_TITLES = "4 / 5\n6 / 7\n8 / 9\nQ / E\nUp / Down\nLeft / Right\n[ / ]\nShift\nJ / K / L\n- / =\nZ\nEsc"
HELP_VALUES = (
    "+Y / -Y\n+X / -X\n+Z / -Z\nroll + / -\npitch + / -\nyaw + / -\njaw open / close\nfine motion\n"
    "speed 0.5x / 1x / 2x\nspeed down / up\nreset\nquit"
)


class ScriptedOperator:
    """A headless operator: holds keys until the commanded pose reaches each goal.

    Goals are ``(kind, value)`` pairs: ``("x"|"y"|"z", metres)``, ``("roll", radians)``,
    ``("jaw", metres)``, ``("wait", seconds)``, or ``("align", None)`` which moves the gripper so
    the peg's bottom is over the hole (it looks at the peg, as a person would).
    """

    _AXIS_KEYS = {"x": ("6", "7"), "y": ("4", "5"), "z": ("8", "9"), "jaw": ("[", "]")}

    def __init__(
        self, session: TeleopSession, goals: Iterable[tuple[str, Any]], *, tol: float = 2e-4
    ) -> None:
        self.session = session
        self.goals = list(goals)
        self.tol = tol

    def run(
        self, *, max_sim_s: float = 60.0, dt: float = 0.01, on_tick: Callable[[], None] | None = None
    ) -> None:
        s = self.session
        m = s.mapper
        t_end = s.data.time + max_sim_s
        queue: list[tuple[str, Any]] = []
        for kind, value in self.goals:
            if kind == "align":
                queue.append(("align", None))
            else:
                queue.append((kind, value))
        while queue and not s.finished and s.data.time < t_end:
            kind, value = queue[0]
            if kind == "wait":
                s.advance(value)
                queue.pop(0)
                continue
            if kind == "align":
                hx, hy = s.scene.hole_xy
                q = s.data.qpos[s._peg_adr : s._peg_adr + 7]
                axis = np.empty(3)
                mujoco.mju_rotVecQuat(axis, np.array([0.0, 0.0, 1.0]), q[3:])
                bottom = q[:3] - math.copysign(0.5 * s.scene.assets.peg_length, axis[2]) * axis
                pinch = s.state().p_world
                queue[0:1] = [("x", hx - (bottom[0] - pinch[0])), ("y", hy - (bottom[1] - pinch[1]))]
                continue
            current = {"x": m.p_world[0], "y": m.p_world[1], "z": m.p_world[2], "jaw": m.jaw_sep_m}.get(kind)
            if kind == "roll":
                current = quat_to_euler(m.quat_world)[0]
            assert current is not None, kind
            error = value - current
            tol = self.tol if kind != "roll" else 2e-3
            if abs(error) <= tol:
                m.release_all()
                s.advance(0.2)  # let the rate limit bring the motion to rest
                queue.pop(0)
                continue
            if kind == "roll":
                plus, minus = "Q", "E"
            else:
                plus, minus = self._AXIS_KEYS[kind]
            m.release_all()
            speed = {"roll": s.cfg.rot_speed, "jaw": s.cfg.jaw_speed}.get(kind, s.cfg.lin_speed)
            fine = abs(error) < 0.5 * speed  # within half a second at full speed: slow down
            m.press(plus if error > 0 else minus, shift=fine)
            s.advance(dt)
            if on_tick is not None:
                on_tick()
        m.release_all()
