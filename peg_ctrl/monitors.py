"""Monitors: what the loop measures after every physics step, independent of the task's targets.

- :class:`InsertionMonitor` — depth, lateral error, tilt and "inserted" of the peg in the hole,
  with a criterion chosen by the caller (:class:`SeatedCriterion` for autonomous episodes,
  :class:`SettledCriterion` for teleoperation, SPEC §5). One geometry serves both.
- :class:`ContactMonitor` — peak contact forces and penetrations; fails on a force spike.
- :class:`GraspMonitor` — slip and turn of the peg in the pads while it is held.
- :class:`DivergenceMonitor` — MuJoCo warnings and non-finite state.

A failing check raises :class:`~peg_ctrl.errors.EpisodeFailure`; the loop turns it into the
episode's outcome.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import mujoco
import numpy as np

from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.scene import GRIPPER_PREFIX, SceneConfig
from peg_ctrl.state import BLOCK_PEG, PAIRS, ControlState, PegObservation

__all__ = [
    "InsertionMeasure",
    "InsertionCriterion",
    "SeatedCriterion",
    "SettledCriterion",
    "InsertionMonitor",
    "ContactMonitor",
    "GraspMonitor",
    "DivergenceMonitor",
]


class InsertionMeasure(NamedTuple):
    """Where the peg is relative to the hole.

    ``depth_m`` [m] of the peg's lower end below the hole mouth; ``lateral_error_m`` [m] from the
    peg axis to the hole axis at the mouth (``inf`` for a horizontal peg); ``radial_m`` [m]
    horizontal distance of the peg centre from the hole axis; ``bottom_z_m`` [m] height of the
    lower end; ``tilt_rad`` [rad] of the peg axis from vertical; ``speed`` [m/s] of the centre.
    """

    depth_m: float
    lateral_error_m: float
    radial_m: float
    bottom_z_m: float
    tilt_rad: float
    speed: float


class InsertionCriterion(Protocol):
    def __call__(self, m: InsertionMeasure) -> bool: ...


class SeatedCriterion(NamedTuple):
    """Autonomous success: deep enough, on the axis, upright."""

    min_depth: float  # [m]
    max_lateral_error: float  # [m]
    max_tilt: float  # [rad]

    def __call__(self, m: InsertionMeasure) -> bool:
        return (
            m.depth_m >= self.min_depth
            and m.lateral_error_m <= self.max_lateral_error
            and m.tilt_rad <= self.max_tilt
        )


class SettledCriterion(NamedTuple):
    """Teleop detection (SPEC §5): near the hole axis, low enough, nearly still."""

    max_radial: float  # peg centre to hole axis, horizontally [m]
    max_bottom_z: float  # peg bottom below this height [m]
    max_speed: float  # [m/s]

    def __call__(self, m: InsertionMeasure) -> bool:
        return (
            m.radial_m <= self.max_radial and m.bottom_z_m < self.max_bottom_z and m.speed <= self.max_speed
        )


class InsertionMonitor:
    """Measures the peg against the hole of ``scene`` and applies ``criterion``."""

    def __init__(self, scene: SceneConfig, criterion: InsertionCriterion) -> None:
        self.block_top = float(scene.assets.block_size[2])
        self.hole_x, self.hole_y = (float(v) for v in scene.hole_xy)
        self.criterion = criterion
        self.last: InsertionMeasure | None = None

    def measure(self, peg: PegObservation) -> InsertionMeasure:
        axis = peg.axis_world
        p = peg.p_world
        hx, hy = self.hole_x, self.hole_y
        depth = self.block_top - float(peg.bottom_world[2])
        tilt = math.acos(min(1.0, abs(float(axis[2]))))
        if abs(axis[2]) > 1e-6:
            s = (self.block_top - p[2]) / axis[2]
            lateral = math.hypot(p[0] + s * axis[0] - hx, p[1] + s * axis[1] - hy)
        else:
            lateral = math.inf
        radial = math.hypot(float(p[0]) - hx, float(p[1]) - hy)
        self.last = InsertionMeasure(depth, lateral, radial, float(peg.bottom_world[2]), tilt, peg.speed)
        return self.last

    def inserted(self, peg: PegObservation) -> bool:
        return self.criterion(self.measure(peg))


class ContactMonitor:
    """Peak contact forces [N] and penetrations [m]; ``force_spike`` [N] (or None) fails the episode."""

    def __init__(self, force_spike: float | None = None) -> None:
        self.force_spike = force_spike
        self.reset()

    def reset(self) -> None:
        self.peak_block = 0.0  # peg-block
        self.peak_any = 0.0
        self.max_penetration = 0.0  # peg-block and peg-table
        self.grip_penetration = 0.0  # pads into the peg

    def check(self, forces: list[float], penetrations: list[float]) -> None:
        """``forces`` per pair of :data:`~peg_ctrl.state.PAIRS`; ``penetrations`` per peg partner."""
        peak = max(forces)
        self.peak_block = max(self.peak_block, forces[BLOCK_PEG])
        self.peak_any = max(self.peak_any, peak)
        self.max_penetration = max(self.max_penetration, penetrations[0], penetrations[2])
        self.grip_penetration = max(self.grip_penetration, penetrations[1])
        if self.force_spike is not None and peak > self.force_spike:
            pair = "-".join(PAIRS[int(np.argmax(forces))])
            raise EpisodeFailure("force_spike", f"{pair} contact force {peak:.1f} N > {self.force_spike} N")


class GraspMonitor:
    """Slip [m] and in-hand turn [rad] of the peg relative to a pad while it is held."""

    def __init__(self, model: mujoco.MjModel, *, lost_distance: float, max_in_hand_tilt: float) -> None:
        self._pad = model.body(GRIPPER_PREFIX + "left_pad").id
        self._peg = model.body("peg").id
        self.lost_distance = lost_distance  # peg centre to pinch point [m]
        self.max_in_hand_tilt = max_in_hand_tilt  # [rad]
        self.reset()

    def reset(self) -> None:
        self.slip = 0.0
        self._rel_ref: np.ndarray | None = None
        self._axis_ref: np.ndarray | None = None

    def check(self, data: mujoco.MjData, gripper: ControlState, peg: PegObservation) -> None:
        r_pad = data.xmat[self._pad].reshape(3, 3)
        rel = r_pad.T @ (data.xpos[self._peg] - data.xpos[self._pad])
        axis_pad = r_pad.T @ peg.axis_world
        if self._rel_ref is None or self._axis_ref is None:
            self._rel_ref, self._axis_ref = rel, axis_pad
        self.slip = max(self.slip, float(np.linalg.norm(rel - self._rel_ref)))
        if float(np.linalg.norm(peg.p_world - gripper.p_world)) > self.lost_distance:
            raise EpisodeFailure("grasp_lost", "peg left the pads while held")
        in_hand = math.acos(min(1.0, abs(float(axis_pad @ self._axis_ref))))
        if in_hand > self.max_in_hand_tilt:
            raise EpisodeFailure("excessive_tilt", f"peg turned {in_hand:.2f} rad in the pads")


class DivergenceMonitor:
    """Fails on a new MuJoCo warning or a non-finite state; checked every ``every`` physics steps."""

    def __init__(self, every: int) -> None:
        self.every = every
        self._warnings0 = 0

    def reset(self, data: mujoco.MjData) -> None:
        self._warnings0 = int(data.warning.number.sum())

    def check(self, data: mujoco.MjData, step: int) -> None:
        if step % self.every:
            return
        # MuJoCo's own warnings catch a blow-up at once; the sum catches a NaN anywhere.
        if int(data.warning.number.sum()) != self._warnings0 or not math.isfinite(
            float(data.qpos.sum() + data.qvel.sum())
        ):
            raise EpisodeFailure("diverged", "non-finite state or MuJoCo warning")
