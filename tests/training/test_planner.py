"""The planner baseline: a certified graph, safe plans for every hard task, and a controller that follows them."""

from __future__ import annotations

import numpy as np
import pytest

from robot_control.planner import safe_graph
from tests.training.conftest import REACH
from training.evaluate import aggregate, evaluate_agent, load_controller


@pytest.fixture(scope="module")
def env():
    """A Planar3RPRReach-v0 env shared by the module."""
    import gymnasium as gym

    env = gym.make(REACH)
    yield env
    env.close()


@pytest.fixture(scope="module")
def graph(env):
    """The certified graph of its workspace."""
    return safe_graph(env.unwrapped.params)


def _k_along(params, start, target, points=200):
    """Values of k and the strokes at ``points`` even points of a segment, by the kinematics library."""
    f = np.linspace(0.0, 1.0, points)[:, None]
    x = start + f * (target - start)
    q = params.robot.inverse_kinematics(x)
    return params.robot.inverse_condition_number(q, x), q


def test_graph_edges_are_certified(env, graph):
    """Random edges of the graph: both ends safe nodes of one component, k ≥ k_safe densely along them."""
    params = env.unwrapped.params
    coo = graph.graph.tocoo()
    rng = np.random.default_rng(0)
    pick = rng.choice(coo.nnz, size=200, replace=False)
    labels = graph.workspace.labels.ravel()
    lo, hi = params.stroke_limits
    for e in pick:
        a, b = coo.row[e], coo.col[e]
        assert labels[a] == labels[b] and labels[a] in graph.workspace.component_ids
        step = np.abs(np.array(np.unravel_index(a, graph.shape)) - np.array(np.unravel_index(b, graph.shape)))
        assert step.max() == 1  # 26-neighbours
        k, q = _k_along(params, graph.nodes[a], graph.nodes[b], 50)
        # between checked points (≤ 1 cm apart) k may dip a little below k_safe, never far
        assert k.min() >= 0.97 * params.safe_threshold
        assert q.min() >= lo and q.max() <= hi
        # edge cost: its length times a clearance factor in [1, 1 + w]
        length = np.linalg.norm((graph.nodes[b] - graph.nodes[a]) * params.pose_metric)
        assert length - 1e-12 <= coo.data[e] <= (1.0 + graph.weight) * length + 1e-12


def test_every_hard_task_has_a_certified_path(env, graph):
    """For 20 hard tasks the planner finds a path keeping k ≥ k_safe on every segment, longer than the straight one."""
    params = env.unwrapped.params
    for seed in range(20):
        _, info = env.reset(seed=seed, options={"targets": "hard"})
        plan = graph.plan(info["pose"], info["target"])
        assert plan.found
        np.testing.assert_allclose(plan.waypoints[0], info["pose"])
        np.testing.assert_allclose(plan.waypoints[-1], info["target"])
        assert plan.min_k >= params.safe_threshold
        assert plan.length > plan.straight  # the straight line of a hard task is not safe
        for a, b in zip(plan.waypoints[:-1], plan.waypoints[1:]):
            k, _ = _k_along(params, a, b)
            assert k.min() >= 0.97 * params.safe_threshold
        # the straight segment really does dip below k_safe
        k_line, _ = _k_along(params, plan.waypoints[0], plan.waypoints[-1], 400)
        assert k_line.min() < params.safe_threshold


def test_a_certified_straight_line_is_the_plan(env, graph):
    """Two nearby safe poses joined by a safe segment: the plan is that segment."""
    _, info = env.reset(seed=3)
    start = info["pose"]
    target = start + np.array([0.02, 0.0, 0.0])
    plan = graph.plan(start, target)
    assert plan.found and len(plan.waypoints) == 2
    assert plan.length == pytest.approx(plan.straight)


def test_planner_reaches_hard_targets_without_singularities(env):
    """On five hard episodes (where resolved-rate meets singularities) the planner always succeeds, safely."""
    agent = load_controller("planner", env)
    records = evaluate_agent(agent, env, 5, 0, "hard")
    metrics = aggregate(records)
    assert metrics["success_rate"] == 1.0, [r.row() for r in records]
    assert metrics["singularity_terminations"] == 0
    assert metrics["planner"]["path_found_rate"] == 1.0
    assert metrics["planner"]["planned_length_ratio"]["mean"] > 1.0
    assert all(r.row()["path_found"] == 1.0 for r in records)  # per-episode planner fields reach episodes.csv
    assert len(agent.log) == 5  # one plan per episode, not one per step
    # the report's table of plans is made from these metrics
    from experiments.family_report import planner_table

    table = planner_table({"planner @ hard": [metrics]})
    assert "| planner @ hard | 5 | 100 % |" in table
    assert planner_table({"ppo @ hard": [{k: v for k, v in metrics.items() if k != "planner"}]}) == ""


