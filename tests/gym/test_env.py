"""The Gymnasium environment ``peg_ctrl/PegInsertion-v0``: the checker, vector envs, seeding,
actions, rewards and terminations, each by running the physics."""

from __future__ import annotations

import importlib.util
import os
import platform
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import peg_ctrl  # noqa: F401  (registers the environment)
from peg_ctrl.config import ConfigError
from peg_ctrl.errors import UnknownComponent
from peg_ctrl.gym.env import ENV_ID, MAX_EPISODE_STEPS, PegInsertionEnv
from peg_ctrl.gym.wrappers import ShapedReward
from peg_ctrl.sim.state import ft_world

# Velocities, forces and the peg's position have no physical bound, and the space says so.
pytestmark = pytest.mark.filterwarnings("ignore:.*Box observation space m.*:UserWarning")

DOWN = np.array([0.0, 0.0, -0.5, 0.0, 0.0, 0.0, 1.0], dtype=np.float32)  # descend, jaw closed


def _rollout(env: gym.Env, actions: list[np.ndarray], seed: int) -> list[dict[str, np.ndarray]]:
    obs, _ = env.reset(seed=seed)
    seen = [obs]
    for a in actions:
        obs, _, terminated, truncated, _ = env.step(a)
        seen.append(obs)
        if terminated or truncated:
            obs, _ = env.reset()
            seen.append(obs)
    return seen


def test_registered_on_import() -> None:
    assert ENV_ID in gym.registry
    env = gym.make(ENV_ID)
    assert isinstance(env.unwrapped, PegInsertionEnv)
    assert isinstance(env, gym.wrappers.TimeLimit)  # Gymnasium's time limit, registered
    assert env.spec.max_episode_steps == gym.spec(ENV_ID).max_episode_steps == MAX_EPISODE_STEPS == 1000
    assert MAX_EPISODE_STEPS * env.unwrapped.control_dt == pytest.approx(5.0)  # 5 s with pd
    env.close()


def test_reward_mode_selects_the_shaped_reward_wrapper() -> None:
    env = gym.make(ENV_ID, reward_mode="shaped")
    assert isinstance(env.env.env.env, ShapedReward)  # inside TimeLimit, order enforcer, checker
    assert env.get_wrapper_attr("force_penalty_steps") == MAX_EPISODE_STEPS
    assert not any(isinstance(e, ShapedReward) for e in _wrappers(gym.make(ENV_ID)))
    env.close()


def _wrappers(env: gym.Env) -> list[gym.Env]:
    out = [env]
    while isinstance(out[-1], gym.Wrapper):
        out.append(out[-1].env)
    return out


def test_check_env_passes_without_a_display() -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array")
    check_env(env.unwrapped, skip_render_check=True)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    assert frame.std() > 5.0  # a picture, not a blank
    env.close()


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="xvfb-run is not installed")
def test_check_env_passes_with_every_render_mode_on_a_virtual_display() -> None:
    script = textwrap.dedent(
        """
        import gymnasium as gym, peg_ctrl
        from gymnasium.utils.env_checker import check_env
        check_env(gym.make("peg_ctrl/PegInsertion-v0").unwrapped)
        print("CHECKED")
        """
    )
    proc = _on_a_virtual_display(script, mujoco_gl="egl")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "CHECKED" in proc.stdout


