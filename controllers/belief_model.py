"""A MuJoCo model of the world as the task believes it, for planning through contact.

:func:`build_belief_model` makes a small model from a task's :class:`~peg_ctrl.sim.belief.Belief`
(everything that is *believed*: where the hole is, its size, how the peg sits in the hand) and
the hand's mass from the simulation's model (the controller's own robot):

- the block as the task's drawing has it (hole radius, chamfer, extents), its hole where the task
  believes it is, made of ``parts`` convex parts (fewer than the simulation's: a polygon whose
  corners stand a little further out than its flats, which is quicker to collide with);
- a *hand*: one rigid body on six joints whose origin is the held peg's lower end — three slides
  along world x, y, z and three hinges about world x, y, z through that point — with the hand's
  mass and its inertia about the tip, carrying the peg in the believed grasp;
- the compliant inner loop that executes a plan, as position actuators on those joints: their
  ``kp`` and ``kv`` are the inner impedance's stiffness and damping about the tip, so a control
  is a setpoint of the tip's position and of its turn about the tip;
- force and torque sensors between the hand and the peg at the tip: the contact's wrench about
  the tip, as the wrist sensor would report it about the same point.

No gravity: the inner loop compensates the hand's weight, and the peg's 16 g are below what the
plan cares about. The contact parameters are the ``precision`` profile's, at the belief model's
own (larger) timestep, with one sliding friction coefficient the planner assumes for the parts
(``friction``): the controller does not know the scene's materials.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.assets import AssetParams, block_parts
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.rotations import rotate

__all__ = ["BeliefModelSpec", "build_belief_model", "HAND_JOINTS"]

HAND_JOINTS = ("tip_x", "tip_y", "tip_z", "turn_x", "turn_y", "turn_z")


@dataclasses.dataclass(frozen=True)
class BeliefModelSpec:
    """How to build the belief model: timestep [s], friction, the inner loop's gains about the
    tip (``kp`` (6,) [N/m, N m/rad], ``kv`` (6,) [N s/m, N m s/rad]) and the hand's joint damping
    left after the inner loop's compensation (6,)."""

    timestep: float
    friction: float
    kp: tuple[float, ...]
    kv: tuple[float, ...]
    damping: tuple[float, ...]
    parts: int = 24
    # The hole's parts end this far outside the mouth, the rest of the block is four slabs
    # (AssetParams.hole_ring): a rollout's landing on the face touches one slab, not a fan of
    # parts. None: the parts reach the block's walls.
    ring_wall: float | None = 0.003


