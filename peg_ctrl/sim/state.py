"""Typed views of the simulation state.

Two levels, because the control loop runs at 1 kHz and a full snapshot is not free:

- :class:`ControlState` — what every controller sees each control step: gripper pose and
  velocity, jaw separation and time. Cheap to build (two array copies).
- :class:`SimState` — a full snapshot for logs and analysis: adds the peg's pose and velocity
  and the contacts grouped by body pair.

:class:`StateReader` resolves all indices once from the model.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.scene import BALL_JOINT, GRIPPER_PREFIX, PAD_BODIES, SLIDE_JOINTS, contact_sensor_name

__all__ = [
    "ControlState",
    "PegObservation",
    "PairContact",
    "SimState",
    "StateReader",
    "BODY_GROUPS",
    "PAIRS",
    "PEG_PARTNERS",
    "BLOCK_PEG",
    "ft_world",
    "SensorBlock",
]

BODY_GROUPS = ("gripper", "peg", "block", "table")
# Every unordered pair of distinct groups, names in alphabetical order (the order used in logs).
PAIRS: tuple[tuple[str, str], ...] = tuple(
    sorted((min(a, b), max(a, b)) for i, a in enumerate(BODY_GROUPS) for b in BODY_GROUPS[i + 1 :])
)
PEG_PARTNERS = ("block", "gripper", "table")  # groups the peg's penetration is tracked against
BLOCK_PEG = PAIRS.index(("block", "peg"))  # index of the peg-block pair in PAIRS


_NO_WRENCH = np.zeros(6)
_NO_WRENCH.setflags(write=False)  # a shared default must not be writable


class ControlState(NamedTuple):
    """Gripper state at time ``t`` [s].

    ``p_world`` (3,) [m] pinch point; ``quat_world`` (4,) ``[w, x, y, z]``; ``v_world`` (3,) [m/s];
    ``omega_body`` (3,) [rad/s] angular velocity in the gripper frame; ``jaw_sep_m`` [m] measured
    between the pad faces; ``ft_wrench`` (6,) the force [N] and torque [N m] that the base exerts
    on the gripper at the mount, in the ``ft_sensor`` site frame (the gripper frame turned 180
    degrees about X), unfiltered.
    """

    t: float
    p_world: NDArray[np.float64]
    quat_world: NDArray[np.float64]
    v_world: NDArray[np.float64]
    omega_body: NDArray[np.float64]
    jaw_sep_m: float
    ft_wrench: NDArray[np.float64] = _NO_WRENCH


class PegObservation(NamedTuple):
    """The peg's state after a physics step (world frame).

    ``p_world`` (3,) [m] centre; ``quat_world`` (4,); ``axis_world`` (3,) unit axis;
    ``bottom_world`` (3,) [m] the lower end of the axis; ``speed`` [m/s] of the centre;
    ``force_block`` [N] the net peg-block contact force.
    """

    p_world: NDArray[np.float64]
    quat_world: NDArray[np.float64]
    axis_world: NDArray[np.float64]
    bottom_world: NDArray[np.float64]
    speed: float
    force_block: float


def ft_world(state: ControlState) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The force/torque sensor's reading in the world frame: the force [N] and torque [N m] that
    the base exerts on the gripper (sensor frame -> gripper frame is 180 degrees about X)."""
    f, t = state.ft_wrench[:3], state.ft_wrench[3:]
    force, torque = np.empty(3), np.empty(3)
    mujoco.mju_rotVecQuat(force, np.array([f[0], -f[1], -f[2]]), state.quat_world)
    mujoco.mju_rotVecQuat(torque, np.array([t[0], -t[1], -t[2]]), state.quat_world)
    return force, torque


@dataclasses.dataclass(frozen=True)
class PairContact:
    """Summed contact between two body groups.

    ``force_world`` (3,) [N] is the force the second group exerts on the first, summed over
    ``count`` contacts; ``position_world`` (3,) [m] is their force-weighted centroid;
    ``max_penetration_m`` the deepest penetration among them, measured from where the contact
    turns active (the geoms' margin), i.e. the depth the soft contact is compressed.
    """

    pair: tuple[str, str]
    force_world: NDArray[np.float64]
    magnitude: float
    position_world: NDArray[np.float64]
    count: int
    max_penetration_m: float

    def to_dict(self) -> dict[str, object]:
        return {
            "pair": "-".join(self.pair),
            "force": [round(float(f), 6) for f in self.force_world],
            "magnitude": round(self.magnitude, 6),
            "position": [round(float(p), 6) for p in self.position_world],
            "count": self.count,
            "max_penetration_m": round(self.max_penetration_m, 9),
        }


