"""What a task believes about the world: the record it hands to controllers that plan on a model.

A task knows things a controller does not: where it thinks the hole is, and how the peg sits
in the hand (the nominal grasp, or what a calibration found). A controller that plans through
contact on a model of the world (``sampling_mpc``) builds that model from this belief — never
from the simulation's true state. The loop passes the task's :class:`Belief` to the controller's
``observe_belief`` whenever the task replaces it (beliefs are immutable: a new belief is a new
object).
"""

from __future__ import annotations

import dataclasses

__all__ = ["Belief"]


@dataclasses.dataclass(frozen=True)
class Belief:
    """The task's belief about the hole and the held peg.

    Attributes:
        hole_xy: The hole's axis in the world (x, y) [m].
        hole_sigma: Standard deviation of that position, x and y [m].
        face_z: Height of the block's top face, the hole's mouth [m].
        hole_radius: The hole's radius (the drawing's: peg radius + clearance) [m].
        chamfer: Depth and width of its 45-degree chamfer [m].
        block_size: The block's extents x, y, z [m].
        peg_radius: The peg's radius [m].
        peg_length: The peg's length [m].
        tip_body: The held peg's lower end (centre of its end face), gripper frame [m].
        axis_body: The held peg's axis (unit, pointing up out of the hole), gripper frame.
    """

    hole_xy: tuple[float, float]
    hole_sigma: float
    face_z: float
    hole_radius: float
    chamfer: float
    block_size: tuple[float, float, float]
    peg_radius: float
    peg_length: float
    tip_body: tuple[float, float, float]
    axis_body: tuple[float, float, float]
