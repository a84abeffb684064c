"""Gymnasium environment ``peg_ctrl/PegInsertion-v0``: the simulator for RL and imitation learning.

Registered when :mod:`peg_ctrl` is imported::

    import gymnasium as gym
    import peg_ctrl  # noqa: F401  (registers the environment)

    env = gym.make("peg_ctrl/PegInsertion-v0", task="held_insertion", controller="impedance")
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

It runs on the one :class:`~peg_ctrl.run.loop.Loop`: an action is the command of one control period
(the controller's ``control_dt``, 5 ms for the default ``pd``), the controller tracks it on the
same actuators as every other driver, and the loop's monitors (force spike, grasp slip, tilt in
the hand, divergence) and the task family's insertion check decide how an episode ends.

Task (``task=``, a task name or a mapping ``{name: ..., <field>: ...}``)
    ``held_insertion`` (default): the peg starts in the closed hand, its lower end 3 mm above
    the hole's mouth, with the task's drawn disturbances (``lateral_error``, ``tilt_error`` in the
    grasp, random gripper yaw); see :mod:`peg_ctrl.tasks.held_insertion`. ``pick_and_place``: the
    peg starts lying on the table (its pose randomised with ``randomize``); the agent must grasp,
    turn and insert it. Only the start state and the insertion check come from the task: the
    agent's actions replace its phase machine.

Action (``action_mode=``), ``float32``, shape ``(7,)``
    ``"delta"`` (default): a velocity in ``[-1, 1]`` and the jaw; ``"absolute"``: the command
    API's pose and the jaw's separation; see :mod:`peg_ctrl.gym.actions`.

Observation, a ``Dict`` of ``float32`` arrays (world frame unless stated; quaternions ``[w, x,
y, z]`` with ``w >= 0``)
    ``gripper_pos`` (3,) pinch point [m]; ``gripper_quat`` (4,); ``gripper_vel`` (6,) linear [m/s]
    (world) and angular [rad/s] (gripper frame) velocity; ``jaw`` (1,) measured pad separation
    [m]; ``ft_wrench`` (6,) the wrist force/torque sensor, force [N] and torque [N m] that the
    base exerts on the gripper, in the world frame, as the sensor reports it (with any
    ``disturbances`` sensor noise, latency and bias drift; the same reading the controller
    acts on in the next step);
    ``peg_pos`` (3,) [m] and ``peg_quat`` (4,) the peg's centre and orientation; ``hole_pos``
    (3,) the centre of the hole's mouth [m] (the goal). Flatten it with
    ``gymnasium.wrappers.FlattenObservation`` for a single vector.

Reward (``reward_mode=``)
    Built so that the undiscounted return orders the outcomes: **any failure < holding still
    until truncation < any success**, in both modes (``tests/gym/test_env.py`` checks it on
    the physics). ``"sparse"`` (default, the environment's own reward): ``+1`` on the step the
    peg is seated, ``-1`` on the step a monitor fails the episode, else 0. ``"shaped"``: the
    wrapper :class:`~peg_ctrl.gym.wrappers.ShapedReward`, ``+3`` seated, ``-3`` failed, plus
    two bounded shaping terms on every step:

    - ``progress = closeness_now - closeness_before`` (potential-based shaping, Ng et al.
      1999: it pays for moving towards the goal when it happens, and sums over an episode to
      the closeness gained, in ``[-1, 1]``); ``closeness = 1 - tanh(d_goal / 0.03 m)`` for
      ``held_insertion``, the mean of that and ``1 - tanh(d_reach / 0.1 m)`` for
      ``pick_and_place``;
    - ``force_penalty = -0.5 * tanh(max(0, F - 10 N) / 10 N) / force_penalty_steps``, which
      sums to at least -0.5 over an episode of up to ``force_penalty_steps`` steps (default
      1000, the registered time limit; pass ``force_penalty_steps=N`` with a longer
      ``max_episode_steps=N``).

    ``d_goal`` [m] is the distance from the peg's lower end to the seated goal (the hole axis
    from ``success.min_depth`` below the mouth down), ``d_reach`` [m] the distance from the
    pinch point to the peg's centre and ``F`` [N] the control period's peak peg-block contact
    force. So a success returns at least 1.5, holding still between -1.5 and 1 (about 0: the
    peg does not move), a failure at most -2. ``info["reward_terms"]`` has the parts: the
    factors ``goal``, ``reach`` (1 for ``held_insertion``), ``closeness`` (each in ``[0, 1]``)
    and the summands ``progress``, ``force_penalty``, ``success``, ``failure`` (their sum is
    the reward); the sparse reward's are ``success`` and ``failure``.

Termination and truncation
    ``terminated`` when the peg is seated (``info["success"]``: depth ≥ ``success.min_depth``,
    lateral error ≤ ``success.max_lateral_error``, tilt ≤ ``success.max_tilt`` for
    ``success.consecutive_steps`` control steps) or a monitor fails the episode
    (``info["reason"]``: ``force_spike``, ``grasp_lost``, ``excessive_tilt`` or ``diverged``).
    ``truncated`` comes from Gymnasium's ``TimeLimit``, which ``gymnasium.make`` puts around
    the environment: after ``max_episode_steps`` control periods, registered 1000 (5 s with
    the 5 ms controllers, 1 s with ``admittance``'s 1 ms); ``gymnasium.make(...,
    max_episode_steps=N)`` sets another (4000 for the 20 s that ``pick_and_place`` needs). The
    environment itself never truncates. ``info`` also has ``depth_m``, ``lateral_error_m`` and
    ``tilt_rad`` of the peg in the hole (NaN while the peg is not at the hole: lying, or beside
    the block), ``peg_block_force_n`` (the period's peak) and ``t`` [s].

Other keyword arguments of ``gymnasium.make``
    ``controller`` (name or mapping, default ``pd``); ``profile`` (physics profile, default
    ``seed``); ``disturbances`` (a mapping of :class:`~peg_ctrl.run.episode.DomainConfig` fields:
    ``peg_mass_scale``, ``friction_scale``, ``gain_scale`` ranges drawn per episode;
    ``position_noise`` [m], ``velocity_noise`` [m/s, rad/s] and ``orientation_noise`` [rad] on
    the sensed state; the wrist F/T sensor as a preset ``ft_sensor`` (``ideal``, ``wrist``,
    ``mini45``, ``forge``) or by its fields
    ``force_noise`` [N] (the forces only: it used to cover the torques too, which now take
    ``torque_noise``), ``torque_noise`` [N m], ``ft_latency`` [s], ``ft_bias_drift``
    [N/sqrt(s)] and ``ft_rate`` [Hz], see docs/sensing.md); ``scene`` (a
    mapping of :class:`~peg_ctrl.sim.scene.SceneConfig` fields, e.g. ``{"assets": {"clearance":
    1e-4, "chamfer": 1e-3}}``); ``config`` (a base episode config: a mapping or a file path, which
    the other arguments override); ``randomize`` (the pick-and-place start pose, default True);
    ``fixed_jaw`` (``held_insertion`` only, default False: keep the jaw closed on the peg and
    ignore the action's ``jaw``, so that exploration cannot drop the peg);
    ``render_mode`` (``"rgb_array"`` or ``"human"``), ``width`` and ``height`` [px];
    ``force_penalty_steps`` (with ``reward_mode="shaped"``, see Reward). ``gymnasium.make``
    passes them to :func:`peg_ctrl.gym.make.make_env`, which builds the environment and the
    reward wrapper.

Seeding
    ``reset(seed=s)`` seeds the environment's generator; each episode's start state, domain draw
    and sensor noise come from it, so the same seed and actions give the same observations.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium
import mujoco
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from peg_ctrl.config import ConfigError, read_mapping
from peg_ctrl.errors import CommandError, EpisodeFailure
from peg_ctrl.gym.actions import (
    ACTION_MODES,
    MAX_ANGULAR_SPEED,
    MAX_SPEED,
    WORKSPACE,
    action_space,
    action_target,
)
from peg_ctrl.gym.agent_task import AgentTask
from peg_ctrl.run.episode import DomainConfig, EpisodeConfig, build_loop, episode_config_from_mapping
from peg_ctrl.run.loop import Loop, StepInfo
from peg_ctrl.run.recorders import FollowCamera, offscreen_renderer
from peg_ctrl.sim.gl import PassiveViewer
from peg_ctrl.sim.state import BLOCK_PEG, ft_world

__all__ = [
    "ENV_ID",
    "MAX_EPISODE_STEPS",
    "PegInsertionEnv",
    "AgentTask",
    "WORKSPACE",
    "MAX_SPEED",
    "MAX_ANGULAR_SPEED",
    "ACTION_MODES",
    "SPARSE_REWARD",
]

ENV_ID = "peg_ctrl/PegInsertion-v0"
#: The registered time limit, in control periods: 5 s of the default ``pd`` controller's 5 ms.
MAX_EPISODE_STEPS = 1000
SPARSE_REWARD = (1.0, -1.0)  # the environment's own reward: (seated, a monitor failed the episode)


class _LastStep:
    """A loop recorder that keeps the last control step's peak peg-block force [N]."""

    def __init__(self) -> None:
        self.block_force = 0.0

    def record(self, loop: Loop, info: StepInfo) -> None:
        self.block_force = info.forces[BLOCK_PEG]


