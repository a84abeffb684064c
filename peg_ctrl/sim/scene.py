"""Assemble the peg-in-hole scene with ``mujoco.MjSpec``.

Layout (world frame, Z up, metres):

- a table plane at z = 0;
- a static block (``block``) whose hole axis passes through ``SceneConfig.hole_xy``; one visual
  mesh (non-colliding) and ``n_parts`` convex collision meshes ``object_01`` .. ``object_NN``;
- a free peg (``peg``) lying on the table, its axis along world Y (rotated 90 degrees about X);
- the Menagerie Robotiq 2F-85 attached under body ``gripper_root``, which moves on three slide
  joints and a ball joint (SPEC §3.2).

The ball joint's centre is the gripper's ``pinch`` site, so the slide coordinates *are* the pinch
point's world position and rotations turn a grasped object about the grasp point. In the home
orientation (ball joint at identity) the fingers point down (-Z) and the jaw closes along world X.

Contact override (SPEC §3.4): ``opt.o_solref`` and ``opt.o_solimp`` are stored, but MuJoCo applies
them only when the ``override`` enable flag is set, and then to *every* contact, replacing all
per-geom ``solref``/``solimp``. Since the per-geom values of the peg, block and pads must govern
their contacts, the flag stays off; ``SceneConfig.contact_override=True`` turns it on for studies.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import mujoco
import numpy as np

from peg_ctrl.errors import ConfigError
from peg_ctrl.io import atomic_write_bytes, atomic_write_text
from peg_ctrl.sim.assets import AssetParams, ensure_assets, part_name
from peg_ctrl.sim.menagerie import gripper_xml
from peg_ctrl.sim.physics import SEED, PhysicsProfile, profile

__all__ = [
    "SceneConfig",
    "check_scene",
    "build_spec",
    "build_model",
    "add_fixture",
    "export_scene",
    "SLIDE_JOINTS",
    "BALL_JOINT",
    "SLIDE_ACTUATORS",
    "BALL_ACTUATORS",
    "JAW_ACTUATOR",
    "PINCH_SITE",
    "GRIPPER_PREFIX",
    "HOME_KEY",
    "contact_sensor_name",
    "FT_SITE",
    "build_robot_spec",
    "export_robot",
]

SLIDE_JOINTS = ("gripper_transX", "gripper_transY", "gripper_transZ")
BALL_JOINT = "gripper_rot"
SLIDE_ACTUATORS = ("act_transX", "act_transY", "act_transZ")
BALL_ACTUATORS = ("act_rotX", "act_rotY", "act_rotZ")
GRIPPER_PREFIX = "2f85/"  # prefix of every name that comes from the Menagerie model
JAW_ACTUATOR = GRIPPER_PREFIX + "fingers_actuator"
PINCH_SITE = GRIPPER_PREFIX + "pinch"
FT_SITE = "ft_sensor"
HOME_KEY = "home"

# Pinch site height above the Menagerie model's own world origin: base_mount at 0.007, base at
# +0.0038, pinch at +0.145 along the approach axis (values from 2f85.xml).
_PINCH_IN_MENAGERIE = 0.007 + 0.0038 + 0.145


@dataclasses.dataclass(frozen=True)
class SceneConfig:
    """Everything that changes the compiled model. Lengths in [m], angles in [rad]."""

    assets: AssetParams = AssetParams()
    hole_xy: tuple[float, float] = (0.20, 0.0)  # hole axis position on the table [m]
    peg_xy: tuple[float, float] = (-0.20, 0.0)  # peg centre at rest [m]
    gripper_home: tuple[float, float, float] = (-0.20, 0.0, 0.20)  # pinch point at home [m]
    jaw_home_byte: float = 0.0  # jaw actuator command at home (0 = open)
    slide_force_limit: float = 100.0  # per-axis slide actuator force range [N]
    ball_torque_limit: float = 80.0  # per-axis ball-joint torque range [N m]
    peg_density: float = 500.0  # [kg/m^3]
    block_density: float = 1000.0  # [kg/m^3] (block is static; kept for the record)
    peg_friction: tuple[float, float, float] = (0.8, 0.1, 1e-4)
    block_friction: tuple[float, float, float] = (0.9, 0.1, 1e-4)
    # One sliding friction coefficient for the peg and the block, replacing the first entry of
    # both (a grid axis of a study: scene.friction: [0.3, 0.9]); None: theirs as given.
    friction: float | None = None
    contact_override: bool = False  # see module docstring

    def __post_init__(self) -> None:
        for name in ("slide_force_limit", "ball_torque_limit", "peg_density", "block_density"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"SceneConfig.{name} must be finite and > 0, got {value!r}")
        if self.friction is not None and not (
            isinstance(self.friction, (int, float)) and np.isfinite(self.friction) and self.friction > 0
        ):
            raise ValueError(f"SceneConfig.friction must be finite and > 0 (or null), got {self.friction!r}")
        if not 0.0 <= self.jaw_home_byte <= 255.0:
            raise ValueError(f"SceneConfig.jaw_home_byte must be in [0, 255], got {self.jaw_home_byte!r}")

    @property
    def peg_friction_used(self) -> tuple[float, float, float]:
        """The peg's friction triple with ``friction`` applied."""
        f = self.peg_friction
        return f if self.friction is None else (float(self.friction), f[1], f[2])

    @property
    def block_friction_used(self) -> tuple[float, float, float]:
        """The block's friction triple with ``friction`` applied."""
        f = self.block_friction
        return f if self.friction is None else (float(self.friction), f[1], f[2])

    @property
    def block_pos(self) -> tuple[float, float, float]:
        """Block centre [m]: the block stands on the table."""
        return (self.hole_xy[0], self.hole_xy[1], 0.5 * self.assets.block_size[2])

    @property
    def peg_rest_pos(self) -> tuple[float, float, float]:
        """Peg centre lying on the table [m]."""
        return (self.peg_xy[0], self.peg_xy[1], self.assets.peg_radius)


