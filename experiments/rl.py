"""Reinforcement learning on ``peg_ctrl/PegInsertion-v0``: Stable-Baselines3 PPO with a learning
curve.

    python -m peg_ctrl.experiments.rl --out runs/ppo

trains ``PPO("MultiInputPolicy", ...)`` on the held insertion (the peg in the closed hand,
``fixed_jaw=True``, the ``shaped`` reward), evaluates the deterministic policy on fixed seeds
every ``--eval-every`` steps, and writes into ``--out``: ``curve.csv`` (one row per evaluation:
timesteps, wall time, success rate, mean return and episode length, the failure reasons, and the
training episodes' success rate since the last evaluation), ``run.json`` (the settings, the
training time and the final evaluation), ``learning_curve.png`` and the policy ``ppo.zip`` with
its observation normalisation ``vecnormalize.pkl``. Needs the ``rl`` extra (``pip install
'peg_ctrl[rl]'``); docs/rl.md shows the run and what it learned.

Observations are normalised (SB3's ``VecNormalize``, running mean and variance): the policy must
tell millimetres of peg position apart next to newtons of wrist force.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from peg_ctrl.config import ConfigError
from peg_ctrl.gym.env import ENV_ID
from peg_ctrl.io import atomic_write_text, prepare_output_dir, to_json
from peg_ctrl.progress import progress_bar

__all__ = [
    "PPOSettings",
    "Evaluation",
    "TranslationOnly",
    "make_env",
    "evaluate",
    "train",
    "plot_curve",
    "main",
]

#: The environment the example trains on (keyword arguments of ``gymnasium.make``).
#: A scripted straight descent seats the peg in under 1 s, so 2 s episodes (400 steps of 5 ms,
#: Gymnasium's ``max_episode_steps``) leave room.
ENV_KWARGS: dict[str, Any] = {
    "task": {"name": "held_insertion"},
    "fixed_jaw": True,
    "reward_mode": "shaped",
    "max_episode_steps": 400,
}
ACTION_SETS = ("translation", "full")  # what the policy commands (see TranslationOnly)
EVAL_SEED0 = 10_000  # evaluation episodes use seeds EVAL_SEED0, EVAL_SEED0 + 1, ... (never trained on)


@dataclass(frozen=True)
class PPOSettings:
    """One training run. ``env`` overrides :data:`ENV_KWARGS` key by key."""

    timesteps: int = 122_880  # environment steps (5 ms control periods); 60 rollouts of 2048
    eval_every: int = 12_288  # environment steps between evaluations
    eval_episodes: int = 10  # episodes per evaluation (seeds EVAL_SEED0 ...)
    seed: int = 0  # PPO's and the training environment's seed
    normalize: bool = True  # VecNormalize on the observations
    # ... and on the reward (returns scaled to unit variance for the value function; the
    # evaluation reports the environment's own reward)
    normalize_reward: bool = True
    n_steps: int = 2048  # PPO's rollout length per update (SB3's default)
    batch_size: int = 64  # PPO's minibatch (SB3's default)
    # The policy's initial exploration noise, log of its std in units of a full action. SB3's
    # default 0 (std 1) jerks the hand by up to 1 mm per 5 ms step; -1 (std 0.37) explores less
    # violently in a 1 mm clearance.
    log_std_init: float = -1.0
    actions: str = "translation"  # "translation" (TranslationOnly) or "full" (the env's 7-D action)
    env: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("timesteps", "eval_every", "eval_episodes", "n_steps", "batch_size"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if self.actions not in ACTION_SETS:
            raise ConfigError(f"actions must be one of {', '.join(ACTION_SETS)}, got {self.actions!r}")

    def env_kwargs(self) -> dict[str, Any]:
        """:data:`ENV_KWARGS` with :attr:`env` on top; the shaped reward's force penalty is
        spread over the episode (``force_penalty_steps = max_episode_steps``) unless set."""
        kwargs = {**ENV_KWARGS, **dict(self.env)}
        if kwargs.get("reward_mode") == "shaped":
            kwargs.setdefault("force_penalty_steps", kwargs["max_episode_steps"])
        return kwargs


@dataclass(frozen=True)
class Evaluation:
    """The deterministic policy on ``episodes`` fixed seeds."""

    timesteps: int
    wall_s: float
    success_rate: float
    mean_return: float
    mean_length: float
    reasons: dict[str, int]  # how episodes ended: "inserted", "truncated", or a monitor's reason
    train_success_rate: float  # the training episodes that ended since the last evaluation
    train_episodes: int


class TranslationOnly(gym.ActionWrapper):  # type: ignore[type-arg]
    """The policy commands the pinch point's velocity, ``[dx, dy, dz]`` in ``[-1, 1]`` (the delta
    action's first three components); the orientation is held (no turn) and the jaw closed.

    Three dimensions instead of seven: a random turn of the wrist tilts the held peg out of line
    with the bore, and exploring it is most of what a 7-D policy spends its steps on.
    """

    def __init__(self, env: gym.Env) -> None:  # type: ignore[type-arg]
        super().__init__(env)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)

    def action(self, action: np.ndarray) -> np.ndarray:
        full = np.zeros(7, dtype=np.float32)
        full[:3] = action
        full[6] = 1.0  # closed (ignored with fixed_jaw)
        return full


def make_env(*, actions: str = "translation", **kwargs: Any) -> Any:
    """``gymnasium.make(ENV_ID, **kwargs)``, in :class:`TranslationOnly` if ``actions`` says so,
    in SB3's ``Monitor`` (episode returns and lengths)."""
    from stable_baselines3.common.monitor import Monitor

    import peg_ctrl  # noqa: F401  (registers the environment)

    env = gym.make(ENV_ID, **kwargs)
    return Monitor(TranslationOnly(env) if actions == "translation" else env)


