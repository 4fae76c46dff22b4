"""training.export: the TorchScript policy gives the actions SB3's predict gives (the oracle), without SB3."""

from __future__ import annotations

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs  # noqa: F401  (registers the ids)
from training.evaluate import EvaluationError, load_run, wrap_for_run
from training.export import deployed_module, export_run, main

SHIPPED = "training/pretrained/distill-Planar3RPRReachMixed-v0"


def _observations(env_id: str, agent, config: dict, n: int = 64) -> np.ndarray:
    """Observations of a rollout of the agent on its run's env, and some far outside the statistics (the clip)."""
    env = wrap_for_run(gym.make(env_id), config)
    obs, _ = env.reset(seed=3)
    seen = [obs]
    for _ in range(n - 1):
        obs, _, terminated, truncated, _ = env.step(agent(obs[None])[0])
        seen.append(obs)
        if terminated or truncated:
            obs, _ = env.reset()
    rng = np.random.default_rng(0)
    wild = rng.uniform(-50.0, 50.0, size=(16, len(obs))).astype(np.float32)
    return np.concatenate([np.array(seen, dtype=np.float32), wild])


def _randomise_statistics(run) -> None:
    """Give the run's VecNormalize non-trivial statistics (an untrained one has mean 0, variance 1)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    path = run / "vecnormalize.pkl"
    normalizer = VecNormalize.load(str(path), DummyVecEnv([lambda: gym.make("Planar3RPRReach-v0")]))
    rng = np.random.default_rng(1)
    normalizer.obs_rms.mean = rng.normal(size=normalizer.obs_rms.mean.shape)
    normalizer.obs_rms.var = rng.uniform(0.01, 4.0, size=normalizer.obs_rms.var.shape)
    normalizer.clip_obs = 3.0
    normalizer.save(str(path))


@pytest.mark.parametrize("source", ["shipped-ppo", "tqc", "td3-unnormalised", "sac-pendulum"])
def test_exported_policy_acts_as_sb3_predicts(source, make_run_folder, tmp_path):
    """Actions of the TorchScript file equal load_run's (VecNormalize + predict) to float32 rounding."""
    if source == "shipped-ppo":
        run, env_id = SHIPPED, "Planar3RPRReachMixed-v0"
    elif source == "tqc":
        run, env_id = make_run_folder("tqc"), "Planar3RPRReach-v0"
        _randomise_statistics(run)
    elif source == "td3-unnormalised":
        run, env_id = make_run_folder("td3", normalize=False), "Planar3RPRReach-v0"
    else:  # an action box other than [-1, 1]: the squashed action is rescaled to [-2, 2]
        run, env_id = make_run_folder("sac", env_id="Pendulum-v1", normalize=False), "Pendulum-v1"
    agent, config = load_run(run)
    obs = _observations(env_id, agent, config)
    expected = agent(obs)
    path = export_run(run, tmp_path / "policy.pt")
    loaded = torch.jit.load(str(path))
    with torch.no_grad():
        actual = loaded(torch.as_tensor(obs)).numpy()
    assert actual.dtype == np.float32 and actual.shape == expected.shape
    np.testing.assert_allclose(actual, expected, rtol=0, atol=2e-6)
    assert np.ptp(expected, axis=0).max() > 1e-3  # the observations do move the action


def test_dict_observations_are_refused():
    """HER's goal view cannot be exported; the error names the space."""
    space = gym.spaces.Dict({"observation": gym.spaces.Box(-1, 1, (3,))})
    model = SimpleNamespace(observation_space=space, action_space=gym.spaces.Box(-1, 1, (3,)))
    with pytest.raises(EvaluationError, match=r"only flat Box observations.*Dict"):
        deployed_module(model, None)


def test_cli_reports_a_missing_run(tmp_path, capsys):
    """The CLI exits 2 naming the folder."""
    assert main(["--run", str(tmp_path / "nothing"), "--out", str(tmp_path / "p.pt")]) == 2
    assert "nothing" in capsys.readouterr().err