def _vector(low: float, high: float, n: int) -> spaces.Box:
    return spaces.Box(low, high, shape=(n,), dtype=np.float32)


def _canonical(q: NDArray[np.float64]) -> NDArray[np.float64]:
    return -q if q[0] < 0 else q


def _choice(value: str, allowed: tuple[str, ...], what: str) -> str:
    if value not in allowed:
        raise ConfigError(f"{what} must be one of {', '.join(allowed)}, got {value!r}")
    return value


def _episode_config(
    config: Mapping[str, Any] | str | os.PathLike[str] | None,
    task: str | Mapping[str, Any],
    controller: str | Mapping[str, Any],
    profile: str,
    disturbances: Mapping[str, Any] | None,
    scene: Mapping[str, Any] | None,
    randomize: bool,
    /,
) -> EpisodeConfig:
    """The episode config the environment runs: ``config`` (a mapping or a file) with the
    environment's named arguments (see :class:`PegInsertionEnv`) on top. Raises
    :class:`ConfigError` naming a bad field."""
    if config is None:
        data: dict[str, Any] = {}
    elif isinstance(config, Mapping):
        data = copy.deepcopy(dict(config))
    else:
        data = read_mapping(Path(config))
    data["task"] = task if isinstance(task, str) else dict(task)
    data["controller"] = controller if isinstance(controller, str) else dict(controller)
    data["physics"] = {**data.get("physics", {}), "profile": profile}
    data["randomization"] = {**data.get("randomization", {}), "enabled": bool(randomize)}
    if disturbances is not None:
        data["domain"] = {**data.get("domain", {}), **dict(disturbances)}
    if scene is not None:
        data["scene"] = _merge(data.get("scene", {}), scene)
    return episode_config_from_mapping(data)


