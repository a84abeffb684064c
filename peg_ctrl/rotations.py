"""Quaternion helpers (MuJoCo's w, x, y, z convention) that return new arrays."""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["quat_mul", "rotate", "rotate_inv"]


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
