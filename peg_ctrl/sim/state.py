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

    def jaw_sep_m(self, data: mujoco.MjData) -> float:
        """Distance between the inner faces of the two pads [m] (from the last kinematics pass)."""
        left, right = self._pads
        xl = data.geom_xpos[left].tolist()
        xr = data.geom_xpos[right].tolist()
        dist = math.sqrt((xr[0] - xl[0]) ** 2 + (xr[1] - xl[1]) ** 2 + (xr[2] - xl[2]) ** 2)
        return dist - self._pad_half_sum

    def control_state(self, data: mujoco.MjData) -> ControlState:
        q = data.qpos[self._q0 : self._q0 + 7].copy()
        v = data.qvel[self._v0 : self._v0 + 6].copy()
        ft = data.sensordata[self._ft : self._ft + 6].copy() if self._ft >= 0 else np.zeros(6)
        return ControlState(float(data.time), q[:3], q[3:], v[:3], v[3:], self.jaw_sep_m(data), ft)

    def peg(self, data: mujoco.MjData, force_block: float, half_length: float) -> PegObservation:
        """The peg's pose, axis and lower end; ``half_length`` [m] is half the peg's length."""
        # Plain floats: this runs every control step.
        px, py, pz, w, x, y, z = data.qpos[self._peg_q : self._peg_q + 7].tolist()
        vx, vy, vz = data.qvel[self._peg_v : self._peg_v + 3].tolist()
        axis = np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])
        sign = -1.0 if axis[2] >= 0.0 else 1.0  # towards the lower end
        p = np.array([px, py, pz])
        bottom = p + (sign * half_length) * axis
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        return PegObservation(p, np.array([w, x, y, z]), axis, bottom, speed, force_block)

    def contacts(self, data: mujoco.MjData) -> tuple[PairContact, ...]:
        """Contacts above the threshold, summed per body-group pair, sorted by pair name."""
        model = self.model
        if data.ncon == 0:
            return ()
        sums: dict[tuple[str, str], list] = {}
        wrench = np.zeros(6)
        for i in range(data.ncon):
            con = data.contact[i]
            if con.efc_address < 0:
                continue  # detected within the margin but not active
            mujoco.mj_contactForce(model, data, i, wrench)
            frame = con.frame.reshape(3, 3)
            f_world = frame.T @ wrench[:3]  # force on geom2 from geom1, world frame
            g1 = BODY_GROUPS[self._body_group[model.geom_bodyid[con.geom1]]]
            g2 = BODY_GROUPS[self._body_group[model.geom_bodyid[con.geom2]]]
            if g1 == g2:
                continue
            # Report the force acting on the alphabetically first group.
            if g1 < g2:
                pair, f_on_first = (g1, g2), -f_world
            else:
                pair, f_on_first = (g2, g1), f_world
            entry = sums.setdefault(pair, [np.zeros(3), np.zeros(3), 0.0, 0, 0.0])
            mag = float(np.linalg.norm(f_on_first))
            entry[0] += f_on_first
            entry[1] += mag * con.pos
            entry[2] += mag
            entry[3] += 1
            entry[4] = max(entry[4], con.includemargin - float(con.dist))
        out = []
        for pair in sorted(sums):
            force, weighted_pos, total, count, pen = sums[pair]
            magnitude = float(np.linalg.norm(force))
            if total < self.contact_threshold_n:
                continue
            out.append(PairContact(pair, force, magnitude, weighted_pos / total, count, max(pen, 0.0)))
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
    steps (one copy in C per step). :meth:`reduce` then computes, in a few numpy calls into
    preallocated arrays, the squared net force per pair of :data:`PAIRS` of every row
    (:attr:`force_sq`, (rows, len(PAIRS)) [N^2]: a matrix product of the squared sensor values),
    and returns the peak force per pair and the peak penetration per peg partner over the rows,
    as :meth:`StateReader.pair_forces` computes them for one step. :meth:`forces` and
    :meth:`penetrations` give every row of any block of sensor rows (for the force trace, off
    the hot path).
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
        self.force_sq = np.zeros((rows, len(PAIRS)))
        self._sq = np.zeros((rows, nsensordata))
        self._sum = np.zeros((nsensordata, len(PAIRS)))  # sums each pair's squared x, y, z
        for k, adr in force_sensors:
            self._sum[adr + 1 : adr + 4, k] = 1.0
        self._peak_sq = np.zeros(len(PAIRS))
        self._dist = [(k, adr, margin) for k, adr, margin in dist_sensors]

    def reduce(self) -> tuple[list[float], list[float]]:
        """Fill :attr:`force_sq`; the peak force per pair [N] and the peak penetration per peg
        partner [m] over the rows."""
        np.multiply(self.raw, self.raw, out=self._sq)
        np.matmul(self._sq, self._sum, out=self.force_sq)
        np.max(self.force_sq, axis=0, out=self._peak_sq)
        forces = [math.sqrt(f) for f in self._peak_sq.tolist()]
        pens = [0.0] * len(PEG_PARTNERS)
        raw = self.raw
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
