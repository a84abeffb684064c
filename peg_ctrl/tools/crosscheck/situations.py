"""The contact situations of the cross-check, and the hand that drives the peg through them.

Every situation is a held peg on a *rig*: a hand body that carries the peg rigidly at the grasp
(the pads 70 mm above the peg's lower end and 10 mm beside its axis, as the held insertion grips
it), driven by a law on its pose about the pinch point. The same law, the same geometry and the
same start run in every engine (:mod:`.mujoco_rig`, :mod:`.drake_rig`): only the contact model
differs.

Two laws (:class:`Hand`):

- the **impedance at the touch**: the contact MPC's inner loop, whose stiffness and damping are
  what a touch of a few milliseconds meets (its outer force loop samples a filtered, late sensor
  every 2 ms, too slow to act within a tap). :func:`touch_impedance` reads them from the study's
  controller as built;
- the **push** of the validity battery (docs/physics.md): laterally free but for the slides'
  damping, the orientation held stiff, the height a velocity servo that descends at up to
  ``push_speed`` and saturates at ``push_force`` in contact.

The situations (:data:`SITUATIONS`): a peg sliding down the bore with a touch at its top edge
(the descents' taps), landings on the face and on the chamfer and a touch on a side at the
strategies' speeds, and the battery's wedging and entry pushes. Positions are of the peg's lower
end's centre relative to the centre of the hole's mouth (z up, 0 at the face) [m].
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import UnknownComponent

__all__ = [
    "Hand",
    "Situation",
    "SITUATIONS",
    "BY_NAME",
    "situation",
    "touch_impedance",
    "push_hand",
    "GRIP_LENGTH",
    "GRASP_OFFSET",
    "coulomb_slide_force",
]

GRIP_LENGTH = 0.070  # pinch above the peg's lower end: pads 20 mm above the centre of a 100 mm peg [m]
GRASP_OFFSET = 0.010  # peg axis from the pinch, along +y at the start (the task's grasp) [m]
_SLIDE_DAMPING = 100.0  # the base slides' joint damping (SPEC §3.2), all a "free" axis keeps [N s/m]


@dataclasses.dataclass(frozen=True)
class Hand:
    """A law on the hand's pose about the pinch point, in the world frame.

    ``k_lin`` [N/m] and ``d_lin`` [N s/m] per world axis (a stiffness of 0 leaves the axis free
    but for its damping), ``k_rot`` [N m/rad] and ``d_rot`` [N m s/rad] about every axis. With
    ``push_force`` [N] the height is a velocity servo instead: down at up to ``push_speed``
    [m/s], gain ``push_gain`` [N s/m], saturating at ``push_force`` (the validity battery's push).
    """

    name: str
    k_lin: tuple[float, float, float]
    d_lin: tuple[float, float, float]
    k_rot: float
    d_rot: float
    push_force: float | None = None
    push_speed: float = 0.03
    push_gain: float = 2000.0

    def wrench(
        self,
        p: NDArray[np.float64],
        r: NDArray[np.float64],
        v: NDArray[np.float64],
        w: NDArray[np.float64],
        p_ref: NDArray[np.float64],
        v_ref: NDArray[np.float64],
        r_ref: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Force [N] and torque [N m] on the hand at the pinch, world frame, from its position
        ``p``, rotation matrix ``r`` (3, 3), velocity ``v`` and angular velocity ``w`` (world)
        and the reference ``p_ref``, ``v_ref``, ``r_ref``."""
        force = np.asarray(self.k_lin) * (p_ref - p) + np.asarray(self.d_lin) * (v_ref - v)
        if self.push_force is not None:
            down = -float(v[2])
            force[2] = -min(self.push_force, max(0.0, self.push_gain * (self.push_speed - down)))
        torque = self.k_rot * rotation_vector(r_ref @ r.T) - self.d_rot * w
        return force, torque


def rotation_vector(r: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation vector [rad] (axis times angle) of the rotation matrix ``r``."""
    cos = max(-1.0, min(1.0, 0.5 * (float(np.trace(r)) - 1.0)))
    angle = math.acos(cos)
    axis2 = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if angle < 1e-6:
        return 0.5 * axis2
    return angle / (2.0 * math.sin(angle)) * axis2


def touch_impedance(k_lin: float, d_lin: float, k_rot: float, d_rot: float) -> Hand:
    """The impedance at the touch: ``k_lin`` [N/m] and ``d_lin`` [N s/m] on every world axis,
    ``k_rot`` [N m/rad] and ``d_rot`` [N m s/rad] about every axis."""
    return Hand("impedance", (k_lin,) * 3, (d_lin,) * 3, k_rot, d_rot)


def push_hand(force: float, speed: float) -> Hand:
    """The validity battery's push (peg_ctrl.sim.grasp_start.HeldRig): laterally free but for the
    slides' damping, the orientation held at 400 N m/rad (damping 5 plus the ball's 50), down at
    up to ``speed`` [m/s] with at most ``force`` [N]."""
    d = (_SLIDE_DAMPING, _SLIDE_DAMPING, 0.0)
    return Hand("push", (0.0, 0.0, 0.0), d, 400.0, 55.0, push_force=force, push_speed=speed)


@dataclasses.dataclass(frozen=True)
class Situation:
    """One contact situation. Lengths [m], angles [rad], speeds [m/s], forces [N], times [s].

    The peg's lower end starts at ``start`` (relative to the mouth's centre, z up from the face),
    tilted by ``tilt`` about world y through that end (its top towards +x), moving with the
    reference. The reference moves the hand at ``velocity`` for ``travel`` metres, then holds
    for ``hold`` seconds. ``hand`` is ``"impedance"`` (the touch's, every axis)
    or ``"push"`` (the battery's, ``push_force`` at up to the speed of ``velocity``). ``press_x``
    sets the impedance's reference that many newtons of its stiffness past the start along +x,
    so that the peg presses on a wall it touches.
    """

    name: str
    kind: str  # "slide", "impact" or "push": how the report groups it
    description: str
    friction: float
    clearance: float  # radial; negative is an interference fit
    chamfer: float
    tilt: float
    start: tuple[float, float, float]
    velocity: tuple[float, float, float]
    travel: float
    hold: float
    hand: str = "impedance"
    push_force: float = 10.0
    touch_depth: float | None = None  # slides: the depth of the end at the first touch [m]
    press_x: float = 0.0  # the impedance's reference this many newtons further along +x [N]

    @property
    def speed(self) -> float:
        return float(np.linalg.norm(self.velocity))

    @property
    def duration(self) -> float:
        return self.travel / self.speed + self.hold

    def reference(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The end's reference displacement [m] and velocity [m/s] from the start at ``t`` [s]."""
        v = np.asarray(self.velocity, dtype=float)
        t_stop = self.travel / self.speed
        if t < t_stop:
            return v * t, v
        return v * t_stop, np.zeros(3)


def _slide(v: float, tilt: float, friction: float) -> Situation:
    """The descent's touch: the end starts 2 mm down the bore, tilted so that its side meets the
    bore's top edge (the chamfer's foot) when the end is 10 mm down, then 15 mm more of slide.
    With no tilt, the peg rides one wall pressed by 1 N of the hand's lateral stiffness."""
    clearance, chamfer, touch = 0.05e-3, 1.0e-3, 0.010
    if tilt > 0.0:
        x0 = clearance - tilt * (touch - chamfer)  # the end's offset that makes that touch
        what = f"{tilt * 1e3:g} mrad off the bore's axis, touching its top edge 10 mm down"
        name = f"slide_{v * 1e3:g}mms_{tilt * 1e3:g}mrad_mu{friction:g}"
    else:
        x0 = clearance - 1.0e-6  # a micrometre off the +x wall, pressed onto it
        what = "parallel to the bore, riding one wall pressed by 1 N"
        name = f"slide_{v * 1e3:g}mms_wall_mu{friction:g}"
    return Situation(
        name=name,
        kind="slide",
        description=f"held peg down the bore at {v * 1e3:g} mm/s, {what}; friction {friction:g}",
        friction=friction,
        clearance=clearance,
        chamfer=chamfer,
        tilt=tilt,
        start=(x0, 0.0, -0.002),
        velocity=(0.0, 0.0, -v),
        travel=0.023,
        hold=0.0,
        touch_depth=touch if tilt > 0.0 else None,
        press_x=0.0 if tilt > 0.0 else 1.0,
    )


_LANDING_TILT = 1.0e-3  # the landings' tilt: the calibration's residual; the rim lands first


def _landing(where: str, what: str, start: tuple[float, float, float], v: float, force: float) -> Situation:
    """A landing from 0.5 mm above at ``v`` [m/s] with the battery's push of ``force`` [N]."""
    travel = 0.0005 + (0.0025 if where == "chamfer" else 0.0003)  # a chamfer's into the bore
    return Situation(
        name=f"land_{where}_{v * 1e3:g}mms",
        kind="impact",
        description=f"landing {what} at {v * 1e3:g} mm/s, pushing {force:g} N, laterally free",
        friction=0.9,
        clearance=0.05e-3,
        chamfer=1.0e-3,
        tilt=_LANDING_TILT,
        start=start,
        velocity=(0.0, 0.0, -v),
        travel=travel,
        hold=0.3 if where == "face" else 0.2,
        hand="push",
        push_force=force,
    )


def _impacts() -> list[Situation]:
    face = (-0.025, 0.0, 0.0005)  # 25 mm off the axis: all of the end over the flat face
    chamfer = (-0.0005, 0.0, 0.0005)  # 0.5 mm off: the rim lands on the 1 mm chamfer
    out = []
    for v, force in ((0.005, 1.0), (0.03, 10.0)):  # a probe's landing; the battery's push
        out.append(_landing("face", "on the face", face, v, force))
        out.append(_landing("chamfer", "on the chamfer 0.5 mm off the axis", chamfer, v, force))
    out.append(
        Situation(
            name="side_touch_5mms",
            kind="impact",
            description="the end meeting the block's -x side at 5 mm/s, 2 mm below the face, pressing 3 N",
            friction=0.9,
            clearance=0.05e-3,
            chamfer=1.0e-3,
            tilt=_LANDING_TILT,
            start=(-0.040 - 0.010 - 0.0005, 0.0, -0.002),  # 0.5 mm short of the side
            velocity=(0.005, 0.0, 0.0),
            travel=0.0005 + 0.0008,  # the side, then 0.8 mm: 3 N at the touch's 3.8 kN/m
            hold=0.3,
        )
    )
    return out


def _pushes() -> list[Situation]:
    common = dict(
        kind="push", friction=0.9, chamfer=0.0, velocity=(0.0, 0.0, -0.03), hand="push", push_force=10.0
    )
    out = []
    for deg in (1.0, 2.0):
        out.append(
            Situation(
                name=f"wedge_{deg:g}deg",
                description=f"{deg:g} deg of tilt pushed with 10 N into 0.1 mm of clearance (the battery's)",
                clearance=0.1e-3,
                tilt=math.radians(deg),
                start=(0.0, 0.0, 0.001),
                travel=0.030,
                hold=0.5,
                **common,  # type: ignore[arg-type]
            )
        )
    for c, lateral, tilt, tag in (
        (0.0, 0.0, 0.0, "entry_0mm"),
        (0.0, 31.3e-6, 0.72e-3, "entry_0mm_off"),
        (-0.02e-3, 0.0, 0.0, "entry_-0.02mm"),
    ):
        off = f", {lateral * 1e6:.0f} um off and {tilt * 1e3:g} mrad tilted" if lateral else ", aligned"
        out.append(
            Situation(
                name=tag,
                description=f"pushed with 10 N at {c * 1e3:g} mm of clearance{off} (the battery's entry bar)",
                clearance=c,
                tilt=tilt,
                start=(lateral, 0.0, 0.001),
                travel=0.030,
                hold=0.0,
                **common,  # type: ignore[arg-type]
            )
        )
    return out


SITUATIONS: tuple[Situation, ...] = (
    *(_slide(v, tilt, mu) for mu in (0.3, 0.9) for v in (0.01, 0.03) for tilt in (0.0, 1.5e-3, 3.0e-3)),
    *_impacts(),
    *_pushes(),
)


#: The situations by name.
BY_NAME: dict[str, Situation] = {s.name: s for s in SITUATIONS}


def situation(name: str) -> Situation:
    """The situation called ``name``; an unknown name lists the known ones."""
    if name not in BY_NAME:
        raise UnknownComponent("situation", name, BY_NAME)
    return BY_NAME[name]


def coulomb_slide_force(s: Situation, k_lateral: float, depth: float) -> float:
    """Quasi-static rigid-Coulomb normal force [N] of a tilted slide's touch when the end is
    ``depth`` [m] down: the hand yields ``tilt x (depth - touch depth)`` at the touch against its
    lateral stiffness ``k_lateral`` [N/m]; the friction's moment about the pinch turns the hand by
    microradians against its rotational stiffness and is left out. 0 before the touch."""
    if s.touch_depth is None:
        raise ValueError(f"{s.name} has no touch depth (only the tilted slides do)")
    return k_lateral * s.tilt * max(0.0, depth - s.touch_depth)
