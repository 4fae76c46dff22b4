"""Confidence intervals of success rates in the results tables: rliable's stratified bootstrap over episodes.

A run's ``metrics.json`` (``training.evaluate.aggregate``) holds its number of episodes n and its success rate;
its per-episode outcomes are then a 0/1 vector with round(success_rate · n) ones. A bootstrap over the episodes
depends only on that multiset, so the interval computed from it is the one the episodes themselves would give.
The runs of a table row (its seeds) make the columns of an (episodes, runs) score matrix, which
``rliable.library.get_interval_estimates`` reads as (runs, tasks): its stratified bootstrap resamples the episodes
of each run independently, with replacement, and keeps every run. The statistic is the mean success over the
runs, the figure the tables show; the interval is the percentile interval of its bootstrap distribution. It
measures the uncertainty from the finite number of episodes of these runs, not the spread over seeds: the seeds
are not resampled.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = [
    "SUCCESS_CI_NOTE",
    "SUCCESS_CI_REPS",
    "SUCCESS_CI_SEED",
    "episode_outcomes",
    "format_success_interval",
    "success_interval",
]

#: Bootstrap resamples per interval.
SUCCESS_CI_REPS = 2000
#: Seed of NumPy's global generator while an interval is computed: rliable's ``StratifiedBootstrap`` draws its
#: indices with ``np.random.choice`` (its ``random_state`` argument does not reach them), so the same metrics give
#: the same interval on every call, whatever ran before; the caller's generator state is restored afterwards.
SUCCESS_CI_SEED = 0
#: What the "success 95 % CI" column of a table holds, printed under the table.
SUCCESS_CI_NOTE = (
    f"success 95 % CI: rliable's 95 % stratified-bootstrap interval ({SUCCESS_CI_REPS} resamples, percentile) of the "
    "mean success, resampling each run's episodes; seeds are not resampled."
)


def episode_outcomes(metrics: Mapping[str, Any]) -> np.ndarray:
    """The per-episode outcomes of one run, as its metrics imply them.

    Args:
        metrics: A run's ``metrics.json`` contents (``episodes`` n ≥ 1 and ``success_rate`` in [0, 1]).

    Returns:
        Outcomes, shape (n,), float: round(success_rate · n) ones followed by zeros.

    Raises:
        ValueError: If n < 1, the rate is outside [0, 1], or success_rate · n is not a whole number of episodes.
    """
    episodes, rate = int(metrics["episodes"]), float(metrics["success_rate"])
    if episodes < 1:
        raise ValueError(f"episodes must be ≥ 1, got {episodes}")
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"success_rate must be in [0, 1], got {rate}")
    successes = round(rate * episodes)
    if abs(rate * episodes - successes) > 1e-6:
        raise ValueError(
            f"success_rate {rate} over {episodes} episodes is not a whole number of successes ({rate * episodes})"
        )
    outcomes = np.zeros(episodes)
    outcomes[:successes] = 1.0
    return outcomes


def success_interval(
    metrics: Sequence[Mapping[str, Any]], reps: int = SUCCESS_CI_REPS, seed: int = SUCCESS_CI_SEED
) -> tuple[float, float]:
    """95 % stratified-bootstrap interval (rliable) of the mean success over runs, resampling each run's episodes.

    With equal episode counts the score matrix is (episodes, runs) and the statistic its mean; with unequal
    counts each run is its own (episodes, 1) array (rliable's independent stratified bootstrap) and the statistic
    the mean of the runs' success rates. The seeds are not resampled.

    Args:
        metrics: The runs of one table row: ``metrics.json`` contents (``episodes``, ``success_rate``), ≥ 1 run.
        reps: Bootstrap resamples.
        seed: Seed of NumPy's global generator during the bootstrap (its previous state is restored).

    Returns:
        (lower, upper) bounds of the mean success rate, each in [0, 1].

    Raises:
        ValueError: If there is no run, or a run's metrics are invalid (see ``episode_outcomes``).
    """
    if not metrics:
        raise ValueError("success_interval needs at least one run, got none")
    counts = []
    for m in metrics:
        outcomes = episode_outcomes(m)
        counts.append((int(outcomes.sum()), outcomes.size))
    return _interval(tuple(counts), reps, seed)


@contextlib.contextmanager
def _global_generator_seeded(seed: int) -> Iterator[None]:
    """NumPy's global generator seeded with ``seed`` inside the block, its previous state restored after it."""
    state = np.random.get_state()  # noqa: NPY002 - rliable's bootstrap draws from the global generator
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


@functools.lru_cache(maxsize=1024)
def _interval(counts: tuple[tuple[int, int], ...], reps: int, seed: int) -> tuple[float, float]:
    """``success_interval`` of runs given as (successes, episodes); cached, as tables repeat rows (100 / 100)."""
    from rliable import library as rly  # arch and pandas: a second to import, only when a table is written

    runs = [np.concatenate([np.ones(k), np.zeros(n - k)])[:, None] for k, n in counts]  # each (episodes, 1)
    if len({n for _, n in counts}) == 1:
        scores: Any = np.hstack(runs)  # (episodes, runs): rliable's (runs, tasks)

        def mean_success(s: np.ndarray) -> np.ndarray:
            return np.array([s.mean()])
    else:
        scores = runs

        def mean_success(*s: np.ndarray) -> np.ndarray:
            return np.array([np.mean([run.mean() for run in s])])

    with _global_generator_seeded(seed):
        _, interval = rly.get_interval_estimates({"success": scores}, mean_success, reps=reps)
    lower, upper = interval["success"][:, 0]
    return float(lower), float(upper)


def format_success_interval(metrics: Sequence[Mapping[str, Any]]) -> str:
    """The table cell of ``success_interval(metrics)``: "[lower, upper] %" with one decimal."""
    lower, upper = success_interval(metrics)
    return f"[{100 * lower:.1f}, {100 * upper:.1f}] %"
