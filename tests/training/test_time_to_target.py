"""The time to the target of an evaluated episode, its aggregate, and the plan-free report's paired table."""

from __future__ import annotations

import csv
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from experiments.plan_free_report import time_to_target_table
from training.evaluate import aggregate, evaluate_agent, load_controller


def _first_success_by_hand(env_id: str, controller: str, seed: int) -> tuple[float | None, int]:
    """Step the env with the controller; the first step whose errors are within the env's tolerances, × dt."""
    env = gym.make(env_id)
    agent = load_controller(controller, env)
    params = env.unwrapped.params
    obs, info = env.reset(seed=seed)
    step, done, first = 0, False, None
    while not done:
        obs, _reward, terminated, truncated, info = env.step(agent(obs[None])[0])
        step += 1
        done = terminated or truncated
        within = (
            not terminated
            and info["position_error"] <= params.success_position_tolerance
            and info["orientation_error"] <= params.success_orientation_tolerance
        )
        if first is None and within:
            first = step
    return (None if first is None else first * params.dt), step


@pytest.mark.parametrize(
    ("env_id", "controller"), [("Planar3RRRReach-v0", "resolved-rate"), ("DeltaReach-v0", "planner")]
)
def test_time_to_target_is_the_first_step_within_the_tolerances(env_id, controller):
    """The record's time equals the first step within the tolerances found by hand, times dt."""
    env = gym.make(env_id)
    records = evaluate_agent(load_controller(controller, env), env, 4, 300)
    reached = 0
    for record in records:
        expected, length = _first_success_by_hand(env_id, controller, 300 + record.episode)
        assert record.length == length
        assert record.time_to_target_s == expected
        reached += expected is not None
    assert reached > 0
    times = [r.time_to_target_s for r in records if r.time_to_target_s is not None]
    metrics = aggregate(records)["time_to_target_s"]
    assert metrics["episodes"] == len(times)
    assert metrics["mean"] == pytest.approx(np.mean(times)) and metrics["median"] == pytest.approx(np.median(times))


def test_an_episode_that_never_reaches_has_no_time():
    """Resolved-rate ends most hard 3-RPR episodes at a singularity: those records have no time, and no row counts."""
    env = gym.make("Planar3RPRReachHard-v0")
    records = evaluate_agent(load_controller("resolved-rate", env), env, 6, 0)
    assert any(not r.success for r in records)
    for record in records:
        if record.time_to_target_s is None:
            assert not record.success
    missing = [r for r in records if r.time_to_target_s is None]
    assert missing and aggregate(records).get("time_to_target_s", {"episodes": 0})["episodes"] == 6 - len(missing)


def _write(folder: Path, times: dict[int, float | None]) -> None:
    folder.mkdir(parents=True)
    with (folder / "episodes.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, ["episode", "success", "time_to_target_s"])
        writer.writeheader()
        for episode, value in times.items():
            writer.writerow({"episode": episode, "success": value is not None, "time_to_target_s": value or ""})


def test_paired_table_uses_only_the_episodes_both_reach(tmp_path):
    """Means over the episodes both reach, per run; then mean ± std over runs (worked by hand)."""
    _write(tmp_path / "planner-hard", {0: 2.0, 1: 4.0, 2: 1.0, 3: None})
    _write(tmp_path / "a-hard", {0: 1.0, 1: 2.0, 2: None, 3: 0.5})  # pairs 0, 1: 1.5 vs 3.0, ratio 0.5
    _write(tmp_path / "b-hard", {0: 3.0, 1: 2.0, 2: 2.0, 3: None})  # pairs 0, 1, 2: 7/3 vs 7/3, ratio (1.5+0.5+2)/3
    text = time_to_target_table(tmp_path, ["runs/a", "runs/b"])
    row = text.strip().splitlines()[-1]
    pairs, policy, planner, ratio = (cell.strip() for cell in row.strip("|").split("|"))
    assert pairs == "2.5 ± 0.7"
    assert policy == f"{np.mean([1.5, 7 / 3]):.2f} ± {np.std([1.5, 7 / 3], ddof=1):.2f}"
    assert planner == f"{np.mean([3.0, 7 / 3]):.2f} ± {np.std([3.0, 7 / 3], ddof=1):.2f}"
    assert ratio == f"{np.mean([0.5, 4 / 3]):.2f} ± {np.std([0.5, 4 / 3], ddof=1):.2f}"


def test_paired_table_refuses_folders_evaluated_without_the_time(tmp_path):
    """An evaluation written before the column existed is named, with what to do."""
    folder = tmp_path / "planner-hard"
    folder.mkdir()
    (folder / "episodes.csv").write_text("episode,success\n0,True\n")
    with pytest.raises(SystemExit, match="no time_to_target_s"):
        time_to_target_table(tmp_path, ["runs/a"])
