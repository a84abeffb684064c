"""Rigid-body dynamics of the base stack from Pinocchio, built from the scene's own MJCF.

The robot-only MJCF (``peg_ctrl.sim.scene.export_robot``: base stack + gripper, every inertial written
explicitly) is written to a temporary directory, read with ``pinocchio.buildModelFromMJCF`` and
deleted again; the finger joints are then locked at their open configuration
(``buildReducedModel``), leaving the 6 base DoF: three slides and the ball joint. Pinocchio orders a
spherical joint's quaternion ``[x, y, z, w]``; MuJoCo ``[w, x, y, z]`` — converted here. Velocities
agree: the ball joint's is in the body frame.

Pinocchio's MJCF reader places hinge joints at their body's origin and ignores a joint ``pos``
offset (the 2F-85's followers have one), so the full models agree only with the fingers open; the
base block, which is all the controllers use, agrees exactly there (see the tests).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.scene import PINCH_SITE, SceneConfig, export_robot

__all__ = ["BaseDynamics", "robot_mjcf", "to_pinocchio_q"]


def robot_mjcf(out_dir: Path, scene: SceneConfig | None = None) -> Path:
    """Write the robot-only MJCF into ``out_dir`` (meshes referenced by absolute path); its path."""
    return export_robot(Path(out_dir), scene)


def _pinch_in_root(path: Path):  # type: ignore[no-untyped-def]
    """The pinch site's pose in the ``gripper_root`` frame, from MuJoCo, as a ``pinocchio.SE3``."""
    import mujoco
    import pinocchio as pin

    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    root = model.body("gripper_root").id
    r_root = data.xmat[root].reshape(3, 3)
    site = model.site(PINCH_SITE).id
    rot = r_root.T @ data.site_xmat[site].reshape(3, 3)
    pos = r_root.T @ (data.site_xpos[site] - data.xpos[root])
    return pin.SE3(rot, pos)


def to_pinocchio_q(qpos_mujoco: NDArray[np.float64]) -> NDArray[np.float64]:
    """MuJoCo robot qpos (slides, ball ``wxyz``, ...) -> Pinocchio order (ball ``xyzw``)."""
    q = np.array(qpos_mujoco, dtype=float)
    q[3:7] = [q[4], q[5], q[6], q[3]]
    return q


class BaseDynamics:
    """Mass matrix, bias forces and pinch Jacobian of the 6-DoF base (fingers locked open)."""

    def __init__(self, scene: SceneConfig | None = None) -> None:
        import pinocchio as pin

        self._pin = pin
        # Neither model keeps a reference to the file once read, so nothing is left in /tmp.
        with tempfile.TemporaryDirectory(prefix="peg_ctrl_robot_") as tmp:
            path = robot_mjcf(Path(tmp), scene)
            full = pin.buildModelFromMJCF(str(path))
            pinch_in_root = _pinch_in_root(path)
        self.full_model = full
        finger_joints = [j for j in range(1, full.njoints) if full.names[j].startswith("2f85/")]
        q_ref = pin.neutral(full)
        self.model = pin.buildReducedModel(full, finger_joints, q_ref)
        # Pinocchio's MJCF reader misplaces sites in welded child bodies (the 2F-85's pinch
        # lands at the base_mount origin), so the pinch frame is added from MuJoCo's placement.
        self.pinch_frame = self.model.addFrame(
            pin.Frame("pinch_point", 1, 0, pinch_in_root, pin.FrameType.OP_FRAME)
        )
        self.data = self.model.createData()
        if self.model.nv != 6:
            raise RuntimeError(f"expected a 6-DoF base after locking the fingers, got nv={self.model.nv}")
        self._q = np.zeros(7)

    def _config(self, p_world: NDArray[np.float64], quat_world: NDArray[np.float64]) -> NDArray[np.float64]:
        q = self._q
        q[:3] = p_world
        q[3:6] = quat_world[1:4]
        q[6] = quat_world[0]
        return q

    def bias(
        self,
        p_world: NDArray[np.float64],
        quat_world: NDArray[np.float64],
        v_world: NDArray[np.float64],
        omega_body: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """Gravity + Coriolis/centrifugal generalised forces (6,): slides [N], ball [N m] (body)."""
        v = np.concatenate([v_world, omega_body])
        return self._pin.rnea(self.model, self.data, self._config(p_world, quat_world), v, np.zeros(6))

    def mass_matrix(
        self, p_world: NDArray[np.float64], quat_world: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Joint-space mass matrix (6, 6) incl. armature."""
        m = self._pin.crba(self.model, self.data, self._config(p_world, quat_world))
        return np.triu(m) + np.triu(m, 1).T

    def pinch_jacobian(
        self, p_world: NDArray[np.float64], quat_world: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """(6, 6) Jacobian of the pinch site: rows linear then angular velocity, world-aligned."""
        pin = self._pin
        q = self._config(p_world, quat_world)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return pin.getFrameJacobian(self.model, self.data, self.pinch_frame, pin.LOCAL_WORLD_ALIGNED).copy()
