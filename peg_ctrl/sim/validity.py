"""Physical validity experiments: a held peg pushed into the hole with a constant force.

These experiments check the contact model, not a controller. The peg is held upright in the
closed gripper (as after the pick-and-place task's turn) with its lower end ``start_height``
above the hole mouth, offset by ``lateral_error`` along world X and tilted by ``tilt`` about
world Y (about its lower end). The gripper base then pushes down with ``force`` newtons on top
of gravity compensation while its orientation is held by a stiff joint-space PD and its
lateral motion is *free* (zero lateral force, only the slides' joint damping): an ideally
compliant hand, so whatever the peg does laterally is the contact's doing.

Measured per run: final and deepest insertion depth, peak and steady peg-block force, steady
penetration of the peg into the block (true geometric overlap, the margin subtracted), the
peg's slip in the pads during the push and the solver's iterations.

``peg-sim validity`` runs the standard battery (clearance curve, chamfer capture, tilt wedging,
penetration) and writes a table and plots; the tests in ``tests/sim/test_validity.py`` assert the bars.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.errors import ConfigError
from peg_ctrl.sim.assets import AssetParams
from peg_ctrl.sim.force_metric import SUSTAIN_WINDOW, SustainedPeak
from peg_ctrl.sim.grasp_start import PUSH_SPEED, Q_TURN, HeldRig, close_on_held_peg, place_held_peg
from peg_ctrl.sim.physics import PhysicsProfile, profile
from peg_ctrl.sim.rotations import quat_mul
from peg_ctrl.sim.scene import (
    PEG_LYING_QUAT,
    SceneConfig,
    build_model,
)

__all__ = [
    "PushCase",
    "PushResult",
    "held_push",
    "wedging_depth",
    "wedging_tilt",
    "Trial",
    "clearance_study",
    "chamfer_cases",
    "tilt_cases",
    "penetration_case",
    "CLEARANCES",
    "INSERTED_DEPTH",
    "LATERAL_RANGE",
    "TILT_RANGE",
    "PUSH_SPEED",
]

INSERTED_DEPTH = 0.040  # a push "inserts" when the peg ends at least this deep [m]
LATERAL_RANGE = 0.05e-3  # the clearance study's start lateral error: uniform within +- this [m]
TILT_RANGE = math.radians(0.05)  # ... and its start tilt [rad]
_SETTLE_TIME = 0.3  # peg free in the closed jaw before the push [s]
_STEADY_WINDOW = 0.2  # the last seconds of the push over which steady values are taken [s]


@dataclasses.dataclass(frozen=True)
class PushCase:
    """One held push. Lengths in [m], angles in [rad], force in [N], time in [s]."""

    clearance: float = 0.0001  # radial; negative is an interference fit
    chamfer: float = 0.0
    lateral_error: float = 0.0  # peg axis from the hole axis along +X at the start
    tilt: float = 0.0  # about world Y, through the peg's lower end
    force: float = 10.0  # downward push on top of gravity compensation
    duration: float = 2.0  # of the push (the descent runs at 30 mm/s)
    start_height: float = 0.001  # peg lower end above the mouth at the start
    grip_above_centre: float = 0.02  # pads this far above the peg's centre: the fingers clear
    # the block top until the peg stands on the table (at the centre they touch it at 36 mm deep)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.force) and self.force > 0):
            raise ConfigError(f"push force must be > 0 N, got {self.force!r}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ConfigError(f"push duration must be > 0 s, got {self.duration!r}")
        if not (math.isfinite(self.tilt) and abs(self.tilt) < 0.5):
            raise ConfigError(f"tilt must be within +-0.5 rad, got {self.tilt!r}")

    def assets(self, base: AssetParams | None = None) -> AssetParams:
        """``base`` (default: the default assets) with this case's clearance and chamfer."""
        return dataclasses.replace(base or AssetParams(), clearance=self.clearance, chamfer=self.chamfer)


