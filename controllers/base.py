"""The controller template: one config base class, one controller base class.

A controller is a frozen :class:`ControllerConfig` subclass (its gains, limits and period, with a
registered ``name``) plus a :class:`ControllerBase` subclass that writes only its control law.
The base class does the rest once, for every controller: timing, saturation to the actuator
ranges, the jaw separation -> actuator byte map, the finiteness check and actuator packing.

Every controller satisfies the :class:`Controller` protocol: it gets the model at construction
and never steps or forwards the simulation; the episode loop owns time.
"""

from __future__ import annotations

import abc
import dataclasses
import math
import time
from collections.abc import Iterable, Sequence
from typing import Any, ClassVar, Generic, NamedTuple, Protocol, TypeVar

import mujoco
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.commands import JAW_SEP_MAX_M, GripperTarget
from peg_ctrl.errors import CommandError, ConfigError, DivergenceError, UnknownComponent
from peg_ctrl.sim.belief import Belief
from peg_ctrl.sim.jaw import JawCalibration, load_default
from peg_ctrl.sim.scene import BALL_ACTUATORS, JAW_ACTUATOR, SLIDE_ACTUATORS
from peg_ctrl.sim.sensing import lowpass_alpha
from peg_ctrl.sim.state import ControlState
from peg_ctrl.timing import control_decimation

__all__ = [
    "Controller",
    "ControllerBase",
    "ControllerConfig",
    "ControlOutput",
    "Diagnostics",
    "Effort",
    "SolveTiming",
    "ActuatorMap",
    "InvalidField",
    "check_target",
    "check_positive",
    "check_multiple",
]

#: The controller an experiment file gets when its ``controller`` mapping names none.
DEFAULT_CONTROLLER = "pd"

_C = TypeVar("_C", bound="ControllerConfig")
_Cfg = TypeVar("_Cfg", bound="ControllerConfig")


class Diagnostics(NamedTuple):
    """Per-call diagnostics for the logs: wall time of ``compute`` [s], solver status, iterations."""

    solve_time_s: float = 0.0
    status: str = "ok"
    iterations: int = 0


class SolveTiming(NamedTuple):
    """Wall times [s] of one of a controller's optimisers over an episode, and how often it
    runs (``period_s``, simulated) — for the episode summary (p50/p99, real-time factor)."""

    name: str
    period_s: float
    times_s: list[float]


class ControlOutput(NamedTuple):
    """Actuator controls ``ctrl`` (nu,) in model order, plus diagnostics.

    (NamedTuples rather than frozen dataclasses: they are built at 1 kHz.)
    """

    ctrl: Sequence[float]
    diagnostics: Diagnostics = Diagnostics()


class Effort(NamedTuple):
    """What a control law returns: the base's generalised forces, before saturation.

    ``force_world`` (3,) slide forces [N] (world axes); ``torque_body`` (3,) ball-joint torques
    [N m] (gripper frame); ``status`` and ``iterations`` of the law's own solver, if any
    (``"hold"`` between the solves of a slower-rate solver).
    """

    force_world: Sequence[float]
    torque_body: Sequence[float]
    status: str = "ok"
    iterations: int = 0


class Controller(Protocol):
    """A controller gets the model at construction and never steps or forwards the simulation.

    The episode loop owns time: it calls :meth:`reset` once with the initial state, then
    :meth:`compute` every control period and writes ``ControlOutput.ctrl`` into ``data.ctrl``.
    A controller that declares :attr:`observes_belief` hears, through :meth:`observe_belief`,
    each belief a task with the ``belief`` capability states.
    """

    @property
    def name(self) -> str:
        """The registered name."""
        ...

    @property
    def control_dt(self) -> float:
        """Control period [s], a whole multiple of the physics timestep."""
        ...

    @property
    def observes_belief(self) -> bool:
        """Whether :meth:`observe_belief` uses the task's belief (a class attribute)."""
        ...

    def reset(self, state: ControlState) -> None: ...

    def compute(self, state: ControlState, target: GripperTarget) -> ControlOutput: ...

    def observe_belief(self, belief: Belief | None) -> None:
        """The task's new belief (None: it states none); called before :meth:`compute`."""
        ...

    def timings(self) -> list[SolveTiming]:
        """The wall times of the controller's optimisers since reset (none for a plain law)."""
        ...


