"""Reward wrappers of ``peg_ctrl/PegInsertion-v0`` (:class:`~peg_ctrl.gym.env.PegInsertionEnv`).

The environment's own reward is sparse (``+1`` seated, ``-1`` failed, else 0);
:class:`ShapedReward` replaces it with a dense one. ``gymnasium.make(ENV_ID,
reward_mode="shaped")`` applies it (:func:`peg_ctrl.gym.make.make_env`); wrapped by hand around a
made environment, it reads the episode length from the ``TimeLimit`` inside::

    env = ShapedReward(gym.make("peg_ctrl/PegInsertion-v0", max_episode_steps=400))
"""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium
import numpy as np
from numpy.typing import NDArray

from peg_ctrl.config import ConfigError
from peg_ctrl.gym.env import PegInsertionEnv

__all__ = [
    "ShapedReward",
    "SHAPED_TERMINAL_REWARD",
    "FORCE_FREE_N",
    "FORCE_PENALTY",
    "GOAL_SCALE_M",
    "REACH_SCALE_M",
]

#: Terminal rewards ``(seated, failed)``. They exceed twice the shaping's bound (progress in
#: [-1, 1], force penalty in [-0.5, 0] per episode): any success >= 1.5 > 1 >= holding still
#: >= -1.5 > -2 >= any failure.
SHAPED_TERMINAL_REWARD = (3.0, -3.0)
FORCE_FREE_N = 10.0  # the force penalty counts peg-block force above this [N]
FORCE_PENALTY = 0.5  # the force penalty's bound over an episode of force_penalty_steps steps
GOAL_SCALE_M = 0.03  # distance of the peg's lower end from the seated goal at which closeness is 0.24
REACH_SCALE_M = 0.1  # the same for the pinch point's distance from the peg (pick_and_place)
_SUMMANDS = ("success", "failure", "progress", "force_penalty")


class ShapedReward(
    gymnasium.RewardWrapper[dict[str, Any], NDArray[Any]], gymnasium.utils.RecordConstructorArgs
):
    """The shaped reward: ``+3`` seated, ``-3`` failed, plus on every step

    - ``progress = closeness_now - closeness_before`` (potential-based shaping, Ng et al. 1999),
      ``closeness = 1 - tanh(d_goal / 0.03 m)`` for ``held_insertion``, the mean of that and
      ``1 - tanh(d_reach / 0.1 m)`` for ``pick_and_place``, each in ``[0, 1]``;
    - ``force_penalty = -0.5 * tanh(max(0, F - 10 N) / 10 N) / force_penalty_steps``, which
      sums to at least -0.5 over an episode of up to ``force_penalty_steps`` steps.

    ``d_goal`` [m]: the peg's lower end to :attr:`PegInsertionEnv.goal_pos`; ``d_reach`` [m]:
    the pinch point to the peg's centre; ``F`` [N]: the control period's peak peg-block force
    (``info["peg_block_force_n"]``). ``info["reward_terms"]`` gets the factors ``goal``,
    ``reach``, ``closeness`` and the summands ``progress``, ``force_penalty``, ``success``,
    ``failure`` (their sum is the reward).

    Args:
        env: ``peg_ctrl/PegInsertion-v0``, made or wrapped.
        force_penalty_steps: The episode length [control periods] the force penalty is spread
            over; ``None``: the ``max_episode_steps`` of the ``TimeLimit`` that ``env`` has.

    Raises:
        ConfigError: ``force_penalty_steps`` is not a positive integer, or is ``None`` and
            ``env`` has no time limit.
        TypeError: ``env`` does not unwrap to a :class:`PegInsertionEnv`.
    """

    def __init__(
        self, env: gymnasium.Env[dict[str, Any], NDArray[Any]], *, force_penalty_steps: int | None = None
    ) -> None:
        gymnasium.utils.RecordConstructorArgs.__init__(self, force_penalty_steps=force_penalty_steps)
        super().__init__(env)
        if not isinstance(env.unwrapped, PegInsertionEnv):
            raise TypeError(f"ShapedReward wraps a PegInsertionEnv, got {type(env.unwrapped).__name__}")
        if force_penalty_steps is None:
            force_penalty_steps = env.spec.max_episode_steps if env.spec is not None else None
            if force_penalty_steps is None:
                raise ConfigError(
                    "ShapedReward needs force_penalty_steps: the environment has no TimeLimit to read it from"
                )
        if not (isinstance(force_penalty_steps, int) and force_penalty_steps >= 1):
            raise ConfigError(f"force_penalty_steps must be a positive integer, got {force_penalty_steps!r}")
        self.force_penalty_steps = force_penalty_steps
        self.peg_env: PegInsertionEnv = env.unwrapped
        self._reach = self.peg_env.cfg.task.name == "pick_and_place"
        self._closeness_before = 0.0  # the potential at the last step
        self._step_info: dict[str, Any] = {}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._closeness_before = self.closeness()["closeness"]
        return obs, info

    def step(self, action: NDArray[Any]) -> tuple[dict[str, Any], SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._step_info = info
        return obs, self.reward(reward), terminated, truncated, info

    def reward(self, reward: SupportsFloat) -> float:
        """The shaped reward of the step just taken (the environment's sparse ``reward`` is
        replaced); writes its terms into that step's ``info["reward_terms"]``."""
        info = self._step_info
        win, lose = SHAPED_TERMINAL_REWARD
        terms = {"success": win * bool(info["success"]), "failure": lose * bool(info["reason"])}
        factors = self.closeness()
        excess = max(0.0, info["peg_block_force_n"] - FORCE_FREE_N) / FORCE_FREE_N
        terms |= factors
        terms["progress"] = factors["closeness"] - self._closeness_before
        terms["force_penalty"] = -FORCE_PENALTY * math.tanh(excess) / self.force_penalty_steps
        self._closeness_before = factors["closeness"]
        info["reward_terms"] = terms
        return sum(terms[k] for k in _SUMMANDS)

    def closeness(self) -> dict[str, float]:
        """The potential now and its factors ``goal``, ``reach``, ``closeness``, each in
        ``[0, 1]`` (1 at the goal)."""
        loop = self.peg_env.loop
        peg = loop.peg
        assert peg is not None
        off = peg.bottom_world - self.peg_env.goal_pos
        off[2] = max(0.0, off[2])  # deeper than min_depth is on the goal
        goal = 1.0 - math.tanh(float(np.linalg.norm(off)) / GOAL_SCALE_M)
        if not self._reach:
            return {"goal": goal, "reach": 1.0, "closeness": goal}
        pinch = loop.state().p_world
        reach = 1.0 - math.tanh(float(np.linalg.norm(pinch - peg.p_world)) / REACH_SCALE_M)
        return {"goal": goal, "reach": reach, "closeness": 0.5 * (goal + reach)}