def _on_a_virtual_display(script: str, *args: str, mujoco_gl: str | None) -> subprocess.CompletedProcess[str]:
    """``python -c script args`` under ``xvfb-run`` (``MUJOCO_GL`` set, or unset as a user's
    usually is); skips the test when Xvfb cannot start."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MUJOCO_GL")}
    if mujoco_gl is not None:
        env["MUJOCO_GL"] = mujoco_gl
    proc = subprocess.run(
        ["xvfb-run", "-a", sys.executable, "-W", "ignore", "-c", script, *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    if "could not start" in proc.stderr.lower() or "xvfb failed" in proc.stderr.lower():
        pytest.skip(f"Xvfb could not start: {proc.stderr.strip()[:200]}")
    return proc


# The full install's crash (docs/rl.md): Triton, which the CUDA build of PyTorch brings,
# segfaults the process when first imported after a GL context exists. The dev install brings the
# real Triton (pyproject.toml), so these open the render modes in the orders a user meets.
_FULL_INSTALL = """
import importlib.util, sys
import gymnasium as gym, peg_ctrl
from gymnasium.utils.env_checker import check_env
spec = importlib.util.find_spec("triton")
print("TRITON", spec.origin if spec else None)
order = sys.argv[1]
if order == "check_env":  # the human viewer first, then rgb_array
    check_env(gym.make("peg_ctrl/PegInsertion-v0").unwrapped)
else:
    modes = order.split(",")
    envs = [gym.make("peg_ctrl/PegInsertion-v0", render_mode=m, width=64, height=48) for m in modes]
    for env in envs:
        env.reset(seed=0)
        env.render()
    from stable_baselines3 import PPO  # PyTorch builds a policy after the contexts exist
    PPO("MultiInputPolicy", gym.make("peg_ctrl/PegInsertion-v0"), n_steps=8, batch_size=8, device="cpu")
    for env in envs:
        env.close()
