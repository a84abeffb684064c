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
from collections.abc import Sequence
from typing import Any, NamedTuple, Protocol

import mujoco
import numpy as np

from peg_ctrl.errors import EpisodeFailure
from peg_ctrl.sim.force_metric import SUSTAIN_WINDOW, SustainedPeak
from peg_ctrl.sim.scene import GRIPPER_PREFIX, SceneConfig
from peg_ctrl.sim.state import BLOCK_PEG, PAIRS, ControlState, PegObservation

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
    "episode_end_state",
    "not_at_hole_detail",
    "END_STATES",
    "AT_HOLE_MAX_TILT",
    "ENTRY_MARGIN",
    "FIRST_CONTACT_N",
    "WEDGED_FRACTION",
]

END_STATES = ("seated", "missed", "jammed", "wedged", "not_at_hole")
# A peg tilted further than this from vertical is not at the hole: nearer lying than upright,
# the height of its lower end says nothing about how deep it is in the bore [rad].
AT_HOLE_MAX_TILT = math.radians(45.0)
ENTRY_MARGIN = 0.0005  # the lower end is in the bore this far below the chamfer [m]
WEDGED_FRACTION = 0.9  # tilted to at least this fraction of the two-point-contact limit: wedged


class InsertionMeasure(NamedTuple):
    """Where the peg is relative to the hole.

    ``depth_m`` [m] of the peg's lower end below the hole mouth; ``lateral_error_m`` [m] from the
    peg axis to the hole axis at the mouth (``inf`` for a horizontal peg); ``radial_m`` [m]
    horizontal distance of the peg centre from the hole axis; ``bottom_z_m`` [m] height of the
    lower end; ``tilt_rad`` [rad] of the peg axis from vertical; ``speed`` [m/s] of the centre.

    ``at_hole``: the peg is over the hole, so that depth, lateral error and tilt describe it in
    the hole: it is upright within :data:`AT_HOLE_MAX_TILT` and its axis meets the plane of the
    mouth within the block's top face. A peg lying on the table, or standing beside the block,
    is not: its lower end may be 40 mm below the mouth's height without being in the bore.
    """

    depth_m: float
    lateral_error_m: float
    radial_m: float
    bottom_z_m: float
    tilt_rad: float
    speed: float
    at_hole: bool = True

    def hole_metrics(self) -> tuple[float | None, float | None, float | None]:
        """``(depth_m, lateral_error_m, tilt_rad)`` for an episode record: all None (undefined)
        when the peg is not :attr:`at_hole`."""
        if not self.at_hole:
            return None, None, None
        return self.depth_m, self.lateral_error_m, self.tilt_rad


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
        # The block's top face around the hole axis (the block is centred on it, unrotated) [m].
        self.half_x, self.half_y = (0.5 * float(v) for v in scene.assets.block_size[:2])
        self.criterion = criterion
        self.last: InsertionMeasure | None = None

    def locate(self, hole_x: float, hole_y: float, block_top: float) -> tuple[float, float, float]:
        """The hole is where the block truly is (off its drawing): mouth (x, y, z) [m]. Returns it."""
        self.hole_x, self.hole_y, self.block_top = float(hole_x), float(hole_y), float(block_top)
        return self.hole_x, self.hole_y, self.block_top

    def measure(self, peg: PegObservation) -> InsertionMeasure:
        # Plain floats: this runs every control step.
        ax, ay, az = peg.axis_world.tolist()
        px, py, pz = peg.p_world.tolist()
        bottom_z = peg.bottom_world.item(2)
        hx, hy, top = self.hole_x, self.hole_y, self.block_top
        tilt = math.acos(min(1.0, abs(az)))
        at_hole = False
        if abs(az) > 1e-6:
            s = (top - pz) / az
            dx, dy = px + s * ax - hx, py + s * ay - hy
            lateral = math.hypot(dx, dy)
            at_hole = tilt <= AT_HOLE_MAX_TILT and abs(dx) <= self.half_x and abs(dy) <= self.half_y
        else:
            lateral = math.inf
        radial = math.hypot(px - hx, py - hy)
        self.last = InsertionMeasure(top - bottom_z, lateral, radial, bottom_z, tilt, peg.speed, at_hole)
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
    """Peak contact forces [N] and penetrations [m]; ``force_spike`` [N] (or None) fails the episode.

    :attr:`peak_block` is the largest peg-block force of one physics step (the solver's peak);
    :attr:`peak_block_sustained` the largest over any ``SUSTAIN_WINDOW`` of steps
    (:mod:`peg_ctrl.sim.force_metric`: the force the studies report).
    """

    def __init__(self, force_spike: float | None = None) -> None:
        self.force_spike = force_spike
        self._sustained: SustainedPeak | None = None
        self.reset()

    def reset(self) -> None:
        self.peak_block = 0.0  # peg-block
        self.peak_any = 0.0
        self.max_penetration = 0.0  # peg-block and peg-table
        self.grip_penetration = 0.0  # pads into the peg
        if self._sustained is not None:
            self._sustained.reset()

    @property
    def peak_block_sustained(self) -> float:
        """The largest mean peg-block force over any ``SUSTAIN_WINDOW`` so far [N]."""
        return self._sustained.peak if self._sustained is not None else 0.0

    def sustain(self, block_forces: Sequence[float], dt: float) -> None:
        """Add a control period's peg-block force of each physics step [N], ``dt`` [s] apart."""
        if self._sustained is None:
            self._sustained = SustainedPeak(dt, SUSTAIN_WINDOW)
        self._sustained.extend(block_forces)

    def check(self, forces: list[float], penetrations: list[float]) -> None:
        """``forces`` per pair of :data:`~peg_ctrl.sim.state.PAIRS`; ``penetrations`` per peg partner."""
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
        self._data: mujoco.MjData | None = None
        self.reset()

    def reset(self) -> None:
        self.slip = 0.0
        self._rel_ref: tuple[float, float, float] | None = None
        self._axis_ref: tuple[float, float, float] | None = None

    def check(self, data: mujoco.MjData, gripper: ControlState, peg: PegObservation) -> None:
        # Plain floats: this runs every control step while the peg is held.
        if data is not self._data:  # views into data's arrays, fixed for its lifetime
            self._data = data
            self._pad_xmat, self._pad_xpos, self._peg_xpos = (
                data.xmat[self._pad],
                data.xpos[self._pad],
                data.xpos[self._peg],
            )
        r = self._pad_xmat.tolist()  # row-major 3x3
        px, py, pz = self._pad_xpos.tolist()
        gx, gy, gz = self._peg_xpos.tolist()
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
    """Fails with ``diverged`` when any physics step of a control period went bad; checked once
    per period, at the cost of a few comparisons.

    Three signs, each of which a bad step leaves behind for the rest of the period:

    - a new MuJoCo warning (its counters ``data.warning[i].number`` accumulate over steps):
      ``BADQPOS``/``BADQVEL``/``BADQACC`` (a NaN, Inf or value over 1e10 in the state),
      ``INERTIA`` (a singular mass matrix), ``CONTACTFULL``/``CNSTRFULL`` (buffers overflowed,
      contacts lost), ``BADCTRL``. The failure's detail is MuJoCo's own text for it;
    - simulated time going back: on a bad state MuJoCo resets the simulation (``mj_resetData``,
      which also clears the warning counters) and carries on from the start;
    - a non-finite ``qpos`` or ``qvel`` (a NaN that no check of MuJoCo's saw).
    """

    def __init__(self) -> None:
        self._warnings0 = [0] * (len(mujoco.mjtWarning.__members__) - 1)
        self._data: mujoco.MjData | None = None

    def reset(self, data: mujoco.MjData) -> None:
        self._warnings0 = data.warning.number.tolist()

    def check(self, data: mujoco.MjData, t_start: float) -> None:
        """Raise :class:`EpisodeFailure` ``diverged`` if a step since ``t_start`` [s] (the time
        at the start of the control period) went bad."""
        if data is not self._data:  # views into data's arrays, fixed for its lifetime
            self._data = data
            self._number, self._qpos, self._qvel = data.warning.number, data.qpos, data.qvel
        number = self._number
        if data.time < t_start:
            raise EpisodeFailure(
                "diverged",
                f"MuJoCo reset the simulation after a bad state (time went back from {t_start:.4f} s "
                f"to {data.time:.4f} s){_warning_text(data, number.nonzero()[0])}",
            )
        if number.tolist() != self._warnings0:
            changed = (number != np.array(self._warnings0)).nonzero()[0]
            raise EpisodeFailure("diverged", _warning_text(data, changed).removeprefix(": "))
        # Python's sum flags what numpy's did: no MuJoCo warning (checked above) means every
        # step started with |qpos|, |qvel| <= 1e10, and one step of a finite acceleration
        # cannot take a finite state near the overflow where the two orders of summing differ.
        if not math.isfinite(sum(self._qpos.tolist()) + sum(self._qvel.tolist())):
            raise EpisodeFailure("diverged", f"non-finite state at t={data.time:.4f} s")


