"""The situations in Drake: the same rig on a discrete ``MultibodyPlant`` with point contact.

The block's convex parts are the very vertex sets the physics profile builds
(:func:`peg_ctrl.sim.assets.block_parts`), registered as ``Convex`` shapes at the block's pose;
the peg is a ``Cylinder`` of the same size welded to a free hand body with the rig's inertia;
gravity is off. Each contact is one point per pair of geometries (Drake's point contact): a
compliant Hunt-Crossley contact of ``stiffness`` [N/m] and ``dissipation`` [s/m] with Coulomb
friction, solved by SAP under one of its discrete approximations:

- ``lagged``: Hunt-Crossley with the friction bound taken from the previous step's normal force.
  Drake's documentation (``MultibodyPlant``, "Discrete model approximations") says that the convex
  ``sap`` and ``similar`` approximations "introduce a spurious effect of 'gliding' in sliding
  contact", and that ``lagged`` "does not suffer from this";
- ``similar``: the convex approximation of the same Hunt-Crossley model;
- ``sap``: SAP's own convex model (linear dissipation with a relaxation time).

Drake is an optional dependency: ``pip install 'peg-ctrl[crosscheck]'``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.assets import block_parts
from peg_ctrl.tools.crosscheck.rig import Rig
from peg_ctrl.tools.crosscheck.situations import Situation

__all__ = ["DrakeContact", "DrakeRig", "drake_available", "require_drake", "APPROXIMATIONS"]

APPROXIMATIONS = ("lagged", "similar", "sap")
_INSTALL = "pip install 'peg-ctrl[crosscheck]' (or: pip install drake)"


def drake_available() -> bool:
    """True where ``pydrake`` imports."""
    try:
        import pydrake.multibody.plant  # noqa: F401
    except ImportError:
        return False
    return True


def require_drake() -> None:
    """A one-line :class:`ConfigError` where Drake is not installed, saying how to install it."""
    if not drake_available():
        raise ConfigError(f"the cross-check needs Drake, which is not installed: {_INSTALL}")


@dataclasses.dataclass(frozen=True)
class DrakeContact:
    """Drake's contact model for the peg and the block (the combined values of a pair)."""

    approximation: str = "lagged"
    stiffness: float = 1.0e7  # point contact [N/m]
    dissipation: float = 0.3  # Hunt-Crossley [s/m]
    relaxation_time: float | None = None  # sap's linear dissipation [s]; None: Drake's default
    timestep: float = 0.5e-3  # [s]

    def __post_init__(self) -> None:
        if self.approximation not in APPROXIMATIONS:
            raise ConfigError(
                f"unknown Drake approximation {self.approximation!r}; known: {', '.join(APPROXIMATIONS)}"
            )


def _material(contact: DrakeContact, mu: float) -> Any:
    """One geometry's contact properties: with the other side's, the pair's ``contact``."""
    from pydrake.geometry import AddContactMaterial, ProximityProperties
    from pydrake.multibody.plant import CoulombFriction

    props = ProximityProperties()
    # Drake combines two geometries' stiffnesses in series and their dissipations weighted by
    # them: each side twice the stiffness makes the pair's the stated one.
    AddContactMaterial(
        dissipation=contact.dissipation,
        point_stiffness=2.0 * contact.stiffness,
        friction=CoulombFriction(mu, mu),
        properties=props,
    )
    if contact.relaxation_time is not None:
        props.AddProperty("material", "relaxation_time", contact.relaxation_time)
    return props


