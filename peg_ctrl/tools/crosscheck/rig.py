"""What every engine shares: the rig's geometry and hand, the loop over a situation, its trace.

:class:`Rig` holds the geometry (the block's convex parts for the situation's clearance and
chamfer, as the physics profile builds them, the peg's cylinder), the hand's inertia and the
touch's impedance, all read from the project: :func:`study_rig` builds the featured study's
contact MPC on its scene and takes the inner loop's gains and the hand's inertia at the pinch
from it. An engine adapter (:class:`Engine`) reads the hand's state, applies a wrench, steps and
reports the peg-block contact; :func:`run_situation` drives any adapter through a situation
with the situation's hand law and records a :class:`Trace`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from importlib import resources
from pathlib import Path
from typing import ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.physics import PRECISION, PhysicsProfile
from peg_ctrl.sim.scene import SceneConfig
from peg_ctrl.tools.crosscheck.situations import (
    GRASP_OFFSET,
    GRIP_LENGTH,
    Hand,
    Situation,
    push_hand,
    touch_impedance,
)

__all__ = ["Rig", "study_rig", "Engine", "Trace", "run_situation", "tilt_matrix"]

_STUDY = "contact_real"  # the study whose touch the rig's hand reproduces
_CONTROLLER = "mpc"


@dataclasses.dataclass(frozen=True)
class Rig:
    """The rig: a hand of ``mass`` [kg] and principal ``inertia`` [kg m^2] about the pinch
    carrying the peg rigidly, the peg ``GRIP_LENGTH`` below and ``GRASP_OFFSET`` beside the
    pinch; the block and its hole as ``profile`` builds them; the touch's impedance."""

    mass: float
    inertia: tuple[float, float, float]
    k_lin: float  # the touch's stiffness [N/m]
    d_lin: float  # ... and damping [N s/m], the slides' joint damping included
    k_rot: float  # [N m/rad] about the pinch
    d_rot: float  # [N m s/rad], the ball joint's damping included
    profile: PhysicsProfile = PRECISION
    scene: SceneConfig = SceneConfig()

    def assets(self, s: Situation) -> AssetParams:
        """The geometry the profile builds for the situation's clearance and chamfer."""
        return self.profile.assets(self.scene_for(s).assets)

    def scene_for(self, s: Situation) -> SceneConfig:
        """The project's scene with the situation's geometry and friction."""
        params = dataclasses.replace(self.scene.assets, clearance=s.clearance, chamfer=s.chamfer)
        return dataclasses.replace(self.scene, assets=params, friction=s.friction)

    @property
    def mouth(self) -> NDArray[np.float64]:
        """The centre of the hole's mouth, world frame [m]."""
        hx, hy = self.scene.hole_xy
        return np.array([hx, hy, self.scene.assets.block_size[2]])

    @property
    def end_in_hand(self) -> NDArray[np.float64]:
        """The peg's lower end's centre in the hand frame (world-aligned at zero tilt) [m]."""
        return np.array([0.0, GRASP_OFFSET, -GRIP_LENGTH])

    @property
    def peg_centre_in_hand(self) -> NDArray[np.float64]:
        return self.end_in_hand + np.array([0.0, 0.0, 0.5 * self.scene.assets.peg_length])

    def hand(self, s: Situation) -> Hand:
        """The situation's hand law."""
        if s.hand == "push":
            return push_hand(s.push_force, s.speed)
        return touch_impedance(self.k_lin, self.d_lin, self.k_rot, self.d_rot)

    def start_pose(self, s: Situation) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The hand's start: the pinch's position [m] and the rotation matrix."""
        r = tilt_matrix(s.tilt)
        end = self.mouth + np.asarray(s.start)
        return end - r @ self.end_in_hand, r


def tilt_matrix(tilt: float) -> NDArray[np.float64]:
    """The rotation by ``tilt`` [rad] about world y."""
    c, s = math.cos(tilt), math.sin(tilt)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def study_rig(profile: PhysicsProfile = PRECISION) -> Rig:
    """The rig whose hand is the featured study's contact MPC at the touch: its inner loop's
    stiffness and damping on the pinch (the LQR gains, plus the joints' own damping) and the
    hand's mass and rotational inertia at the pinch (the mass matrix at home, the ball joint's
    armature included), read from the controller as built on the study's scene."""
    from peg_ctrl.experiments.config import expand, load_experiment
    from peg_ctrl.sim.scene import build_model

    path = Path(str(resources.files("peg_ctrl.experiments") / "configs" / f"{_STUDY}.yaml"))
    job = next(j for j in expand(load_experiment(path)) if j.controller == _CONTROLLER)
    cfg = job.config
    controller = cfg.controller.build(build_model(cfg.scene, cfg.physics.resolved()))
    k = -np.asarray(controller.k_lqr)  # type: ignore[attr-defined]
    mass = np.asarray(controller.mass)  # type: ignore[attr-defined]
    damping = np.asarray(controller.damping)  # type: ignore[attr-defined]
    rot = [3, 4, 5]
    return Rig(
        mass=float(mass[0]),
        inertia=(float(mass[3]), float(mass[4]), float(mass[5])),
        k_lin=float(k[0, 0]),
        d_lin=float(k[0, 1] + damping[0]),
        k_rot=float(np.mean([k[i, 2 * i] for i in rot])),
        d_rot=float(np.mean([k[i, 2 * i + 1] + damping[i] for i in rot])),
        profile=profile,
        scene=dataclasses.replace(cfg.scene, friction=None),
    )