TABLE_FRICTION = 1.0  # the table's sliding friction: MuJoCo's default (SPEC is silent)

# 90 degrees about X: the peg's axis (local Z) lies along world -Y.
PEG_LYING_QUAT = (np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0)


def _set_physics_options(spec: mujoco.MjSpec, cfg: SceneConfig, physics: PhysicsProfile) -> None:
    opt = spec.option
    physics.apply_options(opt)
    opt.o_solref = [0.005, 0.9]
    opt.o_solimp = [0.9, 0.9, 0.01, 0.5, 2.0]
    if cfg.contact_override:
        opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_OVERRIDE)


def _add_mesh(spec: mujoco.MjSpec, name: str, path: Path) -> None:
    mesh = spec.add_mesh()
    mesh.name = name
    mesh.file = str(path)


def _add_table(spec: mujoco.MjSpec) -> None:
    tex = spec.add_texture()
    tex.name = "grid"
    tex.type = mujoco.mjtTexture.mjTEXTURE_2D
    tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_CHECKER
    tex.rgb1 = [0.32, 0.35, 0.38]
    tex.rgb2 = [0.28, 0.30, 0.33]
    tex.width = 512
    tex.height = 512
    mat = spec.add_material()
    mat.name = "table"
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "grid"
    mat.texrepeat = [8, 8]
    table = spec.worldbody.add_geom()
    table.name = "table"
    table.type = mujoco.mjtGeom.mjGEOM_PLANE
    table.size = [1.0, 1.0, 0.05]
    table.material = "table"
    table.friction = [TABLE_FRICTION, 0.005, 0.0001]  # MuJoCo's default, stated (SPEC is silent)
    # Not given by SPEC; as stiff as the peg's own contact so a dropped peg does not sink in.
    table.solref = [0.005, 1.0]
    table.solimp = [0.9, 0.95, 0.001, 0.5, 2.0]


