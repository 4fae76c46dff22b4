"""training.distill: the expert's labels, the fit, and a tiny run that training.evaluate scores."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

from robot_control.controllers import PlannerController
from robot_control.planner import PathFollower
from robot_control.planner import _closest_on_segments as distill_closest
from training import distill
from training.distill import DistillConfig, collect, fit
from training.evaluate import evaluate_agent, load_run

ENV = "Planar3RPRReachMixed-v0"


def _small_model(net_arch: list[int] | None = None):
    """An SB3 PPO model on ENV whose policy the fit tests train (seeded, CPU)."""
    import torch
    from stable_baselines3 import PPO

    torch.manual_seed(0)
    arch = [64, 64] if net_arch is None else net_arch
    return PPO("MlpPolicy", gym.make(ENV), device="cpu", policy_kwargs={"net_arch": arch}, seed=0)


def test_the_follower_replans_when_pushed_off_its_path():
    """With replan_distance, a pose 5 cm off the path gets a new plan from it; without, the old plan stays."""
    env = gym.make("Planar3RPRReachHard-v0")
    _, info = env.reset(seed=3)
    params = env.unwrapped.params
    pose, target = info["pose"], info["target"]
    for distance, plans in ((None, 1), (0.03, 2)):
        follower = PathFollower(params, replan_distance=distance)
        follower.carrot(0, pose, target)
        off = pose + np.array([0.0, 0.05, 0.0])  # 5 cm off a path that starts at the pose, within one jump
        follower._jump = 1.0  # the push is not a new episode
        follower.carrot(0, off, target)
        assert len(follower.log) == plans
        if distance is not None:
            np.testing.assert_array_equal(follower.log[-1].waypoints[0], off)
    with pytest.raises(ValueError, match=r"replan_distance must be None or a positive distance \[m\], got -1"):
        PathFollower(params, replan_distance=-1)


def test_a_failed_replan_keeps_the_certified_plan():
    """Off its path where no certified path exists from the pose, the follower keeps its certified plan.

    The graph's second plan is made to fail: the row keeps the first plan and its carrot lies on it (steering
    back), not at the target; a second plan that is found replaces the first.
    """
    from robot_control.planner import Plan

    env = gym.make("Planar3RPRReachHard-v0")
    _, info = env.reset(seed=3)
    params = env.unwrapped.params
    pose, target = info["pose"], info["target"]
    for found in (False, True):
        follower = PathFollower(params, replan_distance=0.03)
        follower.carrot(0, pose, target)
        first = follower.log[-1]
        assert first.found and len(first.waypoints) > 2  # a detour
        plan = follower.graph.plan
        follower.graph.plan = lambda a, b, found=found: Plan(np.stack([a, b]), found, 1.0, 1.0, 0.0, 0.0)
        off = pose + np.array([0.0, 0.05, 0.0])
        follower._jump = 1.0  # the push is not a new episode
        carrot = follower.carrot(0, off, target)
        follower.graph.plan = plan
        assert len(follower.log) == 2 and follower.log[-1].found == found
        kept = follower._rows[0][1]
        if found:
            assert kept is follower.log[-1]
            np.testing.assert_allclose(carrot, target)  # the new one-segment plan steers at the target
        else:
            assert kept is first
            gap, _ = distill_closest(first.waypoints, params.pose_metric, carrot)
            assert gap.min() < 1e-9 and np.linalg.norm(carrot - target) > 0.05


def test_the_replanning_expert_reaches_a_hard_target_it_drove_straight_at():
    """Replanning 1 cm off its path, the planner controller reaches reset seed 5003's hard target.

    The episode meets a replan that finds no certified path (from a pose within the strokes' margins); driving
    straight at the target from there, as a follower without a certified plan does, ends it singular.
    """
    from training.evaluate import load_controller

    env = gym.make("Planar3RPRReach-v0")
    controller = load_controller("planner", env, replan_distance=0.01)
    (record,) = evaluate_agent(controller, env, 1, 5003, "hard")
    assert record.success and not record.singularity_termination
    assert any(not plan.found for plan in controller.log)  # the episode does meet a failed replan


def test_the_labels_are_the_planner_controllers_actions():
    """Every recorded label equals a fresh PlannerController's action at the recorded observation (same plans)."""
    env = gym.make(ENV)
    config = DistillConfig(replan_distance=1e9)  # plan once per episode, as the plain controller does
    expert = distill._expert(env, config)
    obs, act, k, figures, states = collect(env, expert, None, 2, 1.0, 123, np.random.default_rng(0))
    assert obs.shape == (400, 18) and act.shape == (400, 3) and k.shape == (400,) and states.shape == (400, 6)
    # k is the state's own: the observation's k column (noise-free here), not the next state's
    np.testing.assert_allclose(k, obs[:, -1], rtol=1e-6)
    # and so is the recorded state (q, x): the kinematics give its k
    robot = env.unwrapped.params.robot
    np.testing.assert_allclose(robot.inverse_condition_number(states[:, :3], states[:, 3:]), k, rtol=1e-9)
    # the default expert law: undamped, straight at the target on a one-segment plan, exact steps
    reference = PlannerController(env.unwrapped.params, cross_track=False, damping=config.expert_damping)
    np.testing.assert_allclose(np.stack([reference(o[None])[0] for o in obs]), act, atol=1e-6)
    assert figures["success_rate"] == 1.0 and figures["singular_terminations"] == 0.0
    # with first_order_expert, the first-order law's (which differs from the exact one at these states)
    config = DistillConfig(replan_distance=1e9, first_order_expert=True)
    obs, first, _, _, _ = collect(env, distill._expert(env, config), None, 2, 1.0, 123, np.random.default_rng(0))
    reference = PlannerController(env.unwrapped.params, cross_track=False, damping=False, exact_step=False)
    np.testing.assert_allclose(np.stack([reference(o[None])[0] for o in obs]), first, atol=1e-6)
    assert np.max(np.abs(first - act)) > 1e-3


def test_under_force_control_the_labels_are_planner_computed_torques_actions():
    """On a force env the expert is computed torque along the planner's path.

    Each label equals a fresh PlannerComputedTorqueAgent's action at the recorded observation (same plans).
    """
    from robot_control.controllers import PlannerComputedTorqueAgent

    env = gym.make("Planar3RPRForceReach-v0", targets="mixed")
    expert = distill._expert(env, DistillConfig(replan_distance=None))
    assert isinstance(expert, PlannerComputedTorqueAgent)
    obs, act, _, figures, _ = collect(env, expert, None, 2, 1.0, 77, np.random.default_rng(0))
    assert act.shape == (400, 3) and len(expert.log) == 2  # one plan per episode
    reference = PlannerComputedTorqueAgent(env.unwrapped.params)
    for i in (0, 200):
        reference(obs[i : i + 1])  # the episode's first observation plans
        np.testing.assert_allclose(np.stack([reference(o[None])[0] for o in obs[i : i + 200]]), act[i : i + 200],
                                   atol=1e-6)  # fmt: skip
    assert figures["success_rate"] == 1.0 and figures["singular_terminations"] == 0.0
    for option in ("expert_damping", "first_order_expert"):
        with pytest.raises(ValueError, match=option):
            distill._expert(env, DistillConfig(**{option: True}))


def test_the_computed_torque_expert_labels_a_track_env_with_computed_torques_actions(tmp_path):
    """expert="computed-torque" labels with ComputedTorqueAgent's action (the config's bandwidth).

    Each label is that action at the recorded observation; the expert is refused on a rate-control env; a tiny run
    on a Track id names its expert in its run folder.
    """
    from robot_control.controllers import ComputedTorqueAgent

    env = gym.make("DeltaForceTrack-v0", dt=0.01)
    config = DistillConfig(
        env_id="DeltaForceTrack-v0", env_kwargs={"dt": 0.01}, expert="computed-torque", bandwidth=40.0
    )
    obs, act, _, figures, _ = collect(env, distill._expert(env, config), None, 1, 1.0, 3, np.random.default_rng(0))
    reference = ComputedTorqueAgent(env.unwrapped.params, bandwidth=40.0)
    np.testing.assert_allclose(reference(obs), act, atol=1e-6)
    assert np.max(np.abs(ComputedTorqueAgent(env.unwrapped.params, bandwidth=4.0)(obs) - act)) > 0.02
    assert figures["plans_per_episode"] == 0.0
    with pytest.raises(ValueError, match="control='force'"):
        distill._expert(gym.make("DeltaTrack-v0"), config)
    for bad in ({"expert": "oracle"}, {"bandwidth": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            DistillConfig(**bad)
    tiny = dataclasses.replace(config, expert_episodes=1, iterations=1, episodes=1, epochs=1)
    distill.distill(tiny, tmp_path, log=lambda _: None)
    run_config = yaml.safe_load((tmp_path / "config.yml").read_text())
    assert run_config["distilled_from"] == "computed-torque" and run_config["env_id"] == "DeltaForceTrack-v0"


def test_the_reference_teacher_feeds_forward_the_references_acceleration_over_the_next_period():
    """With reference_acceleration, the labels feed forward the reference's acceleration over the next period.

    Each label is computed torque with ẍ_d = (ẋ*_next − ẋ*) / dt, the difference of the reference velocities the
    next observation and this one show (the teacher reads them from the env's state).
    """
    from robot_control.controllers import ComputedTorqueAgent, decode_observation

    env = gym.make("DeltaForceTrack-v0", dt=0.01, track_period=1.0)
    config = DistillConfig(
        env_id="DeltaForceTrack-v0", expert="computed-torque", bandwidth=40.0, reference_acceleration=True
    )
    obs, act, _, _, _ = collect(env, distill._expert(env, config), None, 1, 1.0, 5, np.random.default_rng(0))
    params = env.unwrapped.params
    velocity = decode_observation(params, obs.astype(np.float64))[2]
    acceleration = np.diff(velocity, axis=0) / params.dt
    assert np.max(np.abs(acceleration)) > 1.0  # the cycle does accelerate
    plain = ComputedTorqueAgent(params, bandwidth=40.0)
    rows = np.arange(0, len(obs) - 1, 7)
    expected = []
    for i in rows:
        plain._acceleration = lambda _obs, a=acceleration[i]: a[None]
        expected.append(plain(obs[i : i + 1].astype(np.float64))[0])
    np.testing.assert_allclose(np.array(expected), act[rows], atol=2e-5)
    plain._acceleration = lambda _obs: None
    assert np.max(np.abs(plain(obs[rows].astype(np.float64)) - act[rows])) > 0.05
    with pytest.raises(ValueError, match="reference_acceleration needs the computed-torque expert"):
        DistillConfig(reference_acceleration=True)


def test_cut_episodes_are_the_first_steps_of_the_full_ones():
    """With max_steps each episode stops after that many steps: its pairs are the full episode's first ones."""
    env = gym.make(ENV)
    config = DistillConfig(replan_distance=1e9)
    full = collect(env, distill._expert(env, config), None, 3, 1.0, 40, np.random.default_rng(0))
    cut = collect(env, distill._expert(env, config), None, 3, 1.0, 40, np.random.default_rng(0), max_steps=7)
    assert cut[0].shape == (21, 18) and full[0].shape == (600, 18)
    rows = np.concatenate([np.arange(7) + 200 * i for i in range(3)])  # every full episode lasts 200 steps
    for a, b in zip((*cut[:3], cut[4]), (*full[:3], full[4]), strict=True):
        np.testing.assert_array_equal(a, b[rows])


def test_start_episodes_add_their_cut_episodes_to_every_round(tmp_path):
    """Round 0 holds the expert's full episodes and start_episodes cut ones; each round adds as many again."""
    config = DistillConfig(expert_episodes=2, iterations=1, episodes=1, epochs=1, start_episodes=3, start_steps=5)
    result = distill.distill(config, tmp_path, log=lambda _: None)
    pairs = [r["pairs"] for r in result["rounds"][:2]]
    assert pairs[0] == 2 * 200 + 3 * 5  # the expert's episodes on this env all run their 200 steps
    added = pairs[1] - pairs[0] - round(result["rounds"][1]["mean_length"])  # less the round's one full episode
    assert 3 <= added <= 15  # three cut episodes of 1 to 5 steps
    with pytest.raises(ValueError, match="start_episodes must be ≥ 0 and start_steps ≥ 1, got -1 and 40"):
        DistillConfig(start_episodes=-1)


def test_with_the_previous_action_the_learner_sees_it_and_the_expert_does_not():
    """Wrapped in PreviousActionWrapper, the observations gain the previous action and the labels stay the same.

    Each recorded observation ends with the action executed one step before (zeros at an episode's first), and the
    labels are those of the unwrapped run: the expert reads the env's own observation.
    """
    from envs import PreviousActionWrapper

    config = DistillConfig(replan_distance=1e9)
    plain = gym.make(ENV)
    obs_p, act_p, _, _, _ = collect(plain, distill._expert(plain, config), None, 2, 1.0, 123, np.random.default_rng(0))
    wrapped = PreviousActionWrapper(gym.make(ENV))
    obs_w, act_w, _, _, _ = collect(
        wrapped, distill._expert(wrapped, config), None, 2, 1.0, 123, np.random.default_rng(0)
    )
    np.testing.assert_array_equal(act_w, act_p)
    np.testing.assert_array_equal(obs_w[:, :18], obs_p)
    previous = np.concatenate([np.zeros((1, 3), np.float32), np.clip(act_p[:-1], -1.0, 1.0)])
    previous[200] = 0.0  # the second episode's first step (200 steps each)
    np.testing.assert_array_equal(obs_w[:, 18:], previous)


def test_collect_counts_every_singularity_termination():
    """Newton failures are singularity terminations too (as in training.evaluate), not only a k below the bound.

    Resolved-rate on the 3-RRR's hard targets ends reset seed 13 with a Newton failure and seed 16 below the bound
    (found by hand); the oracle counts every termination but leaving the bounds, on the same episodes stepped here.
    """
    from robot_control.controllers import ResolvedRateController

    env = gym.make("Planar3RRRReach-v0", targets="hard")
    expert = distill._expert(env, DistillConfig(expert_damping=True))
    driver = ResolvedRateController(env.unwrapped.params)
    _, _, _, figures, _ = collect(env, expert, lambda o: driver(o[None])[0], 4, 0.0, 13, np.random.default_rng(0))
    reasons = []
    for seed in range(13, 17):
        obs, _ = env.reset(seed=seed)
        while True:
            obs, _, terminated, truncated, info = env.step(driver(obs[None])[0])
            if terminated or truncated:
                reasons.append(info["termination_reason"])
                break
    assert "newton_failed" in reasons and "singular" in reasons
    expected = sum(r not in ("", "out_of_bounds") for r in reasons) / len(reasons)
    assert figures["singular_terminations"] == expected


def test_band_weights_rise_linearly_from_the_safe_to_the_hard_threshold():
    """1 at and above k_safe, 1 + w at and below k_hard, linear between (values worked by hand)."""
    k = np.array([0.5, 0.1, 0.08, 0.065, 0.03, 0.0])
    np.testing.assert_allclose(distill.band_weights(k, 0.1, 0.03, 7.0), [1.0, 1.0, 3.0, 4.5, 8.0, 8.0])
    np.testing.assert_allclose(distill.band_weights(k, 0.1, 0.03, 0.0), np.ones(6))
    for weight in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="band weight must be finite and ≥ 0"):
            distill.band_weights(k, 0.1, 0.03, weight)
    with pytest.raises(ValueError, match=r"hard_threshold must be < safe_threshold, got 0\.1 and 0\.1"):
        distill.band_weights(k, 0.1, 0.1, 1.0)


def test_a_weighted_fit_converges_to_the_weighted_mean_of_conflicting_labels():
    """Pairs that share an observation but disagree: the weighted least-squares answer is Σ w a / Σ w per point."""
    import torch

    model = _small_model()
    rng = np.random.default_rng(1)
    points = rng.normal(size=(4, 18)).astype(np.float32)
    low, high = rng.uniform(-0.8, 0.0, size=(4, 3)), rng.uniform(0.0, 0.8, size=(4, 3))
    obs = np.repeat(points, 200, axis=0)  # each point 200 times: half labelled low (weight 1), half high (weight 4)
    act = np.where((np.arange(800) % 200 < 100)[:, None], np.repeat(low, 200, 0), np.repeat(high, 200, 0))
    weights = np.where(np.arange(800) % 200 < 100, 1.0, 4.0)
    fit(model.policy, obs, act.astype(np.float32), DistillConfig(epochs=60, batch_size=64), 0, weights)
    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(points)).distribution.mean.numpy()
    np.testing.assert_allclose(mean, (low + 4.0 * high) / 5.0, atol=0.03)
    with pytest.raises(ValueError, match=r"weights must be \(800,\), finite and > 0, got shape \(3,\)"):
        fit(model.policy, obs, act.astype(np.float32), DistillConfig(epochs=1), 0, np.ones(3))


@pytest.mark.parametrize("env_id", ["Planar3RRRReach-v0", "StewartGoughReach-v0", "DeltaReach-v0"])
def test_platform_gains_are_the_pose_change_of_one_step_in_tolerances(env_id):
    """Oracle: the env's own step. A small action a from a recorded state moves the pose by ≈ tolerances · G a."""
    env = gym.make(env_id)
    params = env.unwrapped.params
    robot = params.robot
    rotations = list(robot.pose_space.rotation_columns)
    tolerance = np.full(robot.pose_space.n_pose, params.success_position_tolerance)
    tolerance[rotations] = params.success_orientation_tolerance
    rng = np.random.default_rng(3)
    for seed in (11, 12):
        _, info = env.reset(seed=seed)
        state = env.unwrapped.state
        gains = distill.platform_gains(params, np.concatenate([state.q[0], state.x[0]])[None])
        assert gains.shape == (1, robot.pose_space.n_pose, robot.n_actuators)
        action = 1e-4 * rng.uniform(-1.0, 1.0, robot.n_actuators)
        _, _, _, _, after = env.step(action)
        moved = robot.pose_space.difference(after["pose"], info["pose"]) / tolerance
        np.testing.assert_allclose(moved, gains[0] @ action, rtol=1e-3, atol=1e-9 * np.abs(gains).max())
    with pytest.raises(ValueError, match=r"states must be finite of shape \(S, \d+\) \(q then x\), got shape \(2, 3\)"):
        distill.platform_gains(params, np.zeros((2, 3)))


def test_the_pair_loss_adds_the_platform_term_to_the_weighted_squared_error():
    """Oracle: the formula in NumPy, pair by pair."""
    import torch

    rng = np.random.default_rng(4)
    mean, target = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    weights, gains = rng.uniform(0.5, 2.0, 5), rng.normal(size=(5, 4, 3))
    error = mean - target
    plain = sum(w * e @ e for w, e in zip(weights, error, strict=True)) / (3 * weights.sum())
    platform = sum(w * (g @ e) @ (g @ e) for w, e, g in zip(weights, error, gains, strict=True)) / (3 * weights.sum())
    as_t = [torch.as_tensor(a) for a in (mean, target, weights, gains)]
    assert float(distill.pair_loss(*as_t[:3], None)) == pytest.approx(plain, rel=1e-12)
    assert float(distill.pair_loss(*as_t)) == pytest.approx(plain + platform, rel=1e-12)


def test_a_fit_with_platform_gains_converges_to_their_least_squares_answer():
    """Pairs that share an observation but disagree, each with its own G_i: the fit finds the least-squares answer.

    The minimiser of Σ ‖μ − a_i‖² + ‖G_i (μ − a_i)‖² is (Σ (I + G_iᵀ G_i))⁻¹ Σ (I + G_iᵀ G_i) a_i, not the labels'
    mean.
    """
    import torch

    model = _small_model()
    rng = np.random.default_rng(5)
    point = rng.normal(size=(1, 18)).astype(np.float32)
    labels = rng.uniform(-0.6, 0.6, size=(2, 3))
    gains = np.stack([np.zeros((3, 3)), np.diag([3.0, 0.0, 1.0])])  # the second label's errors cost more
    obs, act = np.repeat(point, 400, axis=0), np.tile(labels, (200, 1)).astype(np.float32)
    fit(model.policy, obs, act, DistillConfig(epochs=40, batch_size=64), 0, None, np.tile(gains, (200, 1, 1)))
    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(point)).distribution.mean.numpy()[0]
    metrics = [np.eye(3) + g.T @ g for g in gains]
    expected = np.linalg.solve(sum(metrics), sum(m @ a for m, a in zip(metrics, labels, strict=True)))
    np.testing.assert_allclose(mean, expected, atol=0.02)
    assert np.abs(expected - labels.mean(axis=0)).max() > 0.1  # the platform term moved the answer
    with pytest.raises(ValueError, match=r"gains must be \(400, m, 3\) and finite, got shape \(400, 3\)"):
        fit(model.policy, obs, act, DistillConfig(epochs=1), 0, None, np.zeros((400, 3)))
    with pytest.raises(ValueError, match=r"gains must be \(400, m, 3\) and finite, got a non-finite entry"):
        fit(model.policy, obs, act, DistillConfig(epochs=1), 0, None, np.full((400, 2, 3), np.nan))