@dataclasses.dataclass(frozen=True)
class PushResult:
    """What one held push measured. Lengths in [m], forces in [N]."""

    case: PushCase
    profile: str
    depth: float  # peg lower end below the mouth at the end
    max_depth: float
    peak_force: float  # peg-block contact force of one physics step (the solver's peak), whole push
    peak_force_10ms: float  # the largest mean peg-block force over any 10 ms (force_metric)
    steady_force: float  # mean over the last _STEADY_WINDOW
    penetration: float  # deepest true overlap over the last _STEADY_WINDOW (>= 0)
    steady_distance: float  # mean closest peg-block surface distance, last window (< 0: overlap,
    # > 0: held off, as the seed's 1 mm margin holds a peg above the top face); nan without contact
    peak_penetration: float  # deepest true overlap over the whole push
    slip: float  # peg displacement in the pad frame over the push
    final_tilt: float  # peg axis from vertical at the end [rad]
    max_solver_iterations: int
    steps: int  # physics steps of the push
    wall_time_s: float  # of the push, including the measurements
    trace: NDArray[np.float64] | None = None  # (steps, 4): time [s], depth [m], force [N], overlap [m]

    def inserted(self, depth: float = INSERTED_DEPTH) -> bool:
        return self.depth >= depth

    @property
    def us_per_step(self) -> float:
        return 1e6 * self.wall_time_s / self.steps

    def summary(self) -> dict[str, float | int | str]:
        """Plain numbers for JSON (no trace)."""
        out: dict[str, float | int | str] = {
            f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in ("case", "trace")
        }
        out.update({f"case_{k}": v for k, v in dataclasses.asdict(self.case).items()})
        out["us_per_step"] = self.us_per_step
        return out


def wedging_depth(clearance: float, tilt: float, radius: float = 0.010) -> float:
    """Deepest a rigid peg of ``radius`` tilted by ``tilt`` [rad] enters a hole of radius
    ``radius + clearance`` before touching both walls (2-D, two-point contact): the axial
    extent ``l`` at which ``l sin(tilt) + d cos(tilt) = D``."""
    d, big_d = 2.0 * radius, 2.0 * (radius + clearance)
    s = math.sin(abs(tilt))
    if s == 0.0:
        return math.inf
    return max(0.0, (big_d - d * math.cos(tilt)) / s)


