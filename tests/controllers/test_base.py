"""The controller template: timing, checks, saturation, jaw map and packing, for every controller."""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import mujoco
import numpy as np
import pytest

from peg_ctrl.commands import GripperTarget, euler_to_quat
from peg_ctrl.controllers import make_controller
from peg_ctrl.controllers.base import (
    ControllerBase,
    ControllerConfig,
    Diagnostics,
    Effort,
    InvalidField,
    check_multiple,
    check_positive,
    check_target,
)
from peg_ctrl.errors import CommandError, ConfigError, DivergenceError
from peg_ctrl.run.tracker import Tracker
from peg_ctrl.sim.jaw import load_default
from peg_ctrl.sim.state import ControlState

from ..conftest import HOME, target
from .conftest import NAMES


@dataclasses.dataclass(frozen=True, kw_only=True)
class ConstantConfig(ControllerConfig):
    name: ClassVar[str] = "constant"
    GAINS: ClassVar[tuple[str, ...]] = ("gain", "gains")
    gain: float = 2.0
    gains: tuple[float, float] = (1.0, 3.0)
    label: str = "x"
    enabled: bool = True


class Constant(ControllerBase[ConstantConfig]):
    """A control law returning a fixed effort, to test what the base class does around it."""

    name = "constant"

    def __init__(self, model: mujoco.MjModel, effort: Effort) -> None:
        super().__init__(model, ConstantConfig(control_dt=0.002))
        self.effort = effort
        self.resets = 0

    def _reset(self, state: ControlState) -> None:
        self.resets += 1

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        return self.effort


def _ctrl(model: mujoco.MjModel, values: list[float], names: tuple[str, ...]) -> list[float]:
    return [values[model.actuator(n).id] for n in names]


SLIDES = ("act_transX", "act_transY", "act_transZ")
BALLS = ("act_rotX", "act_rotY", "act_rotZ")


# -- the template ------------------------------------------------------------------------------