@pytest.mark.parametrize("seed", [5020, 5045, 5083, 5092])
def test_damped_planner_crosses_the_3rrr_band_where_full_speed_meets_it(seed):
    """The damped planner controller reaches the 3-RRR's hard targets where the full-speed law meets the band.

    On the 3-RRR, a step at full speed next to its thin band leaves the certified line by millimetres where k
    falls below k_hard; slowing down as k falls (``damping``) reaches those ill-conditioned targets.

    The undamped first-order law (``exact_step=False``) is run too, on the same episode, so that the test fails if
    these stop being episodes that need the damping (then they test nothing); the undamped exact (secant) step,
    which does not drift off the line, reaches them too.
    """
    import gymnasium as gym

    from robot_control.controllers import PlannerController

    env = gym.make("Planar3RRRReachHard-v0")
    params = env.unwrapped.params
    damped = evaluate_agent(PlannerController(params), env, 1, seed)[0]
    first_order = evaluate_agent(PlannerController(params, damping=False, exact_step=False), env, 1, seed)[0]
    exact = evaluate_agent(PlannerController(params, damping=False), env, 1, seed)[0]
    assert damped.success and not damped.singularity_termination
    assert first_order.singularity_termination
    assert exact.success and not exact.singularity_termination


def test_the_exact_step_lands_where_the_controller_aims():
    """At full crank rate the 3-RRR's platform moves along the commanded twist with ``exact_step`` only.

    The first-order step J_i ẋ turns the platform several times the commanded angle in one period (the second-order
    term of the forward kinematics; hard episode 1032's start), which drifts it off a certified path.
    """
    import gymnasium as gym

    from robot_control.controllers import PlannerController, decode_observation, pose_error

    env = gym.make("Planar3RRRReachHard-v0")
    params = env.unwrapped.params
    turns = {}
    for exact in (True, False):
        controller = PlannerController(params, damping=False, exact_step=exact)
        obs, info = env.reset(seed=1032, options={"targets": "hard"})
        pose, error, velocity = decode_observation(params, obs[None])
        action = controller.act(pose, error, velocity)[0]
        assert np.max(np.abs(action)) > 0.9  # a step at (nearly) full rate
        aim = controller.desired_velocity(pose, error, velocity)[0]
        _, _, _, _, info = env.step(action)
        moved = pose_error(params, pose, info["pose"][None])[0]
        turns[exact] = (moved[2] / np.linalg.norm(moved[:2])) / (aim[2] / np.linalg.norm(aim[:2]))
    assert turns[True] == pytest.approx(1.0, abs=0.02)
    assert turns[False] > 2.0


@pytest.mark.parametrize(("threshold", "kind"), [(None, "scale"), (0.2, "scale"), (None, "cap"), (0.2, "cap")])
def test_the_damping_slows_the_undamped_action_by_k_over_its_threshold_squared(threshold, kind):
    """Damped action: f · a ("scale") or a · min(1, f / max |a_i|) ("cap"), a the undamped action.

    f = clip((k / k_d)², 0.05, 1), k the state's and k_d the threshold or k_safe.

    k is taken from the env's info (not from the observation the controller reads); both controllers see the same
    observations of one hard 3-RRR episode driven by the undamped one, so they plan the same path.
    """
    import gymnasium as gym

    from robot_control.controllers import PlannerController

    env = gym.make("Planar3RRRReachHard-v0")
    params = env.unwrapped.params
    damped = PlannerController(params, damping_threshold=threshold, damping_kind=kind)
    undamped = PlannerController(params, damping=False)
    k_d = params.safe_threshold if threshold is None else threshold
    obs, info = env.reset(seed=5045)
    factors = []
    for _ in range(40):
        full = undamped(obs[None])[0]
        factor = np.clip((info["inverse_condition_number"] / k_d) ** 2, 0.05, 1.0)
        if kind == "cap":
            factor = min(1.0, factor / np.max(np.abs(full)))
        np.testing.assert_allclose(damped(obs[None])[0], full * factor, rtol=1e-5, atol=1e-7)
        factors.append(factor)
        obs, _, terminated, truncated, info = env.step(full)
        if terminated or truncated:
            break
    assert min(factors) < 0.9  # the episode comes near the band: the damping acted
    with pytest.raises(ValueError, match=r"damping_threshold must be in \(0, 1\], got 0.0"):
        PlannerController(params, damping_threshold=0.0)
    with pytest.raises(ValueError, match="damping_kind must be 'scale' or 'cap', got 'clip'"):
        PlannerController(params, damping_kind="clip")


def test_replan_distance_makes_the_planner_controller_plan_again_off_its_path(tmp_path, capsys):
    """With ``--replan-distance`` the controller plans afresh during an episode; without, once per episode.

    The hard episode of reset seed 5000 is followed to its end both ways; the oracle is the follower's own log of
    plans. The option is refused for the other controllers, naming both.
    """
    import gymnasium as gym

    from training.evaluate import main

    plans = {}
    for distance in (None, 1e-4):
        env = gym.make("Planar3RPRReachHard-v0")
        controller = load_controller("planner", env, replan_distance=distance)
        assert controller.follower.replan_distance == distance
        evaluate_agent(controller, env, 1, 5000, "hard")
        plans[distance] = len(controller.log)
    assert plans[None] == 1 and plans[1e-4] > 10
    argv = ["--env", "Planar3RPRReachHard-v0", "--episodes", "1", "--seed", "5000", "--replan-distance", "0.01"]
    assert main(["--controller", "planner", *argv, "--out", str(tmp_path)]) == 0
    assert "replanning 0.01 m off its path" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["--controller", "resolved-rate", *argv, "--out", str(tmp_path)])
    assert "--replan-distance applies to --controller planner, not 'resolved-rate'" in capsys.readouterr().err
