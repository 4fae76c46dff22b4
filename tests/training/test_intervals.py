"""training.intervals: rliable's interval of the success rate against bootstraps and approximations written out here."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from experiments import family_report
from training import evaluate, intervals
from training.intervals import SUCCESS_CI_NOTE, episode_outcomes, format_success_interval, success_interval


def _run(successes: int, episodes: int) -> dict:
    return {"episodes": episodes, "success_rate": successes / episodes}


def _numpy_bootstrap(runs: list[tuple[int, int]], reps: int = 20_000, seed: int = 123) -> tuple[float, float]:
    """The 95 % percentile bootstrap of the mean success over runs, each run's episodes resampled on their own."""
    rng = np.random.default_rng(seed)
    means = np.zeros(reps)
    for successes, episodes in runs:
        outcomes = np.r_[np.ones(successes), np.zeros(episodes - successes)]
        means += outcomes[rng.integers(0, episodes, size=(reps, episodes))].mean(axis=1)
    lower, upper = np.percentile(means / len(runs), [2.5, 97.5])
    return float(lower), float(upper)


def test_one_run_matches_the_percentile_bootstrap_and_its_exact_distribution():
    """90 / 100: the plain NumPy bootstrap's interval, and the 2.5 / 97.5 % quantiles of Binomial(100, 0.9) / 100."""
    lower, upper = success_interval([_run(90, 100)])
    np.testing.assert_allclose((lower, upper), _numpy_bootstrap([(90, 100)]), atol=0.011)
    np.testing.assert_allclose((lower, upper), stats.binom.ppf([0.025, 0.975], 100, 0.9) / 100, atol=0.011)
    assert lower < 0.9 < upper


def test_a_thousand_episodes_match_the_normal_approximation_and_narrow_the_interval():
    """900 / 1000 agrees with p ± 1.96 √(p(1−p)/n) and is narrower than 90 / 100 (by about √10)."""
    lower, upper = success_interval([_run(900, 1000)])
    half = 1.96 * np.sqrt(0.9 * 0.1 / 1000)
    np.testing.assert_allclose((lower, upper), (0.9 - half, 0.9 + half), atol=0.005)
    lower_100, upper_100 = success_interval([_run(90, 100)])
    assert 2.5 < (upper_100 - lower_100) / (upper - lower) < 4.0


@pytest.mark.parametrize(("successes", "bound"), [(100, 1.0), (0, 0.0)])
def test_all_equal_outcomes_give_a_point(successes, bound):
    """100 / 100 gives [1, 1] and 0 / 100 gives [0, 0]: every resample is the same."""
    assert success_interval([_run(successes, 100)]) == (bound, bound)


def test_runs_are_resampled_separately_and_never_pooled():
    """A run at 100 % and one at 0 %: the mean 0.5 with zero width (pooling their episodes would give ± 0.07)."""
    assert success_interval([_run(100, 100), _run(0, 100)]) == (0.5, 0.5)


@pytest.mark.parametrize(
    "runs",
    [[(90, 100), (80, 100), (70, 100)], [(97, 100), (99, 100), (95, 100)], [(90, 100), (25, 50)]],
    ids=["three-seeds", "near-one", "unequal-episodes"],
)
def test_several_runs_match_the_per_run_bootstrap(runs):
    """Seeds with their own episodes (also of unequal counts): the plain NumPy bootstrap's interval of the mean."""
    lower, upper = success_interval([_run(k, n) for k, n in runs])
    np.testing.assert_allclose((lower, upper), _numpy_bootstrap(runs), atol=0.01)
    assert lower <= np.mean([k / n for k, n in runs]) <= upper


@pytest.mark.parametrize("successes", [0, 1, 29, 57, 58, 99, 100])
def test_the_outcomes_hold_the_rounded_count(successes):
    """A stored rate such as 0.29 (0.29 × 100 = 28.999…) gives 29 ones, and the interval holds 0.29."""
    outcomes = episode_outcomes(_run(successes, 100))
    assert outcomes.shape == (100,) and outcomes.sum() == successes and set(outcomes) <= {0.0, 1.0}
    lower, upper = success_interval([_run(successes, 100)])
    assert lower <= successes / 100 <= upper