def _build(rig: Rig, s: Situation, contact: DrakeContact) -> tuple[Any, Any, Any, Any]:
    """The diagram (a discrete ``MultibodyPlant``, point contact, no gravity), the plant, the
    hand's body and the peg's, welded to it."""
    from pydrake.geometry import Convex, Cylinder
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
    from pydrake.multibody.tree import SpatialInertia, UnitInertia
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    config = MultibodyPlantConfig(
        time_step=contact.timestep,
        discrete_contact_approximation=contact.approximation,
        contact_model="point",
    )
    plant, _ = AddMultibodyPlant(config, builder)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    scene = rig.scene_for(s)
    x_block = RigidTransform(np.asarray(scene.block_pos))
    for i, part in enumerate(block_parts(rig.assets(s))):
        shape = Convex(np.ascontiguousarray(part.vertices.T), f"part{i}")
        plant.RegisterCollisionGeometry(
            plant.world_body(), x_block, shape, f"part{i}", _material(contact, s.friction)
        )
    unit = UnitInertia(*(np.asarray(rig.inertia) / rig.mass))
    hand = plant.AddRigidBody("hand", SpatialInertia(rig.mass, np.zeros(3), unit))
    radius, length = scene.assets.peg_radius, scene.assets.peg_length
    peg = plant.AddRigidBody(
        "peg", SpatialInertia.SolidCylinderWithDensity(scene.peg_density, radius, length, [0.0, 0.0, 1.0])
    )
    plant.WeldFrames(hand.body_frame(), peg.body_frame(), RigidTransform(rig.peg_centre_in_hand))
    plant.RegisterCollisionGeometry(
        peg, RigidTransform(), Cylinder(radius, length), "peg", _material(contact, s.friction)
    )
    plant.Finalize()
    return builder.Build(), plant, hand, peg


class DrakeRig:
    """The rig in Drake with ``contact``, at the situation's start."""

    def __init__(self, rig: Rig, s: Situation, contact: DrakeContact) -> None:
        require_drake()
        from pydrake.math import RigidTransform, RotationMatrix
        from pydrake.multibody.math import SpatialForce, SpatialVelocity
        from pydrake.multibody.plant import ExternallyAppliedSpatialForce
        from pydrake.systems.analysis import Simulator

        self._diagram, plant, hand, peg = _build(rig, s, contact)
        self._simulator = Simulator(self._diagram)
        self._plant = plant
        self._pctx = plant.GetMyMutableContextFromRoot(self._simulator.get_mutable_context())
        self._hand, self._peg = hand, peg
        self.dt = contact.timestep
        p0, r0 = rig.start_pose(s)
        plant.SetFreeBodyPose(self._pctx, hand, RigidTransform(RotationMatrix(r0), p0))
        plant.SetFreeBodySpatialVelocity(self._pctx, hand, SpatialVelocity(np.zeros(3), s.reference(0.0)[1]))
        self._spatial_force = SpatialForce
        self._applied = ExternallyAppliedSpatialForce()
        self._applied.body_index = hand.index()
        self._applied.p_BoBq_B = np.zeros(3)
        self._force_port = plant.get_applied_spatial_force_input_port()
        self._results_port = plant.get_contact_results_output_port()
        self._steps = 0
        self._end_in_hand = rig.end_in_hand

    def hand_state(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        x = self._plant.EvalBodyPoseInWorld(self._pctx, self._hand)
        v = self._plant.EvalBodySpatialVelocityInWorld(self._pctx, self._hand)
        return (
            x.translation().copy(),
            x.rotation().matrix().copy(),
            v.translational().copy(),
            v.rotational().copy(),
        )

    def apply(self, force: NDArray[np.float64], torque: NDArray[np.float64]) -> None:
        self._applied.F_Bq_W = self._spatial_force(torque, force)
        self._force_port.FixValue(self._pctx, [self._applied])

    def step(self) -> None:
        # Half a step past the next update's time: each call crosses exactly one discrete update,
        # whatever the rounding of the time (a sum of steps can land just past an update's time
        # and take two at once).
        self._steps += 1
        self._simulator.AdvanceTo((self._steps - 0.5) * self.dt)

    def contact(self) -> tuple[float, NDArray[np.float64], float, int]:
        results = self._results_port.Eval(self._pctx)
        peg = self._peg.index()
        normal, net, overlap = 0.0, np.zeros(3), 0.0
        n = results.num_point_pair_contacts()
        for k in range(n):
            info = results.point_pair_contact_info(k)
            f = info.contact_force()  # on body B, world frame
            pair = info.point_pair()
            normal += abs(float(np.dot(f, pair.nhat_BA_W)))
            net += f if info.bodyB_index() == peg else -f
            overlap = max(overlap, float(pair.depth))
        return normal, net, overlap, n

    def lower_end(self) -> NDArray[np.float64]:
        x = self._plant.EvalBodyPoseInWorld(self._pctx, self._hand)
        return np.asarray(x.multiply(self._end_in_hand))
