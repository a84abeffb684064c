"""Monitors: what the loop measures after every physics step, independent of the task's targets.

- :class:`InsertionMonitor` — depth, lateral error, tilt and "inserted" of the peg in the hole,
  with a criterion chosen by the caller (:class:`SeatedCriterion` for autonomous episodes,
  :class:`SettledCriterion` for teleoperation, SPEC §5). One geometry serves both.
- :class:`ContactMonitor` — peak contact forces and penetrations; fails on a force spike.
- :class:`GraspMonitor` — slip and turn of the peg in the pads while it is held.
- :class:`DivergenceMonitor` — MuJoCo warnings and non-finite state.
- :class:`ContactHistory` — first peg-block contact, contact impulse, tilt and lateral travel
  of the peg after it; :func:`classify_end_state` names how an unseated peg is stuck.

A failing check raises :class:`~peg_ctrl.errors.EpisodeFailure`; the loop turns it into the
episode's outcome.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

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
    "ContactHistory",
    "SeatedHold",
    "classify_end_state",
    "END_STATES",
    "ENTRY_MARGIN",
    "FIRST_CONTACT_N",
    "WEDGED_FRACTION",
]

END_STATES = ("seated", "missed", "jammed", "wedged")
ENTRY_MARGIN = 0.0005  # the lower end is in the bore this far below the chamfer [m]
WEDGED_FRACTION = 0.9  # tilted to at least this fraction of the two-point-contact limit: wedged


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


class SeatedHold:
    """How long an insertion criterion has held: ``count`` control steps in a row since
    ``since`` [s] (None while it does not hold); :meth:`update` says when ``steps`` are reached."""

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self.reset()

    def reset(self) -> None:
        self.count = 0
        self.since: float | None = None

    def update(self, t: float, holds: bool) -> bool:
        if holds:
            self.count += 1
            if self.since is None:
                self.since = t
        else:
            self.count = 0
            self.since = None
        return self.count >= self.steps


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
        self.lost_distance = lost_distance  # peg displacement in the pad frame since the grasp [m]
        self.max_in_hand_tilt = max_in_hand_tilt  # [rad]
        self.reset()

    def reset(self) -> None:
        self.slip = 0.0
        self._rel_ref: tuple[float, float, float] | None = None
        self._axis_ref: tuple[float, float, float] | None = None

    def check(self, data: mujoco.MjData, gripper: ControlState, peg: PegObservation) -> None:
        # Plain floats: this runs every control step while the peg is held.
        r = data.xmat[self._pad].tolist()  # row-major 3x3
        px, py, pz = data.xpos[self._pad].tolist()
        gx, gy, gz = data.xpos[self._peg].tolist()
        dx, dy, dz = gx - px, gy - py, gz - pz
        ax, ay, az = peg.axis_world.tolist()
        # R^T d and R^T axis: the peg's offset and axis in the pad frame
        rel = (
            r[0] * dx + r[3] * dy + r[6] * dz,
            r[1] * dx + r[4] * dy + r[7] * dz,
            r[2] * dx + r[5] * dy + r[8] * dz,
        )
        axis = (
            r[0] * ax + r[3] * ay + r[6] * az,
            r[1] * ax + r[4] * ay + r[7] * az,
            r[2] * ax + r[5] * ay + r[8] * az,
        )
        if self._rel_ref is None or self._axis_ref is None:
            self._rel_ref, self._axis_ref = rel, axis
        rx, ry, rz = self._rel_ref
        moved = math.sqrt((rel[0] - rx) ** 2 + (rel[1] - ry) ** 2 + (rel[2] - rz) ** 2)
        self.slip = max(self.slip, moved)
        if moved > self.lost_distance:
            raise EpisodeFailure("grasp_lost", f"peg moved {moved * 1e3:.1f} mm in the pads while held")
        bx, by, bz = self._axis_ref
        in_hand = math.acos(min(1.0, abs(axis[0] * bx + axis[1] * by + axis[2] * bz)))
        if in_hand > self.max_in_hand_tilt:
            raise EpisodeFailure("excessive_tilt", f"peg turned {in_hand:.2f} rad in the pads")


class DivergenceMonitor:
    """Fails on a new MuJoCo warning or a non-finite state. Checked every control period:
    MuJoCo's warning counters keep a blow-up (bad qpos, qvel or qacc) of any physics step in
    between; the sum of the state, which catches a NaN anywhere else, every ``state_every``-th."""

    def __init__(self, state_every: int = 10) -> None:
        self.state_every = state_every
        self._warnings0 = 0
        self._count = 0

    def reset(self, data: mujoco.MjData) -> None:
        self._warnings0 = int(data.warning.number.sum())
        self._count = 0

    def check(self, data: mujoco.MjData) -> None:
        self._count += 1
        if int(data.warning.number.sum()) != self._warnings0 or (
            self._count % self.state_every == 0
            and not math.isfinite(float(data.qpos.sum() + data.qvel.sum()))
        ):
            raise EpisodeFailure("diverged", "non-finite state or MuJoCo warning")


def classify_end_state(m: InsertionMeasure, *, clearance: float, chamfer: float, radius: float) -> str:
    """How a peg that is not seated ended: ``missed`` (the lowest point of its lower face never
    passed the chamfer into the bore, by :data:`ENTRY_MARGIN`), ``wedged`` (in the bore, tilted
    to at least :data:`WEDGED_FRACTION` of the largest tilt the bore allows at its depth:
    two-point contact) or ``jammed`` (in the bore, less tilted: held by friction or too little
    force; always, in an interference fit)."""
    from peg_ctrl.validity import wedging_tilt

    lowest = m.depth_m + radius * math.sin(m.tilt_rad)  # the lowest point of the lower face
    if lowest - chamfer <= ENTRY_MARGIN:
        return "missed"
    if clearance <= 0.0:
        return "jammed"  # an interference fit: no tilt fits, the peg is held by the bore itself
    limit = wedging_tilt(clearance, m.depth_m - chamfer, radius)
    return "wedged" if m.tilt_rad >= WEDGED_FRACTION * limit else "jammed"


FIRST_CONTACT_N = 0.05  # peg-block force that counts as contact [N]
TRAVEL_STEP = 1e-4  # lateral travel is counted in moves of at least this [m]: chatter is not travel


class ContactHistory:
    """From the first peg-block contact on: its time [s], the contact impulse ``∫|F| dt`` [N s]
    (at the physics rate), the largest peg tilt [rad] and the lateral travel of the
    peg's lower end [m] (the search distance, counted in moves of :data:`TRAVEL_STEP` or more)."""

    def __init__(self, threshold: float = FIRST_CONTACT_N) -> None:
        self.threshold = threshold  # peg-block force that counts as contact [N]
        self.reset()

    def reset(self) -> None:
        self.first_contact: float | None = None
        self.impulse = 0.0
        self.max_tilt = 0.0
        self.travel = 0.0
        self._xy = (0.0, 0.0)

    def update(self, t: float, dt: float, force_block: NDArray[np.float64], peg: PegObservation) -> None:
        """``force_block`` [N]: the peg-block force of each physics step (``dt`` [s] apart) of the
        control period that ended at ``t`` [s]; ``peg`` as observed at ``t``."""
        x, y = float(peg.bottom_world[0]), float(peg.bottom_world[1])
        if self.first_contact is None:
            if float(force_block.max()) <= self.threshold:
                return
            touching = np.flatnonzero(force_block > self.threshold)
            self.first_contact = t - (len(force_block) - 1 - int(touching[0])) * dt
            self.impulse += float(force_block[touching[0] :].sum()) * dt
            self._xy = (x, y)
        else:
            self.impulse += float(force_block.sum()) * dt
        self.max_tilt = max(self.max_tilt, math.acos(min(1.0, abs(float(peg.axis_world[2])))))
        moved = math.hypot(x - self._xy[0], y - self._xy[1])
        if moved >= TRAVEL_STEP:
            self.travel += moved
            self._xy = (x, y)
