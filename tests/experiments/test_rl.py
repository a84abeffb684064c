"""The reinforcement-learning example (``peg_ctrl.experiments.rl``): a small PPO run writes its
curve, record, figure and policy; its evaluation normalises observations as SB3 does; bad
settings are one error."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason="the rl extra is not installed")

from peg_ctrl.config import ConfigError  # noqa: E402
from peg_ctrl.experiments import rl  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:.*Box observation space m.*:UserWarning")


def test_a_small_ppo_run_writes_curve_record_figure_and_policy(tmp_path: Path) -> None:
    settings = rl.PPOSettings(
        timesteps=128,
        eval_every=64,
        eval_episodes=2,
        n_steps=64,
        batch_size=32,
        env={"max_episode_steps": 10},
    )
    record = rl.train(settings, tmp_path / "ppo", show_progress=False)
    out = tmp_path / "ppo"
    rows = list(csv.DictReader((out / "curve.csv").open()))
    assert [int(r["timesteps"]) for r in rows] == [64, 128]
    for row in rows:
        assert 0.0 <= float(row["success_rate"]) <= 1.0
        assert float(row["mean_length"]) == 10.0  # 0.05 s at 200 Hz, the peg held still by fixed_jaw
        assert row["reasons"] == "truncated=2"
    saved = json.loads((out / "run.json").read_text())
    assert saved["timesteps"] == record["timesteps"] == 128
    assert saved["env"]["fixed_jaw"] is True and saved["env"]["max_episode_steps"] == 10
    assert saved["env"]["force_penalty_steps"] == 10  # the shaped reward follows the episode length
    assert saved["train_wall_s"] > 0 and saved["final"]["timesteps"] == 128
    assert (out / "learning_curve.png").stat().st_size > 10_000
    assert (out / "ppo.zip").is_file() and (out / "vecnormalize.pkl").is_file()


def test_evaluation_normalises_observations_as_vecnormalize() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv = VecNormalize(
        DummyVecEnv([lambda: rl.make_env(**rl.PPOSettings().env_kwargs())]), norm_obs=True, norm_reward=False
    )
    venv.seed(0)
    venv.reset()
    for _ in range(20):  # update the running statistics
        venv.step(np.array([venv.action_space.sample()]))
    raw = {k: v[0] for k, v in venv.get_original_obs().items()}
    expected = venv.normalize_obs({k: v[None] for k, v in raw.items()})
    ours = rl._normalized(raw, venv.obs_rms)
    for key in raw:
        np.testing.assert_allclose(ours[key], expected[key][0], rtol=1e-5, atol=1e-5)
    venv.close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"timesteps": 0}, "timesteps must be a positive integer, got 0"),
        ({"eval_episodes": 1.5}, "eval_episodes"),
    ],
)
def test_bad_settings_are_one_error(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        rl.PPOSettings(**kwargs)


def test_command_line_refuses_bad_settings_with_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert rl.main(["--timesteps", "0", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["python -m peg_ctrl.experiments.rl: error: timesteps must be a positive integer, got 0"]
    assert not (tmp_path / "x").exists()


def test_the_example_env_is_a_2_s_time_limit_with_the_shaped_reward() -> None:
    kwargs = rl.PPOSettings().env_kwargs()
    assert kwargs["max_episode_steps"] == kwargs["force_penalty_steps"] == 400
    env = rl.make_env(**kwargs)
    assert env.spec.max_episode_steps == 400 and env.get_wrapper_attr("force_penalty_steps") == 400
    assert rl.PPOSettings(env={"force_penalty_steps": 500}).env_kwargs()["force_penalty_steps"] == 500
    env.close()


def test_translation_only_holds_the_orientation_and_the_jaw() -> None:
    env = rl.TranslationOnly(rl.make_env(actions="full", **rl.PPOSettings().env_kwargs()))
    assert env.action_space.shape == (3,)
    full = env.action(np.array([0.1, -0.2, -0.3], dtype=np.float32))
    np.testing.assert_array_equal(full, np.array([0.1, -0.2, -0.3, 0, 0, 0, 1], dtype=np.float32))
    env.close()