def _add_block(
    spec: mujoco.MjSpec, cfg: SceneConfig, assets: AssetParams, files: dict[str, Path]
) -> list[str]:
    """The block and its collision parts; returns the parts' geom names."""
    _add_mesh(spec, "block_visual", files["block_visual"])
    block = spec.worldbody.add_body()
    block.name = "block"
    block.pos = list(cfg.block_pos)
    visual = block.add_geom()
    visual.name = "block_visual"
    visual.type = mujoco.mjtGeom.mjGEOM_MESH
    visual.meshname = "block_visual"
    visual.contype = 0
    visual.conaffinity = 0
    visual.group = 2
    visual.density = 0.0
    visual.rgba = [0.55, 0.42, 0.30, 1.0]
    parts = []
    for i in range(assets.part_count):
        name = part_name(i)
        parts.append(name)
        _add_mesh(spec, name, files[name])
        geom = block.add_geom()
        geom.name = name
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = name
        geom.group = 3
        geom.density = cfg.block_density
        geom.friction = list(cfg.block_friction_used)
        geom.condim = 6
        # Contacts turn active within the margin; the hole is widened by the same amount
        # (AssetParams.contact_margin) so the effective clearance is the stated one.
        geom.margin = assets.contact_margin
        geom.solref = [0.01, 1.0]
        geom.solimp = [0.9, 0.95, 0.001, 0.5, 2.0]
        geom.rgba = [0.55, 0.42, 0.30, 0.4]
    site = block.add_site()
    site.name = "hole_top"
    site.pos = [0.0, 0.0, 0.5 * cfg.assets.block_size[2]]
    site.size = [0.002, 0.002, 0.002]
    site.group = 5
    return parts


def _add_peg(spec: mujoco.MjSpec, cfg: SceneConfig, physics: PhysicsProfile, files: dict[str, Path]) -> None:
    peg = spec.worldbody.add_body()
    peg.name = "peg"
    peg.pos = list(cfg.peg_rest_pos)
    peg.quat = list(PEG_LYING_QUAT)
    joint = peg.add_freejoint()
    joint.name = "peg_free"
    geom = peg.add_geom()
    geom.name = "peg"
    if physics.peg_geom == "cylinder":
        geom.type = mujoco.mjtGeom.mjGEOM_CYLINDER
        geom.size = [cfg.assets.peg_radius, 0.5 * cfg.assets.peg_length, 0.0]
    else:
        _add_mesh(spec, "peg", files["peg"])
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = "peg"
    geom.density = cfg.peg_density
    geom.friction = list(cfg.peg_friction_used)
    geom.condim = 6
    geom.solref = [0.005, 1.0]
    geom.solimp = [0.9, 0.95, 0.001, 0.5, 2.0]
    geom.rgba = [0.20, 0.45, 0.80, 1.0]
    half = 0.5 * cfg.assets.peg_length
    for name, z in (("peg_bottom", -half), ("peg_top", half)):
        site = peg.add_site()
        site.name = name
        site.pos = [0.0, 0.0, z]
        site.size = [0.002, 0.002, 0.002]
        site.group = 5


def _add_peg_pairs(spec: mujoco.MjSpec, cfg: SceneConfig, physics: PhysicsProfile, parts: list[str]) -> None:
    """Explicit peg-part and peg-table contact pairs with the profile's parameters (instead of
    mixing the peg's and the block's per-geom values, which also govern the grasp)."""
    c = physics.pair
    if c is None:
        return
    mu = max(cfg.peg_friction_used[0], cfg.block_friction_used[0])
    partners = [(part, mu) for part in parts]
    partners.append(("table", max(cfg.peg_friction_used[0], TABLE_FRICTION)))
    for body in ("block", "world"):  # the table is a world geom
        exclude = spec.add_exclude()
        exclude.bodyname1, exclude.bodyname2 = "peg", body
    for geom, mu in partners:
        pair = spec.add_pair()
        pair.name = f"peg-{geom}"
        pair.geomname1, pair.geomname2 = "peg", geom
        pair.condim = c.condim
        pair.friction = [mu, mu, 0.0, 0.0, 0.0]
        pair.solref = list(c.solref)
        pair.solimp = list(c.solimp)
        if c.solreffriction is not None:
            pair.solreffriction = list(c.solreffriction)
        pair.margin = c.margin