@pytest.mark.parametrize("decay", [False, True])
def test_the_fits_learning_rate_follows_a_cosine_to_zero_with_lr_decay(monkeypatch, decay):
    """The rate at Adam step t of T is lr · (1 + cos(π t / T)) / 2 with ``lr_decay``, else lr throughout."""
    import math

    import torch

    rates = []
    adam = torch.optim.Adam

    class Recording(adam):
        def step(self, closure=None):
            rates.append(self.param_groups[0]["lr"])
            return super().step(closure)

    monkeypatch.setattr(torch.optim, "Adam", Recording)
    model = _small_model([16])
    x = np.random.default_rng(0).normal(size=(100, 18)).astype(np.float32)
    config = DistillConfig(epochs=3, batch_size=32, learning_rate=2e-3, lr_decay=decay)
    fit(model.policy, x, np.zeros((100, 3), np.float32), config, 0)
    total = 3 * 4  # epochs × ⌈100 / 32⌉ batches
    expected = [2e-3 * (1 + math.cos(math.pi * t / total)) / 2 if decay else 2e-3 for t in range(total)]
    np.testing.assert_allclose(rates, expected, rtol=1e-9, atol=1e-15)


def test_fit_lowers_the_error_to_a_known_linear_expert():
    """The policy's mean learns a fixed linear map of the observation (an expert whose answer is known)."""
    model = _small_model()
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4000, 18)).astype(np.float32)
    y = np.tanh(x[:, :3] - 0.5 * x[:, 3:6]).astype(np.float32)
    config = DistillConfig(epochs=1, learning_rate=1e-3)
    first = fit(model.policy, x, y, config, 0)
    last = fit(model.policy, x, y, DistillConfig(epochs=20, learning_rate=1e-3), 1)
    assert last < 0.2 * first and last < 0.02


