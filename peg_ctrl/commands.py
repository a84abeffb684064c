"""The command API: ``u = [x, y, z, roll, pitch, yaw, jaw_sep_m]``.

Position is the gripper's pinch point in [m]; orientation is the gripper's rotation from its
home pose (fingers down, jaw closing along world X) as extrinsic X-Y-Z Euler angles in [rad],
i.e. ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``; ``jaw_sep_m`` is the separation between the finger
pads in [m]. A command may be given in a task frame ``T_world_task``; it is converted to the
world frame before it reaches a controller.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from peg_ctrl.errors import CommandError

__all__ = [
    "JAW_SEP_MAX_M",
    "COMMAND_FIELDS",
    "GripperTarget",
    "TaskFrame",
    "command_to_target",
    "euler_to_quat",
    "quat_to_euler",
]

JAW_SEP_MAX_M = 0.085
POSITION_LIMIT_M = 10.0  # slide joint range (SPEC §3.2)
COMMAND_FIELDS = ("x", "y", "z", "roll", "pitch", "yaw", "jaw_sep_m")
_NO_FORCE = np.zeros(3)
_NO_FORCE.setflags(write=False)  # shared by every pose-only target
_NO_AXES = np.zeros(6, dtype=bool)
_NO_AXES.setflags(write=False)


def euler_to_quat(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """Quaternion ``[w, x, y, z]`` of ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    quat = np.empty(4)
    mujoco.mju_euler2Quat(quat, np.array([roll, pitch, yaw], dtype=float), "XYZ")
    return quat


def quat_to_euler(quat: ArrayLike) -> NDArray[np.float64]:
    """Extrinsic X-Y-Z Euler angles ``[roll, pitch, yaw]`` [rad] of a unit quaternion ``[w, x, y, z]``.

    Pitch is in [-pi/2, pi/2]; at exactly +-pi/2 roll and yaw are not unique (roll is set to 0).
    """
    w, x, y, z = (float(v) for v in np.asarray(quat, dtype=float))
    sinp = 2.0 * (w * y - z * x)
    pitch = math.copysign(math.pi / 2.0, sinp) if abs(sinp) >= 1.0 else math.asin(sinp)
    if abs(sinp) >= 1.0 - 1e-12:
        roll = 0.0
        yaw = math.atan2(-2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z))
    else:
        roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.array([roll, pitch, yaw])


