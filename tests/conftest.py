"""Fixtures shared by every test package."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import gymnasium as gym
import pytest

import envs  # noqa: F401  (registers the ids)


def pytest_configure(config: pytest.Config) -> None:
    """In the controller of a ``pytest -n N`` run, fill the Numba cache before the workers start.

    The workers then load the kernels from ``__pycache__`` rather than each compiling them at the same time
    (minutes on a fresh clone). The warm-up runs in two processes at once (``tests.numba_warmup``), whose
    saves into the cache, like the workers' own, are made exclusive by ``lock_numba_cache``. Workers and runs
    without xdist skip the warm-up: they compile on first use. A warm-up that fails only warns: the tests that
    reach the broken kernel then fail under their own names.
    """
    from tests.numba_warmup import lock_numba_cache, warm_up_in_parallel

    lock_numba_cache()
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    try:
        warm_up_in_parallel()
    except Exception as exc:
        config.issue_config_time_warning(pytest.PytestWarning(f"Numba warm-up failed: {exc!r}"), stacklevel=2)


#: Gymnasium's own TimeLimit, which every env of ``gym.make`` is wrapped in.
_TIME_LIMIT = gym.wrappers.TimeLimit


@pytest.fixture(autouse=True)
def gymnasium_left_unpatched() -> Iterator[None]:
    """Fail a test that leaves gymnasium's TimeLimit replaced (importing rl_zoo3 does: ``rl_zoo3.gym_patches``).

    The replacement adds "TimeLimit.truncated" to every info for the rest of the worker, so that a later test
    comparing infos fails far from the cause.
    """
    yield
    from gymnasium.envs import registration

    found = {
        "gymnasium.wrappers": gym.wrappers.TimeLimit,
        "gymnasium.wrappers.common": gym.wrappers.common.TimeLimit,
        "gymnasium.envs.registration": getattr(registration, "TimeLimit", _TIME_LIMIT),
    }
    patched = [name for name, cls in found.items() if cls is not _TIME_LIMIT]
    assert not patched, f"this test left gymnasium's TimeLimit replaced in {patched} (was rl_zoo3 imported?)"


#: Test modules whose tests share an expensive module fixture (one local Ray session, one set of RL Zoo runs): run
#: by one worker.
ONE_WORKER_MODULES = ("tests/training/test_sweep.py", "tests/training/test_rl_zoo.py")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Put the tests marked ``slow`` first, each part in its collected order (the same in every process)."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist: no error where it is not installed
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """With ``pytest -n N`` (xdist's default ``--dist load``), hand the workers one test at a time, slow ones first.

    The long tests then start early, on every worker, and the short ones fill in behind them, so that the
    workers finish together instead of one waiting on a long test at the end. The tests of a module in
    ``ONE_WORKER_MODULES`` go to one worker together (first: they are the longest). Another ``--dist`` is
    left to xdist.
    """
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SlowFirst(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if module in ONE_WORKER_MODULES else nodeid

    return SlowFirst(config, log)


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
