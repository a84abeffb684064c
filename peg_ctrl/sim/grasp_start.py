"""A peg already in the hand: the held start of the validity pushes and the held-insertion task.

The peg is placed where it should be held (upright or tilted in the grasp), the gripper around it
with the pads ``grip_above_centre`` above the peg's centre and the pinch point ``GRASP_OFFSET``
from the peg axis along the fingers (as the pick-and-place task grasps), and the jaw closes while
the peg is pinned in place, ``CLOSE_TIME`` seconds of simulation with a stiff hold on the base
(:class:`HeldRig`). That is the construction of an initial state, like a keyframe: nothing is
recorded, and the episode's loop owns time from its first control step.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.jaw import load_default
from peg_ctrl.sim.rotations import rotate
from peg_ctrl.sim.scene import (
    BALL_ACTUATORS,
    BALL_JOINT,
    GRIPPER_PREFIX,
    JAW_ACTUATOR,
    SLIDE_ACTUATORS,
    SLIDE_JOINTS,
    SceneConfig,
    contact_sensor_name,
)

__all__ = [
    "HeldRig",
    "place_held_peg",
    "close_on_held_peg",
    "GRASP_OFFSET",
    "CLOSE_TIME",
    "Q_TURN",
    "PUSH_SPEED",
]

GRASP_OFFSET = 0.010  # peg axis from the pinch point along the fingers, as the task grasps [m]
CLOSE_TIME = 0.6  # jaw closing with the peg held in place [s]
Q_TURN = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])  # 90 deg about X: peg upright
_KP_ROT, _KD_ROT = 400.0, 5.0  # ball-joint hold [N m/rad], [N m s/rad] (on top of joint damping)
_KP_POS, _KD_POS = 3000.0, 50.0  # slide hold [N/m], [N s/m]
PUSH_SPEED = 0.03  # quasi-static descent speed of a push [m/s]
_KV_PUSH = 2000.0  # descent speed gain [N s/m]; saturates at the push force in contact


class HeldRig:
    """Indices of the held peg and the gripper, and the base's hold (or push) law."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.slide_qpos = [model.joint(j).qposadr[0] for j in SLIDE_JOINTS]
        self.slide_dof = [model.joint(j).dofadr[0] for j in SLIDE_JOINTS]
        self.ball_qpos = model.joint(BALL_JOINT).qposadr[0]
        self.ball_dof = model.joint(BALL_JOINT).dofadr[0]
        self.slide_act = [model.actuator(a).id for a in SLIDE_ACTUATORS]
        self.ball_act = [model.actuator(a).id for a in BALL_ACTUATORS]
        self.jaw_act = model.actuator(JAW_ACTUATOR).id
        self.peg = model.body("peg").id
        self.peg_qpos = model.joint("peg_free").qposadr[0]
        self.peg_dof = model.joint("peg_free").dofadr[0]
        self.pad = model.body(GRIPPER_PREFIX + "left_pad").id
        # Layouts: force sensor (found, fx, fy, fz); distance sensor (found, closest distance).
        self.force_adr = int(model.sensor(contact_sensor_name("force", "block", "peg")).adr[0])
        self.dist_adr = int(model.sensor(contact_sensor_name("dist", "block", "peg")).adr[0])

    def control(
        self,
        data: mujoco.MjData,
        p_ref: NDArray[np.float64],
        q_ref: NDArray[np.float64],
        push: float | None,
    ) -> None:
        """Hold ``q_ref``; hold ``p_ref`` (``push`` None) or push down with ``push`` N, laterally free."""
        bias = data.qfrc_bias
        for k in range(3):
            dof, act = self.slide_dof[k], self.slide_act[k]
            if push is None:
                err = p_ref[k] - data.qpos[self.slide_qpos[k]]
                data.ctrl[act] = _KP_POS * err - _KD_POS * data.qvel[dof] + bias[dof]
            elif k == 2:
                # Down at up to PUSH_SPEED, with at most ``push`` newtons: the force saturates
                # in contact. The slide's own damping is cancelled so the force is the push.
                down = -data.qvel[dof]
                f = min(push, max(0.0, _KV_PUSH * (PUSH_SPEED - down)))
                data.ctrl[act] = bias[dof] - data.qfrc_passive[dof] - f
            else:
                data.ctrl[act] = bias[dof]
        q = data.qpos[self.ball_qpos : self.ball_qpos + 4]
        err3 = np.empty(3)
        mujoco.mju_subQuat(err3, q_ref, q)
        w = data.qvel[self.ball_dof : self.ball_dof + 3]
        torque = _KP_ROT * err3 - _KD_ROT * w + bias[self.ball_dof : self.ball_dof + 3]
        for k in range(3):
            data.ctrl[self.ball_act[k]] = torque[k]

    def peg_in_pad(self, data: mujoco.MjData) -> NDArray[np.float64]:
        return data.xmat[self.pad].reshape(3, 3).T @ (data.xpos[self.peg] - data.xpos[self.pad])

    def peg_block_contact(self, data: mujoco.MjData) -> tuple[float, float, float]:
        """Net peg-block contact force magnitude [N], the deepest true overlap [m] (>= 0) and
        the closest surface distance [m] among the contacts (nan if none), from the scene's
        peg-block contact sensors."""
        sd = data.sensordata
        f = self.force_adr
        force = math.sqrt(sd[f + 1] ** 2 + sd[f + 2] ** 2 + sd[f + 3] ** 2)
        if sd[self.dist_adr] <= 0.0:  # no peg-block contact
            return force, 0.0, math.nan
        closest = float(sd[self.dist_adr + 1])
        return force, max(0.0, -closest), closest