print("TRITON_LOADED", "triton" in sys.modules)
print("CHECKED")
"""


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="xvfb-run is not installed")
@pytest.mark.skipif(
    not (sys.platform.startswith("linux") and platform.machine() == "x86_64"),
    reason="Triton ships for Linux x86_64 only",
)
@pytest.mark.parametrize("order", ["check_env", "human,rgb_array", "rgb_array,human"])
def test_the_full_install_renders_in_any_order_with_the_real_triton(order: str) -> None:
    """With the real Triton installed, every order of render modes (and a policy built after
    them) runs to the end (without Triton imported before the human viewer, check_env exits 139)."""
    spec = importlib.util.find_spec("triton")
    assert spec is not None and spec.origin, "the dev install brings triton: pip install -e '.[dev]'"
    proc = _on_a_virtual_display(_FULL_INSTALL, order, mujoco_gl=None)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-1500:]}"
    assert f"TRITON {spec.origin}" in proc.stdout  # the real package, not a stand-in
    assert "TRITON_LOADED True" in proc.stdout and "CHECKED" in proc.stdout


def test_human_mode_without_a_display_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ConfigError, match="needs a display"):
        gym.make(ENV_ID, render_mode="human")


@pytest.mark.slow  # ~25 s; docs/api.md's example (test_docs, default suite) steps a vector env
def test_async_vector_env_steps_1000_times_with_random_actions() -> None:
    envs = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="async")
    try:
        obs, _ = envs.reset(seed=0)
        assert obs["peg_pos"].shape == (4, 3)
        envs.action_space.seed(0)
        ends = 0
        for _ in range(1000):
            obs, reward, terminated, truncated, _ = envs.step(envs.action_space.sample())
            assert reward.shape == (4,)
            assert np.all(np.isfinite(obs["gripper_pos"]))
            ends += int(terminated.sum() + truncated.sum())
        assert ends > 0  # random actions let go of the peg: episodes end and auto-reset
    finally:
        envs.close()


def test_same_seed_same_first_100_observations() -> None:
    space = gym.make(ENV_ID).action_space
    space.seed(7)
    actions = [space.sample() for _ in range(100)]
    a, b = gym.make(ENV_ID), gym.make(ENV_ID)
    first, second = _rollout(a, actions, seed=3), _rollout(b, actions, seed=3)
    again = _rollout(a, actions, seed=3)  # the same env, reset with the seed again
    other = _rollout(b, actions, seed=4)
    assert len(first) >= 101
    for x, y, z in zip(first, second, again, strict=True):
        for key in x:
            np.testing.assert_array_equal(x[key], y[key])
            np.testing.assert_array_equal(x[key], z[key])
    assert not np.array_equal(first[0]["gripper_pos"], other[0]["gripper_pos"])


def test_seeding_reproduces_with_domain_disturbances() -> None:
    kwargs = {"disturbances": {"peg_mass_scale": [0.5, 1.5], "force_noise": 0.2}}
    space = gym.make(ENV_ID).action_space
    space.seed(1)
    actions = [space.sample() for _ in range(30)]
    a, b = gym.make(ENV_ID, **kwargs), gym.make(ENV_ID, **kwargs)
    for x, y in zip(_rollout(a, actions, seed=5), _rollout(b, actions, seed=5), strict=True):
        np.testing.assert_array_equal(x["ft_wrench"], y["ft_wrench"])
    env = a.unwrapped
    masses = set()
    for seed in range(3):
        env.reset(seed=seed)
        masses.add(round(float(env.model.body_mass[env.model.body("peg").id]), 9))
    assert len(masses) == 3  # a fresh domain draw per episode


def test_the_observed_wrench_is_the_reading_the_controller_acts_on_next() -> None:
    """With a sensor that has noise, latency and drift, the agent sees the reading the next
    control step uses (one reading per period), not a second draw."""
    env = gym.make(ENV_ID, disturbances={"ft_sensor": "wrist"}).unwrapped
    acted_on: list[np.ndarray] = []

    class Keep:
        def record(self, loop, info) -> None:  # type: ignore[no-untyped-def]
            force, torque = ft_world(info.gripper)
            acted_on.append(np.concatenate([force, torque]).astype(np.float32))

    obs, _ = env.reset(seed=3)
    env.loop.recorders = [*env.loop.recorders, Keep()]
    observed = [obs["ft_wrench"]]
    for _ in range(10):
        obs, *_ = env.step(DOWN)
        observed.append(obs["ft_wrench"])
    np.testing.assert_array_equal(observed[:-1], acted_on)
    force, torque = ft_world(env.loop.state())
    assert not np.array_equal(observed[-1], np.concatenate([force, torque]).astype(np.float32))
    env.close()


def test_a_straight_descent_seats_the_held_peg_with_sparse_reward() -> None:
    env = gym.make(ENV_ID, task={"name": "held_insertion", "lateral_error": 0.0005})
    obs, info = env.reset(seed=0)
    assert info["depth_m"] < 0  # starts above the mouth
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(DOWN)
        total += reward
        steps += 1
        if terminated or truncated:
            break
    assert terminated and info["success"] and info["reason"] == ""
    assert total == 1.0
    assert info["depth_m"] >= 0.02
    assert abs(obs["peg_pos"][2] - (0.05 - 0.02)) < 0.03  # the peg's centre went down into the block
    assert steps * env.unwrapped.control_dt < 5.0


def test_absolute_actions_follow_the_command_api() -> None:
    env = gym.make(ENV_ID, action_mode="absolute")
    obs, _ = env.reset(seed=0)
    p = obs["gripper_pos"].astype(float)
    from peg_ctrl.commands import quat_to_euler

    rpy = quat_to_euler(obs["gripper_quat"].astype(float))
    goal = p + np.array([0.0, 0.0, 0.02])  # lift 2 cm
    action = np.array([*goal, *rpy, 0.0], dtype=np.float32)
    for _ in range(200):  # 1 s at 200 Hz
        obs, _, terminated, _, info = env.step(action)
        assert not terminated, info
    assert np.linalg.norm(obs["gripper_pos"] - goal) < 2e-3
    assert obs["peg_pos"][2] > 0.103 + 0.015  # the peg came up with the hand


def test_opening_the_jaw_terminates_with_grasp_lost_or_tilt() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    up_open = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0], dtype=np.float32)
    for _ in range(400):
        _, reward, terminated, truncated, info = env.step(up_open)
        if terminated or truncated:
            break
    assert terminated and not info["success"]
    assert info["reason"] in ("grasp_lost", "excessive_tilt")
    assert reward == -1.0  # the sparse reward's failure penalty
    with pytest.raises(RuntimeError, match="reset"):
        env.step(up_open)


def test_max_episode_steps_truncates_the_gymnasium_way() -> None:
    env = gym.make(ENV_ID, max_episode_steps=10)  # 0.05 s at 200 Hz
    assert env.spec.max_episode_steps == 10
    env.reset(seed=0)
    hold = np.array([0, 0, 0, 0, 0, 0, 1], dtype=np.float32)
    ends = [env.step(hold)[2:4] for _ in range(10)]
    assert ends[-1] == (False, True)
    assert all(e == (False, False) for e in ends[:-1])
    assert env.unwrapped.step(hold)[2:4] == (False, False)  # the environment itself never truncates
    env.reset(seed=0)  # TimeLimit counts again from the reset
    assert [env.step(hold)[3] for _ in range(10)] == [False] * 9 + [True]


def test_the_registered_time_limit_is_1000_steps() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    hold = np.array([0, 0, 0, 0, 0, 0, 1], dtype=np.float32)
    truncated = [env.step(hold)[3] for _ in range(1000)]
    assert truncated == [False] * 999 + [True]
    assert env.unwrapped.data.time == pytest.approx(5.0)


def test_shaped_reward_grows_as_the_peg_goes_in() -> None:
    env = gym.make(ENV_ID, reward_mode="shaped", task={"name": "held_insertion", "lateral_error": 0.0005})
    env.reset(seed=0)
    rewards, terms, depths = [], [], [-1.0]
    for _ in range(1000):
        _, reward, terminated, truncated, info = env.step(DOWN)
        rewards.append(reward)
        terms.append(info["reward_terms"])
        depths.append(info["depth_m"])
        if terminated or truncated:
            break
    assert info["success"]
    assert set(terms[-1]) == {"goal", "reach", "closeness", "progress", "force_penalty", "success", "failure"}
    assert terms[-1]["success"] == 3.0 and terms[-1]["failure"] == 0.0 and terms[-1]["reach"] == 1.0
    max_steps = env.get_wrapper_attr("force_penalty_steps")
    assert max_steps == 1000
    for t, r in zip(terms, rewards, strict=True):
        assert 0.0 <= t["goal"] == t["closeness"] <= 1.0
        assert -0.5 / max_steps <= t["force_penalty"] <= 0.0
        assert r == pytest.approx(t["progress"] + t["force_penalty"] + t["success"] + t["failure"])
    # Potential-based: the progress terms sum to the closeness gained.
    gained = terms[-1]["closeness"] - (terms[0]["closeness"] - terms[0]["progress"])
    assert sum(t["progress"] for t in terms) == pytest.approx(gained)
    assert terms[-1]["goal"] > 0.9 > 0.5 > terms[0]["goal"]  # seated against centimetres above
    # Paid as the peg goes down: every step that took it 0.1 mm deeper, down to the seated depth.
    deeper = [b - a > 1e-4 and b < 0.04 for a, b in zip(depths, depths[1:], strict=False)]
    assert sum(deeper) > 50
    assert all(t["progress"] > 0 for t, down in zip(terms, deeper, strict=True) if down)


def test_pick_and_place_start_and_reach_term() -> None:
    env = gym.make(
        ENV_ID, task="pick_and_place", reward_mode="shaped", max_episode_steps=4000, force_penalty_steps=4000
    )
    obs, _ = env.reset(seed=0)
    assert abs(obs["peg_pos"][2] - 0.01) < 2e-3  # lying on the table (radius 10 mm)
    _, _, _, _, info = env.step(np.zeros(7, dtype=np.float32))
    d = np.linalg.norm(obs["gripper_pos"] - obs["peg_pos"])
    assert info["reward_terms"]["reach"] == pytest.approx(1.0 - np.tanh(d / 0.1), rel=0.05)
    assert env.spec.max_episode_steps == env.get_wrapper_attr("force_penalty_steps") == 4000  # 20 s at 200 Hz


HOLD = np.array([0, 0, 0, 0, 0, 0, 1], dtype=np.float32)  # stay, jaw closed
LIFT_OPEN = np.array([0, 0, 0.5, 0, 0, 0, -1], dtype=np.float32)
TWIST = np.array([0.5, 0, -0.5, 1, 0, 0, 1], dtype=np.float32)  # roll hard while descending


def _episode_return(mode: str, policy, seed: int = 0, **kwargs) -> tuple[float, dict]:  # type: ignore[no-untyped-def]
    env = gym.make(
        ENV_ID,
        reward_mode=mode,
        task={"name": "held_insertion", "lateral_error": 0.0005},
        max_episode_steps=400,  # 2 s
        **({"force_penalty_steps": 400} if mode == "shaped" else {}),
        **kwargs,
    )
    env.reset(seed=seed)
    total, step = 0.0, 0
    while True:
        _, reward, terminated, truncated, info = env.step(policy(step))
        total += reward
        step += 1
        if terminated or truncated:
            env.close()
            return total, {**info, "truncated": truncated}


# Six episodes (~4 s) per mode; the sparse rewards of a success and a failure are checked above.
@pytest.mark.parametrize("mode", [pytest.param("sparse", marks=pytest.mark.slow), "shaped"])
def test_returns_order_failure_below_holding_still_below_success(mode: str) -> None:
    """The reward teaches: every failure (early, after progress, by tilt or by a dropped peg)
    returns less than holding still until truncation, which returns less than a success."""
    success, s_info = _episode_return(mode, lambda n: DOWN)
    hold, h_info = _episode_return(mode, lambda n: HOLD)
    assert s_info["success"] and h_info["truncated"] and not h_info["success"]
    failures = {
        "open at once": _episode_return(mode, lambda n: LIFT_OPEN),
        "open near the hole": _episode_return(mode, lambda n: DOWN if n < 30 else LIFT_OPEN),
        "tilt near the hole": _episode_return(mode, lambda n: DOWN if n < 30 else TWIST),
    }
    rng = np.random.default_rng(7)
    random_actions = rng.uniform(-1, 1, size=(400, 7)).astype(np.float32)
    failures["random actions"] = _episode_return(mode, lambda n: random_actions[n])
    for name, (ret, info) in failures.items():
        assert info["reason"] in ("grasp_lost", "excessive_tilt", "force_spike"), (name, info)
        assert ret < hold, (name, ret, hold)
    assert max(r for r, _ in failures.values()) < hold < success
    if mode == "shaped":  # the documented bounds: failure <= -2 < -1.5 <= hold <= 1 < 1.5 <= success
        assert max(r for r, _ in failures.values()) <= -2.0 and -1.5 <= hold <= 1.0 and success >= 1.5
        assert abs(hold) < 0.1  # holding still gains little closeness (the gripper settles a little)


def test_fixed_jaw_keeps_the_peg_in_the_hand() -> None:
    ret, info = _episode_return("sparse", lambda n: LIFT_OPEN, fixed_jaw=True)
    assert info["truncated"] and info["reason"] == "" and ret == 0.0  # opening was ignored
    with pytest.raises(ConfigError, match="fixed_jaw=True needs task held_insertion"):
        gym.make(ENV_ID, task="pick_and_place", fixed_jaw=True)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"action_mode": "joint"}, ConfigError, "action_mode must be one of delta, absolute, got 'joint'"),
        ({"reward_mode": "dense"}, ConfigError, "reward_mode must be one of sparse, shaped"),
        ({"render_mode": "ansi"}, ConfigError, "render_mode must be one of human, rgb_array"),
        ({"task": "stack"}, UnknownComponent, "stack"),
        ({"profile": "turbo"}, ConfigError, "turbo"),
        ({"disturbances": {"peg_mass_scale": [2, 1]}}, ConfigError, "peg_mass_scale"),
        ({"time_limit_s": 2.0}, ConfigError, "time_limit_s is replaced by Gymnasium's max_episode_steps"),
        ({"force_penalty_steps": 400}, ConfigError, "force_penalty_steps belongs to reward_mode='shaped'"),
        (
            {"reward_mode": "shaped", "force_penalty_steps": 0},
            ConfigError,
            "force_penalty_steps must be a positive integer, got 0",
        ),
    ],
)
def test_bad_arguments_are_named(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        gym.make(ENV_ID, **kwargs)


def test_bad_actions_are_named() -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(6, dtype=np.float32))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(7, np.nan, dtype=np.float32))


def test_rgb_array_renders_headless_with_mujoco_gl_unset(tmp_path: Path) -> None:
    """No display, no MUJOCO_GL: importing peg_ctrl picks an offscreen backend (EGL, else
    OSMesa) before mujoco loads, and the env renders a frame."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    code = (
        "import peg_ctrl, os, gymnasium as gym\n"
        "env = gym.make('peg_ctrl/PegInsertion-v0', render_mode='rgb_array', width=64, height=48)\n"
        "env.reset(seed=0)\n"
        "frame = env.render()\n"
        "print(os.environ['MUJOCO_GL'], frame.shape, frame.dtype, int(frame.max()), sep='|')\n"
        "env.close()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    backend, shape, dtype, brightest = proc.stdout.strip().split("|")
    assert backend in ("egl", "osmesa")
    assert (shape, dtype) == ("(48, 64, 3)", "uint8")
    assert int(brightest) > 0  # not a blank frame


