"""envs.PreviousActionWrapper: the env's own observation followed by the previous action, clipped; zeros at reset."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from envs import GoalReachWrapper, PreviousActionWrapper


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v0", "StewartGoughReach-v0", "DeltaReach-v0"])
def test_the_observation_is_the_envs_own_then_the_previous_action(env_id):
    """Stepped beside an unwrapped env of the same seed, the first D columns are its observation.

    The last n are the previous action clipped to [-1, 1] (zeros after each reset); rewards and ends are the same.
    """
    plain, wrapped = gym.make(env_id), PreviousActionWrapper(gym.make(env_id))
    n, width = plain.action_space.shape[0], plain.observation_space.shape[0]
    assert wrapped.observation_space.shape == (width + n,)
    rng = np.random.default_rng(1)
    for seed in (3, 4):
        obs_p, _ = plain.reset(seed=seed)
        obs_w, _ = wrapped.reset(seed=seed)
        np.testing.assert_array_equal(obs_w, np.concatenate([obs_p, np.zeros(n, np.float32)]))
        for _ in range(5):
            action = rng.uniform(-1.5, 1.5, n).astype(np.float32)  # some entries beyond the bounds
            obs_p, r_p, term_p, trunc_p, _ = plain.step(action)
            obs_w, r_w, term_w, trunc_w, _ = wrapped.step(action)
            np.testing.assert_array_equal(obs_w[:width], obs_p)
            np.testing.assert_array_equal(obs_w[width:], np.minimum(np.maximum(action, -1.0), 1.0))
            assert (r_w, term_w, trunc_w) == (r_p, term_p, trunc_p)
            assert obs_w.dtype == np.float32 and wrapped.observation_space.contains(obs_w)
            if term_p or trunc_p:
                break


def test_gymnasiums_checker_passes():
    """gymnasium.utils.env_checker.check_env accepts the wrapped env."""
    check_env(PreviousActionWrapper(gym.make("Planar3RPRReach-v0")), skip_render_check=True)


def test_a_dict_observation_is_refused():
    """A Dict observation (HER's goal view) has no column to append to: refused, naming the space."""
    with pytest.raises(TypeError, match=r"needs a one-dimensional Box observation space, got Dict"):
        PreviousActionWrapper(GoalReachWrapper(gym.make("Planar3RPRReach-v0")))


def test_a_run_config_names_it():
    """``env_wrapper: envs.PreviousActionWrapper`` in a run's config resolves to the class."""
    from training.config import resolve_env_wrapper

    assert resolve_env_wrapper("envs.PreviousActionWrapper") is PreviousActionWrapper