def test_a_tiny_run_is_a_run_folder_the_evaluation_scores(tmp_path):
    """A tiny distillation writes a run folder; training.evaluate loads it and runs episodes with it."""
    config = DistillConfig(expert_episodes=3, iterations=1, episodes=2, epochs=1)
    result = distill.distill(config, tmp_path, log=lambda _: None)
    assert [r["round"] for r in result["rounds"]] == [0, 1]
    assert result["rounds"][1]["pairs"] == result["rounds"][0]["pairs"] + 400
    assert json.loads((tmp_path / "distill.json").read_text())["config"]["env_id"] == ENV
    agent, run_config = load_run(tmp_path)
    assert run_config["algo"] == "ppo" and run_config["hyperparams"]["normalize"]
    records = evaluate_agent(agent, gym.make("Planar3RPRReach-v0"), 2, 5000, "hard")
    assert len(records) == 2


def test_a_run_with_the_previous_action_names_its_wrapper_and_is_scored_through_it(tmp_path):
    """The run folder's config names envs.PreviousActionWrapper; training.evaluate wraps the env the same way."""
    from training import evaluate

    config = DistillConfig(expert_episodes=2, iterations=0, epochs=1, previous_action=True)
    distill.distill(config, tmp_path / "run", log=lambda _: None)
    agent, run_config = load_run(tmp_path / "run")
    assert run_config["hyperparams"]["env_wrapper"] == "envs.PreviousActionWrapper"
    assert agent.observation_space.shape == (21,)
    out = tmp_path / "eval"
    argv = ["--run", str(tmp_path / "run"), "--env", "Planar3RPRReach-v0", "--targets", "hard", "--episodes", "2"]
    assert evaluate.main([*argv, "--seed", "5000", "--out", str(out)]) == 0
    assert json.loads((out / "metrics.json").read_text())["episodes"] == 2