@dataclasses.dataclass(frozen=True)
class GripperTarget:
    """What a controller tracks, all in the world frame.

    Attributes:
        p_world: Pinch-point position, shape (3,), [m].
        quat_world: Gripper orientation ``[w, x, y, z]``, shape (4,), unit norm.
        v_world: Feed-forward linear velocity, shape (3,), [m/s].
        omega_body: Feed-forward angular velocity in the gripper frame, shape (3,), [rad/s].
        jaw_sep_m: Desired pad separation [m], in [0, 0.085].
        force_world: Force the gripper should exert on its surroundings, shape (3,), [N], world
            frame. An axis with a non-zero entry is *force-controlled* (hybrid position/force
            control): the controller regulates that force component and ignores the position
            error along the axis (the velocity reference still damps). Zero everywhere (the
            default) is pure pose tracking. How each controller realises it is in its docstring.
        torque_world: Moment the gripper should exert on its surroundings, shape (3,), [N m],
            world axes, about the point the controller regulates moments about: its centre of
            compliance (``impedance``, ``admittance``, ``diffik`` with ``admittance:``, the
            contact ``mpc``, ``sampling_mpc``: the held peg's tip in the studies), or the pinch
            point (``pd`` and the ``effort`` ``mpc``, which apply it open loop). It acts on the
            moment-controlled axes of ``wrench_axes`` only.
        wrench_axes: Shape (6,) bool: the world axes whose wrench is regulated instead of the
            pose: forces along x, y, z, then moments about x, y, z. A flagged axis may ask for
            zero (a zero moment about the peg's tip lets the peg turn until its end lies flat; a
            zero lateral force lets a bore guide it). An axis with a non-zero ``force_world``
            entry is force-controlled whether flagged or not.
    """

    p_world: NDArray[np.float64]
    quat_world: NDArray[np.float64]
    v_world: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(3))
    omega_body: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(3))
    jaw_sep_m: float = JAW_SEP_MAX_M
    force_world: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(3))
    torque_world: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(3))
    wrench_axes: NDArray[np.bool_] = dataclasses.field(default_factory=lambda: np.zeros(6, dtype=bool))

    def __post_init__(self) -> None:
        for name, size in (
            ("p_world", 3),
            ("quat_world", 4),
            ("v_world", 3),
            ("omega_body", 3),
            ("force_world", 3),
            ("torque_world", 3),
        ):
            try:
                value = np.array(getattr(self, name), dtype=float)  # a private, read-only copy
            except (TypeError, ValueError):
                raise CommandError(
                    f"GripperTarget.{name} must be {size} numbers, got {getattr(self, name)!r}"
                ) from None
            value.setflags(write=False)
            if value.shape != (size,):
                raise CommandError(f"GripperTarget.{name} must have shape ({size},), got {value.shape}")
            if not np.all(np.isfinite(value)):
                raise CommandError(f"GripperTarget.{name} must be finite, got {value.tolist()}")
            object.__setattr__(self, name, value)
        axes = np.asarray(self.wrench_axes)
        if axes.shape != (6,) or not (axes.dtype == bool or np.isin(axes, (0, 1)).all()):
            raise CommandError(
                "GripperTarget.wrench_axes must be 6 booleans (fx, fy, fz, mx, my, mz), "
                f"got {self.wrench_axes!r}"
            )
        axes = axes.astype(bool)
        axes.setflags(write=False)
        object.__setattr__(self, "wrench_axes", axes)
        norm = float(np.linalg.norm(self.quat_world))
        if abs(norm - 1.0) > 1e-6:
            raise CommandError(f"GripperTarget.quat_world must be a unit quaternion, norm is {norm:.6g}")
        _check_jaw(self.jaw_sep_m)
        if np.any(np.abs(self.p_world) > POSITION_LIMIT_M):
            raise CommandError(
                f"GripperTarget.p_world {self.p_world.tolist()} is outside the slide range "
                f"[-{POSITION_LIMIT_M}, {POSITION_LIMIT_M}] m"
            )

    @classmethod
    def trusted(
        cls,
        p_world: ArrayLike,
        quat_world: ArrayLike,
        v_world: ArrayLike,
        omega_body: ArrayLike,
        jaw_sep_m: float,
        force_world: ArrayLike | None = None,
        *,
        torque_world: ArrayLike | None = None,
        wrench_axes: ArrayLike | None = None,
    ) -> GripperTarget:
        """Build without validation, for planners whose samples are finite by construction.

        Planners sample at the control rate, where the checks of ``__init__`` would cost more
        than the controller; every controller still rejects a non-finite result.
        """
        obj = object.__new__(cls)
        for name, value in (
            ("p_world", p_world),
            ("quat_world", quat_world),
            ("v_world", v_world),
            ("omega_body", omega_body),
        ):
            arr = np.array(value, dtype=float)
            arr.setflags(write=False)
            object.__setattr__(obj, name, arr)
        object.__setattr__(obj, "jaw_sep_m", float(jaw_sep_m))
        force = _NO_FORCE if force_world is None else np.array(force_world, dtype=float)
        force.setflags(write=False)
        object.__setattr__(obj, "force_world", force)
        torque = _NO_FORCE if torque_world is None else np.array(torque_world, dtype=float)
        torque.setflags(write=False)
        object.__setattr__(obj, "torque_world", torque)
        axes = _NO_AXES if wrench_axes is None else np.array(wrench_axes, dtype=bool)
        axes.setflags(write=False)
        object.__setattr__(obj, "wrench_axes", axes)
        return obj

    @property
    def force_controlled(self) -> bool:
        """Whether any axis (force or moment) is wrench-controlled."""
        f = self.force_world
        return bool(f[0] or f[1] or f[2]) or bool(self.wrench_axes.any())

    @property
    def force_axes(self) -> NDArray[np.bool_]:
        """(3,) bool: the force-controlled axes (flagged in ``wrench_axes`` or a non-zero force)."""
        return self.wrench_axes[:3] | (self.force_world != 0.0)

    @property
    def moment_axes(self) -> NDArray[np.bool_]:
        """(3,) bool: the moment-controlled world axes."""
        return self.wrench_axes[3:]

    def with_force(self, force_world: ArrayLike) -> GripperTarget:
        """This target with ``force_world`` replaced (no validation, like :meth:`trusted`)."""
        return self.with_wrench(force_world, axes=self.wrench_axes, torque_world=self.torque_world)

    def with_wrench(
        self, force_world: ArrayLike, *, axes: ArrayLike, torque_world: ArrayLike | None = None
    ) -> GripperTarget:
        """This target with the wrench replaced: ``force_world`` [N], ``torque_world`` [N m] and
        the regulated ``axes`` (6 booleans); no validation, like :meth:`trusted`."""
        return GripperTarget.trusted(
            self.p_world,
            self.quat_world,
            self.v_world,
            self.omega_body,
            self.jaw_sep_m,
            force_world,
            torque_world=torque_world,
            wrench_axes=axes,
        )

    @classmethod
    def from_pose(
        cls, *, p_world: Sequence[float], rpy: Sequence[float] = (0.0, 0.0, 0.0), jaw_sep_m: float
    ) -> GripperTarget:
        """Target from a position [m], extrinsic X-Y-Z Euler angles [rad] and a jaw separation [m]."""
        return cls(
            p_world=np.asarray(p_world, dtype=float),
            quat_world=euler_to_quat(*[float(a) for a in rpy]),
            jaw_sep_m=jaw_sep_m,
        )


