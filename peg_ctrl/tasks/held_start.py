"""One held-insertion episode's start: the draw of its disturbances, the block off its drawing,
the peg placed in the closed hand above the hole, and what the task believes of them (the
grasp as nominal, the hole as a camera sees it). The task: :mod:`peg_ctrl.tasks.held_insertion`."""

from __future__ import annotations

import dataclasses
import math
from typing import Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.grasp_start import GRASP_OFFSET, Q_TURN, HeldRig, close_on_held_peg, place_held_peg
from peg_ctrl.sim.rotations import quat_mul, rotate, rotate_inv, yaw_quat
from peg_ctrl.sim.scene import PEG_LYING_QUAT, SceneConfig
from peg_ctrl.tasks.monitors import InsertionMonitor
from peg_ctrl.tasks.strategies.base import TaskDisturbance
from peg_ctrl.tasks.strategies.motions import about

__all__ = ["Disturbance", "HeldStart", "StartSpec", "check_start", "place_held_start"]

_Vec = NDArray[np.float64]


class StartSpec(TaskDisturbance, Protocol):
    """What the start needs of the task's config [m, rad]: the disturbances a strategy may read,
    the drawing's tolerance and the start's height."""

    @property
    def drawing_tolerance(self) -> float: ...

    @property
    def start_height(self) -> float: ...

    @property
    def start_over_observed(self) -> bool: ...


@dataclasses.dataclass(frozen=True)
class Disturbance:
    """One seed's draw: the in-hand offset's direction in the world and the gripper's yaw [rad],
    the tilt's sign, observation noise (x, y) [m]. The offset lies in the pads' plane (a peg held
    between two pads cannot sit off along their closing direction): ``draw`` takes its sign from a
    uniform angle, and :meth:`in_pads_plane` turns it along the plane once the yaw is known."""

    lateral_direction: float
    yaw: float
    tilt_sign: float
    noise: tuple[float, float]

    @classmethod
    def draw(cls, rng: np.random.Generator, position_noise: float) -> Disturbance:
        direction, yaw = (float(v) for v in rng.uniform(0.0, 2.0 * math.pi, size=2))
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        nx, ny = (float(v) for v in rng.normal(0.0, 1.0, size=2) * position_noise)
        return cls(direction, yaw, sign, (nx, ny))

    def in_pads_plane(self, closing: NDArray[np.float64]) -> Disturbance:
        """The offset along the pads' plane, horizontal, across the closing direction
        ``closing`` (world), on the side the drawn angle is on."""
        across = math.atan2(float(closing[0]), -float(closing[1]))  # z x closing
        side = 0.0 if math.cos(self.lateral_direction - across) >= 0 else math.pi
        return dataclasses.replace(self, lateral_direction=across + side)


@dataclasses.dataclass(frozen=True)
class HeldStart:
    """The draw, and the belief it leaves: ``b_body`` the believed lower end and ``up_body`` the
    believed axis (gripper frame), ``observed_hole`` (x, y) the camera's [m, world], and
    ``drawing_sides`` the drawing's hole axis to the +x, -x, +y, -y sides [m]."""

    disturbance: Disturbance
    b_body: _Vec
    up_body: _Vec
    observed_hole: _Vec
    drawing_sides: _Vec


