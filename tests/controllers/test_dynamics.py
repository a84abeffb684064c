"""Pinocchio's base dynamics agree with MuJoCo's, and building them leaves no files behind."""

from __future__ import annotations

import tempfile
from pathlib import Path

import mujoco
import numpy as np
import pytest

from peg_ctrl.controllers.dynamics import BaseDynamics, robot_mjcf, to_pinocchio_q
from peg_ctrl.controllers.impedance import ImpedanceController


def test_building_a_controller_leaves_no_temporary_files(
    model: mujoco.MjModel, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Temporary files go to this test's directory, where no other test (running at the same time
    # in another process) makes any.
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    made = []
    real = tempfile.TemporaryDirectory

    def recorded(*args, **kwargs):  # type: ignore[no-untyped-def]
        made.append(kwargs.get("prefix"))
        return real(*args, **kwargs)

    monkeypatch.setattr(tempfile, "TemporaryDirectory", recorded)
    ImpedanceController(model)
    assert made == ["peg_ctrl_robot_"]  # the robot's model was written to a temporary directory
    assert list(tmp_path.iterdir()) == []


def test_to_pinocchio_q_reorders_the_ball_quaternion() -> None:
    q = to_pinocchio_q(np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.4, 9.0]))
    np.testing.assert_array_equal(q, [1.0, 2.0, 3.0, 0.2, 0.3, 0.4, 0.1, 9.0])


def test_pinocchio_matches_mujoco_on_the_base_stack(tmp_path: Path) -> None:
    import pinocchio as pin

    mj = mujoco.MjModel.from_xml_path(str(robot_mjcf(tmp_path)))
    data = mujoco.MjData(mj)
    dyn = BaseDynamics()
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = mj.qpos0.copy()  # fingers open: see controllers.dynamics on joint offsets
        q[:3] = rng.uniform(-0.3, 0.3, 3)
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        v = np.zeros(mj.nv)
        v[:6] = rng.normal(size=6)
        data.qpos[:], data.qvel[:] = q, v
        mujoco.mj_forward(mj, data)
        m_full = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, data, m_full)
        np.testing.assert_allclose(dyn.mass_matrix(q[:3], q[3:7]), m_full[:6, :6], atol=1e-6)
        np.testing.assert_allclose(dyn.bias(q[:3], q[3:7], v[:3], v[3:6]), data.qfrc_bias[:6], atol=1e-6)
        jac_p, jac_r = np.zeros((3, mj.nv)), np.zeros((3, mj.nv))
        mujoco.mj_jacSite(mj, data, jac_p, jac_r, mj.site("2f85/pinch").id)
        np.testing.assert_allclose(
            dyn.pinch_jacobian(q[:3], q[3:7]), np.vstack([jac_p, jac_r])[:, :6], atol=1e-6
        )
        # The full model (fingers included) agrees too where the fingers are at rest and open.
        full = dyn.full_model
        m_pin = pin.crba(full, full.createData(), to_pinocchio_q(q))
        np.testing.assert_allclose(np.triu(m_pin)[:6, :6], np.triu(m_full)[:6, :6], atol=1e-6)