@dataclasses.dataclass(frozen=True)
class SimState:
    """A full snapshot at time ``t`` [s]; vectors in the world frame unless named ``_body``.

    ``omega_body_peg`` is the peg's angular velocity in its own frame (MuJoCo's free-joint convention).
    """

    control: ControlState
    p_world_peg: NDArray[np.float64]
    quat_world_peg: NDArray[np.float64]
    v_world_peg: NDArray[np.float64]
    omega_body_peg: NDArray[np.float64]
    contacts: tuple[PairContact, ...]

    @property
    def t(self) -> float:
        return self.control.t

    def contact(self, a: str, b: str) -> PairContact | None:
        key = tuple(sorted((a, b)))
        for c in self.contacts:
            if c.pair == key:
                return c
        return None


class _PairSum:
    """The sums over one pair's contacts: force [N], force-weighted position [N m], total
    force magnitude [N], count, deepest penetration [m] (0 floor)."""

    __slots__ = ("force", "weighted_pos", "total", "count", "pen")

    def __init__(self) -> None:
        self.force = (0.0, 0.0, 0.0)
        self.weighted_pos = (0.0, 0.0, 0.0)
        self.total = 0.0
        self.count = 0
        self.pen = 0.0

    def add(self, f: tuple[float, float, float], mag: float, pos: list[float], pen: float) -> None:
        fx, fy, fz = self.force
        self.force = (fx + f[0], fy + f[1], fz + f[2])
        px, py, pz = self.weighted_pos
        self.weighted_pos = (px + mag * pos[0], py + mag * pos[1], pz + mag * pos[2])
        self.total += mag
        self.count += 1
        self.pen = max(self.pen, pen)


class _DataViews:
    """Views into one ``MjData``'s arrays that :class:`StateReader` reads every control step:
    the gripper's and the peg's joints, the wrist sensor, the pads. Made once per data (its
    arrays never move), they spare the bindings' accessors, which build a new array per call."""

    def __init__(self, reader: StateReader, data: mujoco.MjData) -> None:
        self.data = data
        q0, v0 = reader._q0, reader._v0
        self.p, self.quat = data.qpos[q0 : q0 + 3], data.qpos[q0 + 3 : q0 + 7]
        self.v, self.omega = data.qvel[v0 : v0 + 3], data.qvel[v0 + 3 : v0 + 6]
        ft = reader._ft
        self.ft = data.sensordata[ft : ft + 6] if ft >= 0 else None
        left, right = reader._pads
        self.pad_left, self.pad_right = data.geom_xpos[left], data.geom_xpos[right]
        self.peg_q = data.qpos[reader.peg_qpos_slice]
        self.peg_v = data.qvel[reader._peg_v : reader._peg_v + 3]


