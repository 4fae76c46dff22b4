"""The goal-conditioned view for HER: Gymnasium/SB3 compliance and compute_reward = the env's reward."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_checker import check_env

from envs import GoalReachWrapper
from envs.wrappers.goal import OBSERVATION_INDEX
from robot_control.controllers import ResolvedRateController, pose_error
from tests.envs import oracle

#: The success reward of the tests that pay one.
SUCCESS_REWARD = 2.75


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


def controlled(env: GoalReachWrapper, info: dict) -> np.ndarray:
    """The resolved-rate controller's action from the pose and target of ``info`` (toward the target)."""
    pose, target = info["pose"][None], info["target"][None]
    error = pose_error(env.params, pose, target)
    return ResolvedRateController(env.params).act(pose, error, np.zeros_like(pose))[0]


@pytest.mark.parametrize("success_reward", [0.0, SUCCESS_REWARD])
def test_compute_reward_reproduces_the_step_reward(goal_env, rng, success_reward):
    """For the real goal, compute_reward returns exactly what step paid (terminations included), batched too.

    600 random steps (which terminate), then an episode of the resolved-rate controller to a standard target
    (which succeeds).
    """
    env = GoalReachWrapper(gym.make(goal_env.unwrapped.spec.id, success_reward=success_reward))
    env.reset(seed=11)
    achieved, desired, infos, rewards = [], [], [], []

    def step(action):
        _, reward, terminated, truncated, info = env.step(action)
        assert env.compute_reward(info["pose"], info["target"], info) == reward
        achieved.append(info["pose"])
        desired.append(info["target"])
        infos.append(info)
        rewards.append(reward)
        return info, terminated or truncated

    while len(rewards) < 600:
        if step(rng.uniform(-1.3, 1.3, size=3).astype(np.float32))[1]:
            env.reset()
    _, info = env.reset(options={"targets": "standard"})
    for _ in range(100):
        info, done = step(controlled(env, info))
        assert not done
    assert any(info["reward_termination"] < 0 for info in infos)  # terminal transitions are covered
    assert sum(info["is_success"] for info in infos) >= 20  # and success steps
    batched = env.compute_reward(np.array(achieved), np.array(desired), np.array(infos, dtype=object))
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


def hand_reward(settings: oracle.Settings, achieved: np.ndarray, goal: np.ndarray, info: dict) -> tuple[float, bool]:
    """(The reward of a step had its goal been ``goal``, whether it pays the success reward), by hand.

    Tracking against ``goal``, the singularity penalty of the info's k, the info's action, termination and Type I
    terms, and the success reward where ``achieved`` is within the tolerances of ``goal`` and the step did not
    terminate.
    """
    position, orientation, _ = oracle.errors(settings, achieved, goal)
    lc = settings.robot.characteristic_length
    tracking = -(settings.position_weight * position + settings.orientation_weight * lc * orientation)
    k, safe = info["inverse_condition_number"], settings.safe_threshold
    singularity = -settings.singularity_weight * ((safe - k) / safe) ** 2 if k < safe else 0.0
    reached = position <= settings.success_position_tolerance and orientation <= settings.success_orientation_tolerance
    paid = bool(info["termination_reason"] == "" and reached)
    others = info["reward_action"] + info["reward_termination"] + info["reward_actuator_singularity"]
    return tracking + singularity + others + (settings.success_reward if paid else 0.0), paid


@pytest.mark.parametrize("env_id", ["Planar3RPRReachHard-v0", "DeltaReach-v0"])
def test_relabelled_goals_pay_the_success_reward(env_id, rng):
    """compute_reward on relabelled goals equals the hand computation, success reward included.

    The goals: each step's own pose (reached, so paid unless the step terminated), that pose moved by half the
    position tolerance (reached), and the pose of another step (mostly not reached).
    """
    env = GoalReachWrapper(gym.make(env_id, success_reward=SUCCESS_REWARD))
    settings = oracle.settings_of(env)
    n, m = env.action_space.shape[0], len(env.params.pose_low)
    env.reset(seed=5)
    infos = []
    while sum(i["termination_reason"] != "" for i in infos) < 3 and len(infos) < 3000:  # random steps terminate
        _, _, terminated, truncated, info = env.step(rng.uniform(-1.3, 1.3, size=n).astype(np.float32))
        infos.append(info)
        if terminated or truncated:
            env.reset()
    _, info = env.reset(options={"targets": "standard"})
    for _ in range(100):  # the controller reaches its target and stays there
        _, _, _, _, info = env.step(controlled(env, info))
        infos.append(info)
    achieved = np.array([i["pose"] for i in infos])
    shift = np.zeros(m)
    shift[0] = 0.5 * settings.success_position_tolerance
    goals = np.concatenate([achieved, achieved + shift, np.roll(achieved, 7, axis=0)])
    achieved, infos = np.tile(achieved, (3, 1)), infos * 3
    got = env.compute_reward(achieved, goals, np.array(infos, dtype=object))
    expected, paid = zip(*(hand_reward(settings, a, g, i) for a, g, i in zip(achieved, goals, infos)))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    for a, g, i, r in zip(achieved[:5], goals[:5], infos[:5], got[:5]):
        assert env.compute_reward(a, g, i) == r  # one at a time as in the batch
    paid, terminated = np.array(paid), np.array([i["termination_reason"] != "" for i in infos])
    assert paid.sum() >= 100 and (~paid).sum() >= 100
    assert terminated.sum() >= 3  # a terminated step at its own pose is not paid