def place_held_peg(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    rig: HeldRig,
    scene: SceneConfig,
    *,
    bottom: NDArray[np.float64],
    q_grip: NDArray[np.float64],
    q_peg: NDArray[np.float64],
    grip_above_centre: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Home keyframe, then the peg with its lower end's centre at ``bottom`` [m] and orientation
    ``q_peg``, the gripper at ``q_grip`` around it; ``mj_forward``. Returns the gripper's pinch
    position and orientation."""
    half = 0.5 * scene.assets.peg_length
    # The lower end: along the peg's local axis, whichever end points down.
    axis = rotate(q_peg, np.array([0.0, 0.0, 1.0]))
    lower_local = -half if axis[2] > 0 else half
    peg_centre = bottom - rotate(q_peg, np.array([0.0, 0.0, lower_local]))
    up = axis if axis[2] > 0 else -axis
    pinch = peg_centre + grip_above_centre * up - rotate(q_grip, np.array([0.0, 0.0, -GRASP_OFFSET]))
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    data.qpos[rig.slide_qpos] = pinch
    data.qpos[rig.ball_qpos : rig.ball_qpos + 4] = q_grip
    data.qpos[rig.peg_qpos : rig.peg_qpos + 3] = peg_centre
    data.qpos[rig.peg_qpos + 3 : rig.peg_qpos + 7] = q_peg
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    return pinch, q_grip


def close_on_held_peg(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    rig: HeldRig,
    pinch: NDArray[np.float64],
    q_grip: NDArray[np.float64],
    seconds: float = CLOSE_TIME,
) -> None:
    """Close the jaw for ``seconds`` with the base held at the pose and the peg pinned in place."""
    peg_pose = data.qpos[rig.peg_qpos : rig.peg_qpos + 7].copy()
    data.ctrl[rig.jaw_act] = load_default().sep_to_byte(0.0)
    for _ in range(round(seconds / model.opt.timestep)):
        rig.control(data, pinch, q_grip, None)
        mujoco.mj_step(model, data)
        data.qpos[rig.peg_qpos : rig.peg_qpos + 7] = peg_pose
        data.qvel[rig.peg_dof : rig.peg_dof + 6] = 0.0
