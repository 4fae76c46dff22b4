"""Fixtures shared by the environment tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator, so that every test is reproducible."""
    return np.random.default_rng(20240607)


@pytest.fixture
def make_env() -> Iterator[Callable[..., gym.Env]]:
    """Factory around ``gym.make`` whose environments are closed at teardown."""
    made: list[gym.Env] = []

    def _make(env_id: str, **kwargs) -> gym.Env:
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()
