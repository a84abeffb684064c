"""Property-based fuzzing of the inputs a user controls: the command API, config mappings and
files, ``--set`` on the command line, and actions of the Gymnasium environment.

The property everywhere: the input is accepted, or it is refused with one of the project's own
errors (:class:`~peg_ctrl.errors.PegCtrlError`) — never another exception — and what is
accepted never puts a NaN into the simulation's state.
"""

from __future__ import annotations

import atexit
import dataclasses
import math
import os
import shutil
import tempfile
import typing
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from peg_ctrl.commands import GripperTarget, TaskFrame, command_to_target
from peg_ctrl.config import is_selectable, read_mapping
from peg_ctrl.controllers import REGISTRY, ControllerConfig
from peg_ctrl.errors import FAILURE_REASONS, EpisodeFailure, PegCtrlError
from peg_ctrl.run.episode import EpisodeConfig, build_loop, episode_config_from_mapping
from peg_ctrl.tasks import TASKS

# Hypothesis keeps caches in ./.hypothesis: instead in a directory of this test process's, neither
# in the repository nor shared with tests running at the same time (other test processes, other
# checkouts); removed at exit.
_HYPOTHESIS_HOME = tempfile.mkdtemp(prefix="peg_ctrl-hypothesis-")
atexit.register(shutil.rmtree, _HYPOTHESIS_HOME, ignore_errors=True)
set_hypothesis_home_dir(_HYPOTHESIS_HOME)

#: ``PEG_CTRL_FUZZ_SCALE=10`` runs ten times the examples (the closing battery of a fault pass).
SCALE = int(os.environ.get("PEG_CTRL_FUZZ_SCALE", "1"))
FUZZ = settings(
    max_examples=100 * SCALE,
    database=None,  # nothing written into the repository; a failure prints its example
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

# -- the command API -------------------------------------------------------------------------------

anything = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1.0, max_value=1.0),
    st.integers(min_value=-(10**20), max_value=10**20),
    st.booleans(),
    st.none(),
    st.text(max_size=4),
)


@FUZZ
@given(
    u=st.one_of(
        st.lists(anything, max_size=9), anything, st.lists(st.lists(anything, max_size=3), max_size=3)
    ),
    origin=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
    angle=st.floats(-math.pi, math.pi),
)
def test_command_to_target_accepts_or_refuses_in_its_own_words(u: Any, origin: Any, angle: float) -> None:
    frame = TaskFrame(p_world=origin, quat_world=(math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)))
    try:
        target = command_to_target(u, frame=frame)
    except PegCtrlError:
        return
    for value in (target.p_world, target.quat_world, target.v_world, target.omega_body):
        assert np.all(np.isfinite(value))
    assert 0.0 <= target.jaw_sep_m <= 0.085
    assert abs(np.linalg.norm(target.quat_world) - 1.0) < 1e-9


vectors = st.one_of(st.lists(anything, max_size=5), anything)


@FUZZ
@given(p=vectors, q=vectors, v=vectors, w=vectors, jaw=anything, force=vectors)
def test_gripper_target_accepts_or_refuses_in_its_own_words(
    p: Any, q: Any, v: Any, w: Any, jaw: Any, force: Any
) -> None:
    try:
        target = GripperTarget(
            p_world=p, quat_world=q, v_world=v, omega_body=w, jaw_sep_m=jaw, force_world=force
        )
    except PegCtrlError:
        return
    assert np.all(np.isfinite(target.p_world)) and 0.0 <= target.jaw_sep_m <= 0.085


# -- configs ---------------------------------------------------------------------------------------


def _field_paths(cls: type, prefix: str = "", depth: int = 0) -> list[str]:
    """Every dotted field path of the config dataclass ``cls`` (selectable families: every
    member's fields)."""
    paths = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        path = f"{prefix}{f.name}"
        paths.append(path)
        hint = hints[f.name]
        if depth < 3 and is_selectable(hint):
            members = REGISTRY.values() if issubclass(hint, ControllerConfig) else TASKS.values()
            for member in members:
                paths += _field_paths(member, f"{path}.", depth + 1)
        elif depth < 3 and dataclasses.is_dataclass(hint):
            paths += _field_paths(hint, f"{path}.", depth + 1)  # type: ignore[arg-type]
    return sorted(set(paths))


PATHS = _field_paths(EpisodeConfig)
NAMES = sorted({*REGISTRY, *TASKS, "seed", "precision", "fast", "ruckig", "fixed_speed", "spiral", "tilt"})
values = st.recursive(
    st.one_of(anything, st.sampled_from(NAMES), st.floats(min_value=-0.01, max_value=0.01)),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(["name", "x"]), inner)
    ),
    max_leaves=6,
)


def _nest(assignments: dict[str, Any]) -> dict[str, Any]:
    data: dict[str, Any] = {}
    for key, value in assignments.items():
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            child = node.get(part)
            node = node.setdefault(part, {}) if not isinstance(child, dict) else child
            if not isinstance(node, dict):
                break
        else:
            node[parts[-1]] = value
    return data