class Engine(Protocol):
    """One engine's rig, ready at the situation's start."""

    dt: float  # [s]

    def hand_state(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The pinch's position [m], the hand's rotation matrix, its velocity [m/s] and angular
        velocity [rad/s], world frame."""
        ...

    def apply(self, force: NDArray[np.float64], torque: NDArray[np.float64]) -> None:
        """Hold this wrench on the hand at the pinch (world frame) over the next step."""
        ...

    def step(self) -> None: ...

    def contact(self) -> tuple[float, NDArray[np.float64], float, int]:
        """The peg-block contact after the step: the sum of the normal forces [N], the net
        force on the peg [N] (3,), the deepest overlap [m] and the number of contact points."""
        ...

    def lower_end(self) -> NDArray[np.float64]:
        """The centre of the peg's lower end, world frame [m]."""
        ...


@dataclasses.dataclass
class Trace:
    """A situation run in one engine, one row per physics step (:attr:`NAMES`): the time [s]
    at the step's end, the sum of the peg-block normal forces [N], the magnitude of the net
    peg-block force [N] (the studies' measure), the magnitude of the hand's force [N] (what a
    wrist sensor between it and the arm reads), the lower end's depth below the face and its
    offset from the hole's axis along x and y [m], and the deepest overlap [m]."""

    dt: float  # [s]
    columns: NDArray[np.float64]  # (steps, len(NAMES))
    wall_time_s: float
    NAMES: ClassVar[tuple[str, ...]] = ("t", "normal", "net", "wrist", "depth", "x", "y", "overlap")

    def column(self, name: str) -> NDArray[np.float64]:
        """The column ``name`` of :attr:`NAMES` (steps,)."""
        return self.columns[:, self.NAMES.index(name)]

    t = property(lambda self: self.column("t"))
    normal = property(lambda self: self.column("normal"))
    net = property(lambda self: self.column("net"))
    wrist = property(lambda self: self.column("wrist"))
    depth = property(lambda self: self.column("depth"))
    x = property(lambda self: self.column("x"))
    overlap = property(lambda self: self.column("overlap"))


def run_situation(engine: Engine, rig: Rig, s: Situation) -> Trace:
    """Drive ``engine`` through ``s`` with the situation's hand law, one physics step at a time."""
    hand = rig.hand(s)
    p0, r_ref = rig.start_pose(s)
    if s.press_x:
        p0 = p0 + np.array([s.press_x / rig.k_lin, 0.0, 0.0])
    steps = int(round(s.duration / engine.dt))
    rows = np.zeros((steps, len(Trace.NAMES)))
    mouth = rig.mouth
    started = time.perf_counter()
    for i in range(steps):
        t = i * engine.dt
        p, r, v, w = engine.hand_state()
        shift, v_ref = s.reference(t)
        force, torque = hand.wrench(p, r, v, w, p0 + shift, v_ref, r_ref)
        engine.apply(force, torque)
        engine.step()
        normal, net, overlap, _ = engine.contact()
        end = engine.lower_end() - mouth
        rows[i] = (
            t + engine.dt,
            normal,
            float(np.linalg.norm(net)),
            float(np.linalg.norm(force)),
            -end[2],
            end[0],
            end[1],
            overlap,
        )
    return Trace(engine.dt, rows, time.perf_counter() - started)