def test_the_interval_is_reproducible_and_leaves_numpys_generator_alone():
    """Same metrics, same interval, whatever was drawn before; the caller's global random state is kept."""
    runs = [_run(87, 100), _run(91, 100)]
    intervals._interval.cache_clear()  # compute, not recall
    first = success_interval(runs, reps=500)
    intervals._interval.cache_clear()
    np.random.seed(7)  # noqa: NPY002 - the state rliable's bootstrap shares with its caller
    expected = np.random.random()  # noqa: NPY002
    np.random.seed(7)  # noqa: NPY002
    assert success_interval(runs, reps=500) == first
    assert np.random.random() == expected  # noqa: NPY002
    assert success_interval(runs, reps=500, seed=1) != first  # the seed is the bootstrap's


@pytest.mark.parametrize(
    ("metrics", "message"),
    [
        ([], "at least one run"),
        ([{"episodes": 0, "success_rate": 0.0}], "episodes must be ≥ 1, got 0"),
        ([{"episodes": 10, "success_rate": 1.5}], r"success_rate must be in \[0, 1\], got 1.5"),
        ([{"episodes": 10, "success_rate": 0.25}], "not a whole number of successes"),
    ],
)
def test_invalid_metrics_are_refused(metrics, message):
    """No run, no episode, a rate outside [0, 1] or one that is no count of episodes: ValueError naming it."""
    with pytest.raises(ValueError, match=message):
        success_interval(metrics)


def _metrics(label: str, successes: int, episodes: int = 100) -> dict:
    stat = {"mean": 1.0, "std": 0.0, "median": 1.0}
    return {
        "label": label,
        **_run(successes, episodes),
        "final_position_error_mm": stat,
        "final_orientation_error_deg": stat,
        "min_inverse_condition": {**stat, "min": 0.5},
        "singularity_terminations": 0,
        "cost_fraction": stat,
        "return": stat,
    }


def test_family_report_table_has_the_interval_column_and_its_note():
    """``family_report.table``: "success 95 % CI" after the success column, from the group's runs, and the note."""
    groups = {"ppo @ hard": [_metrics("a", 90), _metrics("b", 80)], "planner @ hard": [_metrics("c", 100)]}
    lines = family_report.table(groups).splitlines()
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    assert header[2:4] == ["success (mean ± std over runs)", "success 95 % CI"]
    assert lines[1].count("---") == len(header)
    row = [cell.strip() for cell in lines[2].strip("|").split("|")]
    assert len(row) == len(header)
    assert row[:4] == ["ppo @ hard", "2", "85.0 ± 7.1 %", format_success_interval(groups["ppo @ hard"])]
    assert "| planner @ hard | 1 | 100.0 % | [100.0, 100.0] % |" in lines[3]
    assert lines[-1] == SUCCESS_CI_NOTE and "seeds are not resampled" in SUCCESS_CI_NOTE


def test_evaluate_format_table_has_the_interval_column_and_its_note():
    """``evaluate.format_table`` (the main job's reports): one run per row, its interval after the success."""
    rows = {"PPO policy @ hard": _metrics("a", 90), "planner @ hard": _metrics("b", 100)}
    lines = evaluate.format_table(rows).splitlines()
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    assert header[2:4] == ["success", "success 95 % CI"]
    assert lines[1].count("---") == len(header)
    row = [cell.strip() for cell in lines[2].strip("|").split("|")]
    assert len(row) == len(header)
    assert row[:4] == ["PPO policy", "hard", "90 %", "[84.0, 95.0] %"]
    assert lines[3].startswith("| planner | hard | 100 % | [100.0, 100.0] % |")
    assert lines[-1] == SUCCESS_CI_NOTE
