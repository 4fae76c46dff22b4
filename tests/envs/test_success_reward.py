"""The success reward b: paid at exactly the steps that end in success, on every path of the step.

Success is judged here from each step's reported pose and target alone (the oracle's NumPy errors) and the
termination reason; the envs with b > 0 and b = 0 are stepped in lockstep with the resolved-rate controller,
which holds the platform at its target once there.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from envs import physics
from envs import state as family_state
from robot_control.controllers import ResolvedRateController
from tests.envs import oracle

#: The success reward of the tests (not a power of two, so that an added term shows in the last bits).
B = 2.75
#: A Reach id per path of the compiled evaluation: the planar legs' fast path and the generic one (spatial legs;
#: translational cranks, with the Type I term).
PATHS = {
    "planar legs": "Planar3RPRReach-v0",
    "spatial legs": "StewartGoughReach-v0",
    "translational cranks": "DeltaReach-v0",
}


def expected_success(settings: oracle.Settings, info: dict) -> bool | None:
    """Success from ``info``'s pose, target and termination reason; None within 1e-9 of a tolerance."""
    position, orientation, _ = oracle.errors(settings, np.asarray(info["pose"]), np.asarray(info["target"]))
    tolerances = (settings.success_position_tolerance, settings.success_orientation_tolerance)
    if any(abs(error - tol) <= 1e-9 for error, tol in zip((position, orientation), tolerances)):
        return None
    return bool(info["termination_reason"] == "" and position <= tolerances[0] and orientation <= tolerances[1])


@pytest.mark.parametrize("path", list(PATHS))
def test_bonus_is_paid_exactly_on_success_steps(path):
    """r(b) = r(0) + b at a success step and r(b) = r(0) at any other, the single and the vector env alike."""
    env_id = PATHS[path]
    plain, paid = gym.make(env_id), gym.make(env_id, success_reward=B)
    vector = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", success_reward=B)
    settings = oracle.settings_of(paid)
    assert settings.success_reward == B and oracle.settings_of(plain).success_reward == 0.0
    controller = ResolvedRateController(plain.unwrapped.params)
    counts = {True: 0, False: 0, None: 0}
    for seed in range(3):
        obs, _ = plain.reset(seed=seed)
        paid_obs, _ = paid.reset(seed=seed)
        vector_obs, _ = vector.reset(seed=seed)
        np.testing.assert_array_equal(paid_obs, obs)
        np.testing.assert_array_equal(vector_obs[0], obs)
        for _ in range(120):
            action = controller(obs[None])[0]
            obs, reward, terminated, _, info = plain.step(action)
            paid_obs, paid_reward, paid_terminated, _, paid_info = paid.step(action)
            vector_obs, vector_reward, _, _, vector_info = vector.step(action[None])
            np.testing.assert_array_equal(paid_obs, obs)  # the bonus changes the reward only
            assert paid_terminated == terminated and info["reward_success"] == 0.0
            success = expected_success(settings, paid_info)
            counts[success] += 1
            if success is not None:
                assert paid_info["is_success"] is success
                assert paid_info["reward_success"] == (B if success else 0.0)
                assert paid_reward == reward + (B if success else 0.0)
            assert vector_info["reward_success"][0] == paid_info["reward_success"]
            assert vector_reward[0] == pytest.approx(paid_reward, rel=1e-12, abs=1e-12)
            if terminated:
                break
    assert counts[True] >= 10 and counts[False] >= 10, counts
    assert counts[None] == 0


@pytest.mark.parametrize("path", list(PATHS))
def test_reward_terms_pay_the_bonus_only_without_termination(path):
    """physics.reward_terms: b at the target, 0 off it, and 0 at the target once the step terminated."""
    env = gym.make(PATHS[path], success_reward=B)
    _, info = env.reset(seed=0)
    params = env.unwrapped.params
    target = np.tile(info["target"], (4, 1))
    x = target.copy()
    x[3, 0] += 2.0 * params.success_position_tolerance  # off the target
    reason = np.array([0, family_state.SINGULAR, family_state.OUT_OF_BOUNDS, 0])
    n = params.robot.n_actuators
    terms = physics.reward_terms(params, x, target, np.full(4, 0.5), np.zeros((4, n)), reason, np.ones(4))
    np.testing.assert_array_equal(terms["reward_success"], [B, 0.0, 0.0, 0.0])
    penalty = params.termination_penalty
    np.testing.assert_array_equal(terms["reward_termination"], [0.0, -penalty, -penalty, 0.0])