def _outcome(info: Mapping[str, Any], truncated: bool) -> str:
    if info.get("success"):
        return "inserted"
    return "truncated" if truncated else str(info.get("reason") or "terminated")


def evaluate(
    model: Any,
    env_kwargs: Mapping[str, Any],
    *,
    episodes: int,
    obs_rms: Any = None,
    actions: str = "translation",
) -> dict[str, Any]:
    """Success rate, mean return and length of ``model``'s deterministic policy over ``episodes``
    episodes with seeds ``EVAL_SEED0 + i``; ``obs_rms`` normalises the observations as in
    training (``VecNormalize.obs_rms``)."""
    env = make_env(actions=actions, **env_kwargs)
    returns, lengths, outcomes = [], [], Counter[str]()
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=EVAL_SEED0 + i)
            total, steps, done = 0.0, 0, False
            while not done:
                action, _ = model.predict(_normalized(obs, obs_rms), deterministic=True)
                obs, reward, terminated, truncated, info = env.step(action)
                total += float(reward)
                steps += 1
                done = terminated or truncated
            returns.append(total)
            lengths.append(steps)
            outcomes[_outcome(info, truncated)] += 1
    finally:
        env.close()
    return {
        "success_rate": outcomes["inserted"] / episodes,
        "mean_return": float(np.mean(returns)),
        "mean_length": float(np.mean(lengths)),
        "reasons": dict(sorted(outcomes.items())),
    }


def _normalized(obs: dict[str, np.ndarray], obs_rms: Any) -> dict[str, np.ndarray]:
    if obs_rms is None:
        return obs
    clip = 10.0  # VecNormalize's default clip_obs
    return {
        key: np.clip((value - obs_rms[key].mean) / np.sqrt(obs_rms[key].var + 1e-8), -clip, clip).astype(
            np.float32
        )
        for key, value in obs.items()
    }


def _callback(settings: PPOSettings, curve: list[Evaluation], t0: float, bar: Any) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class LearningCurve(BaseCallback):  # type: ignore[misc]
        """Evaluates every ``eval_every`` steps and tallies the training episodes in between."""

        def __init__(self) -> None:
            super().__init__()
            self.next_eval = settings.eval_every
            self.train_outcomes: list[bool] = []

        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                if done:
                    self.train_outcomes.append(bool(info.get("success")))
            bar.update(1)
            if self.num_timesteps >= self.next_eval:
                self.next_eval += settings.eval_every
                self.evaluate_now()
            return True

        def evaluate_now(self) -> None:
            venv = self.model.get_env()
            obs_rms = getattr(venv, "obs_rms", None)
            result = evaluate(
                self.model,
                settings.env_kwargs(),
                episodes=settings.eval_episodes,
                obs_rms=obs_rms,
                actions=settings.actions,
            )
            trained = self.train_outcomes
            curve.append(
                Evaluation(
                    timesteps=int(self.num_timesteps),
                    wall_s=time.perf_counter() - t0,
                    train_success_rate=(sum(trained) / len(trained)) if trained else math.nan,
                    train_episodes=len(trained),
                    **result,
                )
            )
            self.train_outcomes = []
            bar.set_postfix(success=f"{result['success_rate']:.0%}", refresh=False)

    return LearningCurve()


