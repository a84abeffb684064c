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

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["Belief", "HoleBelief"]


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
        plan_depth: None while the task leads (a controller tracks its targets); once it hands
            over, how far below the face the peg's end is to be seated [m]: a controller that
            plans (``sampling_mpc``) plans towards that goal itself.
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
    plan_depth: float | None = None


class HoleBelief:
    """A belief over where the hole's axis is, on a grid of particles, narrowed by touches.

    The prior is a Gaussian of standard deviation ``sigma`` [m] about the observed hole, cut off
    at ``radius`` (as far as the search will look): the task does not know how far off the hole
    is, only that near the observation is likelier. What a press of the peg's flat end at a point
    ``p`` (the peg's lower end, x and y [m]) tells, each a likelihood over the particles:

    - :meth:`no_drop`: the end stayed on the face, so the axis is not within ``capture`` of ``p``
      (the chamfer would have caught it). Soft: a missed drop is not impossible.
    - :meth:`bearing`: where the face supports the end off its centre (the hole takes the rest),
      the centre of pressure lies on the far side of the end from the hole, so the hole is
      *towards* ``-cop`` from ``p``: a von Mises likelihood on the bearing, its concentration
      from the measurement's signal to noise (a noisy sensor tells little, and then the belief
      barely moves).
    - :meth:`landing`: how far the end sank below the face: on the chamfer, the axis is about
      ``reach - depth`` from ``p`` (``reach``: the chamfer's and the clearance's width); on the
      face (no depth), at least ``reach``.

    :meth:`best_probe` is where a press is most likely to be caught: the grid point whose capture
    disc holds the most belief (a convolution of the belief with the disc).

    Attributes:
        points: (n, 2) the particles (x, y) [m], a square grid of ``spacing`` inside the disc.
        weights: (n,) their normalised weights.
    """

    def __init__(
        self,
        centre: tuple[float, float],
        *,
        radius: float,
        sigma: float,
        capture: float,
        spacing: float = 1e-4,
        cov: ArrayLike | None = None,
    ) -> None:
        """``cov`` (2 x 2) [m^2]: the prior's covariance, where it is not round (the task's
        belief of where the end must go; ``sigma`` is then unused)."""
        if not (radius > 0 and sigma > 0 and capture > spacing > 0):
            raise ValueError(
                f"need radius > 0, sigma > 0 and capture > spacing > 0, got radius {radius}, "
                f"sigma {sigma}, capture {capture}, spacing {spacing}"
            )
        self.centre = np.asarray(centre, dtype=float)
        self.radius, self.capture, self.spacing = radius, capture, spacing
        n = int(np.ceil(radius / spacing))
        axis = spacing * np.arange(-n, n + 1)
        gx, gy = np.meshgrid(axis, axis, indexing="ij")
        self._shape = gx.shape
        self._inside = (gx**2 + gy**2 <= radius * radius).ravel()
        self.points = self.centre + np.column_stack([gx.ravel(), gy.ravel()])[self._inside]
        d = self.points - self.centre
        if cov is None:
            r2 = np.einsum("ij,ij->i", d, d) / (sigma * sigma)
        else:
            r2 = np.einsum("ij,jk,ik->i", d, np.linalg.inv(np.asarray(cov, dtype=float)), d)
        self.weights = np.exp(-0.5 * r2)
        self.weights /= self.weights.sum()
        k = int(np.floor(capture / spacing))
        kx, ky = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
        self._disc = ((kx**2 + ky**2) * spacing * spacing < capture * capture).astype(float)

    def _normalise(self, likelihood: np.ndarray) -> None:
        w = self.weights * likelihood
        total = float(w.sum())
        # Evidence against every particle (a hole outside the searched disc): start over, flat.
        self.weights = w / total if total > 1e-300 else np.full(len(w), 1.0 / len(w))

    def _distance(self, p: ArrayLike) -> np.ndarray:
        return np.linalg.norm(self.points - np.asarray(p, dtype=float), axis=1)

    def no_drop(self, p: ArrayLike, *, miss: float = 0.02) -> None:
        """A press at ``p`` met the face: ``miss`` is the chance the chamfer caught it unnoticed."""
        self._normalise(np.where(self._distance(p) < self.capture, miss, 1.0))

    def landing(self, p: ArrayLike, depth: float, *, reach: float, sigma: float) -> None:
        """A landing at ``p`` sank ``depth`` [m] below the face (about 0 on the face): on a
        45-degree chamfer whose mouth is ``reach`` [m] wider than the peg (clearance + chamfer),
        the axis is ``reach - depth`` from ``p``; on the face, at least ``reach``. ``sigma`` [m]
        is the depth's uncertainty."""
        expected = np.maximum(0.0, reach - self._distance(p))
        self._normalise(np.exp(-0.5 * ((depth - expected) / sigma) ** 2))

    def bearing(self, p: ArrayLike, towards: ArrayLike, *, kappa: float) -> None:
        """The hole lies towards unit vector ``towards`` from ``p``, with concentration ``kappa``
        (about 1 / sigma^2 of the bearing [rad])."""
        rel = self.points - np.asarray(p, dtype=float)
        dist = np.linalg.norm(rel, axis=1)
        cos = (rel @ np.asarray(towards, dtype=float)) / np.maximum(dist, 1e-12)
        self._normalise(np.where(dist < self.capture, 1.0, np.exp(kappa * (cos - 1.0))))

    @property
    def mean(self) -> np.ndarray:
        """(2,) The belief's mean [m]."""
        return self.weights @ self.points

    @property
    def spread(self) -> float:
        """The belief's standard deviation, root of the covariance's trace [m]."""
        rel = self.points - self.mean
        return float(np.sqrt(self.weights @ np.einsum("ij,ij->i", rel, rel)))

    @property
    def most_likely(self) -> np.ndarray:
        """(2,) The particle of the highest weight [m] (where a ring-shaped belief's mean is not)."""
        return self.points[int(np.argmax(self.weights))].copy()

    def peak(self, radius: float) -> np.ndarray:
        """(2,) The weighted mean of the particles within ``radius`` [m] of the most likely one:
        the belief's mode, finer than its grid [m]."""
        near = self._distance(self.most_likely) <= radius
        w = self.weights[near]
        return (w @ self.points[near]) / w.sum()

    def capture_mass(self, p: ArrayLike) -> float:
        """The belief that a press at ``p`` is caught by the chamfer."""
        return float(self.weights[self._distance(p) < self.capture].sum())

    def best_probe(self) -> np.ndarray:
        """(2,) The grid point whose capture disc holds the most belief [m]."""
        from scipy.signal import fftconvolve

        image = np.zeros(self._inside.size)
        image[self._inside] = self.weights
        mass = fftconvolve(image.reshape(self._shape), self._disc, mode="same").ravel()[self._inside]
        return self.points[int(np.argmax(mass))].copy()
