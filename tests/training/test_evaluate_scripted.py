"""``training.evaluate`` on a scripted env with known outcomes: the exact counts, rates and records it must report.

The env plays one script per episode (chosen by the reset seed): what each step reports (reward, termination,
reason, ``is_success``, k, cost) is fixed, so every figure of ``evaluate_agent`` and ``aggregate`` is known in
advance. A scripted agent answers each observation with the action the script expects, and the env checks it
received that action, so the evaluation must pass the agent's actions through unchanged.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit

from training.evaluate import aggregate, evaluate_agent

#: Steps before the time limit truncates an episode.
HORIZON = 5

#: Per script, its steps: (is_success, termination reason or "", k, cost); the episode ends at the last one
#: (a termination) or at the time limit.
SCRIPTS: dict[str, list[tuple[bool, str, float, float]]] = {
    "success": [(False, "", 0.5, 0.0), (False, "", 0.4, 0.0), (True, "", 0.6, 0.0), (True, "", 0.7, 0.0)]
    + [(True, "", 0.8, 0.0)],
    "timeout": [(False, "", 0.5, 0.0)] * HORIZON,
    "singular": [(False, "", 0.2, 1.0), (False, "singular", 0.01, 1.0)],
    "out_of_bounds": [(False, "", 0.5, 0.0), (False, "", 0.5, 0.0), (False, "out_of_bounds", 0.3, 0.0)],
    "success_then_leaving": [(False, "", 0.5, 0.0), (True, "", 0.5, 0.0), (False, "", 0.5, 0.0)]
    + [(False, "", 0.5, 1.0), (False, "", 0.5, 0.0)],
    "actuator_singular": [(False, "actuator_singular", 0.45, 1.0)],
}
ORDER = tuple(SCRIPTS)


class ScriptedEnv(gym.Env):
    """Plays ``SCRIPTS[ORDER[seed % len(ORDER)]]``; the observation is the step index, the reward −(step + 1)."""

    observation_space = spaces.Box(-1.0, 100.0, shape=(1,), dtype=np.float32)
    action_space = spaces.Box(-100.0, 100.0, shape=(1,), dtype=np.float32)

    def __init__(self) -> None:
        """An env before its first reset."""
        self.script: list[tuple[bool, str, float, float]] = []
        self.t = 0

    def _info(self, success: bool, reason: str, k: float, cost: float) -> dict[str, Any]:
        return {
            "is_success": success,
            "termination_reason": reason,
            "inverse_condition_number": k,
            "cost": cost,
            "position_error": 0.001 * (self.t + 1),
            "orientation_error": 0.0,
            "pose": np.array([float(self.t), 0.0, 0.0]),
            "target": np.zeros(3),
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start the script chosen by ``seed``."""
        super().reset(seed=seed)
        self.script = SCRIPTS[ORDER[seed % len(ORDER)]]
        self.t = 0
        return np.array([0.0], dtype=np.float32), self._info(False, "", 0.9, 0.0)

    def step(self, action: Any):
        """Play the next step of the script (the action must be the step index, as the agent answers)."""
        assert float(np.asarray(action).ravel()[0]) == float(self.t), "the agent's action was not passed through"
        success, reason, k, cost = self.script[self.t]
        info = self._info(success, reason, k, cost)
        self.t += 1
        return np.array([float(self.t)], dtype=np.float32), -float(self.t), bool(reason), False, info


def scripted_agent(obs: np.ndarray) -> np.ndarray:
    """The batched agent: answers observation [t] with action [t]."""
    return np.asarray(obs, dtype=np.float32).copy()


@pytest.fixture(scope="module")
def records():
    """One evaluated episode per script, in ``ORDER``."""
    return evaluate_agent(scripted_agent, TimeLimit(ScriptedEnv(), HORIZON), episodes=len(ORDER))


def test_each_episode_is_recorded_as_scripted(records):
    """Success is the last step's ``is_success``; an untimely end is never a success; reasons and lengths exact."""
    expected = {
        # script: (success, termination reason, singularity termination, length, min k, cost fraction)
        "success": (True, "", False, 5, 0.4, 0.0),
        "timeout": (False, "", False, 5, 0.5, 0.0),
        "singular": (False, "singular", True, 2, 0.01, 1.0),
        "out_of_bounds": (False, "out_of_bounds", False, 3, 0.3, 0.0),
        "success_then_leaving": (False, "", False, 5, 0.5, 0.2),
        "actuator_singular": (False, "actuator_singular", True, 1, 0.45, 1.0),
    }
    assert [r.episode for r in records] == list(range(len(ORDER)))
    for name, record in zip(ORDER, records):
        success, reason, singular, length, k_min, cost = expected[name]
        assert record.success is success, name
        assert record.termination_reason == reason, name
        assert record.singularity_termination is singular, name
        assert record.length == length, name
        assert record.min_inverse_condition == k_min, name
        assert record.cost_fraction == pytest.approx(cost, abs=1e-15), name
        assert record.episode_return == -sum(range(1, length + 1)), name
        assert record.final_position_error_mm == pytest.approx(length, abs=1e-12), name
        assert len(record.poses) == len(record.inverse_condition) == length + 1, name


def test_the_aggregate_has_the_exact_counts(records):
    """Success rate 1/6, two singularity terminations, each reason counted once, lengths and returns exact."""
    metrics = aggregate(records)
    assert metrics["episodes"] == 6
    assert metrics["success_rate"] == pytest.approx(1 / 6, abs=1e-15)
    assert metrics["singularity_terminations"] == 2
    assert metrics["terminations"] == {"singular": 1, "out_of_bounds": 1, "actuator_singular": 1}
    lengths = [5, 5, 2, 3, 5, 1]
    assert metrics["episode_length"]["mean"] == pytest.approx(np.mean(lengths), abs=1e-15)
    returns = [-sum(range(1, n + 1)) for n in lengths]
    assert metrics["return"]["mean"] == pytest.approx(np.mean(returns), abs=1e-12)
    assert metrics["min_inverse_condition"]["min"] == 0.01
    assert metrics["cost_fraction"]["mean"] == pytest.approx(np.mean([0, 0, 1, 0, 0.2, 1]), abs=1e-15)


def test_episodes_start_from_consecutive_seeds():
    """Episode i resets with seed + i: starting at seed 2 plays the scripts from the third on."""
    records = evaluate_agent(scripted_agent, TimeLimit(ScriptedEnv(), HORIZON), episodes=3, seed=2)
    assert [r.termination_reason for r in records] == ["singular", "out_of_bounds", ""]
    assert [r.success for r in records] == [False, False, False]
    assert aggregate(records)["singularity_terminations"] == 1
