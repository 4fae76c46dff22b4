"""training.policies.DampedMlpPolicy: the mean is the plain network's output times the planner's damping of k."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.policies import ActorCriticPolicy

from training.policies import DampedMlpPolicy

K_INDEX, K_MEAN, K_SCALE, K_D = 17, 0.2, 0.15, 0.1


def _damped(seed: int = 0, **overrides) -> PPO:
    torch.manual_seed(seed)
    kwargs = {"net_arch": [32, 32], "k_index": K_INDEX, "k_mean": K_MEAN, "k_scale": K_SCALE, "damping_threshold": K_D}
    use_sde = overrides.pop("use_sde", False)
    env = gym.make("Planar3RRRReach-v0")
    return PPO(DampedMlpPolicy, env, device="cpu", use_sde=use_sde, policy_kwargs={**kwargs, **overrides})


def _observations(k: np.ndarray) -> np.ndarray:
    """Normalised observations (B, 18) with random entries and column K_INDEX holding raw ``k`` normalised."""
    obs = np.random.default_rng(1).normal(size=(len(k), 18)).astype(np.float32)
    obs[:, K_INDEX] = (k - K_MEAN) / K_SCALE
    return obs


def test_the_mean_is_the_plain_networks_output_times_the_damping_of_the_raw_k():
    """Oracle: SB3's own MlpPolicy with the same weights, times clip((k / k_d)², 0.05, 1) of the un-normalised k."""
    model = _damped()
    plain = ActorCriticPolicy(
        model.observation_space, model.action_space, lambda _: 0.0, net_arch=[32, 32]
    )  # same parameter names and shapes
    plain.load_state_dict(model.policy.state_dict())
    k = np.array([0.0, 0.01, 0.03, 0.05, 0.0999, 0.1, 0.4])
    obs = torch.as_tensor(_observations(k))
    with torch.no_grad():
        damped = model.policy.get_distribution(obs).distribution.mean.numpy()
        undamped = plain.get_distribution(obs).distribution.mean.numpy()
    factor = np.array([max(0.05, min(1.0, (value / K_D) ** 2)) for value in k])
    np.testing.assert_allclose(damped, undamped * factor[:, None], rtol=1e-5, atol=1e-7)
    assert factor[0] == 0.05 and factor[-1] == 1.0  # both clips are exercised
    # the action PPO samples and its log-likelihood use the same damped mean
    with torch.no_grad():
        actions, _, log_prob = model.policy(obs, deterministic=True)
        _, log_prob_again, _ = model.policy.evaluate_actions(obs, actions)
    np.testing.assert_allclose(actions.numpy(), damped, rtol=1e-6)
    np.testing.assert_allclose(log_prob.numpy(), log_prob_again.numpy(), rtol=1e-6)


def test_a_saved_damped_policy_loads_and_exports_with_its_damping(tmp_path):
    """PPO.save / PPO.load keep the class and the k statistics; training.export's module gives the same actions."""
    from training.export import deployed_module

    model = _damped(seed=3)
    model.save(tmp_path / "model.zip")
    loaded = PPO.load(tmp_path / "model.zip", device="cpu")
    assert type(loaded.policy) is DampedMlpPolicy
    assert (loaded.policy.k_index, loaded.policy.k_mean, loaded.policy.k_scale) == (K_INDEX, K_MEAN, K_SCALE)
    obs = _observations(np.array([0.02, 0.06, 0.3]))
    expected, _ = model.predict(obs, deterministic=True)
    again, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_array_equal(again, expected)
    with torch.no_grad():
        exported = deployed_module(loaded, None)(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(exported, expected, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"k_index": 18}, r"k_index must be an integer column in \[0, 18\), got 18"),
        ({"k_index": 1.5}, r"k_index must be an integer column in \[0, 18\), got 1.5"),
        ({"k_mean": float("nan")}, "k_mean must be finite, got nan"),
        ({"k_scale": 0.0}, "k_scale must be a finite number > 0, got 0.0"),
        ({"damping_threshold": 1.5}, r"damping_threshold must be in \(0, 1\], got 1.5"),
        ({"use_sde": True}, "use_sde must be False, got True"),
    ],
)
def test_bad_arguments_are_refused(overrides, message):
    """Each bad argument is named with the value given."""
    with pytest.raises(ValueError, match=message):
        _damped(**overrides)
