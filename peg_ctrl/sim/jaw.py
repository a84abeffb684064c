"""Jaw calibration: actuator byte (0..255) <-> pad separation [m].

The 2F-85's four-bar linkage makes the map mildly nonlinear, so it is measured on the model
itself (:func:`measure`) and stored as a piecewise-linear table in
``peg_ctrl/data/jaw_calibration.json`` (regenerate with ``peg-sim calibrate --replace-packaged``).
"""

from __future__ import annotations

import copy
import dataclasses
import json
from collections.abc import Callable
from importlib import resources
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["JawCalibration", "measure", "fit", "load_default", "source_tree_path", "DEFAULT_PATH"]

DEFAULT_PATH = Path(str(resources.files("peg_ctrl") / "data" / "jaw_calibration.json"))
BYTE_MAX = 255.0


@dataclasses.dataclass(frozen=True)
class JawCalibration:
    """Piecewise-linear map between jaw byte and pad separation.

    ``bytes_`` (k,) strictly increasing in [0, 255]; ``sep_m`` (k,) strictly decreasing [m].
    """

    bytes_: NDArray[np.float64]
    sep_m: NDArray[np.float64]
    fit_max_error_m: float = float("nan")  # max |fit - measured| over all sweep samples [m]

    def __post_init__(self) -> None:
        b = np.asarray(self.bytes_, dtype=float)
        s = np.asarray(self.sep_m, dtype=float)
        if b.shape != s.shape or b.ndim != 1 or len(b) < 2:
            raise ValueError("calibration needs two 1-D arrays of equal length >= 2")
        if np.any(np.diff(b) <= 0) or np.any(np.diff(s) >= 0):
            raise ValueError("calibration bytes must increase and separations decrease strictly")
        object.__setattr__(self, "bytes_", b)
        object.__setattr__(self, "sep_m", s)
        # Reversed copies so np.interp gets increasing abscissae for the inverse map.
        object.__setattr__(self, "_sep_inc", s[::-1].copy())
        object.__setattr__(self, "_bytes_dec", b[::-1].copy())

    @property
    def sep_open_m(self) -> float:
        return float(self.sep_m[0])

    @property
    def sep_closed_m(self) -> float:
        return float(self.sep_m[-1])

    def byte_to_sep(self, byte: float) -> float:
        """Pad separation [m] at steady state for actuator command ``byte``."""
        return float(np.interp(byte, self.bytes_, self.sep_m))

    def sep_to_byte(self, sep_m: float) -> float:
        """Actuator command for separation ``sep_m`` [m]; below the closed separation gives 255."""
        return float(np.interp(sep_m, self._sep_inc, self._bytes_dec))  # type: ignore[attr-defined]

    def to_json(self) -> str:
        from peg_ctrl.io import to_json

        return to_json(
            {
                "bytes": [round(float(b), 6) for b in self.bytes_],
                "sep_m": [round(float(s), 9) for s in self.sep_m],
                "fit_max_error_m": self.fit_max_error_m,
            },
            indent=1,
        )

    @classmethod
    def from_file(cls, path: Path) -> JawCalibration:
        raw = json.loads(Path(path).read_text())
        return cls(
            np.asarray(raw["bytes"]), np.asarray(raw["sep_m"]), float(raw.get("fit_max_error_m", "nan"))
        )


def load_default() -> JawCalibration:
    """The calibration shipped with the package."""
    return JawCalibration.from_file(DEFAULT_PATH)


def source_tree_path() -> Path | None:
    """The shipped table's file in a source checkout (where ``peg-sim calibrate
    --replace-packaged`` regenerates it), or ``None`` in an installed copy, whose package files
    must not be rewritten."""
    package = Path(__file__).resolve().parents[1]
    if not (package.parent / "pyproject.toml").is_file():
        return None
    return package / "data" / "jaw_calibration.json"


def measure(
    model: mujoco.MjModel,
    *,
    bytes_: NDArray[np.float64],
    settle_s: float = 1.0,
    sep_of: Callable[[mujoco.MjData], float],
    jaw_actuator: int,
    progress: bool = False,
) -> NDArray[np.float64]:
    """Steady-state pad separation [m] for each byte, gravity off so the base stays put.

    Each point starts from the ``home`` keyframe and settles for ``settle_s`` [s]. With
    ``progress``, a bar counts the bytes (see :mod:`peg_ctrl.progress`).
    """
    from peg_ctrl.progress import progress as with_bar

    model = _copy_without_gravity(model)
    data = mujoco.MjData(model)
    out = np.empty(len(bytes_))
    steps = int(round(settle_s / model.opt.timestep))
    for i, b in enumerate(with_bar(bytes_, desc="calibrate", unit="byte", enabled=progress)):
        mujoco.mj_resetDataKeyframe(model, data, 0)
        data.ctrl[:] = 0.0
        data.ctrl[jaw_actuator] = b
        mujoco.mj_step(model, data, nstep=steps)
        mujoco.mj_forward(model, data)
        out[i] = sep_of(data)
    return out


def _copy_without_gravity(model: mujoco.MjModel) -> mujoco.MjModel:
    model = copy.copy(model)
    model.opt.gravity[:] = 0.0
    return model


def fit(bytes_: NDArray[np.float64], sep_m: NDArray[np.float64], *, n_knots: int = 52) -> JawCalibration:
    """Piecewise-linear fit through ``n_knots`` of the measured points (both ends included).

    The reported ``fit_max_error_m`` is the worst error over *all* measured points, so it
    measures how well the knots represent the sweep.
    """
    idx = np.unique(np.linspace(0, len(bytes_) - 1, n_knots).round().astype(int))
    knots_b = np.asarray(bytes_, dtype=float)[idx]
    knots_s = np.asarray(sep_m, dtype=float)[idx]
    # Enforce strict monotonicity (the closed end can plateau when the pads touch).
    keep = np.concatenate([[True], np.diff(knots_s) < -1e-7])
    knots_b, knots_s = knots_b[keep], knots_s[keep]
    pred = np.interp(bytes_, knots_b, knots_s)
    err = float(np.max(np.abs(pred - sep_m)))
    return JawCalibration(knots_b, knots_s, err)


def calibrate(
    model: mujoco.MjModel, *, n_samples: int = 103, n_knots: int = 52, progress: bool = False
) -> JawCalibration:
    """Sweep the jaw byte over [0, 255] on ``model`` and fit the piecewise-linear map (with a
    progress bar over the sweep if ``progress``)."""
    from peg_ctrl.sim.scene import JAW_ACTUATOR
    from peg_ctrl.sim.state import StateReader

    reader = StateReader(model)
    bytes_ = np.linspace(0.0, BYTE_MAX, n_samples)
    sep = measure(
        model,
        bytes_=bytes_,
        sep_of=reader.jaw_sep_m,
        jaw_actuator=model.actuator(JAW_ACTUATOR).id,
        progress=progress,
    )
    return fit(bytes_, sep, n_knots=n_knots)
