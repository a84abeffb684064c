"""The action modes of ``peg_ctrl/PegInsertion-v0``: what an action means, and its space.

Action (``action_mode=``), ``float32``, shape ``(7,)``:

- ``"delta"`` (default): ``[dx, dy, dz, droll, dpitch, dyaw, jaw]`` in ``[-1, 1]``. The target
  pose is the gripper's *measured* pose moved by ``a[:3] * MAX_SPEED * control_dt`` [m] and
  turned by ``a[3:6] * MAX_ANGULAR_SPEED * control_dt`` [rad] (extrinsic X-Y-Z in the world
  frame), with the same velocity as a feed-forward; ``jaw`` sets the pad separation: ``-1``
  fully open (0.085 m), ``+1`` closed (robosuite's convention).
- ``"absolute"``: the command API ``[x, y, z, roll, pitch, yaw, jaw_sep_m]`` (see
  :mod:`peg_ctrl.commands`) in the world frame, bounded by :data:`WORKSPACE` and ``[0, 0.085]``
  m.

Actions outside the space are clipped (a non-finite action is refused by the environment). The
mode is an option of the environment, not a wrapper: a delta action is turned into a target
from the pose *measured* at that step, with its velocity as a feed-forward, which a wrapper
mapping it onto the absolute action (pose only) would lose.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from peg_ctrl.commands import JAW_SEP_MAX_M, GripperTarget, euler_to_quat
from peg_ctrl.sim.rotations import quat_mul, rotate_inv
from peg_ctrl.sim.state import ControlState

__all__ = ["ACTION_MODES", "WORKSPACE", "MAX_SPEED", "MAX_ANGULAR_SPEED", "action_space", "action_target"]

ACTION_MODES = ("delta", "absolute")
#: Bounds of the commanded pinch point in absolute mode, ``(low, high)`` per axis [m].
WORKSPACE = ((-0.45, -0.3, 0.0), (0.45, 0.3, 0.4))
MAX_SPEED = 0.2  # [m/s] of a full delta action
MAX_ANGULAR_SPEED = 2.0  # [rad/s] of a full delta action


def action_space(action_mode: str) -> spaces.Box:
    """``delta``: 7 values in [-1, 1]; ``absolute``: the command API's pose in the workspace and
    the jaw's separation."""
    if action_mode == "delta":
        return spaces.Box(-1.0, 1.0, shape=(7,), dtype=np.float32)
    (x0, y0, z0), (x1, y1, z1) = WORKSPACE
    pi = math.pi
    return spaces.Box(
        np.array([x0, y0, z0, -pi, -pi / 2, -pi, 0.0], dtype=np.float32),
        np.array([x1, y1, z1, pi, pi / 2, pi, JAW_SEP_MAX_M], dtype=np.float32),
        dtype=np.float32,
    )


def action_target(
    action_mode: str, a: NDArray[np.float64], state: ControlState, control_dt: float, *, fixed_jaw: bool
) -> GripperTarget:
    """The target of action ``a`` given the gripper's measured ``state`` (``fixed_jaw``: the jaw
    stays closed whatever the action's last entry says)."""
    if action_mode == "absolute":
        space = action_space("absolute")
        u = np.clip(a, space.low, space.high)
        q = euler_to_quat(*u[3:6])
        jaw = 0.0 if fixed_jaw else float(u[6])
        return GripperTarget.trusted(u[:3], q, np.zeros(3), np.zeros(3), jaw)
    a = np.clip(a, -1.0, 1.0)
    v = a[:3] * MAX_SPEED
    w_world = a[3:6] * MAX_ANGULAR_SPEED
    low, high = WORKSPACE
    p = np.clip(state.p_world + v * control_dt, low, high)
    q = quat_mul(euler_to_quat(*(w_world * control_dt)), state.quat_world)
    q /= np.linalg.norm(q)
    jaw = 0.0 if fixed_jaw else 0.5 * (1.0 - a[6]) * JAW_SEP_MAX_M
    return GripperTarget.trusted(p, q, v, rotate_inv(q, w_world), jaw)