def place_held_start(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    rng: np.random.Generator,
    c: StartSpec,
    scene: SceneConfig,
    insertion: InsertionMonitor,
    block_top: float,
) -> HeldStart:
    """Draw the disturbances; place the block off its drawing (``insertion`` measures against
    where it truly is) and the peg in the closed hand above the hole."""
    d = Disturbance.draw(rng, c.position_noise)
    q_grip = quat_mul(yaw_quat(d.yaw), Q_TURN)
    # Tilt in the plane of the pads: about the jaw's closing direction (the gripper's x).
    closing = rotate(q_grip, np.array([1.0, 0.0, 0.0]))
    d = d.in_pads_plane(closing)
    q_peg = quat_mul(about(closing, d.tilt_sign * c.tilt_error), quat_mul(q_grip, np.asarray(PEG_LYING_QUAT)))
    up = rotate(q_peg, np.array([0.0, 0.0, 1.0]))
    up = up if up[2] > 0 else -up
    (hx, hy, top), sides = _place_block(model, rng, c.drawing_tolerance, scene, insertion, block_top)
    observed = np.array([hx, hy]) + np.asarray(d.noise)
    # The believed lower end starts over the hole the task believes in: the observed one (a
    # robot's start), or the true one (``start_over_observed`` false: every earlier study).
    over = observed if c.start_over_observed else np.array([hx, hy])
    mouth = np.array(
        [
            over[0] + c.lateral_error * math.cos(d.lateral_direction),
            over[1] + c.lateral_error * math.sin(d.lateral_direction),
            top,
        ]
    )
    bottom = mouth + (c.start_height / up[2]) * up
    rig = HeldRig(model)
    pinch, _ = place_held_peg(
        model,
        data,
        rig,
        scene,
        bottom=bottom,
        q_grip=q_grip,
        q_peg=q_peg,
        grip_above_centre=c.grip_above_centre,
    )
    close_on_held_peg(model, data, rig, pinch, q_grip)
    data.time = 0.0  # the closing builds the start state; the episode's clock starts here
    # The believed grasp, in the gripper frame: the nominal one (peg upright in the hand),
    # lateral_error off the true one; the hole as a camera sees it, in the world frame.
    half = 0.5 * scene.assets.peg_length
    b_world = -(c.grip_above_centre + half) * np.array([0.0, 0.0, 1.0]) + rotate(
        q_grip, np.array([0.0, 0.0, -GRASP_OFFSET])
    )
    return HeldStart(
        disturbance=d,
        b_body=rotate_inv(q_grip, b_world - (mouth - np.array([*over, top]))),
        up_body=rotate_inv(q_grip, np.array([0.0, 0.0, 1.0])),
        observed_hole=observed,
        drawing_sides=sides,
    )


def check_start(c: StartSpec, scene: SceneConfig) -> None:
    """Raise :class:`ConfigError` if the peg cannot start as ``c`` asks in ``scene``."""
    a = scene.assets
    rim = a.peg_radius * math.sin(c.tilt_error)  # the low rim below the lower end's centre
    if c.start_height <= rim:
        raise ConfigError(
            f"task.start_height must be above the tilted rim's drop of {rim * 1e3:.2f} mm, "
            f"got {c.start_height!r}"
        )
    if c.grip_above_centre >= 0.5 * a.peg_length - 0.01:
        raise ConfigError(
            f"task.grip_above_centre must leave 10 mm of peg above the pads (< "
            f"{0.5 * a.peg_length - 0.01:g} m), got {c.grip_above_centre!r}"
        )


def _place_block(
    model: mujoco.MjModel,
    rng: np.random.Generator,
    tol: float,
    scene: SceneConfig,
    insertion: InsertionMonitor,
    block_top: float,
) -> tuple[tuple[float, float, float], _Vec]:
    """Put the block off its drawing by ``tol`` (nothing drawn at 0): the block (its face and
    hole) by one draw per axis, the drawing's distances from the hole's axis to the four sides
    (+x, -x, +y, -y) by one each. Returns the hole's true mouth (x, y, z) [m] and those distances."""
    delta = rng.uniform(-tol, tol, size=7) if tol > 0 else np.zeros(7)
    model.body_pos[model.body("block").id] = np.asarray(scene.block_pos) + delta[:3]
    half = np.repeat(0.5 * np.asarray(scene.assets.block_size[:2], dtype=float), 2)
    hx, hy = scene.hole_xy
    return insertion.locate(hx + delta[0], hy + delta[1], block_top + delta[2]), half + delta[3:]
