"""The command vector: validation, Euler convention, task frames."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget, TaskFrame, command_to_target, euler_to_quat, quat_to_euler

from .conftest import HOME, IDENTITY, target


@pytest.mark.parametrize("index, name", list(enumerate(["x", "y", "z", "roll", "pitch", "yaw", "jaw_sep_m"])))
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_entry_is_named(index: int, name: str, bad: float) -> None:
    u = [0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.04]
    u[index] = bad
    with pytest.raises(ValueError, match=f"'{name}'"):
        command_to_target(u)


@pytest.mark.parametrize("jaw", [-0.001, 0.0851])
def test_jaw_out_of_range(jaw: float) -> None:
    with pytest.raises(ValueError, match=r"jaw_sep_m must be in \[0, 0.085\]"):
        command_to_target([0, 0, 0.2, 0, 0, 0, jaw])


def test_wrong_length_and_out_of_range_position() -> None:
    with pytest.raises(ValueError, match="7 entries"):
        command_to_target([0.0] * 6)
    with pytest.raises(ValueError, match="slide range"):
        command_to_target([11.0, 0, 0.2, 0, 0, 0, 0.04])


def test_euler_convention_is_extrinsic_xyz() -> None:
    roll, pitch, yaw = 0.3, -0.4, 1.1
    q = euler_to_quat(roll, pitch, yaw)
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, q)

    def rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])

    def ry(a):
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    def rz(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    np.testing.assert_allclose(r.reshape(3, 3), rz(yaw) @ ry(pitch) @ rx(roll), atol=1e-12)


@pytest.mark.parametrize(
    "rpy", [(0.3, -0.4, 1.1), (-2.0, 1.2, 3.0), (0.0, 0.0, 0.0), (1.0, math.pi / 2, 0.0)]
)
def test_euler_round_trip(rpy) -> None:
    q = euler_to_quat(*rpy)
    back = euler_to_quat(*quat_to_euler(q))
    assert abs(abs(float(q @ back)) - 1.0) < 1e-12  # same rotation (q or -q)


def test_task_frame_is_applied() -> None:
    frame = TaskFrame(p_world=(0.2, 0.0, 0.05), quat_world=tuple(euler_to_quat(0.0, 0.0, math.pi / 2)))
    tgt = command_to_target([0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.02], frame=frame)
    np.testing.assert_allclose(tgt.p_world, [0.2, 0.1, 0.05], atol=1e-12)
    np.testing.assert_allclose(quat_to_euler(tgt.quat_world), [0.0, 0.0, math.pi / 2], atol=1e-12)
    assert tgt.jaw_sep_m == 0.02


@pytest.mark.parametrize("field", ["p", "quat", "v", "w"])
def test_nan_target_raises(field: str) -> None:
    kwargs = {"p": HOME.copy(), "quat": IDENTITY.copy(), "v": np.zeros(3), "w": np.zeros(3)}
    kwargs[field][0] = np.nan
    p, quat = kwargs.pop("p"), kwargs.pop("quat")
    names = {"p": "p_world", "quat": "quat_world", "v": "v_world", "w": "omega_body"}
    with pytest.raises(ValueError, match=names[field]):
        target(p, quat, **kwargs)


def test_target_arrays_are_private_and_read_only() -> None:
    p = HOME.copy()
    tgt = target(p)
    p[0] = 1.0
    assert tgt.p_world[0] == HOME[0]
    with pytest.raises(ValueError):
        tgt.p_world[0] = 0.0


# -- wrench-controlled axes ----------------------------------------------------------------------


def test_a_pose_target_regulates_no_wrench() -> None:
    tgt = target(HOME)
    assert not tgt.force_controlled
    assert not tgt.force_axes.any() and not tgt.moment_axes.any()
    assert tgt.wrench_axes.shape == (6,) and tgt.torque_world.shape == (3,)


def test_a_non_zero_force_flags_its_axis_as_before() -> None:
    tgt = target(HOME).with_force((0.0, 0.0, -3.0))
    assert tgt.force_controlled
    assert tgt.force_axes.tolist() == [False, False, True]
    assert not tgt.moment_axes.any()


def test_flagged_axes_may_ask_for_zero() -> None:
    """Zero moment about the tilt axes and zero lateral force: flagged, so regulated."""
    axes = (True, True, True, True, True, False)
    tgt = target(HOME).with_wrench((0.0, 0.0, -3.0), axes=axes)
    assert tgt.force_controlled
    assert tgt.force_axes.tolist() == [True, True, True]
    assert tgt.moment_axes.tolist() == [True, True, False]
    assert tgt.with_force((0.0, 0.0, -1.0)).wrench_axes.tolist() == list(axes)  # kept


def test_wrench_fields_are_validated() -> None:
    with pytest.raises(ValueError, match=r"torque_world must be finite"):
        GripperTarget(p_world=HOME, quat_world=IDENTITY, torque_world=(0.0, math.nan, 0.0))
    with pytest.raises(ValueError, match=r"wrench_axes must be 6 booleans \(fx, fy, fz, mx, my, mz\), got"):
        GripperTarget(p_world=HOME, quat_world=IDENTITY, wrench_axes=(True, False))
    with pytest.raises(ValueError, match=r"wrench_axes must be 6 booleans"):
        GripperTarget(p_world=HOME, quat_world=IDENTITY, wrench_axes=(0, 0, 2, 0, 0, 0))
    tgt = GripperTarget(p_world=HOME, quat_world=IDENTITY, wrench_axes=(0, 0, 1, 0, 0, 0))
    assert tgt.wrench_axes.dtype == bool and tgt.force_axes.tolist() == [False, False, True]
    with pytest.raises(ValueError):
        tgt.wrench_axes[0] = True  # read-only
