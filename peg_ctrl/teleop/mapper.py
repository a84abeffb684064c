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

import mujoco
import numpy as np

from peg_ctrl.commands import JAW_SEP_MAX_M, GripperTarget

__all__ = [
    "KEYMAP",
    "SPEED_KEYS",
    "SPEED_RANGE",
    "TeleopConfig",
    "TeleopMapper",
    "HELP_TITLES",
    "HELP_VALUES",
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
    max_steps: int = 50_000  # SPEC §5; steps of the seed profile (1 ms: 50 s), the same time in others
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


HELP_TITLES = "4 / 5\n6 / 7\n8 / 9\nQ / E\nUp / Down\nLeft / Right\n[ / ]\nShift\nJ / K / L\n- / =\nZ\nEsc"
HELP_VALUES = (
    "+Y / -Y\n+X / -X\n+Z / -Z\nroll + / -\npitch + / -\nyaw + / -\njaw open / close\nfine motion\n"
    "speed 0.5x / 1x / 2x\nspeed down / up\nreset\nquit"
)
