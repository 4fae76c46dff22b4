"""The singularity shield: a one-step look-ahead that keeps any agent from terminating in a singularity."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from envs import SingularityShield
from envs.physics import TERMINATION_REASONS
from envs.wrappers.shield import SHIELD_SCALES, shield_actions

SINGULAR = {"newton_failed", "assembly_mode_change", "singularity_crossed", "singular"}


def run_random(env: gym.Env, steps: int, seed: int) -> tuple[dict[str, int], list[float], list[float]]:
    """Random saturated actions (fixed seed); returns termination counts, k per step and shield scales."""
    rng = np.random.default_rng(seed)
    ends: dict[str, int] = {}
    ks, scales = [], []
    env.reset(seed=seed)
    for _ in range(steps):
        action = np.sign(rng.uniform(-1.0, 1.0, 3)).astype(np.float32)
        _, _, terminated, truncated, info = env.step(action)
        ks.append(info["inverse_condition_number"])
        scales.append(info.get("shield_scale", 1.0))
        if terminated:
            ends[info["termination_reason"]] = ends.get(info["termination_reason"], 0) + 1
        if terminated or truncated:
            env.reset()
    return ends, ks, scales


def test_random_saturated_actions_never_terminate_under_the_shield(make_env):
    """Unshielded, these actions end episodes in singularities; shielded, nothing terminates and k ≥ guard."""
    plain, _, _ = run_random(make_env(), 3000, seed=3)
    assert sum(plain.get(reason, 0) for reason in SINGULAR) > 0  # the same actions do reach singularities
    shielded, ks, scales = run_random(SingularityShield(make_env(), k_guard=0.05), 3000, seed=3)
    assert shielded == {}
    assert min(ks) >= 0.03
    assert set(scales) <= set(SHIELD_SCALES) and min(scales) < 1.0 and np.mean(np.equal(scales, 1.0)) > 0.5


def test_unchanged_action_gives_the_plain_step(make_env):
    """Where the shield lets the action through, the step equals the unwrapped env's step."""
    plain, shielded = make_env(), SingularityShield(make_env())
    obs_a, _ = plain.reset(seed=7)
    obs_b, _ = shielded.reset(seed=7)
    np.testing.assert_array_equal(obs_a, obs_b)
    action = np.array([0.1, -0.05, 0.02], dtype=np.float32)
    out_a = plain.step(action)
    out_b = shielded.step(action)
    assert out_b[4]["shield_scale"] == 1.0
    np.testing.assert_array_equal(out_a[0], out_b[0])
    assert out_a[1:4] == out_b[1:4]


def test_shield_works_on_track_and_reports_reasons(make_env):
    """On Track, the random saturated actions that end episodes in singularities unshielded never do shielded."""
    assert SINGULAR <= set(TERMINATION_REASONS)
    plain, _, _ = run_random(make_env("Planar3RPRTrack-v0"), 600, seed=1)
    assert sum(plain.get(reason, 0) for reason in SINGULAR) > 0  # the negative control: the scenario is dangerous
    shielded, _, scales = run_random(SingularityShield(make_env("Planar3RPRTrack-v0")), 600, seed=1)
    assert not SINGULAR & set(shielded)
    assert min(scales) < 1.0


def test_shield_bad_input(make_env):
    """A bad guard, a foreign env and a step before reset are refused with clear errors."""
    with pytest.raises(ValueError, match=r"k_guard must be a number in \(0, 1\), got 1.5"):
        SingularityShield(make_env(), k_guard=1.5)
    with pytest.raises(TypeError, match="needs a parallel-robot environment of envs, got CartPoleEnv"):
        SingularityShield(gym.make("CartPole-v1"))
    with pytest.raises(gym.error.ResetNeeded):
        SingularityShield(make_env()).step(np.zeros(3, dtype=np.float32))
    env = SingularityShield(make_env())
    env.reset(seed=0)
    with pytest.raises(ValueError):
        env.step(np.array([np.nan, 0.0, 0.0], dtype=np.float32))  # the env's own validation message


def _shield_row_by_row(params, state, actions: np.ndarray, k_guard: float) -> tuple[np.ndarray, np.ndarray]:
    """The shield's rule written out for one robot at a time (the oracle of the batched filter)."""
    from envs.physics import transition

    def row(value, i):  # row i of a state's field (arrays, tuples of arrays, or None)
        if value is None:
            return None
        if isinstance(value, tuple):
            return type(value)(*[row(v, i) for v in value])
        return value[i : i + 1]

    out, scales = np.zeros_like(actions, dtype=np.float32), np.zeros(len(actions))
    for i in range(len(actions)):
        one = row(state, i)
        proposed = np.clip(actions[i].astype(np.float64), -1.0, 1.0)
        for scale in SHIELD_SCALES[:-1]:
            new, outcome = transition(params, one, proposed[None] * scale)
            if outcome.reason[0] == 0 and new.inverse_condition[0] >= min(k_guard, one.inverse_condition[0]):
                out[i], scales[i] = (proposed * scale).astype(np.float32), scale
                break
    return out, scales


def test_vector_shield_filters_each_row_as_the_rule_written_out_for_one_robot():
    """``VectorSingularityShield``: every row's action and scale equal the one-robot rule; shielded rows never end."""
    from envs import VectorSingularityShield

    n = 24
    plain = gym.make_vec("Planar3RPRReach-v0", num_envs=n, vectorization_mode="vector_entry_point")
    venv = VectorSingularityShield(
        gym.make_vec("Planar3RPRReach-v0", num_envs=n, vectorization_mode="vector_entry_point"), k_guard=0.05
    )
    rng = np.random.default_rng(4)
    plain.reset(seed=100, options={"targets": "hard"})
    venv.reset(seed=100, options={"targets": "hard"})
    plain_ends = shielded_ends = 0
    reduced = 0
    for _ in range(150):
        actions = np.sign(rng.uniform(-1.0, 1.0, (n, 3))).astype(np.float32)
        params, state = venv.unwrapped.params, venv.unwrapped.state
        expected, expected_scales = _shield_row_by_row(params, state, actions, 0.05)
        safe, scales = shield_actions(params, state, actions, 0.05)
        np.testing.assert_array_equal(safe, expected)
        np.testing.assert_array_equal(scales, expected_scales)
        _, _, terminated, _, info = venv.step(actions)
        np.testing.assert_array_equal(info["shield_scale"], expected_scales)
        reduced += int((expected_scales < 1.0).sum())
        shielded_ends += int(np.isin(info["termination_reason"][terminated], list(SINGULAR)).sum())
        _, _, terminated, _, info = plain.step(actions)
        plain_ends += int(np.isin(info["termination_reason"][terminated], list(SINGULAR)).sum())
    assert plain_ends > 0 and reduced > 0  # the actions are dangerous and the shield acts
    assert shielded_ends == 0
    with pytest.raises(ValueError, match=r"k_guard must be a number in \(0, 1\), got 0"):
        VectorSingularityShield(plain, k_guard=0)
