"""Residual learning over the planner (``robot_control.PlannerResidualWrapper``): a zero policy is the planner."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs
import robot_control
from envs.kernels.packing import observation_layout
from envs.physics import wrap_angle
from robot_control.controllers import PlannerController

ERROR = observation_layout("planar", 3, False)["error"]


def test_residual_wrapper_passes_the_checker_and_extends_the_observation():
    """Gymnasium's checker is silent; six entries more (carrot offset, planner action), inside the space."""
    env = robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReachMixed-v0").unwrapped)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*is different from the unwrapped")  # it is a wrapper
        check_env(env, skip_render_check=True)
    base = gym.make("Planar3RPRReach-v0").observation_space
    assert env.observation_space.shape == (base.shape[0] + 6,)
    assert env.action_space.shape == (3,)
    obs, info = env.reset(seed=3, options={"targets": "standard"})
    assert env.observation_space.contains(obs)
    # a safe straight line: the waypoint is the target, and a_p is the resolved-rate action toward it
    np.testing.assert_allclose(obs[-6:-3], obs[ERROR], atol=1e-6)
    controller = PlannerController(env.unwrapped.params, exact_step=False)  # the wrapper's base action
    error = info["target"] - info["pose"]
    error[2] = wrap_angle(error[2])
    expected = controller.act(info["pose"][None], error[None], np.zeros((1, 3)))[0]
    np.testing.assert_allclose(obs[-3:], expected, atol=1e-6)


@pytest.mark.parametrize("seed", [10000, 10001, 10002])
def test_a_zero_policy_is_the_planner_controller(seed):
    """Zero actions through the wrapper replay the planner controller's hard episode step for step."""
    wrapped = robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReachHard-v0"))
    plain = gym.make("Planar3RPRReachHard-v0")
    controller = PlannerController(plain.unwrapped.params, exact_step=False)  # the wrapper's base action
    _, info_w = wrapped.reset(seed=seed)
    obs_p, info_p = plain.reset(seed=seed)
    for _ in range(200):
        a_p = controller(obs_p[None])[0]
        _, r_w, term_w, trunc_w, info_w = wrapped.step(np.zeros(3, dtype=np.float32))
        np.testing.assert_allclose(info_w["planner_action"], a_p, atol=1e-5)
        obs_p, r_p, term_p, trunc_p, info_p = plain.step(a_p)
        np.testing.assert_allclose(info_w["pose"], info_p["pose"], atol=1e-6)
        assert r_w == pytest.approx(r_p, abs=1e-6)
        assert (term_w, trunc_w) == (term_p, trunc_p)
        if term_w or trunc_w:
            break
    assert info_w["is_success"] and info_p["is_success"]


def test_the_policy_action_is_scaled_added_and_clipped():
    """The env gets clip(a_p + scale · clip(a_π, −1, 1), −1, 1)."""
    env = robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReach-v0"), scale=0.25)
    obs, _ = env.reset(seed=0)
    a_p = obs[-3:].astype(np.float64)
    for a in (np.zeros(3), np.array([1.0, -1.0, 0.5]), np.array([5.0, -5.0, 0.0])):
        np.testing.assert_allclose(env.action(a), np.clip(a_p + 0.25 * np.clip(a, -1, 1), -1, 1), atol=1e-6)


def test_bad_arguments_are_named():
    """Scale out of range, a foreign env, the grid planner off-grid and a malformed action get precise errors."""
    with pytest.raises(ValueError, match=r"scale must be a number in \(0, 2\], got 0"):
        robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReach-v0"), scale=0)
    with pytest.raises(ValueError, match="lookahead must be a positive distance"):
        robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReach-v0"), lookahead=-1.0)
    with pytest.raises(TypeError, match="wraps the Reach environments of envs, got CartPoleEnv"):
        robot_control.PlannerResidualWrapper(gym.make("CartPole-v1"))
    with pytest.raises(
        ValueError, match="the planner needs a planar robot with task_region='grid', got spatial with task_region='box'"
    ):
        robot_control.PlannerResidualWrapper(gym.make("StewartGoughReach-v0"), planner="grid")
    env = robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReach-v0"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be 3 finite numbers, got shape \(2,\)"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="action must be 3 finite numbers"):
        env.step(np.array([0.0, np.nan, 0.0]))


def test_the_shield_inside_filters_the_summed_action():
    """SingularityShield inside the wrapper: a zero policy still succeeds, with no termination."""
    env = robot_control.PlannerResidualWrapper(envs.SingularityShield(gym.make("Planar3RPRReachHard-v0"), k_guard=0.05))
    env.reset(seed=10003)
    for _ in range(200):
        _, _, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
        if terminated or truncated:
            break
    assert not terminated and info["is_success"]


def test_the_shield_inside_keeps_a_random_residual_out_of_singularities():
    """Random saturated residuals end episodes at singularities without the shield inside; with it, never."""
    singular = {"singular", "singularity_crossed", "newton_failed", "assembly_mode_change"}

    def run(env: gym.Env) -> list[str]:
        env.reset(seed=10003)
        rng = np.random.default_rng(0)
        reasons = []
        for _ in range(300):
            _, _, terminated, truncated, info = env.step(rng.choice([-1.0, 1.0], size=3).astype(np.float32))
            reasons.append(info["termination_reason"])
            if terminated or truncated:
                env.reset()
        return reasons

    assert singular & set(
        run(robot_control.PlannerResidualWrapper(gym.make("Planar3RPRReachHard-v0")))
    )  # negative control
    shielded = robot_control.PlannerResidualWrapper(
        envs.SingularityShield(gym.make("Planar3RPRReachHard-v0"), k_guard=0.05)
    )
    assert not singular & set(run(shielded))