def train(settings: PPOSettings, out: str | Path, *, show_progress: bool = True) -> dict[str, Any]:
    """Train PPO as ``settings`` say, write the results into ``out`` (see the module docstring)
    and return ``run.json``'s content."""
    try:
        import torch
        from stable_baselines3 import PPO
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    except ImportError as exc:
        raise ConfigError(
            f"the RL example needs stable-baselines3 ({exc.name} is not installed): "
            "pip install 'peg_ctrl[rl]'"
        ) from None
    out = prepare_output_dir(out)
    torch.set_num_threads(1)  # a small MLP: more threads only contend with the physics
    env_kwargs = settings.env_kwargs()
    venv: Any = DummyVecEnv([lambda: make_env(actions=settings.actions, **env_kwargs)])
    if settings.normalize:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=settings.normalize_reward)
    venv.seed(settings.seed)
    model = PPO(
        "MultiInputPolicy",
        venv,
        n_steps=settings.n_steps,
        batch_size=settings.batch_size,
        policy_kwargs={"log_std_init": settings.log_std_init},
        seed=settings.seed,
        device="cpu",
        verbose=0,
    )
    curve: list[Evaluation] = []
    t0 = time.perf_counter()
    with progress_bar(
        total=settings.timesteps, desc="PPO", unit="step", enabled=show_progress, lines="steps"
    ) as bar:
        callback = _callback(settings, curve, t0, bar)
        model.learn(total_timesteps=settings.timesteps, callback=callback)
        if not curve or curve[-1].timesteps != model.num_timesteps:  # PPO ends on a whole rollout
            callback.evaluate_now()
    train_s = time.perf_counter() - t0
    model.save(out / "ppo.zip")
    if settings.normalize:
        venv.save(str(out / "vecnormalize.pkl"))
    venv.close()
    record = {
        "settings": asdict(settings),
        "env": env_kwargs,
        "timesteps": int(model.num_timesteps),
        "train_wall_s": train_s,
        "steps_per_s": model.num_timesteps / train_s,
        "threads": {"torch": torch.get_num_threads()},
        "versions": _versions(),
        "final": asdict(curve[-1]) if curve else None,
    }
    _write_curve(out / "curve.csv", curve)
    atomic_write_text(out / "run.json", to_json(record, indent=2) + "\n")
    plot_curve(curve, out / "learning_curve.png", title=_title(record))
    return record


def _versions() -> dict[str, str]:
    from importlib.metadata import version

    return {name: version(name) for name in ("peg_ctrl", "stable_baselines3", "torch", "gymnasium", "mujoco")}


def _title(record: Mapping[str, Any]) -> str:
    final = record["final"] or {}
    minutes = record["train_wall_s"] / 60.0
    return (
        f"PPO on held_insertion: {record['timesteps']:,} steps in {minutes:.0f} min, "
        f"final success {final.get('success_rate', math.nan):.0%}"
    )


def _write_curve(path: Path, curve: Sequence[Evaluation]) -> None:
    buf = io.StringIO()
    names = [f for f in Evaluation.__dataclass_fields__ if f != "reasons"] + ["reasons"]
    writer = csv.DictWriter(buf, fieldnames=names, lineterminator="\n")
    writer.writeheader()
    for row in curve:
        data = asdict(row)
        data["reasons"] = " ".join(f"{k}={v}" for k, v in row.reasons.items())
        writer.writerow(data)
    atomic_write_text(path, buf.getvalue())


def plot_curve(curve: Sequence[Evaluation], path: Path, *, title: str = "") -> Path:
    """Success rate (evaluation and training episodes) and mean evaluation return against
    training steps."""
    from peg_ctrl.run.plots import pyplot, save_figure

    plt = pyplot()
    fig, (ax_s, ax_r) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    steps = [c.timesteps for c in curve]
    ax_s.plot(steps, [c.success_rate for c in curve], "o-", label="evaluation (deterministic, fixed seeds)")
    ax_s.plot(steps, [c.train_success_rate for c in curve], "s--", alpha=0.7, label="training episodes")
    ax_s.set_ylabel("success rate")
    ax_s.set_ylim(-0.05, 1.05)
    ax_s.legend(loc="lower right")
    ax_s.grid(alpha=0.3)
    ax_r.plot(steps, [c.mean_return for c in curve], "o-", color="C2")
    ax_r.axhline(0.0, color="grey", lw=0.8)
    ax_r.set_ylabel("mean evaluation return")
    ax_r.set_xlabel("training steps (control periods of 5 ms)")
    ax_r.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m peg_ctrl.experiments.rl", description=__doc__.splitlines()[0]
    )
    defaults = PPOSettings()
    parser.add_argument("--timesteps", type=int, default=defaults.timesteps)
    parser.add_argument("--eval-every", type=int, default=defaults.eval_every)
    parser.add_argument("--eval-episodes", type=int, default=defaults.eval_episodes)
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--actions", choices=ACTION_SETS, default=defaults.actions)
    parser.add_argument(
        "--normalize-reward", action=argparse.BooleanOptionalAction, default=defaults.normalize_reward
    )
    parser.add_argument("--out", default="runs/ppo")
    args = parser.parse_args(argv)
    try:
        settings = PPOSettings(
            timesteps=args.timesteps,
            eval_every=args.eval_every,
            eval_episodes=args.eval_episodes,
            seed=args.seed,
            actions=args.actions,
            normalize_reward=args.normalize_reward,
        )
        record = train(settings, args.out)
    except ConfigError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    print(f"{_title(record)}; wrote {Path(args.out) / 'run.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