def _warning_text(data: mujoco.MjData, kinds: Any) -> str:
    """``": <MuJoCo's text> (mjWARN_X at t=...)"`` for the first of the warnings ``kinds``."""
    if not len(kinds):
        return ""
    kind = int(kinds[0])
    text = mujoco.mju_warningText(kind, int(data.warning[kind].lastinfo))
    return f": {text} ({mujoco.mjtWarning(kind).name}, t={data.time:.4f} s)"


def classify_end_state(m: InsertionMeasure, *, clearance: float, chamfer: float, radius: float) -> str:
    """How a peg that is not seated ended: ``missed`` (the lowest point of its lower face never
    passed the chamfer into the bore, by :data:`ENTRY_MARGIN`), ``wedged`` (in the bore, tilted
    to at least :data:`WEDGED_FRACTION` of the largest tilt the bore allows at its depth:
    two-point contact) or ``jammed`` (in the bore, less tilted: held by friction or too little
    force; always, in an interference fit)."""
    from peg_ctrl.sim.validity import wedging_tilt

    lowest = m.depth_m + radius * math.sin(m.tilt_rad)  # the lowest point of the lower face
    if lowest - chamfer <= ENTRY_MARGIN:
        return "missed"
    if clearance <= 0.0:
        return "jammed"  # an interference fit: no tilt fits, the peg is held by the bore itself
    limit = wedging_tilt(clearance, m.depth_m - chamfer, radius)
    return "wedged" if m.tilt_rad >= WEDGED_FRACTION * limit else "jammed"