class StateReader:
    """Reads :class:`ControlState` / :class:`SimState` from ``MjData`` using indices resolved once."""

    def __init__(self, model: mujoco.MjModel, *, contact_threshold_n: float = 0.01) -> None:
        self.model = model
        self.contact_threshold_n = contact_threshold_n
        self._slide_qpos = np.array([model.joint(n).qposadr[0] for n in SLIDE_JOINTS])
        self._slide_dof = np.array([model.joint(n).dofadr[0] for n in SLIDE_JOINTS])
        self._q0 = int(self._slide_qpos[0])
        self._v0 = int(self._slide_dof[0])
        if not (np.all(np.diff(self._slide_qpos) == 1) and np.all(np.diff(self._slide_dof) == 1)):
            raise ValueError("slide joints must be consecutive in qpos/qvel")
        ball = model.joint(BALL_JOINT)
        if ball.qposadr[0] != self._q0 + 3 or ball.dofadr[0] != self._v0 + 3:
            raise ValueError("the ball joint must follow the slide joints in qpos/qvel")
        peg_joint = model.joint("peg_free")
        self._peg_q = int(peg_joint.qposadr[0])
        self.peg_qpos_slice = slice(self._peg_q, self._peg_q + 7)  # the peg's pose in qpos
        self._peg_v = int(peg_joint.dofadr[0])
        self._pads = [model.geom(GRIPPER_PREFIX + n).id for n in ("left_pad1", "right_pad1")]
        # Box half-thickness along the closing direction (local y of the pad boxes).
        self._pad_half_sum = float(sum(model.geom_size[g][1] for g in self._pads))
        self._body_group = self._classify_bodies(model)
        self._geom_group = [BODY_GROUPS[g] for g in self._body_group[model.geom_bodyid].tolist()]
        force = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, "ft_force")
        torque = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, "ft_torque")
        self._ft = -1
        if force >= 0 and torque >= 0:
            if model.sensor_adr[torque] != model.sensor_adr[force] + 3:
                raise ValueError("ft_force and ft_torque must be adjacent in sensordata")
            self._ft = int(model.sensor_adr[force])
        # Contact sensors of the scene (see scene._add_contact_sensors).
        self._force_sensors: list[tuple[int, int]] = []
        for k, (a, b) in enumerate(PAIRS):
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, contact_sensor_name("force", a, b))
            if sid >= 0:
                self._force_sensors.append((k, int(model.sensor_adr[sid])))
        self._dist_sensors: list[tuple[int, int, float]] = []
        peg_margin = float(model.geom_margin[model.geom("peg").id])
        for k, other in enumerate(PEG_PARTNERS):
            a, b = sorted(("peg", other))
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, contact_sensor_name("dist", a, b))
            if sid < 0:
                continue
            geoms = np.flatnonzero(self._body_group[model.geom_bodyid] == BODY_GROUPS.index(other))
            # MuJoCo uses the larger margin of the two geoms; take the group's largest.
            margin = max(peg_margin, float(model.geom_margin[geoms].max()) if len(geoms) else 0.0)
            self._dist_sensors.append((k, int(model.sensor_adr[sid]), margin))
        pads = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, contact_sensor_name("force", pad, "peg"))
            for pad in PAD_BODIES
        ]
        #: sensordata addresses of the left and right pad-peg force sensors (None without them).
        self.grip_sensors = (
            (int(model.sensor_adr[pads[0]]), int(model.sensor_adr[pads[1]])) if min(pads) >= 0 else None
        )
        self._one_step: SensorBlock | None = None  # pair_forces' block of one row
        self._bound: _DataViews | None = None  # views into the data read last

    @staticmethod
    def _classify_bodies(model: mujoco.MjModel) -> NDArray[np.int64]:
        """Group index (into BODY_GROUPS) of every body; world bodies (table plane) are 'table'."""
        groups = np.full(model.nbody, BODY_GROUPS.index("table"), dtype=np.int64)
        root = model.body("gripper_root").id
        for b in range(model.nbody):
            a = b
            while a != 0 and a != root:
                a = model.body_parentid[a]
            if a == root:
                groups[b] = BODY_GROUPS.index("gripper")
        groups[model.body("peg").id] = BODY_GROUPS.index("peg")
        groups[model.body("block").id] = BODY_GROUPS.index("block")
        return groups

    def _views(self, data: mujoco.MjData) -> _DataViews:
        """The views into ``data`` read every control step (made once per ``data``)."""
        views = self._bound
        if views is None or views.data is not data:
            views = self._bound = _DataViews(self, data)
        return views

    def jaw_sep_m(self, data: mujoco.MjData) -> float:
        """Distance between the inner faces of the two pads [m] (from the last kinematics pass)."""
        views = self._views(data)
        xl = views.pad_left.tolist()
        xr = views.pad_right.tolist()
        dist = math.sqrt((xr[0] - xl[0]) ** 2 + (xr[1] - xl[1]) ** 2 + (xr[2] - xl[2]) ** 2)
        return dist - self._pad_half_sum

    def control_state(self, data: mujoco.MjData) -> ControlState:
        views = self._views(data)
        ft = views.ft.copy() if views.ft is not None else np.zeros(6)
        return ControlState(
            float(data.time),
            views.p.copy(),
            views.quat.copy(),
            views.v.copy(),
            views.omega.copy(),
            self.jaw_sep_m(data),
            ft,
        )

    def peg(self, data: mujoco.MjData, force_block: float, half_length: float) -> PegObservation:
        """The peg's pose, axis and lower end; ``half_length`` [m] is half the peg's length."""
        # Plain floats: this runs every control step.
        views = self._views(data)
        px, py, pz, w, x, y, z = views.peg_q.tolist()
        vx, vy, vz = views.peg_v.tolist()
        ax, ay, az = 2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)
        s = (-1.0 if az >= 0.0 else 1.0) * half_length  # towards the lower end
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        return PegObservation(
            np.array([px, py, pz]),
            np.array([w, x, y, z]),
            np.array([ax, ay, az]),
            np.array([px + s * ax, py + s * ay, pz + s * az]),
            speed,
            force_block,
        )

    def contacts(self, data: mujoco.MjData) -> tuple[PairContact, ...]:
        """Contacts above the threshold, summed per body-group pair, sorted by pair name."""
        model = self.model
        ncon = data.ncon
        if ncon == 0:
            return ()
        sums: dict[tuple[str, str], _PairSum] = {}
        wrench = np.zeros(6)
        # The contacts' fields read once (indexing data.contact builds an object per contact),
        # and plain floats: the contact frame's transpose times the force is the matrix-vector
        # product numpy takes, term by term in its order, and |f| its sqrt(f . f).
        contact = data.contact
        efc, geom1, geom2 = contact.efc_address.tolist(), contact.geom1.tolist(), contact.geom2.tolist()
        frames, positions = contact.frame.tolist(), contact.pos.tolist()
        dist, includemargin = contact.dist.tolist(), contact.includemargin.tolist()
        group = self._geom_group
        for i in range(ncon):
            if efc[i] < 0:
                continue  # detected within the margin but not active
            g1, g2 = group[geom1[i]], group[geom2[i]]
            if g1 == g2:
                continue
            mujoco.mj_contactForce(model, data, i, wrench)
            a, b, c = wrench[:3].tolist()
            r = frames[i]  # rows: the contact frame's axes, world frame
            # the force on geom2 from geom1, world frame
            fx = r[0] * a + r[3] * b + r[6] * c
            fy = r[1] * a + r[4] * b + r[7] * c
            fz = r[2] * a + r[5] * b + r[8] * c
            mag = math.sqrt(fx * fx + fy * fy + fz * fz)
            # Report the force acting on the alphabetically first group.
            if g1 < g2:
                pair, fx, fy, fz = (g1, g2), -fx, -fy, -fz
            else:
                pair = (g2, g1)
            entry = sums.get(pair)
            if entry is None:
                entry = sums[pair] = _PairSum()
            entry.add((fx, fy, fz), mag, positions[i], includemargin[i] - dist[i])
        out = []
        for pair in sorted(sums):
            entry = sums[pair]
            total = entry.total
            if total < self.contact_threshold_n:
                continue
            fx, fy, fz = entry.force
            magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
            force, position = np.array(entry.force), np.array(entry.weighted_pos) / total
            out.append(PairContact(pair, force, magnitude, position, entry.count, max(entry.pen, 0.0)))
        return tuple(out)

    def pair_forces(self, data: mujoco.MjData) -> tuple[list[float], list[float]]:
        """Net contact force magnitude per pair of :data:`PAIRS` [N], and the deepest active
        penetration [m] of the peg's contacts with each of :data:`PEG_PARTNERS`, read from the
        scene's contact sensors (computed in C during the step): one step's
        :meth:`SensorBlock.reduce`."""
        if self._one_step is None:
            self._one_step = self.sensor_block(1)
        self._one_step.raw[0] = data.sensordata
        return self._one_step.reduce()

    def sensor_block(self, rows: int) -> SensorBlock:
        """A :class:`SensorBlock` for ``rows`` physics steps of this model's contact sensors."""
        return SensorBlock(
            self._force_sensors, self._dist_sensors, rows, self.model.nsensordata, grip=self.grip_sensors
        )

    def sim_state(self, data: mujoco.MjData) -> SimState:
        pq = data.qpos[self._peg_q : self._peg_q + 7].copy()
        pv = data.qvel[self._peg_v : self._peg_v + 6].copy()
        return SimState(
            control=self.control_state(data),
            p_world_peg=pq[:3],
            quat_world_peg=pq[3:],
            v_world_peg=pv[:3],
            omega_body_peg=pv[3:],
            contacts=self.contacts(data),
        )


