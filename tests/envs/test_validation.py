"""The environments validate actions, call order and constructor arguments at the boundary, precisely."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

from envs import PLANAR_3RPR_IDS, Planar3RPRReachEnv, Planar3RPRTrackEnv

ENV_CLASSES = [Planar3RPRReachEnv, Planar3RPRTrackEnv]

#: (keyword arguments, exception, message pattern) refused by both environment classes.
BAD_ARGUMENTS = [
    ({"dt": 0}, ValueError, r"dt must be > 0, got 0\.0"),
    ({"dt": -1}, ValueError, r"dt must be > 0, got -1\.0"),
    ({"dt": float("nan")}, ValueError, r"dt must be finite, got nan"),
    ({"dt": "0.05"}, TypeError, r"dt must be a real number, got str '0\.05'"),
    ({"max_rate": 0}, ValueError, r"max_rate must be > 0, got 0\.0"),
    ({"stroke_limits": (1.0, 0.5)}, ValueError, r"stroke_limits must satisfy 0 < L_min < L_max, got \(1\.0, 0\.5\)"),
    ({"stroke_limits": (0, 1)}, ValueError, r"stroke_limits must satisfy 0 < L_min < L_max, got \(0\.0, 1\.0\)"),
    ({"stroke_limits": (0.3,)}, ValueError, r"stroke_limits must be a sequence of 2 numbers"),
    ({"integrator": "rk5"}, ValueError, r"integrator must be one of \('euler', 'rk4'\), got 'rk5'"),
    ({"safe_threshold": 0.03}, ValueError, r"0 < hard_threshold < safe_threshold < 1, got 0\.03 and 0\.03"),
    ({"safe_threshold": 0.02}, ValueError, r"0 < hard_threshold < safe_threshold < 1, got 0\.03 and 0\.02"),
    ({"hard_threshold": 0}, ValueError, r"hard_threshold must be > 0, got 0\.0"),
    ({"render_mode": "video"}, ValueError, r"render_mode must be one of \['human', 'rgb_array'\] or None, got 'video'"),
    ({"base": [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]]}, ValueError, r"base anchors must not be collinear"),
    ({"newton_max_iterations": 0}, ValueError, r"newton_max_iterations must be ≥ 1, got 0"),
    ({"newton_max_iterations": 2.0}, TypeError, r"newton_max_iterations must be an int, got 2\.0"),
    ({"position_weight": -1}, ValueError, r"position_weight must be ≥ 0, got -1\.0"),
]


def _terminate(env, rng: np.random.Generator) -> dict:
    """Step with random actions until the episode terminates; returns the last info."""
    env.reset(seed=3, options={"targets": "hard"})
    for _ in range(5_000):
        _, _, terminated, truncated, info = env.step(rng.uniform(-1.0, 1.0, size=3).astype(np.float32))
        if terminated:
            return info
        if truncated:
            env.reset(options={"targets": "hard"})
    pytest.fail("random actions never terminated an episode")


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
def test_non_finite_action_raises(env_id, value, make_env):
    """A NaN or infinite action is refused before it reaches the dynamics; the state is untouched."""
    env = make_env(env_id)
    env.reset(seed=0)
    x_before = env.unwrapped.state.x.copy()
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(np.array([0.0, value, 0.0], dtype=np.float32))
    np.testing.assert_array_equal(env.unwrapped.state.x, x_before)
    env.step(np.zeros(3, dtype=np.float32))


@pytest.mark.parametrize("shape", [(2,), (3, 1), (4,), ()])
@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
def test_wrong_action_shape_raises(env_id, shape, make_env):
    """An action that is not of shape (3,) is refused, naming the shape it got."""
    env = make_env(env_id)
    env.reset(seed=0)
    pattern = rf"action must have shape \(3,\), got shape {re.escape(str(shape))}"
    with pytest.raises(ValueError, match=pattern):
        env.unwrapped.step(np.zeros(shape, dtype=np.float32))


@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
def test_step_before_reset_raises(env_id, make_env):
    """step() before reset() raises ResetNeeded, on the bare env and through gym.make's wrappers."""
    env = make_env(env_id)
    action = np.zeros(3, dtype=np.float32)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(action)
    with pytest.raises(gym.error.ResetNeeded, match="before reset"):
        env.unwrapped.step(action)


@pytest.mark.parametrize("wrapped", [False, True], ids=["unwrapped", "made"])
def test_step_after_termination_raises(wrapped, make_env, rng):
    """After a terminal step, step() raises ResetNeeded until the next reset."""
    made = make_env("Planar3RPRReach-v0")
    env = made if wrapped else made.unwrapped
    info = _terminate(env, rng)
    assert info["termination_reason"] != ""
    with pytest.raises(gym.error.ResetNeeded, match="terminated"):
        env.step(np.zeros(3, dtype=np.float32))
    env.reset(seed=1)
    env.step(np.zeros(3, dtype=np.float32))


@pytest.mark.parametrize(("kwargs", "error", "match"), BAD_ARGUMENTS)
@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_invalid_constructor_arguments(cls, kwargs, error, match):
    """Each invalid argument is refused with the right exception and a message naming it."""
    with pytest.raises(error, match=match):
        cls(**kwargs)


def test_invalid_targets_argument():
    """Reach refuses an unknown targets mode, naming the valid ones; gym.make forwards the refusal."""
    with pytest.raises(ValueError, match=r"targets must be one of \('standard', 'hard', 'mixed'\), got 'impossible'"):
        Planar3RPRReachEnv(targets="impossible")
    with pytest.raises(ValueError, match="targets must be one of"):
        gym.make("Planar3RPRReach-v0", targets="impossible")


def test_track_period_is_validated():
    """Track's own argument is validated like the shared ones."""
    with pytest.raises(ValueError, match=r"track_period must be > 0, got 0\.0"):
        Planar3RPRTrackEnv(track_period=0)