def test_bad_options_are_refused(capsys):
    """Unknown ids and out-of-range options are named."""
    with pytest.raises(SystemExit):
        distill.main(["--run-dir", "x", "--env", "Planar3RPRTrack-v0"])
    assert "--env must be a Reach id" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        distill.main(["--run-dir", "x", "--beta", "2"])
    assert "--beta must be in [0, 1], got 2.0" in capsys.readouterr().err
    for argv, message in (
        (["--band-weight", "-1"], "--band-weight must be finite and ≥ 0, got -1.0"),
        (["--platform-loss", "nan"], "--platform-loss must be finite and ≥ 0, got nan"),
        (["--action-noise", "-0.1"], "--action-noise must be in [0, 1), got -0.1"),
        (["--action-noise", "1"], "--action-noise must be in [0, 1), got 1.0"),
        (["--damping-threshold", "0.2"], "--damping-threshold needs --expert-damping and a value in (0, 1], got 0.2"),
        (["--expert-damping", "--damping-threshold", "0"], "a value in (0, 1], got 0.0"),
        (["--damping-kind", "cap"], "--damping-kind cap needs --expert-damping"),
        (["--start-episodes", "-1"], "--start-episodes must be ≥ 0, got -1"),
        (["--start-steps", "0"], "--start-steps must be ≥ 1, got 0"),
        (["--hold-fraction", "1"], "--hold-fraction must be in [0, 1), got 1.0"),
        (["--net-arch", "64", "0"], "--net-arch widths must be ≥ 1, got [64, 0]"),
        (["--env", "DeltaForceTrack-v0"], "--env must be a Reach id"),
        (
            ["--expert", "computed-torque", "--env", "DeltaForceTrack-v0", "--select-round", "validated"],
            "Reach id only",
        ),
        (["--expert", "computed-torque", "--bandwidth", "0"], "--bandwidth must be finite and > 0, got 0.0"),
        (["--reference-acceleration"], "--reference-acceleration needs --expert computed-torque"),
        (["--damped-output"], "--damped-output needs --expert-damping and --damping-kind scale, got no --expert"),
        (
            ["--damped-output", "--expert-damping", "--damping-kind", "cap"],
            "got --expert-damping and --damping-kind cap",
        ),
    ):
        with pytest.raises(SystemExit):
            distill.main(["--run-dir", "x", *argv])
        assert message in capsys.readouterr().err


