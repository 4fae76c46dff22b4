"""Time-optimal references under drive limits (``TimeOptimalPath``, TOPP-RA) and the Delta's adept cycle.

Oracles: finite differences of the reference, the inverse dynamics of ``RobotDynamics`` evaluated along it, the
shortest minimum-jerk move within the same limits (found by bisection: a time-optimal move is never slower), and
the NumPy plant ``RobotDynamics.step`` driven by computed torque along it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from kinematics import Delta, StewartGough
from kinematics.dynamics import RobotDynamics, default_inertia
from robot_control.computed_torque import ComputedTorqueController, MinimumJerkPath, TimeOptimalPath

pytest.importorskip("toppra")


def _delta():
    robot = Delta()
    dynamics = RobotDynamics(robot, default_inertia(robot))
    home = robot.home_pose()
    points = np.stack([home - [0.15, 0.0, 0.0], home - [0.15, 0.0, -0.025], home + [0.15, 0.0, 0.025]])
    return robot, dynamics, points, np.array([12.0, 13.0, 13.0])


def _efforts(robot, dynamics, ref):
    q = robot.inverse_kinematics(ref.x)
    wrench = dynamics.mass_matrix(q, ref.x) @ ref.xddot + dynamics.bias_forces(q, ref.x, ref.xdot)
    return robot.actuator_forces(q, ref.x, wrench)


def test_the_reference_is_consistent_and_within_the_limits():
    """x(t), ẋ(t), ẍ(t) agree by finite differences; rest at every waypoint; |τ| ≤ τ_max; a drive at its limit."""
    robot, dynamics, points, limits = _delta()
    path = TimeOptimalPath(dynamics, points, limits, grid=60)
    for k, when in enumerate(path.times):
        ref = path(float(when))
        np.testing.assert_allclose(ref.x, points[k], atol=1e-12)
        assert np.linalg.norm(ref.xdot) < 1e-9
    np.testing.assert_allclose(path(0.0).xddot, path(1e-9).xddot, rtol=1e-6)  # it starts accelerating at t = 0
    assert np.linalg.norm(path(0.0).xddot) > 1.0
    h = 1e-6
    ts = np.linspace(0.003, path.duration - 0.003, 97)
    ts = ts[np.min(np.abs(ts[:, None] - path.times[None, :]), axis=1) > 2 * h]
    for t in ts:
        before, now, after = path(t - h), path(t), path(t + h)
        np.testing.assert_allclose((after.x - before.x) / (2 * h), now.xdot, atol=1e-6)
    efforts = np.array([_efforts(robot, dynamics, path(t)) for t in ts]) / limits
    assert np.abs(efforts).max() <= 1.0 + 1e-4  # exact at the grid points, within 1e-5 between them
    assert np.mean(np.abs(efforts).max(axis=1) > 0.97) > 0.8  # time-optimal: some drive at its limit almost always


def test_no_minimum_jerk_move_within_the_limits_is_faster():
    """The shortest minimum-jerk move whose efforts stay within the limits (bisection) is slower than TOPP-RA's."""
    robot, dynamics, points, limits = _delta()
    start, end = points[1], points[2]
    optimal = TimeOptimalPath(dynamics, np.stack([start, end]), limits, grid=60).duration

    def within(duration):
        path = MinimumJerkPath.point_to_point(robot, start, end, duration)
        return all(np.all(np.abs(_efforts(robot, dynamics, path(t))) <= limits) for t in np.linspace(0, duration, 80))

    low, high = 0.01, 2.0
    for _ in range(25):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if within(mid) else (mid, high)
    assert optimal < high
    assert optimal > 0.5 * high  # and not absurdly faster: a rest-to-rest move needs the same reach


def test_computed_torque_follows_it_within_a_millimetre():
    """On the NumPy plant at 2 ms with 90 % of the limits: the platform ends within 0.5 mm; efforts within limits."""
    robot, dynamics, points, limits = _delta()
    path = TimeOptimalPath(dynamics, points, 0.9 * limits, grid=60)
    controller = ComputedTorqueController.critically_damped(robot, dynamics.inertia, bandwidth=40.0,
                                                            force_limits=limits)  # fmt: skip
    x, xdot, dt = points[0].copy(), np.zeros(3), 0.002
    for i in range(int(np.ceil(path.duration / dt))):
        command = controller.compute(robot.inverse_kinematics(x), x, xdot, *path(i * dt))
        _, x, xdot = dynamics.step(x, xdot, command.tau, dt, substeps=2)
    assert np.linalg.norm(x - points[-1]) < 5e-4