def _merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in top.items():
        nested = isinstance(value, Mapping) and isinstance(out.get(key), Mapping)
        out[key] = _merge(out[key], value) if nested else value
    return out


def _observation_space() -> spaces.Dict:
    """The observation: the gripper's pose, velocity and jaw, the wrist wrench, the peg's pose
    and the hole's position."""
    inf = np.inf
    return spaces.Dict(
        {
            "gripper_pos": _vector(-10.0, 10.0, 3),
            "gripper_quat": _vector(-1.0, 1.0, 4),
            "gripper_vel": _vector(-inf, inf, 6),
            "jaw": _vector(0.0, 0.1, 1),
            "ft_wrench": _vector(-inf, inf, 6),
            "peg_pos": _vector(-inf, inf, 3),
            "peg_quat": _vector(-1.0, 1.0, 4),
            "hole_pos": _vector(-10.0, 10.0, 3),
        }
    )


class PegInsertionEnv(gymnasium.Env[dict[str, Any], NDArray[Any]]):
    """Peg-in-hole insertion with the Robotiq 2F-85 on a 6-DoF base (see the module docstring)."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    def __init__(
        self,
        *,
        task: str | Mapping[str, Any] = "held_insertion",
        controller: str | Mapping[str, Any] = "pd",
        profile: str = "seed",
        disturbances: Mapping[str, Any] | None = None,
        scene: Mapping[str, Any] | None = None,
        config: Mapping[str, Any] | str | os.PathLike[str] | None = None,
        randomize: bool = True,
        fixed_jaw: bool = False,
        action_mode: str = "delta",
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
    ) -> None:
        self.action_mode = _choice(action_mode, ACTION_MODES, "action_mode")
        self.render_mode = self._checked_render_mode(render_mode)
        self.cfg = _episode_config(config, task, controller, profile, disturbances, scene, randomize)
        self.width, self.height = int(width), int(height)
        self._randomized_domain = self.cfg.domain != DomainConfig()
        self._build(self.cfg)
        self.control_dt = self.loop.control_dt
        a = self.cfg.scene.assets
        hx, hy = self.cfg.scene.hole_xy
        self.hole_pos = np.array([hx, hy, a.block_size[2]])
        #: The seated goal of the peg's lower end: the hole axis ``success.min_depth`` below the mouth.
        self.goal_pos = self.hole_pos - np.array([0.0, 0.0, self.cfg.success.min_depth])
        if fixed_jaw and self.cfg.task.name != "held_insertion":
            raise ConfigError(
                f"fixed_jaw=True needs task held_insertion (the peg starts in the hand), got task "
                f"{self.cfg.task.name!r}, whose agent must open and close the jaw"
            )
        self.fixed_jaw = bool(fixed_jaw)
        self.observation_space = _observation_space()
        self.action_space = action_space(self.action_mode)
        self._renderer: mujoco.Renderer | None = None
        self._camera: FollowCamera | None = None
        self._viewer: Any = None
        self._wall0 = 0.0
        self._done = True

    def _checked_render_mode(self, render_mode: str | None) -> str | None:
        if render_mode is not None:
            _choice(render_mode, tuple(self.metadata["render_modes"]), "render_mode")
        if render_mode == "human" and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise ConfigError(
                "render_mode='human' needs a display (DISPLAY is not set); "
                "use render_mode='rgb_array' headless"
            )
        return render_mode

    # -- building ---------------------------------------------------------------------------------
    def _build(self, cfg: EpisodeConfig) -> None:
        self.loop = build_loop(cfg)
        self.task = AgentTask(self.loop.task)
        self.loop.task = self.task
        self._last = _LastStep()
        self.loop.recorders = [self._last]
        self.model, self.data = self.loop.model, self.loop.data

    # -- the Gymnasium API --------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        super().reset(seed=seed)
        episode_seed = int(self.np_random.integers(0, 2**31 - 1))
        if self._randomized_domain:  # a fresh domain draw and noise stream per episode
            self._build(dataclasses.replace(self.cfg, seed=episode_seed))
            self._close_renderers()
        obs = self.loop.reset(np.random.default_rng(episode_seed))
        self._done = False
        self._wall0 = time.perf_counter()
        m = self.task.insertion.measure(obs.peg)
        info = self._info(m, success=False, reason="")
        if self.render_mode == "human":
            self.render()
        return self._observation(), info

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[dict[str, NDArray[np.float32]], float, bool, bool, dict[str, Any]]:
        if self._done:
            raise RuntimeError("step() after the episode terminated; call reset()")
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (7,):
            raise CommandError(f"action must have shape (7,), got {np.shape(action)}")
        if not np.all(np.isfinite(a)):
            raise CommandError(f"action must be finite, got {a.tolist()}")
        self.task.command = action_target(
            self.action_mode, a, self.loop.state(), self.control_dt, fixed_jaw=self.fixed_jaw
        )
        success, reason = False, ""
        try:
            evaluation = self.loop.step()
            success, terminated, m = evaluation.success, evaluation.done, evaluation.metrics
        except EpisodeFailure as failure:  # a monitor ended the step before the task measured it
            self.task.finish(float(self.data.time), failure.reason)
            reason, terminated = failure.reason, True
            assert self.loop.peg is not None
            m = self.task.insertion.measure(self.loop.peg)
        self._done = terminated
        win, lose = SPARSE_REWARD
        terms = {"success": win * success, "failure": lose * bool(reason)}
        info = self._info(m, success=success, reason=reason)
        info["reward_terms"] = terms
        if self.render_mode == "human":
            self.render()
        # The time limit is Gymnasium's TimeLimit around the environment: never truncated here.
        return self._observation(), sum(terms.values()), terminated, False, info

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode == "rgb_array":
            return self._render_rgb()
        if self.render_mode == "human":
            self._render_human()
        return None

    def close(self) -> None:
        self._close_renderers()

    # -- pieces ---------------------------------------------------------------------------------
    def _observation(self) -> dict[str, NDArray[np.float32]]:
        """The observation now: the gripper as sensed (the reading the next step acts on)."""
        s = self.loop.sensed()
        force, torque = ft_world(s)
        peg = self.loop.peg
        assert peg is not None
        f32 = np.float32
        return {
            "gripper_pos": s.p_world.astype(f32),
            "gripper_quat": _canonical(s.quat_world).astype(f32),
            "gripper_vel": np.concatenate([s.v_world, s.omega_body]).astype(f32),
            "jaw": np.array([min(max(s.jaw_sep_m, 0.0), 0.1)], dtype=f32),
            "ft_wrench": np.concatenate([force, torque]).astype(f32),
            "peg_pos": peg.p_world.astype(f32),
            "peg_quat": _canonical(peg.quat_world).astype(f32),
            "hole_pos": self.hole_pos.astype(f32),
        }

    def _info(self, m: Any, *, success: bool, reason: str) -> dict[str, Any]:
        depth, lateral, tilt = (math.nan if v is None else float(v) for v in m.hole_metrics())
        return {
            "success": success,
            "reason": reason,
            "t": float(self.data.time),
            "depth_m": depth,  # NaN while the peg is not at the hole (lying, or beside the block)
            "lateral_error_m": lateral,
            "tilt_rad": tilt,
            "peg_block_force_n": float(self._last.block_force),
        }

    def _render_rgb(self) -> NDArray[np.uint8]:
        if self._renderer is None:
            self._renderer = offscreen_renderer(self.model, self.height, self.width)
            self._camera = FollowCamera(self.model)
        assert self._camera is not None
        self._renderer.update_scene(self.data, camera=self._camera.update(self.data))
        return self._renderer.render()

    def _render_human(self) -> None:
        if self._viewer is None:
            self._viewer = PassiveViewer(self.model, self.data)  # Triton first (peg_ctrl.sim.gl)
        if self._viewer.is_running():
            self._viewer.sync()
            lag = self.data.time - (time.perf_counter() - self._wall0)
            if lag > 0:
                time.sleep(lag)  # real-time pacing

    def _close_renderers(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
