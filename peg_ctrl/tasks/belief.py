"""The task's belief over what a cell leaves open, one Gaussian that every skill's reading updates.

The state (:data:`STATE`): the hole's axis in the world (x, y) [m]; the peg's true lower end's
offset from the believed one (world x, y, with the hand at the episode's start orientation) [m],
which a tilt in the hand moves too (the pads hold the peg ``grip_length`` above its end: a tilt
``θ`` about their normal swings the end by about ``grip_length θ`` across them, 2.4 mm at 2°, so
the prior correlates the two);
the peg's tilt in the hand about the pads' normal, against the believed axis [rad]; the top
face's height [m]. The prior is what the cell states of itself: the camera's error on the hole
(``task.position_noise``), the grasp's tolerance across the pads (``task.lateral_error``, the
pads centre the peg along their closing direction), the grasp's tilt tolerance
(``task.tilt_error``, or :data:`TILT_FLOOR` where it states none: a peg the pads close on sits
upright to within that) and the drawing's tolerance on the face (uniform: σ = tol/√3).

A skill's reading is linear in the state (:class:`Reading`: ``z = H x + v``, ``v ~ N(0, R)``);
its measurement model (:mod:`peg_ctrl.tasks.strategies.skills.models`) gives ``H`` and ``R``
before the touch, so what a touch will teach, its expected information, is known before it is
made (a linear-Gaussian belief's covariance after a reading does not depend on the reading).
When the task revises what it believes of the grasp (a located end, a calibrated tilt) the
state's reference moves with it: :meth:`TaskBelief.shift`.

Not a particle belief: the search's :class:`~peg_ctrl.sim.belief.HoleBelief` keeps its own
non-Gaussian picture of where the chamfer caught the end while it lands; its result (the end in
the bore) is one :class:`Reading` here.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["STATE", "TILT_FLOOR", "Reading", "TaskBelief"]

_Vec = NDArray[np.float64]

STATE = ("hole_x", "hole_y", "end_x", "end_y", "tilt", "face_z")
_INDEX = {name: k for k, name in enumerate(STATE)}
TILT_FLOOR = 0.002  # [rad] a peg the pads close on, with no tilt stated: upright to within this (1 sigma)
_CLOSING_SIGMA = 5e-5  # [m] the pads centre the peg along their closing direction to this


@dataclasses.dataclass(frozen=True)
class Reading:
    """A linear reading of the state: ``z = H x + v``, ``v ~ N(0, R)`` (``H``: rows over
    :data:`STATE`), and what made it."""

    skill: str
    H: _Vec
    R: _Vec
    z: _Vec | None = None  # None: a reading not made yet (its information is still known)

    def with_value(self, z: ArrayLike) -> Reading:
        return dataclasses.replace(self, z=np.asarray(z, dtype=float))


def rows(**weights: float) -> _Vec:
    """One row of ``H``: ``rows(hole_x=1, end_x=-1)``."""
    h = np.zeros(len(STATE))
    for name, w in weights.items():
        h[_INDEX[name]] = w
    return h


class TaskBelief:
    """A Gaussian over :data:`STATE` (module docstring); ``history`` holds, per reading, the
    time, the skill, the information it gave [bits] and the spreads after it."""

    def __init__(self, mean: _Vec, cov: _Vec) -> None:
        self.mean = np.asarray(mean, dtype=float).copy()
        self.cov = np.asarray(cov, dtype=float).copy()
        self.history: list[dict[str, object]] = []

    @classmethod
    def prior(
        cls,
        observed_hole: ArrayLike,
        hole_sigma: float,
        across: ArrayLike,
        offset_tolerance: float,
        tilt_tolerance: float,
        face_z: float,
        face_tolerance: float,
        swing: ArrayLike = (0.0, 0.0),
    ) -> TaskBelief:
        """The cell's prior (module docstring); ``across``: the unit direction across the pads
        (world x, y) along which the end can sit off the believed one; ``swing``: how far the
        end moves (world x, y) per radian of tilt [m/rad]."""
        u = np.asarray(across, dtype=float)
        u = u / np.linalg.norm(u)
        n = np.array([-u[1], u[0]])
        w = np.asarray(swing, dtype=float)
        s_tilt2 = max(tilt_tolerance, TILT_FLOOR) ** 2
        cov = np.zeros((len(STATE), len(STATE)))
        cov[0, 0] = cov[1, 1] = max(hole_sigma, 1e-6) ** 2
        cov[2:4, 2:4] = max(offset_tolerance, 1e-6) ** 2 * np.outer(u, u) + _CLOSING_SIGMA**2 * np.outer(n, n)
        cov[2:4, 2:4] += s_tilt2 * np.outer(w, w)
        cov[2:4, 4] = cov[4, 2:4] = s_tilt2 * w
        cov[4, 4] = s_tilt2
        cov[5, 5] = max(face_tolerance / math.sqrt(3.0), 1e-6) ** 2
        hole = np.asarray(observed_hole, dtype=float)
        mean = np.array([hole[0], hole[1], 0.0, 0.0, 0.0, face_z])
        belief = cls(mean, cov)
        belief.history.append({"t": 0.0, "skill": "prior", "bits": 0.0, **belief.spread()})
        return belief

    # -- reading --------------------------------------------------------------------------------
    def _gain(self, reading: Reading) -> _Vec:
        """The Kalman gain of ``reading``."""
        H, P = reading.H, self.cov
        return P @ H.T @ np.linalg.inv(H @ P @ H.T + reading.R)

    def _after(self, reading: Reading, gain: _Vec) -> _Vec:
        out = (np.eye(len(STATE)) - gain @ reading.H) @ self.cov
        return 0.5 * (out + out.T)

    def posterior_cov(self, reading: Reading) -> _Vec:
        """The covariance after ``reading``, whatever its value."""
        return self._after(reading, self._gain(reading))

    def information(self, reading: Reading, of: Sequence[str] = STATE) -> float:
        """What ``reading`` would teach of the quantities ``of`` [bits]: the log-ratio of their
        marginal covariance's volume before and after it."""
        return self._bits(self.posterior_cov(reading), of)

    def _bits(self, after: _Vec, of: Sequence[str] = STATE) -> float:
        k = [_INDEX[name] for name in of]
        return 0.5 * math.log2(np.linalg.det(self.cov[np.ix_(k, k)]) / np.linalg.det(after[np.ix_(k, k)]))

    def update(self, reading: Reading, t: float) -> float:
        """Take a made reading (Kalman update); returns its information about the state [bits]."""
        if reading.z is None:
            raise ValueError(f"the reading of {reading.skill} has no value")
        gain = self._gain(reading)
        after = self._after(reading, gain)
        bits = self._bits(after)
        self.mean = self.mean + gain @ (reading.z - reading.H @ self.mean)
        self.cov = after
        self.history.append({"t": float(t), "skill": reading.skill, "bits": bits, **self.spread()})
        return bits

    def shift(self, **by: float) -> None:
        """The state's reference moved by a known amount (the task revised its belief of the
        grasp): each named component's mean moves by ``-by`` (the truth stays where it is)."""
        for name, value in by.items():
            self.mean[_INDEX[name]] -= value

    # -- what it says ----------------------------------------------------------------------------------
    def sigma(self, name: str) -> float:
        return math.sqrt(max(0.0, float(self.cov[_INDEX[name], _INDEX[name]])))

    def value(self, name: str) -> float:
        return float(self.mean[_INDEX[name]])

    def relative(self) -> tuple[_Vec, _Vec]:
        """Where the believed lower end must go for the true one to be over the hole (x, y)
        [m], and that position's covariance: ``hole - end``."""
        H = np.array([rows(hole_x=1.0, end_x=-1.0), rows(hole_y=1.0, end_y=-1.0)])
        return H @ self.mean, H @ self.cov @ H.T

    def relative_sigma(self) -> float:
        """The larger standard deviation of :meth:`relative`'s position [m]."""
        return math.sqrt(float(np.linalg.eigvalsh(self.relative()[1])[-1]))

    def spread(self) -> dict[str, float]:
        """The belief's spread, in a person's units: the hole's and the end's (larger axis) and
        the two together (where the end must go) [mm], the tilt [mrad], the face [µm]."""

        def larger(k: slice) -> float:
            return math.sqrt(float(np.linalg.eigvalsh(self.cov[k, k])[-1]))

        return {
            "hole_mm": 1e3 * larger(slice(0, 2)),
            "end_mm": 1e3 * larger(slice(2, 4)),
            "relative_mm": 1e3 * self.relative_sigma(),
            "tilt_mrad": 1e3 * self.sigma("tilt"),
            "face_um": 1e6 * self.sigma("face_z"),
        }