def test_the_hexapod_rotates_on_its_geodesic():
    """Spatial poses: the reference's twist is the finite difference of its poses (``pose_difference``)."""
    robot = StewartGough()
    dynamics = RobotDynamics(robot, default_inertia(robot))
    home = robot.home_pose()
    end = robot.retract(home, np.array([0.03, -0.02, 0.04, 0.1, -0.05, 0.2]))
    path = TimeOptimalPath(dynamics, np.stack([home, end]), 3000.0, grid=40)
    h = 1e-6
    for t in np.linspace(0.1, 0.9, 5) * path.duration:
        step = robot.pose_difference(path(t + h).x, path(t - h).x)
        np.testing.assert_allclose(step / (2 * h), path(t).xdot, atol=1e-5)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"waypoints": np.zeros((1, 3))}, "K ≥ 1"),
        ({"force_limits": -1.0}, "force_limits"),
        ({"grid": 3}, "grid"),
        ({"waypoints": "repeat"}, "differ"),
        ({"force_limits": 0.5}, "no motion"),  # cannot even hold the platform against gravity
    ],
)
def test_bad_arguments_are_refused(kwargs, match):
    """Misshapen or repeated waypoints, limits not > 0, a coarse grid, limits below the holding forces."""
    _, dynamics, points, limits = _delta()
    args = {"waypoints": points, "force_limits": limits, "grid": 20, **kwargs}
    if isinstance(args["waypoints"], str):
        args["waypoints"] = np.stack([points[0], points[0], points[1]])
    with pytest.raises(ValueError, match=match):
        TimeOptimalPath(dynamics, args["waypoints"], args["force_limits"], grid=args["grid"])


def test_the_adept_cycle_experiment_writes_its_table(tmp_path, monkeypatch):
    """``experiments.pick_and_place`` through the compiled force-control env: table, results and GIF.

    And a policy's table per ``--policy`` run, named by how it was trained (here a tiny ``training.distill`` run).
    """
    from experiments import pick_and_place
    from training.distill import DistillConfig, distill

    run = tmp_path / "run"
    config = DistillConfig(
        env_id="DeltaForceTrack-v0", env_kwargs={"dt": 0.01}, expert="computed-torque", expert_episodes=1,
        iterations=0, epochs=1,
    )  # fmt: skip
    distill(config, run, log=lambda _: None)
    out = tmp_path / "out"
    argv = ["--out", str(out), "--margins", "0.8", "--dt", "0.004", "--grid", "30", "--policy", str(run)]
    counted = []
    monkeypatch.setattr(pick_and_place, "_counts", lambda row: counted.append(row["period_s"]) or True)
    assert pick_and_place.main([*argv, "--periods", "1.0", "--episodes", "1", "--cycles", "1"]) == 0
    results = json.loads((out / "results.json").read_text())
    rows = results["rows"]
    assert len(rows) == 1 and rows[0]["termination"] is None and rows[0]["max_residual"] < 1e-10
    assert rows[0]["place_error_mm"] < 1.0 and rows[0]["pick_error_mm"] < 1.0
    table = (out / "table.md").read_text()
    assert "| 0.80 |" in table
    assert (out / "cycle.gif").stat().st_size > 0
    assert results["policies"] == [str(run)] and len(results["policy"]) == 1 and len(results["policy"][0]) == 1
    assert "A policy distilled from computed torque (`training.distill`) of `DeltaForceTrack-v0` (`run`" in table
    assert "| 1.00 |" in table
    # the shortest period the policy makes (every one here) is drawn: one cycle at 1.0 s, a frame every 20 ms
    assert counted and "![the policy's cycle](policy_cycle.gif)" in table
    with Image.open(out / "policy_cycle.gif") as gif:
        assert gif.n_frames == 50


def test_a_track_policy_is_scored_when_the_reference_reaches_the_place_and_pick_points():
    """``policy_cycles`` reads the errors at half and whole periods, where the reference is at the place point.

    There it is 305 mm across, level with the pick point, and back at the pick point; a hold-still agent's
    errors are those distances.
    """
    import gymnasium as gym

    from experiments.pick_and_place import TRACK_ID, policy_cycles

    env = gym.make(TRACK_ID, dt=0.01, track_period=1.0)
    _, info = env.reset(seed=0)
    pick = np.asarray(info["target"]).copy()
    targets = []
    for _ in range(100):
        _, _, _, _, info = env.step(np.zeros(3, np.float32))
        targets.append(np.asarray(info["target"]).copy())
    np.testing.assert_allclose(np.linalg.norm((targets[49] - pick)[:2]), 0.305, atol=1e-9)
    np.testing.assert_allclose(targets[49][2], pick[2], atol=1e-9)
    np.testing.assert_allclose(targets[99], pick, atol=1e-9)

    def hold(obs):
        return np.zeros((len(obs), 3), np.float32)

    row = policy_cycles(hold, {"dt": 0.01}, 1.0, episodes=1, cycles=2)
    assert row["ended"] == 0
    assert row["place_error_mm"]["median"] == pytest.approx(305.0, abs=0.5)
    assert row["pick_error_mm"]["max"] < 0.5
    with pytest.raises(ValueError, match="whole number of control periods"):
        policy_cycles(hold, {"dt": 0.01}, 1.005, episodes=1, cycles=1)