def test_a_damped_and_holding_run_reads_the_raw_observation_through_its_normaliser(tmp_path):
    """With damped_output, hold_fraction and error_gain the run's policy is PlanFreeMlpPolicy on the env's columns.

    A planar observation is pose 4, target 4, error 3 (δx, δy, δφ: columns 8–10), strokes 3, stroke errors 3, k
    (column 17); the previous action follows. The raw columns the policy recovers from the normalised observation
    are the env's; the hold's tolerances are the fraction of the env's success tolerances; at the target the
    run's agent (as training.evaluate loads it) commands exactly 0; training.evaluate scores the run.
    """
    import torch

    from training.evaluate import load_model, wrap_for_run
    from training.policies import PlanFreeMlpPolicy

    with pytest.raises(ValueError, match="damped_output needs expert_damping with damping_kind 'scale'"):
        DistillConfig(damped_output=True)
    with pytest.raises(ValueError, match=r"hold_fraction must be in \[0, 1\), got 1.0"):
        DistillConfig(hold_fraction=1.0)
    config = DistillConfig(
        env_id="Planar3RRRReach-v0",
        env_kwargs={"targets": "mixed"},
        expert_episodes=2,
        iterations=0,
        epochs=1,
        expert_damping=True,
        damped_output=True,
        hold_fraction=0.1,
        error_gain=True,
        previous_action=True,
    )
    distill.distill(config, tmp_path / "run", log=lambda _: None)
    model, normalizer, run_config = load_model(tmp_path / "run")
    params = gym.make("Planar3RRRReach-v0").unwrapped.params
    assert run_config["hyperparams"]["policy"] == "training.policies.PlanFreeMlpPolicy"
    policy = model.policy
    assert type(policy) is PlanFreeMlpPolicy and policy.k_index == 17
    assert (policy.position_columns, policy.orientation_columns) == ([8, 9], [10])
    assert policy.damping_threshold == params.safe_threshold and policy.error_gain
    assert policy.hold_position == pytest.approx(0.1 * params.success_position_tolerance)
    assert policy.hold_orientation == pytest.approx(0.1 * params.success_orientation_tolerance)
    agent, _ = load_run(tmp_path / "run")
    env = gym.make("Planar3RRRReach-v0", targets="hard")
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        wrapped = np.concatenate([obs, np.zeros(3, np.float32)])
        normalised = torch.as_tensor(normalizer.normalize_obs(wrapped[None]))
        recovered = policy._raw(normalised, torch.tensor([17, 8, 9, 10])).numpy()[0]
        np.testing.assert_allclose(recovered, obs[[17, 8, 9, 10]], rtol=1e-5, atol=1e-7)
        assert np.any(agent(wrapped) != 0.0)  # 2 cm or more from the target
        at_target = wrapped.copy()
        at_target[8:11] = 0.0
        np.testing.assert_array_equal(agent(at_target), 0.0)
    assert len(evaluate_agent(agent, wrap_for_run(gym.make("Planar3RRRReach-v0"), run_config), 2, 5000, "hard")) == 2