def not_at_hole_detail(m: InsertionMeasure) -> str:
    """Where a peg that is not at the hole is, for a failure's detail."""
    return (
        f"peg not at the hole (tilted {math.degrees(m.tilt_rad):.0f} deg, its centre "
        f"{m.radial_m * 1e3:.0f} mm from the hole axis, its lower end at {m.bottom_z_m * 1e3:.0f} mm)"
    )


def episode_end_state(
    m: InsertionMeasure | None, *, seated: bool, clearance: float, chamfer: float, radius: float
) -> str:
    """The ``end_state`` of an episode record, from the last measure ``m`` of the peg:
    ``seated`` if it was inserted; ``not_at_hole`` if it never got to the hole (``m`` is None or
    not :attr:`~InsertionMeasure.at_hole`: lying, dropped, beside the block); else
    :func:`classify_end_state` (``missed``, ``jammed`` or ``wedged``)."""
    if seated:
        return "seated"
    if m is None or not m.at_hole:
        return "not_at_hole"
    return classify_end_state(m, clearance=clearance, chamfer=chamfer, radius=radius)


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

    def update(self, t: float, dt: float, force_block: Sequence[float], peg: PegObservation) -> None:
        """``force_block`` [N]: the peg-block force of each physics step (``dt`` [s] apart) of the
        control period that ended at ``t`` [s]; ``peg`` as observed at ``t``."""
        x, y = peg.bottom_world[:2].tolist()
        if self.first_contact is None:
            threshold = self.threshold
            touching = next((i for i, f in enumerate(force_block) if f > threshold), None)
            if touching is None:
                return
            self.first_contact = t - (len(force_block) - 1 - touching) * dt
            self.impulse += _sum(force_block[touching:]) * dt
            self._xy = (x, y)
        else:
            self.impulse += _sum(force_block) * dt
        self.max_tilt = max(self.max_tilt, math.acos(min(1.0, abs(float(peg.axis_world[2])))))
        moved = math.hypot(x - self._xy[0], y - self._xy[1])
        if moved >= TRAVEL_STEP:
            self.travel += moved
            self._xy = (x, y)


def _sum(values: Sequence[float]) -> float:
    """``numpy.sum`` of a few floats, in its order: one by one below 8 terms (pairwise beyond,
    left to numpy), so the impulse is the same number to the last bit whichever computes it."""
    if len(values) >= 8:
        return float(np.sum(values))
    total = 0.0
    for v in values:
        total += v
    return total
