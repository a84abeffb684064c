"""The situations in MuJoCo: on the rig, and in the project's scene with the gripper's grasp.

:class:`MujocoRig` builds the rig from the project's own fixture (the table, the block's parts
and the peg's contact pairs exactly as the physics profile builds them, ``add_fixture``) and
hangs the peg rigidly under a free hand body; gravity is off, as the hand's law would cancel it.

:class:`MujocoGrasp` runs the same situation in the project's scene: the Menagerie gripper holds
the peg in its pads (closed on it as the held insertion starts, ``close_on_held_peg``), and the
same law drives the base's six joints, their gravity and joint damping cancelled, so that the
hand is the rig's but for the grasp. The difference between the two bounds what the rig's rigid
grasp, which Drake cannot reproduce, changes.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.physics import PhysicsProfile
from peg_ctrl.sim.rotations import quat_mul
from peg_ctrl.sim.scene import PEG_LYING_QUAT, add_fixture, build_model
from peg_ctrl.tools.crosscheck.rig import Rig
from peg_ctrl.tools.crosscheck.situations import GRIP_LENGTH, Situation

__all__ = ["MujocoRig", "MujocoGrasp"]


def _matrix(quat: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation matrix of a unit quaternion (w, x, y, z)."""
    out = np.empty(9)
    mujoco.mju_quat2Mat(out, quat)
    return out.reshape(3, 3)


class _Contacts:
    """The peg-block contacts of a model: the sum of their normal forces, the net force on the
    peg, the deepest overlap and their count."""

    def __init__(self, model: mujoco.MjModel, peg_geom: int, parts: set[int]) -> None:
        self.model, self.peg, self.parts = model, peg_geom, parts
        self._f = np.zeros(6)

    def read(self, data: mujoco.MjData) -> tuple[float, NDArray[np.float64], float, int]:
        normal, net, overlap, n = 0.0, np.zeros(3), 0.0, 0
        for i in range(data.ncon):
            c = data.contact[i]
            if c.geom1 == self.peg and c.geom2 in self.parts:
                sign = 1.0
            elif c.geom2 == self.peg and c.geom1 in self.parts:
                sign = -1.0
            else:
                continue
            mujoco.mj_contactForce(self.model, data, i, self._f)
            normal += float(self._f[0])
            # the force geom1 exerts on geom2, in the contact frame: the peg's share, world frame
            net -= sign * (c.frame.reshape(3, 3).T @ self._f[:3])
            overlap = max(overlap, -float(c.dist))
            n += 1
        return normal, net, overlap, n