@pytest.mark.parametrize(
    ("env_id", "previous_action", "controllers"),
    [
        ("Planar3RPRReach-v0", False, ("planner", "resolved-rate", "singularity-aware")),
        ("Planar3RPRForceReach-v0", True, ("planner-computed-torque", "computed-torque")),
    ],
)
def test_the_plan_free_report_tabulates_every_agent(tmp_path, env_id, previous_action, controllers):
    """A tiny run through experiments.plan_free_report: each agent's row, the timing and the paths picture.

    Under force control the classical rows are computed torque's, along the planner's path (the expert) and straight.
    """
    from experiments import plan_free_report

    run = tmp_path / "run"
    config = DistillConfig(env_id=env_id, expert_episodes=2, iterations=0, epochs=1, previous_action=previous_action)
    distill.distill(config, run, log=lambda _: None)
    out = tmp_path / "report"
    plan_free_report.main(["--runs", str(run), "--env", env_id, "--episodes", "1", "--out", str(out)])
    table = (out / "table.md").read_text()
    for label in (*controllers, "plan-free", "plan-free + shield"):
        for targets in ("standard", "hard"):
            assert f"| {label} @ {targets} | " in table
    assert table.split("The planner's plans")[0].count(" @ standard | ") == len(controllers) + 2
    timing = (out / "timing.md").read_text()
    assert "ratio, exported" in timing and "time to the target" in timing
    assert (out / "paths_hard.png").stat().st_size > 0


def test_best_round_selection_keeps_the_learner_that_did_best_when_it_acted(tmp_path):
    """``select_round="best"`` keeps the argmax of success − singular over the rounds the learners acted in.

    The saved model is that learner: where it is not the last one, its actions differ from the last learner's.
    """
    import torch

    config = DistillConfig(
        env_id="Planar3RRRReach-v0", env_kwargs={"targets": "mixed"}, expert_episodes=3, iterations=3, episodes=3,
        epochs=1, select_round="best", expert_damping=True,
    )  # fmt: skip
    result = distill.distill(config, tmp_path, log=lambda _: None)
    rounds = result["rounds"]
    assert rounds[-1].get("scoring_only") and len(rounds) == config.iterations + 2
    scores = {r["round"] - 1: r["success_rate"] - r["singular_terminations"] for r in rounds if r["beta"] == 0.0}
    best = max(scores.values())
    assert result["kept_round"] == max(i for i, v in scores.items() if v == best)  # ties: the later learner
    agent, run_config = load_run(tmp_path)
    assert run_config["hyperparams"]["env_kwargs"] == {"targets": "mixed"}
    last = distill.distill(dataclasses.replace(config, select_round="last"), tmp_path / "last", log=lambda _: None)
    assert last["kept_round"] == config.iterations
    if result["kept_round"] != config.iterations:  # another learner was kept: the saved policies differ
        other, _ = load_run(tmp_path / "last")
        obs = np.random.default_rng(0).normal(size=(8, agent.observation_space.shape[0])).astype(np.float32)
        with torch.no_grad():
            assert not np.allclose(agent(obs), other(obs))