def _add_gripper(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    """The 6-DoF base (three slides, a ball joint), the Menagerie gripper hung from it, and the
    base's actuators."""
    root = _add_base(spec)
    _hang_gripper(spec, root)
    _add_base_actuators(spec, cfg)


def _add_base(spec: mujoco.MjSpec) -> mujoco.MjsBody:
    root = spec.worldbody.add_body()
    root.name = "gripper_root"
    # An explicit inertial needs its position too: MjSpec's default ``ipos`` is NaN ("unset"),
    # which the compiler takes as the body origin but ``to_xml`` answers by dropping the inertial.
    root.ipos = [0.0, 0.0, 0.0]
    root.mass = 0.1
    root.inertia = [0.01, 0.01, 0.01]
    root.explicitinertial = True
    for name, axis in zip(SLIDE_JOINTS, np.eye(3), strict=True):
        joint = root.add_joint()
        joint.name = name
        joint.type = mujoco.mjtJoint.mjJNT_SLIDE
        joint.axis = list(axis)
        joint.range = [-10.0, 10.0]
        joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        joint.damping = [100.0, 0.0, 0.0]
    ball = root.add_joint()
    ball.name = BALL_JOINT
    ball.type = mujoco.mjtJoint.mjJNT_BALL
    ball.damping = [50.0, 0.0, 0.0]
    ball.stiffness = [0.0, 0.0, 0.0]
    ball.armature = 0.1
    return root


def _hang_gripper(spec: mujoco.MjSpec, root: mujoco.MjsBody) -> None:
    # Hang the gripper upside down (180 degrees about X) so the pinch site sits at the origin.
    # A massless welded body (not an MJCF frame) so that other MJCF readers (Pinocchio) follow.
    mount = root.add_body()
    mount.name = "gripper_mount"
    mount.quat = [0.0, 1.0, 0.0, 0.0]
    mount.pos = [0.0, 0.0, _PINCH_IN_MENAGERIE]
    ft = mount.add_site()
    ft.name = FT_SITE  # simulated 6-axis force/torque sensor between the base and the gripper
    ft.size = [0.005, 0.005, 0.005]
    ft.group = 5
    frame = mount.add_frame()
    gripper = mujoco.MjSpec.from_file(str(gripper_xml()))
    # The scene's solver options govern; align the child's so attaching does not warn.
    gripper.option.impratio = spec.option.impratio
    gripper.option.cone = spec.option.cone
    meshdir = Path(gripper.modelfiledir) / gripper.meshdir
    for mesh in gripper.meshes:
        mesh.file = str((meshdir / mesh.file).resolve())
    frame.attach_body(gripper.body("base_mount"), GRIPPER_PREFIX, "")
    # The child's tendon, equalities, excludes and actuator come along with the attached body.


def _add_base_actuators(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    gear_axes = np.eye(3)
    for name, joint_name in zip(SLIDE_ACTUATORS, SLIDE_JOINTS, strict=True):
        act = spec.add_actuator()
        act.name = name
        act.target = joint_name
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.ctrlrange = [-cfg.slide_force_limit, cfg.slide_force_limit]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    for name, axis in zip(BALL_ACTUATORS, gear_axes, strict=True):
        act = spec.add_actuator()
        act.name = name
        act.target = BALL_JOINT
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.gear = [*axis, 0.0, 0.0, 0.0]
        act.ctrlrange = [-cfg.ball_torque_limit, cfg.ball_torque_limit]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE


def _add_cameras_and_lights(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    light = spec.worldbody.add_light()
    light.pos = [0.0, -0.3, 1.2]
    light.dir = [0.0, 0.2, -1.0]
    light.castshadow = True
    hx, hy = cfg.hole_xy
    # Look at the hole mouth from the side the fingers point to after the turn (+Y), so the
    # gripper's body (towards -Y) does not hide the insertion.
    _add_look_at_camera(
        spec, "insertion", eye=(hx + 0.20, hy + 0.30, 0.20), target=(hx - 0.02, hy, 0.06), fovy=50.0
    )
    _add_look_at_camera(spec, "overview", eye=(0.0, -0.75, 0.45), target=(0.0, 0.0, 0.08), fovy=45.0)


def _add_look_at_camera(
    spec: mujoco.MjSpec,
    name: str,
    *,
    eye: tuple[float, float, float],
    target: tuple[float, float, float],
    fovy: float,
) -> None:
    """A fixed camera at ``eye`` [m] looking at ``target`` [m], world Z up."""
    forward = np.subtract(target, eye)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    quat = np.zeros(4)
    # A MuJoCo camera looks along its -Z with +Y up.
    mujoco.mju_mat2Quat(quat, np.column_stack([right, up, -forward]).flatten())
    cam = spec.worldbody.add_camera()
    cam.name = name
    cam.pos = list(eye)
    cam.quat = list(quat)
    cam.fovy = fovy


# How each body group is named to a contact sensor: (object type, name).
_GROUP_OBJECTS = {
    "gripper": (mujoco.mjtObj.mjOBJ_XBODY, "gripper_root"),  # the whole subtree
    "peg": (mujoco.mjtObj.mjOBJ_BODY, "peg"),
    "block": (mujoco.mjtObj.mjOBJ_BODY, "block"),
    "table": (mujoco.mjtObj.mjOBJ_GEOM, "table"),
}
#: The finger-pad bodies of the 2F-85 (without the ``2f85/`` prefix), left then right.
PAD_BODIES = ("left_pad", "right_pad")
_CON_FOUND, _CON_FORCE, _CON_DIST = 1, 2, 8  # mjtConDataField bits
_REDUCE_MINDIST, _REDUCE_NETFORCE = 1, 3


def contact_sensor_name(kind: str, first: str, second: str) -> str:
    """Name of the ``kind`` ("force" or "dist") contact sensor between two body groups."""
    return f"contact_{kind}/{first}-{second}"


def _add_ft_sensor(spec: mujoco.MjSpec) -> None:
    """Force and torque at the gripper mount, in the ``ft_sensor`` site frame (gripper frame
    turned 180 degrees about X): what the base exerts on the gripper below it."""
    for kind, sensor_type in (
        ("force", mujoco.mjtSensor.mjSENS_FORCE),
        ("torque", mujoco.mjtSensor.mjSENS_TORQUE),
    ):
        sensor = spec.add_sensor()
        sensor.name = f"ft_{kind}"
        sensor.type = sensor_type
        sensor.objtype = mujoco.mjtObj.mjOBJ_SITE
        sensor.objname = FT_SITE


def _add_contact_sensors(spec: mujoco.MjSpec) -> None:
    """Net contact force per body-group pair and the closest contact on the peg, computed in C.

    A ``force`` sensor for the pair (first, second) reports the net force [N] that ``second``
    exerts on ``first`` in the world frame (MuJoCo reports object 1's force on object 2).
    """
    groups = list(_GROUP_OBJECTS)
    pairs = sorted(tuple(sorted((a, b))) for i, a in enumerate(groups) for b in groups[i + 1 :])
    for first, second in pairs:
        if {first, second} == {"block", "table"}:
            continue  # both static: MuJoCo never collides them
        sensor = spec.add_sensor()
        sensor.name = contact_sensor_name("force", first, second)
        sensor.type = mujoco.mjtSensor.mjSENS_CONTACT
        sensor.objtype, sensor.objname = _GROUP_OBJECTS[second]
        sensor.reftype, sensor.refname = _GROUP_OBJECTS[first]
        sensor.intprm = [_CON_FOUND | _CON_FORCE, _REDUCE_NETFORCE, 1]
    for other in ("block", "gripper", "table"):
        first, second = sorted(("peg", other))
        sensor = spec.add_sensor()
        sensor.name = contact_sensor_name("dist", first, second)
        sensor.type = mujoco.mjtSensor.mjSENS_CONTACT
        sensor.objtype, sensor.objname = _GROUP_OBJECTS["peg"]
        sensor.reftype, sensor.refname = _GROUP_OBJECTS[other]
        sensor.intprm = [_CON_FOUND | _CON_DIST, _REDUCE_MINDIST, 1]
    # Each finger pad on the peg: the grip (squeeze) is half their difference, which the net
    # gripper-peg force cancels (StateReader.grip_sensors).
    for pad in PAD_BODIES:
        sensor = spec.add_sensor()
        sensor.name = contact_sensor_name("force", pad, "peg")
        sensor.type = mujoco.mjtSensor.mjSENS_CONTACT
        sensor.objtype, sensor.objname = _GROUP_OBJECTS["peg"]
        sensor.reftype, sensor.refname = mujoco.mjtObj.mjOBJ_BODY, f"{GRIPPER_PREFIX}{pad}"
        sensor.intprm = [_CON_FOUND | _CON_FORCE, _REDUCE_NETFORCE, 1]


def _add_home_key(spec: mujoco.MjSpec, model: mujoco.MjModel, cfg: SceneConfig) -> None:
    qpos = model.qpos0.copy()
    for name, value in zip(SLIDE_JOINTS, cfg.gripper_home, strict=True):
        qpos[model.joint(name).qposadr[0]] = value
    ball = model.joint(BALL_JOINT).qposadr[0]
    qpos[ball : ball + 4] = [1.0, 0.0, 0.0, 0.0]
    ctrl = np.zeros(model.nu)
    ctrl[model.actuator(JAW_ACTUATOR).id] = cfg.jaw_home_byte
    key = spec.add_key()
    key.name = HOME_KEY
    key.qpos = list(qpos)
    key.ctrl = list(ctrl)


def build_spec(cfg: SceneConfig | None = None, physics: str | PhysicsProfile = SEED) -> mujoco.MjSpec:
    """The scene as an editable ``MjSpec`` (with a ``home`` keyframe), built by the physics
    profile ``physics`` (see :mod:`peg_ctrl.sim.physics`)."""
    cfg = cfg or SceneConfig()
    physics = profile(physics)
    assets = physics.assets(cfg.assets)
    files = ensure_assets(assets)
    spec = mujoco.MjSpec()
    spec.modelname = "peg_in_hole"
    spec.compiler.degree = False
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 720
    _set_physics_options(spec, cfg, physics)
    add_fixture(spec, cfg, physics, files)
    _add_peg(spec, cfg, physics, files)
    _add_gripper(spec, cfg)
    _add_cameras_and_lights(spec, cfg)
    _add_contact_sensors(spec)
    _add_ft_sensor(spec)
    model = spec.compile()
    _add_home_key(spec, model, cfg)
    return spec


def add_fixture(
    spec: mujoco.MjSpec, cfg: SceneConfig, physics: PhysicsProfile, files: dict[str, Path] | None = None
) -> list[str]:
    """The table, the block with its collision parts as ``physics`` builds them, and the peg's
    contact pairs with them; returns the parts' geom names. The peg itself, a body ``peg`` with
    a geom ``peg``, is the caller's (the scene's free peg, or a rig's held one). ``files``: the
    assets ``ensure_assets`` wrote for ``physics.assets(cfg.assets)``, if already at hand."""
    files = files if files is not None else ensure_assets(physics.assets(cfg.assets))
    _add_table(spec)
    parts = _add_block(spec, cfg, physics.assets(cfg.assets), files)
    _add_peg_pairs(spec, cfg, physics, parts)
    return parts


def build_model(cfg: SceneConfig | None = None, physics: str | PhysicsProfile = SEED) -> mujoco.MjModel:
    """Compile the scene. The ``home`` keyframe holds the initial state."""
    return build_spec(cfg, physics).compile()


def build_robot_spec(cfg: SceneConfig | None = None) -> mujoco.MjSpec:
    """Only the base stack and the gripper (no table, peg, block, sensors or keyframes): the
    robot model for other dynamics libraries (Pinocchio)."""
    cfg = cfg or SceneConfig()
    spec = mujoco.MjSpec()
    spec.modelname = "peg_ctrl_robot"
    spec.compiler.degree = False
    _set_physics_options(spec, cfg, SEED)
    _add_gripper(spec, cfg)
    return spec


def export_robot(out_dir: Path, cfg: SceneConfig | None = None) -> Path:
    """Write the robot-only model as ``out_dir/robot.xml`` (meshes referenced by absolute path)."""
    spec = build_robot_spec(cfg)
    model = spec.compile()
    # Write every body's compiled inertial explicitly: MuJoCo derives some from mesh geoms,
    # which other readers cannot do.
    for body in spec.bodies:
        if body.name == "world" or not body.name:
            continue
        b = model.body(body.name)
        body.mass = float(b.mass[0])
        body.ipos = b.ipos.tolist()
        body.explicitinertial = True
        if body.mass == 0.0:  # the welded mount: say so, rather than let a reader pick a default
            body.inertia = [0.0, 0.0, 0.0]
            continue
        # Full tensor in the body frame (no inertial quaternion: not every reader applies it).
        flat = np.zeros(9)
        mujoco.mju_quat2Mat(flat, b.iquat)
        rot = flat.reshape(3, 3)
        tensor = rot @ np.diag(b.inertia) @ rot.T
        body.iquat = [1.0, 0.0, 0.0, 0.0]
        body.inertia = [0.0, 0.0, 0.0]
        body.fullinertia = [
            tensor[0, 0],
            tensor[1, 1],
            tensor[2, 2],
            tensor[0, 1],
            tensor[0, 2],
            tensor[1, 2],
        ]
        body.explicitinertial = True
    spec.compile()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "robot.xml"
    atomic_write_text(path, spec.to_xml())
    return path


def export_scene(out_dir: Path, cfg: SceneConfig | None = None, physics: str | PhysicsProfile = SEED) -> Path:
    """Write ``out_dir/scene.xml`` plus its meshes under ``out_dir/meshes``.

    The result loads with plain ``mujoco.MjModel.from_xml_path`` and opens in MuJoCo's own viewer.
    """
    import xml.etree.ElementTree as ET

    spec = build_spec(cfg, physics)
    out_dir = Path(out_dir)
    mesh_dir = out_dir / "meshes"
    mesh_dir.mkdir(parents=True, exist_ok=True)
    # Serialise with absolute mesh paths (the spec compiles), then point them at local copies.
    root = ET.fromstring(spec.to_xml())
    for elem in root.iter("mesh"):
        src = elem.get("file")
        if src is None:
            continue
        dst_name = (elem.get("name") or Path(src).stem).replace("/", "_") + Path(src).suffix
        atomic_write_bytes(mesh_dir / dst_name, Path(src).read_bytes())
        elem.set("file", dst_name)
    compiler = root.find("compiler")
    if compiler is None:
        compiler = ET.Element("compiler")
        root.insert(0, compiler)
    compiler.set("meshdir", "meshes")
    path = out_dir / "scene.xml"
    ET.indent(root)
    atomic_write_text(path, ET.tostring(root, encoding="unicode") + "\n")
    mujoco.MjModel.from_xml_path(str(path))  # fail here, not in the user's viewer
    return path


def check_scene(name: str | PhysicsProfile, scene: SceneConfig) -> None:
    """Reject scene fields that the profile sets or that would override it, rather than let
    them be ignored (or ignore the profile) silently."""
    prof = profile(name)
    assets = scene.assets
    default = AssetParams()
    if prof.pair is not None and scene.contact_override:
        raise ConfigError(
            f"scene.contact_override: would replace physics.profile={prof.name}'s contact "
            "parameters with opt.o_solref/o_solimp; use it with physics.profile=seed"
        )
    if prof.contact_margin is not None and assets.contact_margin != default.contact_margin:
        raise ConfigError(
            f"scene.assets.contact_margin: set by physics.profile={prof.name} "
            f"({prof.contact_margin} m); leave it out or use physics.profile=seed"
        )
    if prof.hole_play_tolerance is not None and assets.n_parts != default.n_parts:
        raise ConfigError(
            f"scene.assets.n_parts: set by physics.profile={prof.name} (a round peg's play within "
            f"{prof.hole_play_tolerance * 1e6:g} um of a round hole's); leave it out or use "
            "physics.profile=seed"
        )
    if prof.hole_ring_wall is not None and assets.hole_ring is not None:
        raise ConfigError(
            f"scene.assets.hole_ring: set by physics.profile={prof.name}; leave it out or use "
            "physics.profile=seed"
        )
