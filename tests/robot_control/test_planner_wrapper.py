"""Mixed targets and the planner's waypoint in the observation (``robot_control.PlannerWaypointWrapper``)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import robot_control
from envs.kernels.packing import observation_layout

ERROR = observation_layout("planar", 3, False)["error"]


def segment_min_condition(params, start: np.ndarray, target: np.ndarray, n: int) -> float:
    """Smallest inverse condition number at n points of the straight line start → target (x, y, φ), ends included."""
    points = start + np.linspace(0.0, 1.0, n)[:, None] * (target - start)
    robot = params.robot
    q = robot.inverse_kinematics(points, validate=False)
    return float(np.min(robot.inverse_condition_number(np.maximum(q, 1e-9), points, validate=False)))


def test_mixed_targets_draw_both_kinds():
    """Planar3RPRReachMixed-v0 draws standard and hard tasks; the hard ones' straight line dips below k_hard."""
    env = gym.make("Planar3RPRReachMixed-v0")
    params = env.unwrapped.params
    dips = []
    for seed in range(60):
        _, info = env.reset(seed=seed)
        k = segment_min_condition(params, info["pose"], info["target"], 400)
        dips.append(k < params.hard_threshold)
    share = np.mean(dips)
    assert 0.3 < share < 0.7, share  # hard with probability 1/2 (standard pairs almost never dip that low)
    # the kind is drawn from the episode's own generator: same seed, same task
    a = env.reset(seed=5)[1]["target"]
    b = env.reset(seed=5)[1]["target"]
    np.testing.assert_array_equal(a, b)


def test_standard_and_hard_tasks_are_unchanged_by_the_mixed_mode():
    """The targets="standard"/"hard" draws are those of before (held-out episodes keep their tasks)."""
    reach, hard = gym.make("Planar3RPRReach-v0"), gym.make("Planar3RPRReachHard-v0")
    mixed = gym.make("Planar3RPRReachMixed-v0")
    for seed in range(5):
        for env, option in ((reach, "standard"), (hard, "hard")):
            own = env.reset(seed=seed)[1]
            via = mixed.reset(seed=seed, options={"targets": option})[1]
            np.testing.assert_array_equal(own["pose"], via["pose"])
            np.testing.assert_array_equal(own["target"], via["target"])


def test_waypoint_wrapper_passes_the_checker_and_extends_the_observation():
    """Gymnasium's checker is silent; three entries more, inside the space; the carrot offset is what it says."""
    env = robot_control.PlannerWaypointWrapper(gym.make("Planar3RPRReachMixed-v0").unwrapped)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*is different from the unwrapped")  # it is a wrapper
        check_env(env, skip_render_check=True)
    base = gym.make("Planar3RPRReach-v0").observation_space
    assert env.observation_space.shape == (base.shape[0] + 3,)
    rng = np.random.default_rng(0)
    for seed in range(6):
        obs, info = env.reset(seed=seed, options={"targets": "hard" if seed % 2 else "standard"})
        plan = env.follower.log[-1]
        assert plan.found
        for _ in range(30):
            assert env.observation_space.contains(obs)
            offset = obs[-3:]
            if len(plan.waypoints) == 2:  # a safe straight line: the waypoint is the target itself
                np.testing.assert_allclose(offset, obs[ERROR], atol=1e-6)
            else:  # a detour: the carrot lies on the path, at most the lookahead beyond the closest point
                carrot = info["pose"] + offset
                gap = np.min(np.linalg.norm((plan.waypoints - carrot) * env.unwrapped.params.pose_metric, axis=-1))
                assert gap < 0.5
            obs, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 3).astype(np.float32))
            if terminated or truncated:
                break


def test_waypoint_on_a_detour_points_along_the_path_not_at_the_target():
    """At the start of a hard task the offset is the lookahead along the certified path, not the target error."""
    env = robot_control.PlannerWaypointWrapper(gym.make("Planar3RPRReachHard-v0"))
    found = 0
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        plan = env.follower.log[-1]
        if len(plan.waypoints) > 2:
            metric = env.unwrapped.params.pose_metric
            # the carrot is the lookahead along the path: its chord is at most that, and not much less
            assert 0.5 * env.follower.lookahead < np.linalg.norm(obs[-3:] * metric) <= env.follower.lookahead + 1e-6
            assert not np.allclose(obs[-3:], obs[ERROR], atol=1e-3)
            found += 1
    assert found >= 5


def test_waypoint_wrapper_is_deterministic_and_refuses_other_envs():
    """The same seed gives the same observations; a foreign env, the grid off-grid or a bad lookahead is refused."""
    a, b = (robot_control.PlannerWaypointWrapper(gym.make("Planar3RPRReachHard-v0")) for _ in range(2))
    np.testing.assert_array_equal(a.reset(seed=3)[0], b.reset(seed=3)[0])
    for _ in range(5):
        action = np.full(3, 0.3, dtype=np.float32)
        np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])
    with pytest.raises(TypeError, match="wraps the Reach environments of envs, got CartPoleEnv"):
        robot_control.PlannerWaypointWrapper(gym.make("CartPole-v1"))
    with pytest.raises(
        ValueError, match="the planner needs a planar robot with task_region='grid', got spatial with task_region='box'"
    ):
        robot_control.PlannerWaypointWrapper(gym.make("StewartGoughReach-v0"), planner="grid")
    with pytest.raises(ValueError, match="lookahead must be a positive distance"):
        robot_control.PlannerWaypointWrapper(gym.make("Planar3RPRReach-v0"), lookahead=0.0)


@pytest.mark.parametrize("env_id", ["StewartGoughReachHard-v0", "DeltaReach-v0"])
def test_the_planner_wrappers_work_in_every_pose_space(env_id):
    """The hexapod (spatial) and the Delta (translational): the observation gains m (+ n) entries, checker-clean.

    The waypoint offset of a straight plan is the observation's own error block (the carrot is the target).
    """
    from gymnasium.utils.env_checker import check_env

    base = gym.make(env_id)
    m, n = base.unwrapped.params.robot.n_pose, base.action_space.shape[0]
    waypoint = robot_control.PlannerWaypointWrapper(gym.make(env_id))
    residual = robot_control.PlannerResidualWrapper(gym.make(env_id))
    obs, _ = waypoint.reset(seed=0)
    assert obs.shape == (base.observation_space.shape[0] + m,)
    assert residual.reset(seed=0)[0].shape == (base.observation_space.shape[0] + m + n,)
    plain, _ = base.reset(seed=0)
    error = observation_layout(base.unwrapped.params.robot.pose_space.name, n, False)["error"]
    np.testing.assert_allclose(obs[-m:], plain[error], atol=1e-5)
    with warnings.catch_warnings():  # any checker warning fails, but its note that a wrapper is not the raw env
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=r".*is different from the unwrapped version")
        check_env(waypoint, skip_render_check=True)
        check_env(residual, skip_render_check=True)