def test_template_packs_the_effort_and_passes_diagnostics(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    c = Constant(model, Effort((1.0, -2.0, 3.0), (0.1, -0.2, 0.3), "solved", 7))
    assert c.control_dt == 0.002
    out = c.compute(home_state, target(HOME, jaw=0.03))
    assert len(out.ctrl) == model.nu
    assert _ctrl(model, out.ctrl, SLIDES) == [1.0, -2.0, 3.0]
    assert _ctrl(model, out.ctrl, BALLS) == [0.1, -0.2, 0.3]
    assert out.ctrl[model.actuator("2f85/fingers_actuator").id] == load_default().sep_to_byte(0.03)
    assert out.diagnostics.status == "solved"
    assert out.diagnostics.iterations == 7
    assert isinstance(out.diagnostics, Diagnostics)


def test_template_saturates_to_the_actuator_ranges(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = Constant(model, Effort((1e9, -1e9, 5.0), (-1e9, 1e9, 0.0)))
    ctrl = np.asarray(c.compute(home_state, target(HOME)).ctrl)
    lo, hi = model.actuator_ctrlrange.T
    slides = [model.actuator(n).id for n in SLIDES]
    balls = [model.actuator(n).id for n in BALLS]
    np.testing.assert_array_equal(ctrl[slides], [hi[slides[0]], lo[slides[1]], 5.0])
    np.testing.assert_array_equal(ctrl[balls], [lo[balls[0]], hi[balls[1]], 0.0])


def test_template_jaw_byte_follows_the_target(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = Constant(model, Effort((0.0,) * 3, (0.0,) * 3))
    jaw = model.actuator("2f85/fingers_actuator").id
    calibration = load_default()
    for sep in (0.085, 0.03, 0.03, 0.01, 0.085):
        assert c.compute(home_state, target(HOME, jaw=sep)).ctrl[jaw] == calibration.sep_to_byte(sep)


def test_reset_calls_the_law_reset(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = Constant(model, Effort((0.0,) * 3, (0.0,) * 3))
    c.reset(home_state)
    c.reset(home_state)
    assert c.resets == 2


def test_template_raises_on_a_non_finite_effort(model: mujoco.MjModel, home_state: ControlState) -> None:
    """An infinite effort is a divergence, not something to saturate."""
    for bad in (math.inf, math.nan):
        c = Constant(model, Effort((0.0, bad, 0.0), (0.0,) * 3))
        with pytest.raises(DivergenceError, match="non-finite control from state at t="):
            c.compute(home_state, target(HOME))


def test_template_names_a_non_finite_target(model: mujoco.MjModel, home_state: ControlState) -> None:
    c = Constant(model, Effort((0.0,) * 3, (0.0,) * 3))
    bad = GripperTarget.trusted(
        np.asarray(HOME), np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3), math.nan
    )
    with pytest.raises(CommandError, match="target jaw_sep_m must be in \\[0, 0.085\\] m, got nan"):
        c.compute(home_state, bad)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    ("quat", "jaw", "match"),
    [
        ((1.0, 0.0, 0.0, 0.0), 0.0851, r"jaw_sep_m must be in \[0, 0.085\] m, got 0.0851"),
        ((1.0, 0.0, 0.0, 0.0), -0.001, r"jaw_sep_m must be in \[0, 0.085\] m, got -0.001"),
        ((0.0, 0.0, 0.0, 0.0), 0.05, r"unit quaternion, got \[0.0, 0.0, 0.0, 0.0\] \(norm 0\)"),
        ((1.0, 0.0, 0.0, 1.0), 0.05, r"unit quaternion.*norm 1.41421"),
        ((math.nan, 0.0, 0.0, 0.0), 0.05, r"unit quaternion, got \[nan"),
    ],
)
def test_every_controller_refuses_a_malformed_trusted_target(
    name: str,
    quat: tuple[float, ...],
    jaw: float,
    match: str,
    model: mujoco.MjModel,
    home_state: ControlState,
) -> None:
    """``GripperTarget.trusted`` skips validation; no controller clips or ignores what it lets through."""
    c = make_controller(name, model)
    c.reset(home_state)
    bad = GripperTarget.trusted(np.asarray(HOME), np.array(quat), np.zeros(3), np.zeros(3), jaw)
    with pytest.raises(CommandError, match=match):
        c.compute(home_state, bad)


def test_check_target_names_the_entries() -> None:
    check_target(target(HOME))
    bad = GripperTarget.trusted(
        np.array([np.nan, 0.0, 0.2]), np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3), 0.05
    )
    with pytest.raises(CommandError, match=r"p_world=\[nan, 0.0, 0.2\]"):
        check_target(bad)


# -- the config base class ---------------------------------------------------------------------


def test_scaled_scales_float_and_tuple_gains_only() -> None:
    cfg = ConstantConfig(gain=2.0, gains=(1.0, 3.0), control_dt=0.002)
    scaled = cfg.scaled(0.5)
    assert scaled.gain == 1.0
    assert scaled.gains == (0.5, 1.5)
    assert scaled.control_dt == 0.002 and scaled.label == "x"
    assert cfg.scaled(1.0) == cfg


@pytest.mark.parametrize("factor", [0.0, -1.0, math.nan, math.inf])
def test_scaled_rejects_a_bad_factor(factor: float) -> None:
    with pytest.raises(ConfigError, match="gain scale factor"):
        ConstantConfig().scaled(factor)


@pytest.mark.parametrize(
    ("field", "value"),
    [("gain", 0.0), ("gain", -1.0), ("gain", math.nan), ("gains", (1.0, math.inf)), ("control_dt", 0.0)],
)
def test_numeric_fields_must_be_finite_and_positive(field: str, value: object) -> None:
    with pytest.raises(InvalidField, match=rf"^constant\.{field}: must be finite and > 0") as info:
        ConstantConfig(**{field: value})
    assert info.value.field == field
    assert isinstance(info.value, ConfigError)


def test_check_positive_rejects_non_numbers() -> None:
    cfg = ConstantConfig()
    with pytest.raises(InvalidField, match="constant.label"):
        check_positive(cfg, ["label"])
    with pytest.raises(InvalidField, match="constant.enabled"):
        check_positive(cfg, ["enabled"])


def test_check_multiple() -> None:
    cfg = ConstantConfig(control_dt=0.002)
    assert check_multiple(cfg, "gain") == 1000
    with pytest.raises(InvalidField, match=r"constant\.gain: must be a whole multiple of control_dt"):
        check_multiple(dataclasses.replace(cfg, gain=0.003), "gain")


def test_build_is_required() -> None:
    with pytest.raises(NotImplementedError):
        ConstantConfig().build(None)  # type: ignore[arg-type]


# -- every registered controller honours the template ------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_finite_command_of_the_right_shape(
    name: str, model: mujoco.MjModel, home_state: ControlState
) -> None:
    ctrl_a = make_controller(name, model)
    ctrl_b = make_controller(name, model)
    tgt = target(HOME + [0.02, -0.01, -0.03], euler_to_quat(0.3, -0.1, 0.2), jaw=0.03, v=(0.05, 0, 0))
    ctrl_a.reset(home_state)
    ctrl_b.reset(home_state)
    lo, hi = model.actuator_ctrlrange.T
    for _ in range(12):  # past the first slow-rate update of diffik and mpc
        a, b = ctrl_a.compute(home_state, tgt), ctrl_b.compute(home_state, tgt)
        assert len(a.ctrl) == model.nu
        assert np.all(np.isfinite(a.ctrl))
        assert list(a.ctrl) == list(b.ctrl)  # same inputs, same outputs
        assert np.all(np.asarray(a.ctrl) >= lo) and np.all(np.asarray(a.ctrl) <= hi)