@settings(FUZZ, max_examples=300 * SCALE)
@given(
    assignments=st.dictionaries(st.one_of(st.sampled_from(PATHS), st.text(max_size=6)), values, max_size=4)
)
def test_a_config_mapping_loads_or_is_refused_in_its_own_words(assignments: dict[str, Any]) -> None:
    try:
        episode_config_from_mapping(_nest(assignments))
    except PegCtrlError:
        pass


@settings(FUZZ, max_examples=150 * SCALE)
@given(text=st.text(max_size=120), suffix=st.sampled_from([".yaml", ".toml", ".json"]))
def test_a_config_file_loads_or_is_refused_in_its_own_words(tmp_path: Path, text: str, suffix: str) -> None:
    path = tmp_path / f"c{suffix}"
    path.write_text(text, encoding="utf-8")
    try:
        episode_config_from_mapping(read_mapping(path))
    except PegCtrlError:
        pass


# Plausible but perturbed configs: they load often, and then the physics runs.
plausible = st.fixed_dictionaries(
    {},
    optional={
        "controller": st.fixed_dictionaries(
            {"name": st.sampled_from(["pd", "impedance", "admittance"])},
            optional={"control_dt": st.sampled_from([0.001, 0.002, 0.005, 0.003])},
        ),
        "task": st.fixed_dictionaries(
            {"name": st.sampled_from(["pick_and_place", "held_insertion"])},
        ),
        "physics": st.fixed_dictionaries({"profile": st.sampled_from(["seed", "fast", "precision"])}),
        "scene": st.fixed_dictionaries(
            {},
            optional={
                "assets": st.fixed_dictionaries(
                    {},
                    optional={
                        "clearance": st.floats(-2e-4, 3e-3),
                        "chamfer": st.floats(0.0, 3e-3),
                    },
                )
            },
        ),
        "domain": st.fixed_dictionaries(
            {},
            optional={
                "peg_mass_scale": st.tuples(st.floats(1e-3, 1.0), st.floats(1.0, 1e3)),
                "friction_scale": st.tuples(st.floats(1e-3, 1.0), st.floats(1.0, 100.0)),
                "gain_scale": st.tuples(st.floats(1e-2, 1.0), st.floats(1.0, 100.0)),
                "force_noise": st.floats(0.0, 1e3),
                "torque_noise": st.floats(0.0, 1e2),
                "ft_latency": st.floats(0.0, 0.1),
                "ft_bias_drift": st.floats(0.0, 1e2),
                "ft_sensor": st.sampled_from(["", "ideal", "wrist", "forge"]),
                "position_noise": st.floats(0.0, 1.0),
            },
        ),
        "seed": st.integers(0, 2**31 - 1),
    },
)


@settings(FUZZ, max_examples=25 * SCALE)
@given(data=plausible)
def test_an_accepted_config_never_puts_a_nan_into_the_state(data: dict[str, Any]) -> None:
    try:
        cfg = episode_config_from_mapping(data)
        loop = build_loop(cfg)
        loop.reset(np.random.default_rng(cfg.seed))
    except PegCtrlError:
        return
    try:
        for _ in range(40):
            loop.step()
    except EpisodeFailure as failure:
        assert failure.reason in FAILURE_REASONS
        if failure.reason == "diverged":
            return  # detected and named: what a diverging state must do
    assert np.all(np.isfinite(loop.data.qpos)) and np.all(np.isfinite(loop.data.qvel))


# -- the command line ------------------------------------------------------------------------------


@settings(FUZZ, max_examples=40 * SCALE)
@given(key=st.one_of(st.sampled_from(PATHS), st.text(max_size=8)), value=st.text(max_size=12))
def test_set_on_the_command_line_runs_or_exits_2_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], key: str, value: str
) -> None:
    from peg_ctrl.cli import main

    try:
        code = main(["run", "--set", f"{key}={value}", "--max-steps", "5", "--out", str(tmp_path / "run")])
    except SystemExit as exit_:  # argparse: a malformed argument
        code = exit_.code
    err = capsys.readouterr().err
    assert code in (0, 1, 2)
    if code == 2:
        lines = [line for line in err.splitlines() if line.startswith("peg-sim: error:")]
        assert len(lines) == 1 and "Traceback" not in err


# -- the Gymnasium environment ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def env():  # type: ignore[no-untyped-def]
    import gymnasium as gym

    import peg_ctrl  # noqa: F401

    env = gym.make("peg_ctrl/PegInsertion-v0").unwrapped
    env.reset(seed=0)
    yield env
    env.close()


@settings(FUZZ, max_examples=200 * SCALE)
@given(action=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=7, max_size=7))
def test_env_actions_step_or_are_refused_and_the_state_stays_finite(env, action: list[float]) -> None:  # type: ignore[no-untyped-def]
    try:
        obs, _, terminated, truncated, _ = env.step(np.array(action, dtype=np.float32))
    except PegCtrlError:
        return
    for value in obs.values():
        assert np.all(np.isfinite(value))
    if terminated or truncated:
        env.reset()