def _check_jaw(jaw_sep_m: float) -> None:
    number = isinstance(jaw_sep_m, (int, float, np.floating, np.integer)) and not isinstance(jaw_sep_m, bool)
    if not (number and math.isfinite(jaw_sep_m) and 0.0 <= jaw_sep_m <= JAW_SEP_MAX_M):
        raise CommandError(f"jaw_sep_m must be in [0, {JAW_SEP_MAX_M}] m, got {jaw_sep_m!r}")


@dataclasses.dataclass(frozen=True)
class TaskFrame:
    """A fixed frame ``T_world_task``: origin ``p_world`` [m] and orientation ``quat_world``."""

    p_world: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat_world: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


WORLD = TaskFrame()


def command_to_target(u: Sequence[float], *, frame: TaskFrame = WORLD) -> GripperTarget:
    """Validate a command vector ``[x, y, z, roll, pitch, yaw, jaw_sep_m]`` and express it in the world.

    Raises:
        CommandError (a ValueError): not numbers, wrong length, a non-finite entry (named), a
            jaw separation outside [0, 0.085] m, or a position outside the slide range.
    """
    try:
        values = np.asarray(u, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise CommandError(f"command must be 7 numbers {list(COMMAND_FIELDS)}, got {u!r}") from None
    if values.shape != (7,):
        raise CommandError(f"command must have 7 entries {list(COMMAND_FIELDS)}, got {values.shape[0]}")
    for name, value in zip(COMMAND_FIELDS, values, strict=True):
        if not math.isfinite(value):
            raise CommandError(f"command entry {name!r} must be finite, got {value!r}")
    _check_jaw(float(values[6]))
    quat_task = euler_to_quat(*values[3:6])
    p_world = values[:3].copy()
    quat_world = quat_task
    if frame != WORLD:
        q_frame = np.asarray(frame.quat_world, dtype=float)
        p_world = np.empty(3)
        mujoco.mju_rotVecQuat(p_world, values[:3], q_frame)
        p_world += np.asarray(frame.p_world, dtype=float)
        quat_world = np.empty(4)
        mujoco.mju_mulQuat(quat_world, q_frame, quat_task)
    return GripperTarget(p_world=p_world, quat_world=quat_world, jaw_sep_m=float(values[6]))