def test_shaped_reward_wrapped_by_hand_reads_the_time_limit() -> None:
    """ShapedReward around a made environment spreads its force penalty over that
    environment's max_episode_steps: the same rewards as reward_mode="shaped" with
    force_penalty_steps set to it."""
    by_hand = ShapedReward(gym.make(ENV_ID, max_episode_steps=400))
    by_make = gym.make(ENV_ID, reward_mode="shaped", max_episode_steps=400, force_penalty_steps=400)
    assert by_hand.force_penalty_steps == 400
    rng = np.random.default_rng(3)
    actions = [DOWN] * 40 + list(rng.uniform(-1, 1, size=(60, 7)).astype(np.float32))
    by_hand.reset(seed=1)
    by_make.reset(seed=1)
    for a in actions:
        x, y = by_hand.step(a), by_make.step(a)
        assert x[1:4] == y[1:4]
        assert x[4]["reward_terms"] == y[4]["reward_terms"]
        if x[2] or x[3]:
            break
    assert {"progress", "force_penalty"} <= set(x[4]["reward_terms"])  # the shaped reward's terms


def test_shaped_reward_needs_a_peg_insertion_env_and_a_length() -> None:
    with pytest.raises(ConfigError, match="ShapedReward needs force_penalty_steps"):
        ShapedReward(PegInsertionEnv())
    assert ShapedReward(PegInsertionEnv(), force_penalty_steps=50).force_penalty_steps == 50
    with pytest.raises(TypeError, match="ShapedReward wraps a PegInsertionEnv, got CartPoleEnv"):
        ShapedReward(gym.make("CartPole-v1"))


def test_rendering_imports_triton_before_the_first_renderer(
    fake_triton: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With Triton installed (a stand-in package here), it is imported before the GL context
    exists: the CUDA build of PyTorch importing it after crashes (docs/rl.md)."""
    import mujoco

    real = mujoco.Renderer
    triton_loaded: list[bool] = []

    def renderer(*args: object) -> mujoco.Renderer:
        triton_loaded.append("triton" in sys.modules)
        return real(*args)

    monkeypatch.setattr(mujoco, "Renderer", renderer)
    env = gym.make(ENV_ID, render_mode="rgb_array", width=64, height=48)
    env.reset(seed=0)
    assert "triton" not in sys.modules  # not at import or reset: only to render
    frame = env.render()
    assert triton_loaded == [True]
    assert frame.shape == (48, 64, 3)
    env.close()
