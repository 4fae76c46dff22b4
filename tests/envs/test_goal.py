"""The goal-conditioned view for HER: Gymnasium/SB3 compliance and compute_reward = the env's reward."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env

from envs import GoalReachWrapper
from envs.wrappers.goal import OBSERVATION_INDEX


@pytest.fixture(params=["Planar3RPRReach-v0", "Planar3RPRReachHard-v0"])
def goal_env(request):
    """A goal view of a Reach env."""
    env = GoalReachWrapper(gym.make(request.param))
    yield env
    env.close()


def test_checkers_pass_without_warnings(goal_env, recwarn):
    """SB3's checker (which also checks a goal env's compute_reward) passes with no warning."""
    check_env(goal_env, warn=True)
    assert not [w for w in recwarn if "envs" in str(w.filename) or "stable_baselines3" in str(w.filename)]


def test_observation_splits_the_flat_one(goal_env, rng):
    """Observation = goal-free entries of the flat obs; achieved = pose; desired = target."""
    obs, info = goal_env.reset(seed=4)
    for _ in range(20):
        assert goal_env.observation_space.contains(obs)
        np.testing.assert_array_equal(obs["achieved_goal"], info["pose"].astype(np.float32))
        np.testing.assert_array_equal(obs["desired_goal"], info["target"].astype(np.float32))
        obs, _, terminated, truncated, info = goal_env.step(rng.uniform(-1, 1, size=3).astype(np.float32))
        if terminated or truncated:
            obs, info = goal_env.reset()
    flat_env = gym.make(goal_env.spec.id if goal_env.spec else "Planar3RPRReach-v0")
    flat, _ = flat_env.reset(seed=9)
    goal_obs, _ = goal_env.reset(seed=9)
    np.testing.assert_array_equal(goal_obs["observation"], flat[OBSERVATION_INDEX])


def test_compute_reward_reproduces_the_step_reward(goal_env, rng):
    """For the real goal, compute_reward returns exactly what step paid (terminations included), batched too."""
    goal_env.reset(seed=11)
    achieved, desired, infos, rewards = [], [], [], []
    while len(rewards) < 600:
        _, reward, terminated, truncated, info = goal_env.step(rng.uniform(-1.3, 1.3, size=3).astype(np.float32))
        assert goal_env.compute_reward(info["pose"], info["target"], info) == reward
        achieved.append(info["pose"])
        desired.append(info["target"])
        infos.append(info)
        rewards.append(reward)
        if terminated or truncated:
            goal_env.reset()
    assert any(info["reward_termination"] < 0 for info in infos)  # terminal transitions are covered
    batched = goal_env.compute_reward(np.array(achieved), np.array(desired), np.array(infos, dtype=object))
    np.testing.assert_array_equal(batched, np.array(rewards))


def test_relabelled_goal_changes_only_the_tracking_term(goal_env, rng):
    """With the achieved pose as goal the tracking term vanishes; the other terms stay."""
    goal_env.reset(seed=2)
    _, reward, _, _, info = goal_env.step(rng.uniform(-1, 1, size=3).astype(np.float32))
    relabelled = goal_env.compute_reward(info["pose"], info["pose"], info)
    assert relabelled == pytest.approx(reward - info["reward_tracking"], abs=1e-12)
    assert relabelled > reward


def test_refuses_other_environments():
    """Only a Reach env has a fixed goal to relabel; Track and foreign envs are refused by name."""
    with pytest.raises(TypeError, match="Reach environment"):
        GoalReachWrapper(gym.make("Planar3RPRTrack-v0"))
    with pytest.raises(TypeError, match="CartPoleEnv"):
        GoalReachWrapper(gym.make("CartPole-v1"))
    env = GoalReachWrapper(gym.make("Planar3RPRReach-v0"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match="must match"):
        env.compute_reward(np.zeros((2, 3)), np.zeros((3, 3)), [{}, {}])