class ActuatorMap:
    """Indices of the slide, ball and jaw actuators in ``data.ctrl``, resolved once.

    ``slide_limit`` (3,) [N] and ``ball_limit`` (3,) [N m] are the symmetric actuator ranges.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.nu = model.nu
        self.slides = np.array([model.actuator(n).id for n in SLIDE_ACTUATORS])
        self.ball = np.array([model.actuator(n).id for n in BALL_ACTUATORS])
        self.jaw = int(model.actuator(JAW_ACTUATOR).id)
        self.slide_limit = model.actuator_ctrlrange[self.slides, 1].copy()
        self._slides = [int(i) for i in self.slides]
        self._ball = [int(i) for i in self.ball]
        self.ball_limit = model.actuator_ctrlrange[self.ball, 1].copy()

    def pack(
        self, force_world: Sequence[float], torque_body: Sequence[float], jaw_byte: float
    ) -> list[float]:
        """``ctrl`` (nu,) from slide forces [N], ball torques [N m] and the jaw byte."""
        values = [0.0] * self.nu
        for i, f in zip(self._slides, force_world, strict=True):
            values[i] = f
        for i, t in zip(self._ball, torque_body, strict=True):
            values[i] = t
        values[self.jaw] = jaw_byte
        return values


def check_target(target: GripperTarget) -> None:
    """Raise :class:`CommandError` naming the entries if ``target`` has a non-finite one.

    ``GripperTarget`` validates on construction, but ``GripperTarget.trusted`` does not, so the
    controllers re-check cheaply (one sum) where it matters.
    """
    total = (
        float(target.p_world.sum())
        + float(target.quat_world.sum())
        + float(target.v_world.sum())
        + float(target.omega_body.sum())
        + float(target.jaw_sep_m)
        + float(target.force_world.sum())
        + float(target.torque_world.sum())
    )
    if not math.isfinite(total):  # a NaN or inf anywhere makes the sum non-finite
        raise CommandError(
            f"target must be finite, got p_world={target.p_world.tolist()}, "
            f"quat_world={target.quat_world.tolist()}, v_world={target.v_world.tolist()}, "
            f"omega_body={target.omega_body.tolist()}, jaw_sep_m={target.jaw_sep_m}, "
            f"force_world={target.force_world.tolist()}, torque_world={target.torque_world.tolist()}"
        )


def _check_pose(target: GripperTarget) -> None:
    """Raise :class:`CommandError` for a jaw separation outside [0, 0.085] m or a quaternion that
    is not of unit norm (a NaN in either included): the checks ``GripperTarget.trusted`` skips,
    which the control laws would otherwise clip or read as no rotation. Plain floats: every
    control step runs it."""
    w, x, y, z = target.quat_world.tolist()
    norm_sq = w * w + x * x + y * y + z * z
    jaw = target.jaw_sep_m
    if not (0.0 <= jaw <= JAW_SEP_MAX_M and abs(norm_sq - 1.0) <= _UNIT_TOLERANCE):
        if not 0.0 <= jaw <= JAW_SEP_MAX_M:
            raise CommandError(f"target jaw_sep_m must be in [0, {JAW_SEP_MAX_M}] m, got {jaw!r}")
        raise CommandError(
            f"target quat_world must be a unit quaternion, got {[w, x, y, z]} (norm {math.sqrt(norm_sq):.6g})"
        )


_UNIT_TOLERANCE = 1e-6  # on the squared norm of a target quaternion


# -- configs -----------------------------------------------------------------------------------


class InvalidField(ConfigError):
    """A config field with a bad value: ``<owner>.<field>: <reason>``.

    ``ControllerConfig.select`` re-raises it under the dotted path the config was loaded from
    (``controller.kp_pos``), which ``__post_init__`` cannot know.
    """

    def __init__(self, owner: str, field: str, reason: str) -> None:
        super().__init__(f"{owner}.{field}: {reason}")
        self.owner = owner
        self.field = field
        self.reason = reason


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_positive(config: ControllerConfig, names: Iterable[str]) -> None:
    """Require each named field to be a finite number > 0, or a non-empty tuple of them.

    Raises:
        InvalidField: naming ``<config.name>.<field>``.
    """
    for field in names:
        value = getattr(config, field)
        values = value if isinstance(value, tuple) else (value,)
        if not values or not all(_is_number(v) and math.isfinite(v) and v > 0 for v in values):
            raise InvalidField(config.name, field, f"must be finite and > 0, got {value!r}")


def check_multiple(config: ControllerConfig, field: str) -> int:
    """Require field ``field`` (a period [s]) to be a whole multiple of ``config.control_dt``.

    Returns the ratio. Raises :class:`InvalidField` naming ``<config.name>.<field>``.
    """
    value = getattr(config, field)
    try:
        return control_decimation(value, config.control_dt)
    except ConfigError:
        raise InvalidField(
            config.name, field, f"must be a whole multiple of control_dt {config.control_dt} s, got {value!r}"
        ) from None


@dataclasses.dataclass(frozen=True, kw_only=True)
class ControllerConfig:
    """Base of every controller's config: a frozen dataclass naming its controller.

    Subclasses set ``name`` (the registry key) and ``GAINS`` (the fields that ``gain_scale``
    perturbs, float or tuple-valued), add their fields with units in comments, and implement
    :meth:`build`. Every numeric field (a number or a tuple of numbers) must be finite and > 0;
    ``__post_init__`` checks that, subclasses add their own checks after calling it.
    """

    name: ClassVar[str]
    GAINS: ClassVar[tuple[str, ...]] = ()
    VECTORS: ClassVar[tuple[str, ...]] = ()  # 3-vector fields of any sign (points, offsets) [m]
    # Number fields that may be 0; a subclass's add to its bases' (collected along the MRO).
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = ("velocity_filter_hz", "position_filter_hz")
    control_dt: float = 0.001  # control period [s], a whole multiple of the physics timestep
    # A first-order low-pass on the sensed velocities before the control law [Hz]; 0: none. A
    # robot's velocities are differences of encoder positions: noisy (docs/sensing.md).
    velocity_filter_hz: float = 0.0
    # The sensed position through a first-order observer of this bandwidth [Hz]: predicted with
    # the (filtered) sensed velocity, corrected towards each reading; 0: the reading as is. A
    # pose sensed with noise on every reading makes a stiff law shake the hand by as much. It
    # quiets a position whose noise is independent of the velocity's (the studies' model).
    position_filter_hz: float = 0.0

    def __post_init__(self) -> None:
        numeric = []
        non_negative = {name for cls in type(self).__mro__ for name in vars(cls).get("NON_NEGATIVE", ())}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None or isinstance(value, (bool, str, ControllerConfig)) or f.name in self.VECTORS:
                continue
            if f.name in non_negative:
                if not (_is_number(value) and math.isfinite(value) and value >= 0):
                    raise InvalidField(self.name, f.name, f"must be finite and >= 0, got {value!r}")
                continue
            numeric.append(f.name)
        check_positive(self, numeric)
        for field in self.VECTORS:
            value = getattr(self, field)
            if not (
                isinstance(value, tuple)
                and len(value) == 3
                and all(_is_number(v) and math.isfinite(v) for v in value)
            ):
                raise InvalidField(self.name, field, f"must be 3 finite numbers, got {value!r}")

    def build(self, model: mujoco.MjModel) -> Controller:
        """The controller this config describes, for ``model``."""
        raise NotImplementedError(f"{type(self).__name__} does not build a controller")

    def scaled(self: _C, factor: float) -> _C:
        """A copy with every ``GAINS`` field, and every nested controller config's, times ``factor``.

        Tuple-valued gains are scaled element-wise; ``factor == 1.0`` returns an equal config.
        """
        if not (_is_number(factor) and math.isfinite(factor) and factor > 0):
            raise ConfigError(f"gain scale factor must be finite and > 0, got {factor!r}")
        changes: dict[str, Any] = {}
        for field in self.GAINS:
            value = getattr(self, field)
            changes[field] = tuple(v * factor for v in value) if isinstance(value, tuple) else value * factor
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, ControllerConfig):
                changes[f.name] = value.scaled(factor)
        return dataclasses.replace(self, **changes)

    @classmethod
    def select(cls, data: object, *, prefix: str = "controller.") -> ControllerConfig:
        """The config named by ``data``: a name, a mapping ``{"name": ..., <fields>}`` or a config.

        On the base class the name picks the class from ``peg_ctrl.controllers.REGISTRY``; a
        missing name means ``"pd"``. On a subclass (a composite's ``inner`` field) the name may be
        left out and must otherwise name that class. Fields load with
        :func:`peg_ctrl.config.load`.

        Raises:
            UnknownComponent: for a name not in the registry (the message lists the known ones).
            ConfigError: for a bad field name or value, naming it as ``<prefix><field>``.
        """
        from peg_ctrl.config import load, named_fields
        from peg_ctrl.controllers import REGISTRY  # here: the registry imports this module

        if isinstance(data, ControllerConfig):
            if not isinstance(data, cls):
                where = prefix.rstrip(".") or "controller"
                raise ConfigError(f"{where}: expected a {cls.__name__}, got {type(data).__name__}")
            return data
        default = cls.__dict__.get("name", DEFAULT_CONTROLLER)
        name, fields = named_fields(data, kind="controller", default=default, prefix=prefix)
        if name not in REGISTRY:
            raise UnknownComponent("controller", name, REGISTRY, where=prefix.rstrip("."))
        config_cls = REGISTRY[name]
        if not issubclass(config_cls, cls):
            raise ConfigError(f"{prefix}name: expected {default!r}, got {name!r}")
        try:
            return load(config_cls, fields, prefix=prefix)
        except InvalidField as exc:
            raise ConfigError(f"{prefix}{exc.field}: {exc.reason}") from None


# -- controllers -------------------------------------------------------------------------------


def _clip(value: float, limit: float) -> float:
    return limit if value > limit else (-limit if value < -limit else value)


class ControllerBase(abc.ABC, Generic[_Cfg]):
    """Template for every controller: subclasses implement :meth:`control_law` (and ``_reset``).

    :meth:`compute` times the call, runs the law, checks the result is finite, saturates it to
    the actuator ranges, maps the jaw separation to its actuator byte and packs ``ctrl``.

    A subclass that uses the task's belief sets ``observes_belief = True`` and overrides
    :meth:`observe_belief`; the one without the other is refused when the class is defined.

    Attributes:
        config: The controller's config.
        control_dt: Control period in [s] (``config.control_dt``).
    """

    name: ClassVar[str]
    observes_belief: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        overrides = cls.observe_belief is not ControllerBase.observe_belief
        if overrides != cls.observes_belief:
            raise TypeError(
                f"{cls.__name__}: observes_belief = {cls.observes_belief} but observe_belief is "
                f"{'overridden' if overrides else 'not overridden'}; declare both or neither"
            )

    def __init__(
        self, model: mujoco.MjModel, config: _Cfg, *, jaw_calibration: JawCalibration | None = None
    ) -> None:
        self.config: _Cfg = config
        self.control_dt = config.control_dt
        self._act = ActuatorMap(model)
        self._jaw = jaw_calibration or load_default()
        self._slide_lim = tuple(float(v) for v in self._act.slide_limit)
        self._ball_lim = tuple(float(v) for v in self._act.ball_limit)
        self._jaw_cache = (math.nan, 0.0)  # (separation [m], byte): targets hold it for long
        hz = config.velocity_filter_hz
        self._v_alpha = lowpass_alpha(hz, config.control_dt) if hz > 0 else 0.0
        self._v_filtered: NDArray[np.float64] | None = None
        hz = config.position_filter_hz
        self._p_alpha = lowpass_alpha(hz, config.control_dt) if hz > 0 else 0.0
        self._p_estimate: NDArray[np.float64] | None = None

    def reset(self, state: ControlState) -> None:
        """Start an episode from ``state``: clears the controller's memory."""
        self._jaw_cache = (math.nan, 0.0)
        self._v_filtered = None
        self._p_estimate = None
        self._reset(self._filtered(state))

    def _filtered(self, state: ControlState) -> ControlState:
        """``state`` with its velocities through the ``velocity_filter_hz`` low-pass and its
        position through the ``position_filter_hz`` observer (each as is without one)."""
        if self._v_alpha:
            v = np.concatenate([state.v_world, state.omega_body])
            if self._v_filtered is None:
                self._v_filtered = v
            else:
                self._v_filtered += self._v_alpha * (v - self._v_filtered)
            state = state._replace(
                v_world=self._v_filtered[:3].copy(), omega_body=self._v_filtered[3:].copy()
            )
        if self._p_alpha:
            if self._p_estimate is None:
                self._p_estimate = np.array(state.p_world, dtype=float)
            else:
                self._p_estimate += self.control_dt * np.asarray(state.v_world)
                self._p_estimate += self._p_alpha * (state.p_world - self._p_estimate)
            state = state._replace(p_world=self._p_estimate.copy())
        return state

    def _reset(self, state: ControlState) -> None:
        """Clear the control law's own memory (filters, integrators, warm starts)."""

    def timings(self) -> list[SolveTiming]:
        """The wall times of the controller's optimisers since reset (none by default)."""
        return []

    def observe_belief(self, belief: Belief | None) -> None:
        """Ignored: a controller that uses the task's belief declares ``observes_belief``."""

    @abc.abstractmethod
    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        """Slide forces and ball torques for ``state`` tracking ``target``, before saturation."""

    def compute(self, state: ControlState, target: GripperTarget) -> ControlOutput:
        """Actuator controls for ``state`` tracking ``target``. Do not override.

        Raises:
            CommandError: if the control is non-finite because the target is.
            DivergenceError: if the control is non-finite otherwise (a diverged state).
        """
        t0 = time.perf_counter()
        _check_pose(target)
        effort = self.control_law(self._filtered(state), target)
        force, torque = effort.force_world, effort.torque_body
        jaw_sep = float(target.jaw_sep_m)
        if jaw_sep != self._jaw_cache[0]:
            self._jaw_cache = (jaw_sep, self._jaw.sep_to_byte(jaw_sep))
        jaw_byte = self._jaw_cache[1]
        # Before saturation, which would turn an infinite effort into a finite one.
        if not math.isfinite(sum(force) + sum(torque) + jaw_byte):
            check_target(target)  # names the bad entry
            raise DivergenceError(f"non-finite control from state at t={state.t}: {state}")
        fl, tl = self._slide_lim, self._ball_lim
        fx, fy, fz = force
        tx, ty, tz = torque
        ctrl = self._act.pack(
            (_clip(fx, fl[0]), _clip(fy, fl[1]), _clip(fz, fl[2])),
            (_clip(tx, tl[0]), _clip(ty, tl[1]), _clip(tz, tl[2])),
            jaw_byte,
        )
        return ControlOutput(ctrl, Diagnostics(time.perf_counter() - t0, effort.status, effort.iterations))