def wedging_tilt(clearance: float, depth: float, radius: float = 0.010) -> float:
    """The tilt [rad] at which :func:`wedging_depth` equals ``depth`` [m] (bisection)."""
    lo, hi = 0.0, 0.5
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if wedging_depth(clearance, mid, radius) > depth:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _initial_state(
    model: mujoco.MjModel, data: mujoco.MjData, rig: HeldRig, scene: SceneConfig, case: PushCase
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gripper and peg poses for the case; returns the gripper's (position, orientation) target."""
    q_tilt = np.array([math.cos(case.tilt / 2), 0.0, math.sin(case.tilt / 2), 0.0])  # about Y
    q_grip = quat_mul(q_tilt, Q_TURN)
    q_peg = quat_mul(q_grip, np.asarray(PEG_LYING_QUAT))
    hx, hy = scene.hole_xy
    bottom = np.array([hx + case.lateral_error, hy, scene.assets.block_size[2] + case.start_height])
    return place_held_peg(
        model,
        data,
        rig,
        scene,
        bottom=bottom,
        q_grip=q_grip,
        q_peg=q_peg,
        grip_above_centre=case.grip_above_centre,
    )


def held_push(
    case: PushCase,
    physics: str | PhysicsProfile,
    *,
    scene: SceneConfig | None = None,
    model: mujoco.MjModel | None = None,
    trace: bool = False,
    on_finish: Callable[[mujoco.MjModel, mujoco.MjData], None] | None = None,
) -> PushResult:
    """Grasp, then push ``case.force`` newtons down for ``case.duration`` seconds; measure.

    ``model`` (compiled for this case's geometry and profile) may be passed to skip compiling;
    ``on_finish(model, data)`` sees the final state (the benchmark times steps from it).
    """
    prof = profile(physics)
    base = scene or SceneConfig()
    scene = dataclasses.replace(base, assets=case.assets(base.assets))
    if model is None:
        model = build_model(scene, prof)
    data = mujoco.MjData(model)
    rig = HeldRig(model)
    pinch, q_grip = _initial_state(model, data, rig, scene, case)
    close_on_held_peg(model, data, rig, pinch, q_grip)
    dt = model.opt.timestep
    for _ in range(round(_SETTLE_TIME / dt)):
        rig.control(data, pinch, q_grip, None)
        mujoco.mj_step(model, data)
    ref = rig.peg_in_pad(data)
    top = scene.assets.block_size[2]
    lower = model.site("peg_bottom").id, model.site("peg_top").id
    meter = _PushMeter(n_push=round(case.duration / dt), n_steady=max(1, round(_STEADY_WINDOW / dt)), dt=dt)
    meter.rows = np.zeros((meter.n_push, 4)) if trace else None
    started = time.perf_counter()
    for step in range(meter.n_push):
        rig.control(data, pinch, q_grip, case.force)
        mujoco.mj_step(model, data)
        force, pen, dist = rig.peg_block_contact(data)
        z = min(data.site_xpos[lower[0], 2], data.site_xpos[lower[1], 2])
        slip = float(np.linalg.norm(rig.peg_in_pad(data) - ref))
        meter.add(step, top - z, force, pen, dist, slip, int(data.solver_niter[0]))
    axis = data.xmat[rig.peg].reshape(3, 3)[:, 2]
    if on_finish is not None:
        on_finish(model, data)
    return meter.result(
        case, prof.name, float(math.acos(min(1.0, abs(axis[2])))), time.perf_counter() - started
    )


@dataclasses.dataclass
class _PushMeter:
    """What a push measures, step by step: depth, peaks, slip, and the steady window's means."""

    n_push: int
    n_steady: int
    dt: float
    depth: float = 0.0
    max_depth: float = 0.0
    peak_force: float = 0.0
    peak_pen: float = 0.0
    slip: float = 0.0
    steady_pen: float = 0.0
    max_iter: int = 0
    steady_forces: list[float] = dataclasses.field(default_factory=list)
    steady_dist: list[float] = dataclasses.field(default_factory=list)
    rows: NDArray[np.float64] | None = None
    sustained: SustainedPeak = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        self.sustained = SustainedPeak(self.dt, SUSTAIN_WINDOW)

    def add(
        self, step: int, depth: float, force: float, pen: float, dist: float, slip: float, niter: int
    ) -> None:
        """One physics step of the push."""
        self.depth = depth
        self.max_depth = max(self.max_depth, depth)
        self.peak_force = max(self.peak_force, force)
        self.sustained.extend((force,))
        self.peak_pen = max(self.peak_pen, pen)
        self.slip = max(self.slip, slip)
        self.max_iter = max(self.max_iter, niter)
        if self.rows is not None:
            self.rows[step] = (step * self.dt, depth, force, pen)
        if step >= self.n_push - self.n_steady:
            self.steady_forces.append(force)
            self.steady_pen = max(self.steady_pen, pen)
            if not math.isnan(dist):
                self.steady_dist.append(dist)

    def result(self, case: PushCase, profile: str, final_tilt: float, wall_time_s: float) -> PushResult:
        """The push's result."""
        return PushResult(
            case=case,
            profile=profile,
            depth=float(self.depth),
            max_depth=float(self.max_depth),
            peak_force=float(self.peak_force),
            peak_force_10ms=self.sustained.peak,
            steady_force=float(np.mean(self.steady_forces)),
            penetration=float(self.steady_pen),
            steady_distance=float(np.mean(self.steady_dist)) if self.steady_dist else math.nan,
            peak_penetration=float(self.peak_pen),
            slip=self.slip,
            final_tilt=final_tilt,
            max_solver_iterations=self.max_iter,
            steps=self.n_push,
            wall_time_s=wall_time_s,
            trace=self.rows,
        )


# -- the standard battery -------------------------------------------------------------------------
CLEARANCES = (0.25e-3, 0.1e-3, 0.05e-3, 0.02e-3, 0.0, -0.02e-3)  # radial [m]


@dataclasses.dataclass(frozen=True)
class Trial:
    """One randomised push of the clearance study."""

    clearance: float
    trial: int
    lateral_error: float
    tilt: float
    result: PushResult

    @property
    def inserted(self) -> bool:
        return self.result.inserted()


def clearance_study(
    physics: str | PhysicsProfile,
    clearances: tuple[float, ...] = CLEARANCES,
    *,
    trials: int = 10,
    seed: int = 0,
    lateral_range: float = LATERAL_RANGE,
    tilt_range: float = TILT_RANGE,
    on_result: Callable[[Trial], None] | None = None,
) -> list[Trial]:
    """Held pushes at each clearance: ``trials`` runs with the start's lateral error and tilt
    drawn uniformly within ``±lateral_range`` [m] and ``±tilt_range`` [rad] (trial 0 is exact).

    A real fixture places a part to a few hundredths of a millimetre and a fraction of a degree;
    the spread turns the outcome at each clearance into a rate. Trial 0 keeps its trace.
    """
    prof = profile(physics)
    rng = np.random.default_rng(seed)
    draws = [(0.0, 0.0)] + [
        (float(rng.uniform(-lateral_range, lateral_range)), float(rng.uniform(-tilt_range, tilt_range)))
        for _ in range(trials - 1)
    ]
    out = []
    for c in clearances:
        case0 = PushCase(clearance=c)
        model = build_model(dataclasses.replace(SceneConfig(), assets=case0.assets()), prof)
        for i, (e, tilt) in enumerate(draws):
            case = dataclasses.replace(case0, lateral_error=e, tilt=tilt)
            trial = Trial(c, i, e, tilt, held_push(case, prof, model=model, trace=i == 0))
            out.append(trial)
            if on_result is not None:
                on_result(trial)
    return out


def chamfer_cases(width: float = 1.0e-3, clearance: float = 0.1e-3) -> list[tuple[PushCase, bool | None]]:
    """Lateral errors around a chamfer of ``width`` [m]: (case, expected capture).

    Expected: captured below ``width - 0.1 mm``, not captured above ``width + clearance + 0.1 mm``
    (the peg's rim lands on the flat top); None in between (the rim lands on the chamfer's edge).
    """
    errors = (0.3e-3, 0.6e-3, width - 0.15e-3, width, width + clearance + 0.15e-3, width + 0.6e-3)
    cases = []
    for e in errors:
        if e < width - 0.1e-3:
            expected: bool | None = True
        elif e > width + clearance + 0.1e-3:
            expected = False
        else:
            expected = None
        cases.append((PushCase(clearance=clearance, chamfer=width, lateral_error=e), expected))
    return cases


def tilt_cases(clearance: float = 0.1e-3) -> list[tuple[PushCase, float]]:
    """Tilts well below and above the limit for a 40 mm insertion: (case, geometric depth [m])."""
    limit = wedging_tilt(clearance, INSERTED_DEPTH)
    tilts = (limit / 3.0, 3.5 * limit, 7.0 * limit)
    return [(PushCase(clearance=clearance, tilt=t), wedging_depth(clearance, t)) for t in tilts]


def penetration_case() -> PushCase:
    """The peg's flat end pushed on the block's top face, 25 mm off the hole axis: all of it on
    the flat, clear of the hole."""
    return PushCase(clearance=0.1e-3, lateral_error=0.025)