class SensorBlock:
    """The contact sensors of the physics steps of one control period, read in bulk.

    The loop copies ``data.sensordata`` into row ``i`` of :attr:`raw` after each of its physics
    steps (one copy in C per step). :meth:`reduce` then gives the peak force per pair of
    :data:`PAIRS` and the peak penetration per peg partner over the rows, as
    :meth:`StateReader.pair_forces` computes them for one step, and the peg-block force of every
    row (:attr:`block_force`). :meth:`forces` and :meth:`penetrations` give every row of any
    block of sensor rows (for the force trace, off the hot path).
    """

    def __init__(
        self,
        force_sensors: list[tuple[int, int]],
        dist_sensors: list[tuple[int, int, float]],
        rows: int,
        nsensordata: int,
        *,
        grip: tuple[int, int] | None = None,
    ) -> None:
        self.rows = rows
        self._grip = grip
        self.raw = np.zeros((rows, nsensordata))
        #: The peg-block force of each row [N] (from the last :meth:`reduce`).
        self.block_force = [0.0] * rows
        self._sum = np.zeros((nsensordata, len(PAIRS)))  # sums each pair's squared x, y, z
        for k, adr in force_sensors:
            self._sum[adr + 1 : adr + 4, k] = 1.0
        self._force = [(k, adr + 1) for k, adr in force_sensors]  # pair, address of its x
        self._dist = [(k, adr, margin) for k, adr, margin in dist_sensors]

    def reduce(self) -> tuple[list[float], list[float]]:
        """The peak force per pair [N] and the peak penetration per peg partner [m] over the
        rows; fills :attr:`block_force`."""
        # Plain floats: a few dozen numbers per control period, where numpy's per-call cost
        # would dominate. Bit for bit what the array code (_reduce_arrays) computes: each
        # pair's x*x + y*y + z*z is the sum its matrix product takes, in the same order.
        rows = self.raw.tolist()
        for row in rows:
            if not math.isfinite(sum(row)):  # a diverging step: numpy's NaN and inf propagation
                return self._reduce_arrays()
        peak = [0.0] * len(PAIRS)  # squared [N^2]
        block = [0.0] * len(rows)
        for i, row in enumerate(rows):
            for k, x in self._force:
                fx, fy, fz = row[x], row[x + 1], row[x + 2]
                sq = fx * fx + fy * fy + fz * fz
                if sq > peak[k]:
                    peak[k] = sq
                if k == BLOCK_PEG:
                    block[i] = math.sqrt(sq)
        self.block_force = block
        pens = [0.0] * len(PEG_PARTNERS)
        for k, adr, margin in self._dist:
            closest = math.inf  # the closest distance where a contact was found
            for row in rows:
                if row[adr] > 0.0 and row[adr + 1] < closest:
                    closest = row[adr + 1]
            if closest < math.inf:
                pens[k] = max(0.0, margin - closest)
        return [math.sqrt(f) for f in peak], pens

    def _reduce_arrays(self) -> tuple[list[float], list[float]]:
        """:meth:`reduce` in numpy, for rows that are not all finite."""
        raw = self.raw
        force_sq = (raw * raw) @ self._sum
        self.block_force = np.sqrt(force_sq[:, BLOCK_PEG]).tolist()
        forces = [math.sqrt(f) for f in np.max(force_sq, axis=0).tolist()]
        pens = [0.0] * len(PEG_PARTNERS)
        for k, adr, margin in self._dist:
            found = raw[:, adr]
            if found.any():  # the closest distance where a contact was found
                pens[k] = max(0.0, margin - float(raw[:, adr + 1][found > 0.0].min()))
        return forces, pens

    def forces(self, raw: NDArray[np.float64]) -> NDArray[np.float64]:
        """Net force per pair (n, len(PAIRS)) [N] of sensor rows ``raw`` (n, nsensordata)."""
        return np.sqrt((raw * raw) @ self._sum)

    def grip(self, raw: NDArray[np.float64]) -> NDArray[np.float64]:
        """The grip (n,) [N] of sensor rows ``raw``: half the difference of the two finger pads'
        net forces on the peg. The pads press from opposite sides, so this is their squeeze (the
        weight they carry together cancels); NaN if the model has no pad sensors."""
        if self._grip is None:
            return np.full(len(raw), np.nan)
        left, right = self._grip
        diff = raw[:, left + 1 : left + 4] - raw[:, right + 1 : right + 4]
        return 0.5 * np.sqrt((diff * diff).sum(axis=1))

    def penetrations(self, raw: NDArray[np.float64]) -> NDArray[np.float64]:
        """Deepest penetration over the peg partners (n,) [m] of sensor rows ``raw``."""
        out = np.zeros(len(raw))
        for _, adr, margin in self._dist:
            pen = np.where(raw[:, adr] > 0.0, margin - raw[:, adr + 1], 0.0)
            np.maximum(out, pen, out=out)
        return out