class MujocoRig:
    """The rig in MuJoCo with the contact model of ``physics``, at the situation's start."""

    def __init__(self, rig: Rig, s: Situation, physics: PhysicsProfile) -> None:
        if physics.pair is None or physics.peg_geom != "cylinder":
            raise ValueError(
                f"the rig needs a profile with peg pairs and a cylinder peg, not {physics.name!r}"
            )
        scene = rig.scene_for(s)
        spec = mujoco.MjSpec()
        physics.apply_options(spec.option)
        spec.option.gravity = [0.0, 0.0, 0.0]
        parts = add_fixture(spec, scene, physics)
        hand = spec.worldbody.add_body()
        hand.name = "hand"
        hand.mass = rig.mass
        hand.inertia = list(rig.inertia)
        hand.ipos = [0.0, 0.0, 0.0]
        hand.explicitinertial = True
        hand.add_freejoint().name = "hand_free"
        peg = hand.add_body()
        peg.name = "peg"
        peg.pos = list(rig.peg_centre_in_hand)
        geom = peg.add_geom()
        geom.name = "peg"
        geom.type = mujoco.mjtGeom.mjGEOM_CYLINDER
        geom.size = [scene.assets.peg_radius, 0.5 * scene.assets.peg_length, 0.0]
        geom.density = scene.peg_density
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        self._hand = self.model.body("hand").id
        self._end_in_hand = rig.end_in_hand
        self._contacts = _Contacts(
            self.model, self.model.geom("peg").id, {self.model.geom(p).id for p in parts}
        )
        p0, r0 = rig.start_pose(s)
        q = np.empty(4)
        mujoco.mju_mat2Quat(q, r0.flatten())
        self.data.qpos[:7] = [*p0, *q]
        self.data.qvel[:3] = s.reference(0.0)[1]
        mujoco.mj_forward(self.model, self.data)

    def hand_state(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        # From the state itself: the kinematics mj_step leaves in data are the step's start's.
        q, v = self.data.qpos, self.data.qvel
        r = _matrix(q[3:7])
        return q[:3].copy(), r, v[:3].copy(), r @ v[3:6]  # a free joint's angular velocity: body frame

    def apply(self, force: NDArray[np.float64], torque: NDArray[np.float64]) -> None:
        self.data.xfrc_applied[self._hand, :3] = force
        self.data.xfrc_applied[self._hand, 3:] = torque

    def step(self) -> None:
        mujoco.mj_step(self.model, self.data)

    def contact(self) -> tuple[float, NDArray[np.float64], float, int]:
        return self._contacts.read(self.data)

    def lower_end(self) -> NDArray[np.float64]:
        q = self.data.qpos
        return q[:3] + _matrix(q[3:7]) @ self._end_in_hand


class MujocoGrasp:
    """The situation in the project's scene: the Menagerie gripper holding the peg in its pads,
    the base driven by the same law (gravity, Coriolis and the joints' damping cancelled)."""

    _SETTLE = 0.3  # the closed jaw held still before the situation starts [s] (the battery's)

    def __init__(self, rig: Rig, s: Situation, physics: PhysicsProfile) -> None:
        from peg_ctrl.sim.grasp_start import Q_TURN, HeldRig, close_on_held_peg, place_held_peg

        scene = rig.scene_for(s)
        self.model = build_model(scene, physics)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        self.held = h = HeldRig(self.model)
        q_tilt = np.array([math.cos(s.tilt / 2), 0.0, math.sin(s.tilt / 2), 0.0])
        q_grip = quat_mul(q_tilt, Q_TURN)
        pinch, _ = place_held_peg(
            self.model,
            self.data,
            h,
            scene,
            bottom=rig.mouth + np.asarray(s.start),
            q_grip=q_grip,
            q_peg=quat_mul(q_grip, np.asarray(PEG_LYING_QUAT)),
            grip_above_centre=GRIP_LENGTH - 0.5 * scene.assets.peg_length,
        )
        close_on_held_peg(self.model, self.data, h, pinch, q_grip)
        for _ in range(round(self._SETTLE / self.dt)):
            h.control(self.data, pinch, q_grip, None)
            mujoco.mj_step(self.model, self.data)
        self._turn = _matrix(Q_TURN)  # the gripper's rotation in the rig's hand frame
        self._root = self.model.body("gripper_root").id
        v0 = s.reference(0.0)[1]
        self.data.qvel[h.slide_dof] = v0
        self.data.qvel[h.peg_dof : h.peg_dof + 3] = v0
        mujoco.mj_forward(self.model, self.data)
        block = self.model.body("block").id
        parts = {i for i in range(self.model.ngeom) if self.model.geom_bodyid[i] == block}
        self._contacts = _Contacts(self.model, self.model.geom("peg").id, parts)
        self._half = 0.5 * scene.assets.peg_length

    def hand_state(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        q, v, h = self.data.qpos, self.data.qvel, self.held
        grip = _matrix(q[h.ball_qpos : h.ball_qpos + 4])
        omega = grip @ v[h.ball_dof : h.ball_dof + 3]  # a ball joint's velocity: body frame
        return q[h.slide_qpos].copy(), grip @ self._turn.T, v[h.slide_dof].copy(), omega

    def apply(self, force: NDArray[np.float64], torque: NDArray[np.float64]) -> None:
        d, h = self.data, self.held
        cancel = d.qfrc_bias - d.qfrc_passive  # the last step's start's: they change little in a step
        grip = _matrix(d.qpos[h.ball_qpos : h.ball_qpos + 4])
        local = grip.T @ torque  # the ball's motors act in the body frame
        for k in range(3):
            d.ctrl[h.slide_act[k]] = force[k] + cancel[h.slide_dof[k]]
            d.ctrl[h.ball_act[k]] = local[k] + cancel[h.ball_dof + k]

    def step(self) -> None:
        mujoco.mj_step(self.model, self.data)

    def contact(self) -> tuple[float, NDArray[np.float64], float, int]:
        return self._contacts.read(self.data)

    def lower_end(self) -> NDArray[np.float64]:
        q = self.data.qpos[self.held.peg_qpos : self.held.peg_qpos + 7]
        axis = _matrix(q[3:7])[:, 2] * self._half
        return q[:3] - axis if axis[2] > 0.0 else q[:3] + axis
