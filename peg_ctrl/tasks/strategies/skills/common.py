"""What the skills share: the wrench axes a touch frees, and small geometry."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PRESS_AXES", "LAND_AXES", "SLIDE_AXES", "NO_AXES", "distance", "angle"]

_Vec = np.ndarray

PRESS_AXES = (False, False, True, False, False, False)  # press along z, the pose held otherwise
LAND_AXES = (True, True, True, False, False, False)  # press along z, lateral forces free
SLIDE_AXES = (True, True, False, False, False, False)  # lateral forces free, z and orientation tracked
NO_AXES = (False,) * 6  # the pose tracked on every axis


def distance(a: _Vec, b: _Vec) -> float:
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))


def angle(a: _Vec, b: _Vec) -> float:
    """The angle between two orientations [rad]."""
    return 2.0 * math.acos(min(1.0, abs(float(np.dot(a, b)))))
