"""Fixtures shared by every test package."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import gymnasium as gym
import pytest

import envs  # noqa: F401  (registers the ids)


@pytest.fixture
def make_env() -> Iterator[Callable[..., gym.Env]]:
    """Factory around ``gym.make`` (default id Planar3RPRReach-v0) whose environments are closed at teardown."""
    made: list[gym.Env] = []

    def _make(env_id: str = "Planar3RPRReach-v0", **kwargs) -> gym.Env:
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()
