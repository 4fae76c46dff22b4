"""Residual learning over computed torque (``robot_control.ComputedTorqueResidualWrapper``) and its vector form."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import envs  # noqa: F401  (registers the ids)
import robot_control
from robot_control.controllers import ComputedTorqueAgent

ENV = "Planar3RPRForceReach-v0"


def test_the_wrapper_passes_the_checker_and_appends_computed_torques_action():
    """Gymnasium's checker is silent; n entries more: ComputedTorqueAgent's action for the wrapped observation."""
    env = robot_control.ComputedTorqueResidualWrapper(gym.make(ENV).unwrapped)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*is different from the unwrapped")  # it is a wrapper
        check_env(env, skip_render_check=True)
    plain = gym.make(ENV)
    assert env.observation_space.shape == (plain.observation_space.shape[0] + 3,)
    obs, _ = env.reset(seed=4)
    raw, _ = plain.reset(seed=4)
    np.testing.assert_array_equal(obs[:-3], raw)
    expected = ComputedTorqueAgent(plain.unwrapped.params)(raw[None])[0]
    np.testing.assert_array_equal(obs[-3:], expected)
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize(("seed", "scale"), [(21, 0.5), (22, 0.25)])
def test_the_env_receives_computed_torque_plus_the_scaled_residual(seed, scale):
    """A twin env stepped with clip(a_c + scale · clip(a_π)) by hand follows the wrapped one step for step."""
    wrapped = robot_control.ComputedTorqueResidualWrapper(gym.make(ENV), scale=scale)
    twin = gym.make(ENV)
    agent = ComputedTorqueAgent(twin.unwrapped.params)
    wrapped.reset(seed=seed)
    obs_t, _ = twin.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for step in range(60):
        residual = np.zeros(3) if step < 20 else rng.uniform(-1.5, 1.5, 3)  # zero first: computed torque itself
        base = agent(obs_t[None])[0]
        _, r_w, term_w, trunc_w, info_w = wrapped.step(residual)
        np.testing.assert_array_equal(info_w["base_action"], base)
        summed = np.clip(base + scale * np.clip(residual, -1, 1), -1, 1).astype(np.float32)
        obs_t, r_t, term_t, trunc_t, info_t = twin.step(summed)
        np.testing.assert_array_equal(info_w["pose"], info_t["pose"])
        assert (r_w, term_w, trunc_w) == (r_t, term_t, trunc_t)
        if term_w or trunc_w:
            break


def test_the_vector_form_is_the_single_wrapper_row_by_row_through_autoresets():
    """Rows of VectorComputedTorqueResidualWrapper (same-step autoreset) equal single wrappers on the same seeds.

    Each ended episode's last observation (``final_obs``) carries computed torque's action for it, as the single
    wrapper's last observation does.
    """
    n, kwargs = 3, {"max_episode_steps": 15}
    venv = robot_control.VectorComputedTorqueResidualWrapper(
        gym.make_vec(
            ENV, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=AutoresetMode.SAME_STEP, **kwargs
        )
    )
    singles = [robot_control.ComputedTorqueResidualWrapper(gym.make(ENV, **kwargs)) for _ in range(n)]
    obs, _ = venv.reset(seed=[30 + i for i in range(n)])
    for i, env in enumerate(singles):
        single_obs, _ = env.reset(seed=30 + i)
        np.testing.assert_allclose(obs[i], single_obs, rtol=1e-6, atol=1e-6)
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(20):
        actions = rng.uniform(-1.0, 1.0, (n, 3)).astype(np.float32)
        obs, rewards, terminated, truncated, info = venv.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, _ = env.step(actions[i])
            assert (te, tr) == (terminated[i], truncated[i])
            assert r == pytest.approx(rewards[i], abs=1e-6)
            if te or tr:
                ends += 1
                np.testing.assert_allclose(info["final_obs"][i], o, rtol=1e-6, atol=1e-6)
                o, _ = env.reset()
            np.testing.assert_allclose(obs[i], o, rtol=1e-6, atol=1e-6)
    assert ends >= n


def test_refusals_name_the_value():
    """Rate-control envs, a scale outside (0, 2] and actions of the wrong shape or not finite are refused."""
    with pytest.raises(TypeError, match=r"control='force'.*control='rate'"):
        robot_control.ComputedTorqueResidualWrapper(gym.make("Planar3RPRReach-v0"))
    with pytest.raises(ValueError, match=r"scale must be a number in \(0, 2\], got 3"):
        robot_control.ComputedTorqueResidualWrapper(gym.make(ENV), scale=3)
    env = robot_control.ComputedTorqueResidualWrapper(gym.make(ENV))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be 3 finite numbers, got shape \(2,\)"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([0.0, np.nan, 0.0]))
