"""Fixtures shared by every test package."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import gymnasium as gym
import pytest

import envs  # noqa: F401  (registers the ids)


def pytest_configure(config: pytest.Config) -> None:
    """In the controller of a ``pytest -n N`` run, fill the Numba cache before the workers start.

    The workers then load the kernels from ``__pycache__`` rather than each compiling them at the same time
    (minutes on a fresh clone). Workers and runs without xdist skip this: they compile on first use. A
    warm-up that fails only warns: the tests that reach the broken kernel then fail under their own names.
    """
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    from tests.numba_warmup import warm_up

    try:
        warm_up()
    except Exception as exc:
        config.issue_config_time_warning(pytest.PytestWarning(f"Numba warm-up failed: {exc!r}"), stacklevel=2)


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
