"""training.evaluate.evaluate_vector: all episodes at once on the native vector env, recorded as one at a time."""

from __future__ import annotations

from dataclasses import asdict

import gymnasium as gym
import numpy as np
import pytest

import envs
import robot_control
from training.evaluate import EvaluationError, evaluate_agent, evaluate_vector, load_controller, make_vector_env


def assert_same_records(one_by_one, batched, exact_planning_time=False):
    """Every field equal to the last bit (the planner's wall time apart)."""
    assert len(one_by_one) == len(batched)
    for a, b in zip(one_by_one, batched, strict=True):
        da, db = asdict(a), asdict(b)
        assert da.keys() == db.keys()
        for key in da:
            va, vb = da[key], db[key]
            if isinstance(va, np.ndarray):
                np.testing.assert_array_equal(va, vb, err_msg=f"episode {a.episode}: {key}")
            elif isinstance(va, dict):
                skip = set() if exact_planning_time else {"planning_s"}
                assert {k: v for k, v in va.items() if k not in skip} == {
                    k: v for k, v in vb.items() if k not in skip
                }, f"episode {a.episode}: {key}"
            else:
                assert va == vb, f"episode {a.episode}: {key}: {va} != {vb}"


@pytest.mark.parametrize(
    ("env_id", "controller", "targets", "shield"),
    [
        ("Planar3RPRReach-v0", "resolved-rate", "hard", None),  # ends in singularities: lengths differ per row
        ("Planar3RPRReach-v0", "singularity-aware", "hard", 0.05),
        ("Planar3RRRReachHard-v0", "planner", None, None),  # per-row plans and their figures
        ("DeltaTrack-v0", "resolved-rate", None, None),  # the tracking metrics
    ],
)
def test_vector_records_equal_the_one_at_a_time_records(env_id, controller, targets, shield):
    """Row i of the batched run is episode i of ``evaluate_agent`` on the single env, to the last bit."""
    env = gym.make(env_id)
    if shield is not None:
        env = envs.SingularityShield(env, k_guard=shield)
    one_by_one = evaluate_agent(load_controller(controller, env), env, 8, 1000, targets)
    batched = evaluate_vector(
        load_controller(controller, env), make_vector_env(env_id, 8, shield=shield), 1000, targets
    )
    assert_same_records(one_by_one, batched)
    if controller == "resolved-rate" and targets == "hard":  # the rows do end at different steps
        assert len({r.length for r in batched}) > 1 and any(r.singularity_termination for r in batched)
    if controller == "planner":
        assert all(r.planner is not None for r in batched)


def test_vector_evaluation_refuses_what_the_single_one_refuses():
    """Targets on a Track id, unknown target sets and ids without a native vector env are refused by name."""
    with pytest.raises(EvaluationError, match="--targets applies only to the Reach environments"):
        evaluate_vector(
            lambda o: np.zeros((len(o), 3), np.float32), make_vector_env("Planar3RPRTrack-v0", 2), 0, "hard"
        )
    with pytest.raises(EvaluationError, match=r"--targets must be one of \['standard', 'hard'\], got 'easy'"):
        evaluate_vector(
            lambda o: np.zeros((len(o), 3), np.float32), make_vector_env("Planar3RPRReach-v0", 2), 0, "easy"
        )
    with pytest.raises(EvaluationError, match="CartPole-v1 has no native vector env"):
        make_vector_env("CartPole-v1", 2)


@pytest.mark.parametrize(
    "package, wrapper",
    [
        (robot_control, "PlannerResidualWrapper"),
        (robot_control, "PlannerWaypointWrapper"),
        (envs, "PreviousActionWrapper"),
    ],
)
def test_vector_planner_wrappers_equal_the_single_ones(package, wrapper):
    """Row i of the vector wrappers (the planner's, the previous action's) is the single wrapper on episode i."""
    from training.evaluate import wrap_vector_for_run

    config = {"hyperparams": {"env_wrapper": f"{package.__name__}.{wrapper}"}}
    n = 6

    def agent(obs):  # a fixed function of the observation, row by row: batching cannot change it
        return (0.8 * np.tanh(3.0 * obs[:, -3:] - obs[:, :3])).astype(np.float32)

    env = getattr(package, wrapper)(envs.SingularityShield(gym.make("Planar3RPRReach-v0"), k_guard=0.05))
    one_by_one = evaluate_agent(agent, env, n, 5000, "hard")
    venv = wrap_vector_for_run(make_vector_env("Planar3RPRReach-v0", n, shield=0.05), config)
    assert isinstance(venv, getattr(package, "Vector" + wrapper))
    assert venv.single_observation_space == env.observation_space
    assert_same_records(one_by_one, evaluate_vector(agent, venv, 5000, "hard"))
    assert wrap_vector_for_run(make_vector_env("Planar3RPRReach-v0", 2), {"hyperparams": {}}) is not None
    goal = {"hyperparams": {"env_wrapper": "envs.GoalReachWrapper"}}
    assert wrap_vector_for_run(make_vector_env("Planar3RPRReach-v0", 2), goal) is None  # no vector form