def _hand_inertia(model: mujoco.MjModel, tip_body: NDArray[np.float64]) -> tuple[float, float]:
    """Mass [kg] and rotational inertia about the tip [kg m^2] of the gripper on its joints."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    slide = model.joint("gripper_transX").dofadr[0]
    ball = model.joint("gripper_rot").dofadr[0]
    mass = float(full[slide, slide])
    inertia = float(np.mean(np.diag(full)[ball : ball + 3])) + mass * float(tip_body @ tip_body)
    return mass, inertia


def build_belief_model(
    model: mujoco.MjModel,
    belief: Belief | None,
    quat_ref: NDArray[np.float64],
    spec: BeliefModelSpec,
    *,
    tip_body: NDArray[np.float64] | None = None,
) -> mujoco.MjModel:
    """The belief model (see the module docstring) with the hand at its reference orientation
    ``quat_ref`` (the gripper's, world): at zero hinge angles the peg is as the belief holds it
    in a gripper turned by ``quat_ref``. Without a belief (a task that states none) the model is
    the hand alone, its origin at ``tip_body`` (gripper frame), in free space."""
    s = mujoco.MjSpec()
    s.modelname = "belief"
    s.compiler.degree = False
    opt = s.option
    opt.timestep = spec.timestep
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    opt.iterations = 20
    opt.tolerance = 1e-8
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.impratio = 10.0
    opt.gravity = [0.0, 0.0, 0.0]
    opt.ccd_tolerance = 1e-9
    opt.ccd_iterations = 100

    parts = _add_block(s, belief, spec) if belief is not None else []
    _add_hand(s, model, belief, quat_ref, spec, tip_body)
    for name in parts:
        pair = s.add_pair()
        pair.geomname1, pair.geomname2 = "peg", name
        pair.condim = 3
        pair.friction = [spec.friction, spec.friction, 0.0, 0.0, 0.0]
        pair.solref = [0.001, 1.0]
        pair.solimp = [0.99, 0.999, 1e-4, 0.5, 2.0]
    return s.compile()


def _add_block(s: mujoco.MjSpec, belief: Belief, spec: BeliefModelSpec) -> list[str]:
    """The block as drawn, with the hole where the task believes it is; its parts' names."""
    params = AssetParams(
        peg_radius=belief.peg_radius,
        peg_length=belief.peg_length,
        clearance=belief.hole_radius - belief.peg_radius,
        block_size=belief.block_size,
        n_parts=spec.parts,
        chamfer=belief.chamfer,
        contact_margin=0.0,
    )
    if spec.ring_wall is not None:
        mouth = params.hole_circumradius + params.chamfer / np.cos(np.pi / params.n_parts)
        params = dataclasses.replace(params, hole_ring=mouth + spec.ring_wall)
    block = s.worldbody.add_body()
    block.name = "block"
    block.pos = [belief.hole_xy[0], belief.hole_xy[1], belief.face_z - 0.5 * belief.block_size[2]]
    parts = []
    for i, part in enumerate(block_parts(params)):
        mesh = s.add_mesh()
        mesh.name = f"part{i}"
        mesh.uservert = part.vertices.ravel().tolist()
        mesh.userface = part.faces.ravel().tolist()
        geom = block.add_geom()
        geom.name = mesh.name
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = mesh.name
        geom.contype = 0
        geom.conaffinity = 0
        parts.append(geom.name)
    return parts


def _add_hand(
    s: mujoco.MjSpec,
    model: mujoco.MjModel,
    belief: Belief | None,
    quat_ref: NDArray[np.float64],
    spec: BeliefModelSpec,
    tip_body: NDArray[np.float64] | None,
) -> None:
    """The hand on six joints through the tip, carrying the peg (when there is a belief)."""
    if belief is not None:
        tip_body = np.asarray(belief.tip_body, dtype=float)
    tip_body = np.zeros(3) if tip_body is None else np.asarray(tip_body, dtype=float)
    mass, inertia = _hand_inertia(model, tip_body)
    hand = s.worldbody.add_body()
    hand.name = "hand"
    hand.ipos = [0.0, 0.0, 0.0]
    hand.mass = mass
    hand.inertia = [inertia, inertia, inertia]
    hand.explicitinertial = True
    for i, name in enumerate(HAND_JOINTS):
        joint = hand.add_joint()
        joint.name = name
        joint.type = mujoco.mjtJoint.mjJNT_SLIDE if i < 3 else mujoco.mjtJoint.mjJNT_HINGE
        joint.axis = np.eye(3)[i % 3].tolist()
        joint.damping = [spec.damping[i], 0.0, 0.0]
    peg = hand.add_body()
    peg.name = "peg"
    site = peg.add_site()
    site.name = "tip"
    for i, name in enumerate(HAND_JOINTS):
        act = s.add_actuator()
        act.name = name
        act.target = name
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_position(kp=spec.kp[i], kv=spec.kv[i])
    for kind, name in ((mujoco.mjtSensor.mjSENS_FORCE, "force"), (mujoco.mjtSensor.mjSENS_TORQUE, "torque")):
        sensor = s.add_sensor()
        sensor.name = name
        sensor.type = kind
        sensor.objtype = mujoco.mjtObj.mjOBJ_SITE
        sensor.objname = "tip"
    if belief is None:
        peg.mass = 1e-3
        peg.inertia = [1e-8, 1e-8, 1e-8]
        peg.explicitinertial = True
        return
    axis_world = rotate(quat_ref, np.asarray(belief.axis_body, dtype=float))
    radius, half = belief.peg_radius, 0.5 * belief.peg_length
    quat = np.empty(4)
    mujoco.mju_quatZ2Vec(quat, axis_world)
    peg.quat = quat.tolist()
    geom = peg.add_geom()
    geom.name = "peg"
    geom.type = mujoco.mjtGeom.mjGEOM_CYLINDER
    geom.size = [radius, half, 0.0]
    geom.pos = [0.0, 0.0, half]
    geom.mass = 1e-3  # the hand carries the mass
    geom.contype = 0
    geom.conaffinity = 0
