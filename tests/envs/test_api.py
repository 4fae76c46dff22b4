"""The environments follow the Gymnasium API to the letter: checkers, spaces, registry, rewards and infos."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from envs import ENV_IDS
from tests.envs.helpers import INFO_KEYS, MAX_EPISODE_STEPS, REWARD_TERMS

REPO_ROOT = Path(__file__).resolve().parents[2]


def _format(caught: list[warnings.WarningMessage]) -> str:
    return "\n".join(f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught)


def _rollout(env: gym.Env, steps: int, seed: int = 0) -> list[tuple]:
    """(obs, reward, terminated, truncated, info) of ``steps`` random steps, resetting when needed."""
    env.action_space.seed(seed)
    env.reset(seed=seed)
    out = []
    for _ in range(steps):
        result = env.step(env.action_space.sample())
        out.append(result)
        if result[2] or result[3]:
            env.reset()
    return out


@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_env_checker_passes_without_warnings(env_id, render_mode, make_env):
    """Gymnasium's own checker accepts the bare environment and emits no warning."""
    env = make_env(env_id, render_mode=render_mode)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gymnasium_check_env(env.unwrapped)
    assert not caught, f"gymnasium check_env warned:\n{_format(caught)}"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_env_checker_passes_without_warnings(env_id, make_env):
    """Stable-Baselines3's checker accepts the made (wrapped) environment and emits no warning."""
    env = make_env(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env, warn=True)
    assert not caught, f"SB3 check_env warned:\n{_format(caught)}"


def test_registry_matches_expected_ids():
    """ENV_IDS is exactly the documented set of ids, each registered."""
    assert set(ENV_IDS) == set(MAX_EPISODE_STEPS)
    for env_id in ENV_IDS:
        assert env_id in gym.registry, env_id


def test_make_with_module_prefix_in_fresh_interpreter():
    """gym.make("envs:Planar3RPRReach-v0") imports the package itself and gives a working env."""
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('envs:Planar3RPRReach-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "obs, reward, terminated, truncated, info = env.step(env.action_space.sample())\n"
        "print(type(env.unwrapped).__name__, env.spec.max_episode_steps, obs.shape)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["Planar3RPRReachEnv", "200", "(15,)"]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_max_episode_steps_truncates(env_id, make_env):
    """The spec sets max_episode_steps and the TimeLimit truncates exactly there (robot at rest)."""
    expected = MAX_EPISODE_STEPS[env_id]
    assert gym.spec(env_id).max_episode_steps == expected
    env = make_env(env_id)
    assert env.spec.max_episode_steps == expected
    env.reset(seed=0)
    still = np.zeros(3, dtype=np.float32)
    for step in range(1, expected + 1):
        _, _, terminated, truncated, _ = env.step(still)
        assert not terminated, f"terminated at rest at step {step}"
        assert truncated == (step == expected), f"truncated={truncated} at step {step}"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_spaces(env_id, make_env):
    """Normalised Box(-1, 1, (3,), float32) actions; finite float32 observation bounds of the right size."""
    env = make_env(env_id)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
    space = env.observation_space
    assert isinstance(space, gym.spaces.Box)
    assert space.dtype == np.float32
    assert space.shape == ((18,) if "Track" in env_id else (15,))
    assert np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))
    assert np.all(space.low < space.high)
    assert space.is_bounded("both")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_observations_rewards_and_infos(env_id, make_env):
    """Observations are float32 members of the space; rewards are Python floats; infos carry every key."""
    env = make_env(env_id)
    obs, info = env.reset(seed=1)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    missing = set(INFO_KEYS) - set(info)
    assert not missing, f"reset info lacks {sorted(missing)}"
    for obs, reward, terminated, truncated, info in _rollout(env, 400, seed=1):
        assert obs.dtype == np.float32
        assert env.observation_space.contains(obs), obs
        assert type(reward) is float
        assert type(terminated) is bool and type(truncated) is bool
        missing = set(INFO_KEYS) - set(info)
        assert not missing, f"step info lacks {sorted(missing)}"
        assert all(type(info[k]) is float for k in REWARD_TERMS)
        assert type(info["is_success"]) is bool
        assert isinstance(info["termination_reason"], str)
        assert (info["termination_reason"] != "") == terminated


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reward_is_sum_of_terms(env_id, make_env):
    """reward == reward_tracking + reward_singularity + reward_action + reward_termination, every step."""
    env = make_env(env_id)
    terminated_seen = False
    for step, (_, reward, terminated, _, info) in enumerate(_rollout(env, 600, seed=2)):
        total = sum(info[k] for k in REWARD_TERMS)
        assert reward == pytest.approx(total, rel=1e-12, abs=1e-12), (step, reward, info)
        terminated_seen |= terminated
        if terminated:
            assert info["reward_termination"] == -env.unwrapped.params.termination_penalty
        else:
            assert info["reward_termination"] == 0.0
    if env_id == "Planar3RPRReachHard-v0":
        assert terminated_seen, "600 random steps of the hard task never terminated"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_cost_flags_low_conditioning(env_id, make_env):
    """info["cost"] is 1.0 exactly when the inverse condition number is below safe_threshold, else 0.0."""
    env = make_env(env_id)
    safe = env.unwrapped.params.safe_threshold
    costs = []
    for _, _, _, _, info in _rollout(env, 600, seed=3):
        expected = 1.0 if info["inverse_condition_number"] < safe else 0.0
        assert info["cost"] == expected, info
        costs.append(info["cost"])
    assert 0.0 in costs
    if env_id == "Planar3RPRReachHard-v0":
        assert 1.0 in costs, "600 random steps of the hard task never went below safe_threshold"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_returned_arrays_are_fresh(env_id, make_env, rng):
    """Mutating a returned observation or info array changes neither the env nor the next results."""
    mutated, clean = make_env(env_id), make_env(env_id)
    obs_a, info_a = mutated.reset(seed=4)
    obs_b, info_b = clean.reset(seed=4)
    previous = None
    for step in range(30):
        for value in (obs_a, *info_a.values()):
            if isinstance(value, np.ndarray):
                value[...] = 123.0
        action = rng.uniform(-1.0, 1.0, size=3).astype(np.float32)
        obs_a, _, terminated, truncated, info_a = mutated.step(action)
        obs_b, _, _, _, info_b = clean.step(action)
        np.testing.assert_array_equal(obs_a, obs_b, err_msg=f"step {step}")
        for key, value in info_b.items():
            np.testing.assert_array_equal(info_a[key], value, err_msg=f"step {step}, info[{key!r}]")
        if previous is not None:
            assert obs_a is not previous[0] and not np.shares_memory(obs_a, previous[0])
            assert info_a is not previous[1]
        previous = (obs_a, info_a)
        if terminated or truncated:
            obs_a, info_a = mutated.reset(seed=step)
            obs_b, info_b = clean.reset(seed=step)
            previous = None
