"""The belief planner's cost, declared once as named residual terms (MuJoCo MPC's shape).

A rollout's cost is ``sum over terms of weight * sum over steps of |residual|^2``; a term is a
:class:`Residual`: its name, the residual's unit, its weight (in 1/unit^2) and the function that
computes it from a batch of rollouts (:class:`Rollouts`, in the frame of one hypothesis of where
the hole is: the hole's axis at x = y = 0, its face at z = 0). A new term is one entry of
:data:`TERMS`; its weight is the config field ``w_<name>`` of ``sampling_mpc`` (0 switches it
off). docs/planning.md lists them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["Residual", "Rollouts", "TERMS", "term_costs"]

_Arr = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class Rollouts:
    """A batch of rollouts, each in its hypothesis's frame, shapes (n, steps, ...).

    Attributes:
        tip: (n, steps, 3) the peg's lower end, the hole's axis at x = y = 0, its face at z = 0 [m].
        velocity: (n, steps, 3) its velocity [m/s].
        tilt: (n, steps, 2) the peg's axis off the vertical (its x and y components) [rad].
        force: (n, steps, 3) the contact force on the peg, in the peg's frame (z along its axis) [N].
        knots: (n, knots, 3) the plan's tip setpoints (the first the present one) [m].
        goal_depth: how far below the face the end seats [m]; ``free_depth``: below this the
            end is in the bore, past the face and the chamfer [m]; ``near_height``: above this the
            end is clear of the face whatever the hypothesis [m].
        budget: the contact force the plan may use [N]; ``slip_force``: the axial force the
            pads hold without slipping [N].
    """

    tip: _Arr
    velocity: _Arr
    tilt: _Arr
    force: _Arr
    knots: _Arr
    goal_depth: float
    free_depth: float
    near_height: float
    budget: float
    slip_force: float


@dataclasses.dataclass(frozen=True)
class Residual:
    """One cost term: ``fn(rollouts)`` -> (n, steps, k) or (n, k) residuals in ``unit``."""

    name: str
    unit: str
    doc: str
    fn: Callable[[Rollouts], _Arr]


def _depth(r: Rollouts) -> _Arr:
    return np.sqrt(np.maximum(0.0, r.tip[..., 2:3] + r.goal_depth))


def _lateral(r: Rollouts) -> _Arr:
    return r.tip[..., :2]


def _sink_speed(r: Rollouts) -> _Arr:
    z = r.tip[..., 2:3]
    return r.velocity[..., 2:3] * ((z > -r.free_depth) & (z < r.near_height))


def _bore_speed(r: Rollouts) -> _Arr:
    return r.velocity[..., 2:3] * (r.tip[..., 2:3] < -r.free_depth)


def _side_speed(r: Rollouts) -> _Arr:
    return r.velocity[..., :2]


def _tilt(r: Rollouts) -> _Arr:
    return r.tilt


def _budget(r: Rollouts) -> _Arr:
    return np.maximum(0.0, np.linalg.norm(r.force, axis=-1, keepdims=True) - r.budget)


def _slip(r: Rollouts) -> _Arr:
    return np.maximum(0.0, np.abs(r.force[..., 2:3]) - r.slip_force)


def _effort(r: Rollouts) -> _Arr:
    return r.knots[:, 1:] - r.knots[:, :1]


def _accel(r: Rollouts) -> _Arr:
    return np.diff(r.knots, n=2, axis=1) if r.knots.shape[1] > 2 else np.zeros((len(r.knots), 1, 3))


#: The terms, in the order docs/planning.md lists them.
TERMS: tuple[Residual, ...] = (
    Residual(
        "depth",
        "m^0.5",
        "the root of how far the end is above its seat: the cost grows with the depth to go, a pull "
        "as strong at the seat as at the face",
        _depth,
    ),
    Residual("lateral", "m", "the end off the hole's axis (x, y)", _lateral),
    Residual(
        "sink_speed",
        "m/s",
        "the end's descent near the face, above the bore (an impact grows with it)",
        _sink_speed,
    ),
    Residual(
        "bore_speed", "m/s", "the end's descent in the bore (a tilted peg taps the walls harder)", _bore_speed
    ),
    Residual("side_speed", "m/s", "the end's sideways velocity (a tap on a wall grows with it)", _side_speed),
    Residual("tilt", "rad", "the peg's axis off the vertical (x, y components)", _tilt),
    Residual("budget", "N", "the contact force above the budget", _budget),
    Residual("slip", "N", "the force along the peg above what the pads hold", _slip),
    Residual("effort", "m", "each knot's move from the present setpoint (once per plan)", _effort),
    Residual("accel", "m", "the knots' second difference (once per plan)", _accel),
)


def term_costs(rollouts: Rollouts, weights: dict[str, float]) -> dict[str, _Arr]:
    """Each weighted term's cost per rollout, (n,) arrays, by name (terms of weight 0 left out)."""
    out = {}
    for term in TERMS:
        w = weights[term.name]
        if w > 0.0:
            r = term.fn(rollouts)
            out[term.name] = w * np.sum(r.reshape(len(r), -1) ** 2, axis=1)
    return out
