"""The classical baselines: batched, bounded actions; deterministic episodes; reach, track and avoid singularities."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from PIL import Image

from envs import FORCE_IDS, PLANAR_3RPR_IDS
from robot_control.controllers import (
    CONTROLLERS,
    ComputedTorqueAgent,
    PlannerComputedTorqueAgent,
    PlannerController,
    ResolvedRateController,
    SingularityAwareController,
)
from tests.training.conftest import REACH
from training import evaluate
from training.evaluate import EvaluationError, aggregate, evaluate_agent, load_controller

#: The rate-control controllers (the computed-torque agents drive force control: ``test_*computed_torque_*``).
FORCE_AGENTS = (ComputedTorqueAgent.name, PlannerComputedTorqueAgent.name)
NAMES = sorted(name for name in CONTROLLERS if name not in FORCE_AGENTS)
EPISODES = 5


@pytest.fixture(scope="module")
def hard_results() -> dict[str, dict]:
    """Aggregated metrics of both controllers on the same five hard Reach episodes (seed 0)."""
    import gymnasium as gym

    env = gym.make(REACH)
    try:
        return {name: aggregate(evaluate_agent(load_controller(name, env), env, EPISODES, 0, "hard")) for name in NAMES}
    finally:
        env.close()


def _observations(
    make_env, env_id: str, count: int, rng: np.random.Generator, with_hard: bool = True, scale: float = 1.0
) -> np.ndarray:
    """Real observations of ``env_id``: resets (standard and, for Reach, hard targets) and random-action steps.

    ``with_hard=False``: standard targets only; ``scale``: the random actions' size.
    """
    env = make_env(env_id)
    env.action_space.seed(int(rng.integers(1 << 31)))
    hard = with_hard and "targets" in type(env.unwrapped).reset_options
    obs_list = []
    episode = 0
    while len(obs_list) < count:
        options = {"targets": "hard"} if hard and episode % 2 else None
        obs, _ = env.reset(seed=int(rng.integers(1 << 31)), options=options)
        obs_list.append(obs)
        for _ in range(int(rng.integers(0, 40))):
            obs, _, terminated, truncated, _ = env.step(scale * env.action_space.sample())
            obs_list.append(obs)
            if terminated or truncated:
                break
        episode += 1
    return np.array(obs_list[:count])


def test_registry_names():
    """The command-line names map to the five controller classes."""
    assert CONTROLLERS == {
        "computed-torque": ComputedTorqueAgent,
        "planner-computed-torque": PlannerComputedTorqueAgent,
        "planner": PlannerController,
        "resolved-rate": ResolvedRateController,
        "singularity-aware": SingularityAwareController,
    }


@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
@pytest.mark.parametrize("name", NAMES)
def test_actions_are_bounded_float32(name, env_id, make_env):
    """On real observations the actions are finite float32 in [-1, 1] with shape (N, 3) and in the action space."""
    env = make_env(env_id)
    controller = load_controller(name, env)
    obs = _observations(make_env, env_id, 200, np.random.default_rng(0))
    actions = controller(obs)
    assert actions.shape == (len(obs), 3)
    assert actions.dtype == np.float32
    assert np.all(np.isfinite(actions))
    assert np.all(np.abs(actions) <= 1.0)
    assert all(env.action_space.contains(a) for a in actions)
    assert np.max(np.abs(actions)) > 0.5, "a controller that never moves is not a baseline"


@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
@pytest.mark.parametrize("name", NAMES)
def test_batch_equals_stacked_single_calls(name, env_id, make_env):
    """A batch of N = 5 observations gives (5, 3), equal to five one-row calls stacked.

    Each one-row call gets a fresh controller: the planner keeps a plan per row, and five observations
    of one episode given in turn to row 0 are (rightly) followed along one plan.
    """
    env = make_env(env_id)
    obs = _observations(make_env, env_id, 5, np.random.default_rng(1))
    batch = load_controller(name, env)(obs)
    assert batch.shape == (5, 3)
    stacked = np.concatenate([load_controller(name, env)(obs[i : i + 1]) for i in range(5)])
    np.testing.assert_allclose(batch, stacked, rtol=0, atol=1e-6)


def test_controller_does_not_modify_observations(make_env):
    """Calling a controller leaves the observation array unchanged."""
    obs = _observations(make_env, REACH, 20, np.random.default_rng(2))
    before = obs.copy()
    for name in NAMES:
        load_controller(name, make_env(REACH))(obs)
    np.testing.assert_array_equal(obs, before)


def test_unknown_controller_lists_choices(make_env):
    """load_controller with an unknown name raises EvaluationError listing the valid names."""
    with pytest.raises(
        EvaluationError,
        match=(
            r"unknown controller 'pid'; valid choices: "
            r"\['computed-torque', 'planner', 'planner-computed-torque', 'resolved-rate', 'singularity-aware'\]"
        ),
    ):
        load_controller("pid", make_env(REACH))


def test_the_grid_planner_refuses_a_robot_without_a_certified_grid():
    """planner="grid" needs a planar robot with task_region="grid"; on the hexapod it says why ("auto" takes OMPL)."""
    params = gym.make("StewartGoughReach-v0").unwrapped.params
    with pytest.raises(
        ValueError,
        match=r"the planner needs a planar robot with task_region='grid', got spatial with task_region='box'",
    ):
        PlannerController(params, planner="grid")
    with pytest.raises(ValueError, match=r"planner must be one of \('auto', 'ompl', 'grid'\), got 'rrt'"):
        PlannerController(params, planner="rrt")
    assert type(PlannerController(params).follower.graph).__name__ == "SafePlanner"


@pytest.mark.parametrize("targets", ["standard", "hard"])
@pytest.mark.parametrize("name", NAMES)
def test_episodes_are_deterministic(name, targets, make_env):
    """The same seed gives the same episodes, in a fresh env or in one that already ran other episodes."""
    env_a, env_b = make_env(REACH), make_env(REACH)
    evaluate_agent(load_controller(name, env_b), env_b, 1, 123, targets)  # leave env_b in another state
    runs = [evaluate_agent(load_controller(name, env), env, 2, 0, targets) for env in (env_a, env_b)]
    for a, b in zip(*runs):
        timing = ("planning_s",)  # the planner's wall time, the only field that may differ
        assert {k: v for k, v in a.row().items() if k not in timing} == {
            k: v for k, v in b.row().items() if k not in timing
        }
        np.testing.assert_array_equal(a.poses, b.poses)
        np.testing.assert_array_equal(a.inverse_condition, b.inverse_condition)


def test_different_seeds_give_different_episodes(make_env):
    """Episodes with other seeds start elsewhere (the seed reaches reset)."""
    env = make_env(REACH)
    agent = load_controller("resolved-rate", env)
    a, b = (evaluate_agent(agent, env, 1, seed, "standard")[0] for seed in (0, 1))
    assert not np.allclose(a.poses[0], b.poses[0])


def test_resolved_rate_reaches_standard_targets(make_env):
    """On standard targets resolved-rate succeeds in at least 4 of 5 episodes, with mm-level final error."""
    env = make_env(REACH)
    records = evaluate_agent(load_controller("resolved-rate", env), env, EPISODES, 0)
    metrics = aggregate(records)
    assert sum(r.success for r in records) >= 4, [r.row() for r in records]
    assert metrics["singularity_terminations"] == 0
    assert metrics["final_position_error_mm"]["median"] < 20.0


def test_hard_targets_send_resolved_rate_into_singularities(hard_results):
    """Hard targets do what they promise: the straight line meets the ill-conditioned zone in most episodes."""
    rr = hard_results["resolved-rate"]
    assert rr["singularity_terminations"] >= 3, rr["terminations"]
    assert rr["min_inverse_condition"]["mean"] < 0.08


def test_singularity_aware_keeps_away_from_singularities(hard_results):
    """On hard targets singularity-aware keeps a higher min inverse condition and ends fewer episodes singular."""
    rr, sa = hard_results["resolved-rate"], hard_results["singularity-aware"]
    assert sa["min_inverse_condition"]["mean"] > rr["min_inverse_condition"]["mean"] + 0.05
    assert sa["singularity_terminations"] < rr["singularity_terminations"]
    assert sa["singularity_terminations"] <= 1


def test_resolved_rate_tracks(make_env):
    """On Track, resolved-rate (with the target-velocity feed-forward) succeeds in at least 80 % of episodes."""
    env = make_env("Planar3RPRTrack-v0")
    records = evaluate_agent(load_controller("resolved-rate", env), env, EPISODES, 0)
    metrics = aggregate(records)
    assert metrics["success_rate"] >= 0.8, [r.row() for r in records]
    assert metrics["singularity_terminations"] == 0
    assert all(r.length == env.spec.max_episode_steps for r in records), "tracking episodes run to the time limit"


def test_evaluate_cli_writes_gif(tmp_path, capsys):
    """evaluate.main with a controller, hard targets and --video writes an animated GIF and the metrics."""
    out = tmp_path / "rr-hard"
    argv = ["--controller", "resolved-rate", "--episodes", "2", "--targets", "hard", "--video", "--out", str(out)]
    assert evaluate.main(argv) == 0
    with Image.open(out / "episodes.gif") as gif:
        assert gif.format == "GIF"
        assert gif.n_frames > 2
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["episodes"] == 2
    assert metrics["label"] == "resolved-rate @ hard"
    assert (out / "trajectories.png").is_file() and (out / "condition_number.png").is_file()
    assert str(out) in capsys.readouterr().out


def test_evaluate_hard_env_id_uses_hard_targets(tmp_path):
    """--env Planar3RPRReachHard-v0 evaluates the same episodes as Planar3RPRReach-v0 with --targets hard."""
    common = ["--controller", "resolved-rate", "--episodes", "2"]
    hard_id, hard_option = tmp_path / "hard-id", tmp_path / "hard-option"
    assert evaluate.main([*common, "--env", "Planar3RPRReachHard-v0", "--out", str(hard_id)]) == 0
    assert evaluate.main([*common, "--env", REACH, "--targets", "hard", "--out", str(hard_option)]) == 0
    assert (hard_id / "episodes.csv").read_text() == (hard_option / "episodes.csv").read_text()


def test_evaluate_shield_removes_the_straight_line_singularity_terminations(tmp_path):
    """On hard targets the straight line ends in singularities; with --shield it never does."""
    common = ["--controller", "resolved-rate", "--episodes", "4", "--targets", "hard"]
    plain, shielded = tmp_path / "plain", tmp_path / "shielded"
    assert evaluate.main([*common, "--out", str(plain)]) == 0
    assert evaluate.main([*common, "--shield", "0.05", "--out", str(shielded)]) == 0
    assert json.loads((plain / "metrics.json").read_text())["singularity_terminations"] > 0
    metrics = json.loads((shielded / "metrics.json").read_text())
    assert metrics["singularity_terminations"] == 0
    assert metrics["label"] == "resolved-rate + shield @ hard"


def test_tracking_metrics_find_a_known_lag_and_errors():
    """A target delayed by 0.25 s gives lag 0.25 s; RMS and max come from the errors after the settling time."""
    from training.evaluate import TRACKING_SETTLING_S, tracking_metrics

    dt, steps = 0.05, 400
    t = np.arange(steps + 1) * dt
    target = np.stack([0.1 * np.sin(t), 0.1 * np.cos(t)], axis=-1)
    pose = np.stack([0.1 * np.sin(t - 0.25), 0.1 * np.cos(t - 0.25)], axis=-1)
    errors = np.linalg.norm(target - pose, axis=-1)
    metrics = tracking_metrics(errors, np.full(steps + 1, 0.01), np.zeros(steps), pose, target, dt)
    assert metrics["lag_s"] == pytest.approx(0.25)
    skip = int(round(TRACKING_SETTLING_S / dt))
    assert metrics["rms_position_mm"] == pytest.approx(1000 * np.sqrt(np.mean(errors[skip:] ** 2)))
    assert metrics["max_orientation_deg"] == pytest.approx(np.degrees(0.01))
    assert metrics["cost_fraction"] == 0.0


@pytest.mark.parametrize("env_id", ["Planar3RPRTrack-v0", "StewartGoughTrack-v0"])
def test_track_evaluations_report_tracking_metrics(env_id):
    """Track envs get RMS / max errors, cost fraction and lag in the aggregate; Reach envs do not."""
    env = gym.make(env_id)
    agent = load_controller("resolved-rate", env)
    metrics = aggregate(evaluate_agent(agent, env, 1, 0))
    tracking = metrics["tracking"]
    assert tracking["settling_s"] == 1.0
    assert tracking["rms_position_mm"]["mean"] <= tracking["max_position_mm"]["mean"]
    assert 0.0 <= tracking["lag_s"]["mean"] <= 1.0
    reach = gym.make(env_id.replace("Track", "Reach"))
    assert "tracking" not in aggregate(evaluate_agent(load_controller("resolved-rate", reach), reach, 1, 0))


def test_singularity_aware_control_at_the_edge_of_a_crank_robots_reach():
    """Where a finite-difference neighbour of the pose is out of the 3-RRR's reach, k there is NaN, not an error.

    The controller then pushes along the other coordinates only, and its actions stay finite (it raised
    "SVD did not converge" from inside NumPy on such a pose).
    """
    params = gym.make("Planar3RRRReach-v0").unwrapped.params
    controller = SingularityAwareController(params)
    robot = params.robot
    inside, outside = 0.0, 1.0  # along +x from the home pose: bisect the edge of the reach
    home = robot.home_pose()
    for _ in range(60):
        mid = 0.5 * (inside + outside)
        reached = np.all(np.isfinite(robot.inverse_kinematics(home + [mid, 0.0, 0.0], validate=False)))
        inside, outside = (mid, outside) if reached else (inside, mid)
    pose = home + [inside - 0.5 * controller.step, 0.0, 0.0]  # +x neighbour out of reach, the pose inside
    k = controller._k(np.stack([pose, pose + [controller.step, 0.0, 0.0]]))
    assert np.isfinite(k[0]) and np.isnan(k[1])
    velocity = controller.desired_velocity(pose[None], np.array([[0.01, 0.0, 0.0]]), np.zeros((1, 3)))
    assert np.all(np.isfinite(velocity))


@pytest.mark.parametrize("env_id", FORCE_IDS)
def test_computed_torque_actions_are_bounded_and_batched(env_id, make_env):
    """On real force-control observations: finite float32 in [-1, 1], a batch equal to one-row calls stacked."""
    env = make_env(env_id)
    agent = load_controller("computed-torque", env)
    obs = _observations(make_env, env_id, 40, np.random.default_rng(3), with_hard=False, scale=0.1)
    actions = agent(obs)
    n = env.action_space.shape[0]
    assert actions.shape == (len(obs), n) and actions.dtype == np.float32
    assert np.all(np.isfinite(actions)) and np.all(np.abs(actions) <= 1.0)
    stacked = np.concatenate([agent(obs[i : i + 1]) for i in range(5)])
    np.testing.assert_allclose(actions[:5], stacked, rtol=0, atol=1e-6)


def test_the_planner_takes_computed_torque_around_the_3rprs_singularities(make_env):
    """3-RPR detours under force control: the planner's certified path takes computed torque around the band.

    Straight at the target it ends singular on most of three hard episodes; along the path it reaches all three.
    """
    env = make_env("Planar3RPRForceReach-v0")
    results = {name: aggregate(evaluate_agent(load_controller(name, env), env, 3, 0, "hard")) for name in FORCE_AGENTS}
    assert results["computed-torque"]["singularity_terminations"] >= 2
    planned = results["planner-computed-torque"]
    assert planned["success_rate"] == 1.0 and planned["singularity_terminations"] == 0


def test_computed_torque_gets_the_efforts_it_asks_for(make_env):
    """Through the env's action map the applied efforts are the controller's, clipped to the drive limits.

    Also where an effort lies more than τ_max from the holding force (a stiff controller far from its target).
    """
    from robot_control.controllers import decode_observation

    env = make_env("DeltaForceReach-v0")
    params = env.unwrapped.params
    agent = ComputedTorqueAgent(params, bandwidth=20.0)
    limits = params.force_limit_array
    far = 0
    for seed in range(4):
        obs, info = env.reset(seed=seed)
        for _ in range(3):
            pose, error, _ = decode_observation(params, obs[None])
            q = params.robot.inverse_kinematics(pose)
            command = agent.controller.compute(q, pose, obs[None, agent._layout["twist"]], pose + error)
            hold = params.dynamics.holding_forces(q, pose)
            far += int(np.any(np.abs(np.clip(command.tau_model, -limits, limits) - hold) > limits))
            obs, _, terminated, truncated, info = env.step(agent(obs[None])[0])
            np.testing.assert_allclose(info["actuator_forces"], np.clip(command.tau_model, -limits, limits)[0],
                                       rtol=1e-5, atol=1e-5 * limits.max())  # fmt: skip
            if terminated or truncated:
                break
    assert far > 0  # the case the offset map (τ_h + a τ_max) could not reach


def test_computed_torque_reaches_standard_targets_of_the_delta(make_env):
    """Computed torque on DeltaForceReach-v0: 5 of 5 standard targets, no singularity termination."""
    env = make_env("DeltaForceReach-v0")
    metrics = aggregate(evaluate_agent(load_controller("computed-torque", env), env, EPISODES, 0, "standard"))
    assert metrics["success_rate"] == 1.0 and metrics["singularity_terminations"] == 0
    assert 0.0 < metrics["peak_effort"]["max"] <= 1.0
    assert 0.0 < metrics["target_holding_effort"]["max"] < 1.0  # the Delta holds its standard targets


def test_the_hexapods_ill_conditioned_targets_need_more_than_its_drives_to_hold():
    """The holding effort at the target (``target_holding_effort``) exceeds 1 at the hexapod's hard targets.

    Recomputed from the constraint Jacobians with NumPy's own solver: J_i = −J_q⁻¹ J_x, J_iᵀ τ_h = G(x).
    """
    env = gym.make("StewartGoughForceReach-v0", robot="stewart_gough_hard")
    try:
        records = evaluate_agent(load_controller("computed-torque", env), env, 2, 0, "hard")
    finally:
        env.close()
    params = env.unwrapped.params
    for record in records:
        target = record.targets[0]
        q = params.robot.inverse_kinematics(target)
        J_q, J_x = params.robot.jacobians(q, target)
        J_i = -np.linalg.inv(J_q) @ J_x
        tau = np.linalg.solve(J_i.T, params.dynamics.gravity_forces(q, target))
        assert record.target_holding_effort == pytest.approx(np.max(np.abs(tau) / params.force_limit_array), rel=1e-8)
        assert record.target_holding_effort > 1.0


def test_each_controller_refuses_the_other_control_mode(make_env):
    """Rate controllers refuse a force-control env and computed torque a rate-control one, saying why."""
    with pytest.raises(EvaluationError, match=r"resolved-rate commands stroke rates \(control='rate'\)"):
        load_controller("resolved-rate", make_env("DeltaForceReach-v0"))
    with pytest.raises(EvaluationError, match=r"computed-torque commands efforts \(control='force'\)"):
        load_controller("computed-torque", make_env("DeltaReach-v0"))