@pytest.mark.parametrize("name", NAMES)
def test_nan_state_raises_divergence(name: str, model: mujoco.MjModel, home_state: ControlState) -> None:
    c = make_controller(name, model)
    c.reset(home_state)
    bad = home_state._replace(p_world=np.array([np.nan, 0.0, 0.2]))
    with pytest.raises(DivergenceError, match="non-finite control"):
        c.compute(bad, target(HOME))


@pytest.mark.parametrize("field", ["p", "quat", "v", "w"])
@pytest.mark.parametrize("name", NAMES)
def test_nan_target_raises_command_error(
    name: str, field: str, model: mujoco.MjModel, home_state: ControlState
) -> None:
    entries = {
        "p": np.asarray(HOME, float),
        "quat": np.array([1.0, 0, 0, 0]),
        "v": np.zeros(3),
        "w": np.zeros(3),
    }
    entries[field] = entries[field].copy()
    entries[field][0] = np.nan
    bad = GripperTarget.trusted(entries["p"], entries["quat"], entries["v"], entries["w"], 0.05)
    c = make_controller(name, model)
    c.reset(home_state)
    match = "unit quaternion, got \\[nan" if field == "quat" else "target must be finite"
    with pytest.raises(CommandError, match=match):
        c.compute(home_state, bad)


@pytest.mark.parametrize("name", NAMES)
def test_every_controller_holds_a_pose(name: str, model: mujoco.MjModel) -> None:
    """Closed loop, through :class:`peg_ctrl.run.tracker.Tracker` (a driver of the episode loop)."""
    tracker = Tracker(model, make_controller(name, model))
    goal = target(HOME + [0.03, 0.02, -0.04], euler_to_quat(0.4, 0.0, -0.3))
    state = tracker.hold(goal, 2.5)
    assert np.linalg.norm(state.p_world - goal.p_world) < 2e-3
    err = np.zeros(3)
    mujoco.mju_subQuat(err, goal.quat_world, state.quat_world)
    assert np.linalg.norm(err) < 0.02


def test_observing_the_task_s_belief_is_declared_with_the_method_that_does_it(model: mujoco.MjModel) -> None:
    assert make_controller("sampling_mpc", model).observes_belief
    assert not Constant.observes_belief
    with pytest.raises(
        TypeError, match=r"^Deaf: observes_belief = True but observe_belief is not overridden;"
    ):

        class Deaf(Constant):
            observes_belief = True

    with pytest.raises(
        TypeError, match=r"^Secret: observes_belief = False but observe_belief is overridden;"
    ):

        class Secret(Constant):
            def observe_belief(self, belief: object) -> None:
                pass