def test_validation_counts_as_the_evaluation_does():
    """``validate``'s rates equal a manual rollout's counts of the same agent on the same seeds and targets.

    Oracle: the episodes stepped here, counting ``is_success`` and every termination but leaving the bounds.
    """
    from robot_control.controllers import ResolvedRateController

    env = gym.make("Planar3RPRReach-v0")
    driver = ResolvedRateController(env.unwrapped.params)
    figures = distill.validate(env, lambda o: driver(o[None])[0], 4, 5000)
    ends = {}
    for targets in ("hard", "standard"):
        ends[targets] = []
        for i in range(4):
            obs, _ = env.reset(seed=5000 + i, options={"targets": targets})
            while True:
                obs, _, terminated, truncated, info = env.step(driver(obs[None])[0])
                if terminated or truncated:
                    ends[targets].append((info["is_success"], info["termination_reason"] not in ("", "out_of_bounds")))
                    break
    hard, both = ends["hard"], ends["hard"] + ends["standard"]
    assert figures["hard_success_rate"] == np.mean([s for s, _ in hard])
    assert figures["hard_singular_terminations"] == np.mean([t for _, t in hard]) > 0
    assert figures["success_rate"] == np.mean([s for s, _ in both])
    assert figures["singular_terminations"] == np.mean([t for _, t in both])


def test_validated_selection_keeps_the_round_with_the_best_validation_score(tmp_path):
    """``select_round="validated"`` scores every round's learner, the behaviour-cloned one included."""
    config = DistillConfig(
        expert_episodes=2, iterations=2, episodes=2, epochs=1, select_round="validated", select_episodes=2
    )
    result = distill.distill(config, tmp_path, log=lambda _: None)
    scores = [v["score"] for v in result["validation"]]
    assert [v["round"] for v in result["validation"]] == [0, 1, 2]
    assert result["kept_round"] == max(i for i, v in enumerate(scores) if v == max(scores))


def test_the_command_line_sets_the_finetuning_log_std(tmp_path, monkeypatch, capsys):
    """``--from-run RUN --log-std S`` fine-tunes with that initial log σ; a non-finite one is refused."""
    seen = []
    monkeypatch.setattr(distill, "finetune", lambda source, run_dir, config: seen.append(config))
    assert distill.main(["--from-run", "x", "--run-dir", str(tmp_path), "--log-std", "-2.5"]) == 0
    assert seen[0].log_std == -2.5 and seen[0].steps == distill.FinetuneConfig.steps
    with pytest.raises(SystemExit):
        distill.main(["--from-run", "x", "--run-dir", str(tmp_path), "--log-std", "nan"])
    assert "--log-std must be finite, got nan" in capsys.readouterr().err


def test_finetuning_fits_the_critic_alone_first_then_both(tmp_path):
    """The warm-up changes the critic and leaves the actor's weights as distilled; the PPO phase then moves them."""
    import torch
    from stable_baselines3 import PPO

    source = tmp_path / "distilled"
    distill.distill(DistillConfig(expert_episodes=2, iterations=0, epochs=1), source, log=lambda _: None)
    warm = tmp_path / "warm"
    distill.finetune(source, warm, distill.FinetuneConfig(steps=0, warmup_steps=2048, n_envs=4), log=lambda _: None)
    both = tmp_path / "both"
    distill.finetune(source, both, distill.FinetuneConfig(steps=4096, warmup_steps=2048, n_envs=4), log=lambda _: None)

    def weights(run, part):
        policy = PPO.load(run / "model.zip", device="cpu").policy
        modules = {"actor": (policy.mlp_extractor.policy_net, policy.action_net), "critic": (policy.value_net,)}
        return torch.cat([p.detach().flatten() for m in modules[part] for p in m.parameters()])

    assert torch.equal(weights(source, "actor"), weights(warm, "actor"))
    assert not torch.equal(weights(source, "critic"), weights(warm, "critic"))
    assert not torch.equal(weights(source, "actor"), weights(both, "actor"))
    agent, config = load_run(both)
    assert config["finetuned_from"] == str(source)
    assert len(evaluate_agent(agent, gym.make("Planar3RPRReach-v0"), 1, 5000, "hard")) == 1
    with pytest.raises(ValueError, match=r"must be a training\.distill run folder"):
        ppo_run = Path(__file__).resolve().parents[2] / "training" / "pretrained" / "ppo-Planar3RPRReach-v0"
        distill.finetune(ppo_run, tmp_path / "x", distill.FinetuneConfig(steps=1), log=lambda _: None)
    assert not (tmp_path / "x").exists()


def test_finetuning_a_run_with_the_previous_action_keeps_its_wrapper(tmp_path):
    """A distilled run that sees its previous action is fine-tuned on the env wrapped the same way."""
    source = tmp_path / "distilled"
    config = DistillConfig(expert_episodes=2, iterations=0, epochs=1, previous_action=True)
    distill.distill(config, source, log=lambda _: None)
    tuned = tmp_path / "tuned"
    tuning = distill.FinetuneConfig(steps=512, warmup_steps=0, n_envs=4, n_steps=128, batch_size=128)
    distill.finetune(source, tuned, tuning, log=lambda _: None)
    agent, run_config = load_run(tuned)
    assert run_config["hyperparams"]["env_wrapper"] == "envs.PreviousActionWrapper"
    assert agent.observation_space.shape == (21,)


