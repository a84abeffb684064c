"""Quaternion helpers (MuJoCo's w, x, y, z convention) that return new arrays, and their plain-float
twins for code that runs every control step (:func:`rotate_floats`, :func:`cross_floats`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "quat_mul",
    "rotate",
    "rotate_inv",
    "cross",
    "yaw_quat",
    "rotate_floats",
    "cross_floats",
    "Floats3",
]

Floats3 = tuple[float, float, float]


def quat_mul(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """The product ``a * b`` (``b`` applied first)."""
    out = np.empty(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def rotate(quat: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``v`` rotated by ``quat``."""
    out = np.empty(3)
    mujoco.mju_rotVecQuat(out, v, quat)
    return out


def rotate_inv(quat: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``v`` rotated by the inverse of ``quat`` (a world vector into the frame ``quat``)."""
    q_inv = np.empty(4)
    mujoco.mju_negQuat(q_inv, quat)
    return rotate(q_inv, v)


def yaw_quat(yaw: float) -> NDArray[np.float64]:
    """The rotation by ``yaw`` [rad] about world Z."""
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a x b`` for 3-vectors: the same arithmetic as ``np.cross``, without its axis handling
    (~40 µs a call at 1 kHz control, where this runs a few times per step)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def rotate_floats(quat: Sequence[float], v: Sequence[float]) -> Floats3:
    """``v`` rotated by the unit ``quat`` (``[w, x, y, z]``), in plain floats: ``mju_rotVecQuat``'s
    arithmetic operation for operation, so the same bits as :func:`rotate` (a zero vector gives
    zeros, the identity a copy), without the two arrays a call of it costs. The inverse rotation
    is by ``(w, -x, -y, -z)``, as ``mju_negQuat`` gives it."""
    a, b, c = v
    if a == 0 and b == 0 and c == 0:
        return (0.0, 0.0, 0.0)
    w, x, y, z = quat
    if w == 1 and x == 0 and y == 0 and z == 0:
        return (a, b, c)
    t0 = w * a + y * c - z * b  # q_w v + q_xyz x v
    t1 = w * b + z * a - x * c
    t2 = w * c + x * b - y * a
    return (a + 2 * (y * t2 - z * t1), b + 2 * (z * t0 - x * t2), c + 2 * (x * t1 - y * t0))


def cross_floats(a: Sequence[float], b: Sequence[float]) -> Floats3:
    """``a x b`` in plain floats (the arithmetic of :func:`cross`)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