@pytest.mark.parametrize("mode", [gym.vector.AutoresetMode.NEXT_STEP, gym.vector.AutoresetMode.SAME_STEP])
def test_vector_previous_action_is_zero_where_an_episode_starts(mode):
    """Each row's observation ends with its last action; zeros in the first observation of its next episode.

    Oracle: the single wrapper's first observation after ``reset`` (zeros) and the actions sent, clipped.
    """
    plain = gym.make_vec("Planar3RPRReach-v0", 3, vectorization_mode="vector_entry_point", autoreset_mode=mode)
    venv = envs.VectorPreviousActionWrapper(plain)
    obs, _ = venv.reset(seed=5, options={"targets": "hard"})
    np.testing.assert_array_equal(obs[:, -3:], 0.0)
    rng = np.random.default_rng(0)
    ended, starts = np.zeros(3, dtype=bool), 0
    for _ in range(600):
        actions = rng.uniform(-1.5, 1.5, (3, 3)).astype(np.float32)
        obs, _, terminated, truncated, _ = venv.step(actions)
        start = ended if mode == gym.vector.AutoresetMode.NEXT_STEP else terminated | truncated
        np.testing.assert_array_equal(obs[start, -3:], 0.0)
        np.testing.assert_array_equal(obs[~start, -3:], np.clip(actions, -1.0, 1.0)[~start])
        starts += int(start.sum())
        ended = terminated | truncated
    assert starts >= 3


def test_vector_residual_wrapper_restarts_plans_with_the_next_episode():
    """After an autoreset a row's plan runs from its new episode's start to its new target."""
    venv = robot_control.VectorPlannerResidualWrapper(make_vector_env("Planar3RPRReach-v0", 2))
    venv.reset(seed=11, options={"targets": "hard"})
    rng = np.random.default_rng(0)
    ended = np.zeros(2, dtype=bool)
    for _ in range(400):
        _, _, terminated, truncated, info = venv.step(rng.uniform(-1.0, 1.0, (2, 3)).astype(np.float32))
        if ended[0]:
            break  # row 0 has just started its second episode
        ended = terminated | truncated
    assert ended[0]
    plan = venv.follower._rows[0][1]
    np.testing.assert_allclose(plan.waypoints[0], info["pose"][0], atol=1e-12)
    np.testing.assert_allclose(plan.waypoints[-1], info["target"][0], atol=1e-12)


def test_evaluation_scores_every_run_with_its_ids_reward(make_run_folder):
    """A run trained with a success bonus (and hard targets) is scored on hard targets without the bonus.

    Oracle: the same agent, one episode at a time, on the env built by hand with the non-reward setting only.
    """
    import yaml

    from training.evaluate import evaluate_rows, evaluation_env_kwargs, load_run

    run = make_run_folder("ppo")
    config = yaml.safe_load((run / "config.yml").read_text())
    config["hyperparams"]["env_kwargs"] = {"targets": "hard", "success_reward": 5.0, "action_weight": 3.0}
    (run / "config.yml").write_text(yaml.safe_dump(config, sort_keys=False))
    agent, config = load_run(run)
    assert evaluation_env_kwargs(config) == {"targets": "hard"}
    batched = evaluate_rows(agent, config, "Planar3RPRReach-v0", 4, 700, None)
    env = gym.make("Planar3RPRReach-v0", targets="hard")
    one_by_one = evaluate_agent(agent, env, 4, 700)
    assert [r.episode_return for r in batched] == pytest.approx([r.episode_return for r in one_by_one], abs=1e-4)
    assert [r.targets[0].tolist() for r in batched] == [r.targets[0].tolist() for r in one_by_one]