def test_the_command_line_sets_the_learners_hidden_layers(tmp_path):
    """--net-arch 16 8 gives a learner whose actor has hidden layers of 16 and 8 units, as config.yml says."""
    import torch
    import yaml

    from training.evaluate import load_model

    argv = ["--run-dir", str(tmp_path), "--expert-episodes", "1", "--iterations", "0", "--epochs", "1"]
    assert distill.main([*argv, "--net-arch", "16", "8"]) == 0
    config = yaml.safe_load((tmp_path / "config.yml").read_text())
    assert config["hyperparams"]["policy_kwargs"]["net_arch"] == [16, 8]
    model, _, _ = load_model(tmp_path)
    widths = [m.out_features for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    assert widths == [16, 8]


@pytest.mark.parametrize("weight", [0.0, 4.0])
def test_the_command_lines_platform_loss_reaches_the_fit_as_root_lambda_times_g(tmp_path, monkeypatch, weight):
    """--platform-loss λ: every fit gets √λ times platform_gains of its pairs' states; λ = 0: no gains."""
    seen, made = [], []
    real_fit, real_gains = distill.fit, distill.platform_gains
    monkeypatch.setattr(distill, "fit", lambda *args: seen.append(args[6]) or real_fit(*args))
    monkeypatch.setattr(distill, "platform_gains", lambda *args: made.append(real_gains(*args)) or made[-1])
    argv = ["--run-dir", str(tmp_path), "--expert-episodes", "1", "--iterations", "1", "--episodes", "1"]
    assert distill.main([*argv, "--epochs", "1", "--platform-loss", str(weight)]) == 0
    assert len(seen) == 2
    if weight == 0.0:
        assert seen == [None, None] and made == []
        return
    assert [len(g) for g in seen] == [len(g) for g in made] and seen[1].shape[1:] == (3, 3)
    for given, gains in zip(seen, made, strict=True):
        np.testing.assert_allclose(given, 2.0 * gains)
    assert json.loads((tmp_path / "distill.json").read_text())["config"]["platform_loss"] == 4.0


def test_action_noise_moves_the_executed_actions_and_not_the_labels():
    """With noise σ the executed action is the clean label plus N(0, σ²) per actuator, clipped to the rate range.

    The executed action is read from the next observation's previous-action columns; the labels stay the expert's.
    """
    from envs import PreviousActionWrapper

    config = DistillConfig(replan_distance=1e9)
    env = PreviousActionWrapper(gym.make(ENV))
    obs, act, _, _, _ = collect(env, distill._expert(env, config), None, 2, 1.0, 123, np.random.default_rng(0))
    noisy_obs, labels, _, _, _ = collect(
        env, distill._expert(env, config), None, 2, 1.0, 123, np.random.default_rng(0), noise=0.05
    )
    assert len(noisy_obs) == 400  # both episodes still run their 200 steps
    executed = np.delete(noisy_obs[1:, 18:], 199, axis=0)  # row t + 1 holds step t's action; 200 starts anew
    clean = np.delete(labels[:-1], 199, axis=0)
    free = np.all(np.abs(executed) < 1.0, axis=1)  # where the clipping does not bind
    assert free.mean() > 0.9
    residual = (executed - clean)[free]
    assert abs(residual.mean()) < 0.01 and abs(residual.std() - 0.05) < 0.005
    # the labels are the expert's clean action at the state visited: its first step's equals the noise-free run's
    np.testing.assert_allclose(labels[[0, 200]], act[[0, 200]], atol=1e-6)
    # the noise moves the platform: the visited states differ from the noise-free run's
    assert np.max(np.abs(noisy_obs[1:200, :18] - obs[1:200, :18])) > 1e-3
    with pytest.raises(ValueError, match=r"noise must be finite and ≥ 0, got -0\.1"):
        collect(env, distill._expert(env, config), None, 1, 1.0, 0, np.random.default_rng(0), noise=-0.1)
    with pytest.raises(ValueError, match=r"action_noise must be in \[0, 1\), got nan"):
        DistillConfig(action_noise=float("nan"))


def test_the_command_lines_action_noise_reaches_every_training_episode(tmp_path, monkeypatch):
    """--action-noise σ: the expert's episodes, the cut start episodes, the rounds and the scoring round get σ."""
    noises = []
    real_collect = distill.collect

    def spy(*args, **kwargs):
        noises.append(kwargs.get("noise", 0.0))  # every call passes it by name
        return real_collect(*args, **kwargs)

    monkeypatch.setattr(distill, "collect", spy)
    argv = ["--run-dir", str(tmp_path), "--expert-episodes", "1", "--iterations", "1", "--episodes", "1"]
    argv += ["--epochs", "1", "--start-episodes", "1", "--start-steps", "3", "--select-round", "best"]
    assert distill.main([*argv, "--action-noise", "0.2"]) == 0
    assert noises == [0.2] * 5  # expert, its start episodes, round 1, its start episodes, the scoring round
    assert json.loads((tmp_path / "distill.json").read_text())["config"]["action_noise"] == 0.2


def test_dagger_labels_the_states_the_learner_visits_with_the_experts_action():
    """With the learner acting (β = 0), each pair's label is the expert's action at that state, not the learner's.

    Oracle: a fresh ``PlannerController`` (the expert's law, its own plans) fed the visited observations in order.
    The learner is a fixed linear map of the observation, far from the expert: it moves the platform elsewhere
    (the visited states are not the expert's own) and its actions differ from the labels.
    """
    env = gym.make(ENV)
    config = DistillConfig(replan_distance=1e9)  # plan once per episode, as the plain controller does
    weights = np.random.default_rng(4).normal(0.0, 0.4, size=(3, 18))

    def learner(o: np.ndarray) -> np.ndarray:
        return np.clip(weights @ o, -1.0, 1.0)

    obs, labels, _, _, states = collect(
        env, distill._expert(env, config), learner, 2, 0.0, 123, np.random.default_rng(0)
    )
    _, _, _, _, expert_states = collect(env, distill._expert(env, config), None, 2, 1.0, 123, np.random.default_rng(0))
    assert len(obs) >= 10
    steps = min(len(states), len(expert_states))
    assert np.max(np.abs(states[:steps] - expert_states[:steps])) > 1e-2  # the learner drove
    reference = PlannerController(env.unwrapped.params, cross_track=False, damping=config.expert_damping)
    expected = np.stack([reference(o[None])[0] for o in obs])
    np.testing.assert_allclose(labels, expected, rtol=0, atol=1e-6)
    own = np.stack([learner(o) for o in obs])
    assert np.mean(np.linalg.norm(own - labels, axis=1)) > 0.1  # a label that were the learner's would show
