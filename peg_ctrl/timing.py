"""Control and physics periods."""

from __future__ import annotations

import math

from peg_ctrl.errors import ConfigError

__all__ = ["control_decimation"]


def control_decimation(control_dt: float, timestep: float) -> int:
    """Physics steps per control step.

    Args:
        control_dt: Control period in [s]; must be a whole multiple of ``timestep``.
        timestep: Physics timestep in [s].

    Raises:
        ConfigError: if ``control_dt`` is not finite and positive, or not a whole multiple.
    """
    if not (math.isfinite(control_dt) and control_dt > 0):
        raise ConfigError(f"control_dt must be finite and > 0 s, got {control_dt!r}")
    ratio = control_dt / timestep
    n = round(ratio)
    if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
        raise ConfigError(
            f"control_dt {control_dt} s is not a whole multiple of the physics timestep {timestep} s"
        )
    return int(n)