class Recording(ControllerBase[ConstantConfig]):
    """Records the state its control law is handed."""

    name = "recording"

    def __init__(self, model: mujoco.MjModel, config: ConstantConfig) -> None:
        super().__init__(model, config)
        self.seen: list[ControlState] = []

    def control_law(self, state: ControlState, target: GripperTarget) -> Effort:
        self.seen.append(state)
        return Effort((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_the_velocity_filter_low_passes_the_sensed_velocities(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """velocity_filter_hz: a first-order low-pass on v_world and omega_body, started at the
    reset's; the pose untouched. 0 (the default): the state as sensed, the very object."""
    dt, hz = 0.001, 30.0
    filtered = Recording(model, ConstantConfig(control_dt=dt, velocity_filter_hz=hz))
    plain = Recording(model, ConstantConfig(control_dt=dt))
    for c in (filtered, plain):
        c.reset(home_state)
    step = home_state._replace(v_world=np.array([0.01, 0.0, -0.02]), omega_body=np.array([0.0, 0.3, 0.0]))
    tgt = target(home_state.p_world)
    for _ in range(10):
        filtered.compute(step, tgt)
        plain.compute(step, tgt)
    assert all(s is step for s in plain.seen)
    alpha = 1.0 - math.exp(-2.0 * math.pi * hz * dt)
    expected = 1.0 - (1.0 - alpha) ** np.arange(1, 11)  # the share of the step after n periods
    np.testing.assert_allclose([s.v_world[0] / 0.01 for s in filtered.seen], expected, rtol=1e-12)
    np.testing.assert_allclose([s.omega_body[1] / 0.3 for s in filtered.seen], expected, rtol=1e-12)
    assert all(np.array_equal(s.p_world, step.p_world) for s in filtered.seen)
    with pytest.raises(
        ConfigError, match=r"^constant\.velocity_filter_hz: must be finite and >= 0, got -1\.0$"
    ):
        ConstantConfig(velocity_filter_hz=-1.0)


def test_the_position_observer_quiets_a_noisy_pose_without_lagging_a_motion(
    model: mujoco.MjModel, home_state: ControlState
) -> None:
    """position_filter_hz: the sensed position predicted with the sensed velocity and pulled
    towards each reading. Readings with 30 um of white noise about a still hand come out within
    a quarter of that; a hand moving at constant speed, sensed exactly, is followed with no lag;
    reset starts again from the reading."""
    dt, hz, sigma = 0.001, 3.0, 3e-5
    observer = Recording(model, ConstantConfig(control_dt=dt, position_filter_hz=hz))
    observer.reset(home_state)
    rng = np.random.default_rng(0)
    tgt = target(home_state.p_world)
    for _ in range(2000):
        noisy = home_state._replace(p_world=home_state.p_world + rng.normal(0.0, sigma, 3))
        observer.compute(noisy, tgt)
    error = np.array([s.p_world - home_state.p_world for s in observer.seen[500:]])
    assert float(error.std()) < 0.25 * sigma
    v = np.array([0.03, -0.01, 0.0])
    observer.reset(home_state)
    observer.seen.clear()
    for k in range(1, 200):
        moving = home_state._replace(p_world=home_state.p_world + k * dt * v, v_world=v)
        observer.compute(moving, tgt)
        np.testing.assert_allclose(observer.seen[-1].p_world, moving.p_world, atol=1e-12)
    jumped = home_state._replace(p_world=home_state.p_world + 0.01)
    observer.reset(jumped)
    observer.compute(jumped, tgt)
    np.testing.assert_array_equal(observer.seen[-1].p_world, jumped.p_world)
    with pytest.raises(
        ConfigError, match=r"^constant\.position_filter_hz: must be finite and >= 0, got -3\.0$"
    ):
        ConstantConfig(position_filter_hz=-3.0)
