"""What ``gymnasium.make("peg_ctrl/PegInsertion-v0", ...)`` builds: :func:`make_env`, the
registered entry point.

Gymnasium adds its own wrappers around what :func:`make_env` returns: the ``TimeLimit`` of
``max_episode_steps`` (registered: :data:`~peg_ctrl.gym.env.MAX_EPISODE_STEPS`), the order
enforcer and the passive checker.
"""

from __future__ import annotations

from typing import Any

import gymnasium
from numpy.typing import NDArray

from peg_ctrl.config import ConfigError
from peg_ctrl.gym.env import MAX_EPISODE_STEPS, PegInsertionEnv
from peg_ctrl.gym.wrappers import ShapedReward

__all__ = ["make_env", "REWARD_MODES"]

REWARD_MODES = ("sparse", "shaped")


def make_env(
    *, reward_mode: str = "sparse", force_penalty_steps: int | None = None, **kwargs: Any
) -> gymnasium.Env[dict[str, Any], NDArray[Any]]:
    """:class:`PegInsertionEnv` with the keyword arguments ``kwargs``, in :class:`ShapedReward`
    if ``reward_mode`` is ``"shaped"`` (``"sparse"``: the environment's own reward).

    Args:
        reward_mode: ``"sparse"`` or ``"shaped"``.
        force_penalty_steps: The shaped reward's force penalty is spread over this many control
            periods (default :data:`MAX_EPISODE_STEPS`, the registered time limit); give the
            same number as ``max_episode_steps`` when that is longer, so that the penalty keeps
            its bound of -0.5 per episode.

    Raises:
        ConfigError: an unknown ``reward_mode``, ``force_penalty_steps`` without the shaped
            reward or not a positive integer, ``time_limit_s`` (replaced by
            ``max_episode_steps``), or a bad environment argument.
    """
    if "time_limit_s" in kwargs:
        raise ConfigError(
            "time_limit_s is replaced by Gymnasium's max_episode_steps, in control periods: "
            "gymnasium.make(..., max_episode_steps=400) is 2 s at 5 ms"
        )
    if reward_mode not in REWARD_MODES:
        raise ConfigError(f"reward_mode must be one of {', '.join(REWARD_MODES)}, got {reward_mode!r}")
    if force_penalty_steps is not None and reward_mode != "shaped":
        raise ConfigError(
            f"force_penalty_steps belongs to reward_mode='shaped', got reward_mode={reward_mode!r}"
        )
    env = PegInsertionEnv(**kwargs)
    if reward_mode == "shaped":
        steps = MAX_EPISODE_STEPS if force_penalty_steps is None else force_penalty_steps
        return ShapedReward(env, force_penalty_steps=steps)
    return env


# gymnasium.make reads the render modes of its entry point (as it would of an Env class).
make_env.metadata = PegInsertionEnv.metadata  # type: ignore[attr-defined]
