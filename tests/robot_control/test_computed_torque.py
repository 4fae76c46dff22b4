"""Computed-torque control against the NumPy plant ``RobotDynamics.step``, and minimum-jerk references on the manifold.

The plant integrates M ẍ + c + G = J_iᵀ τ with τ held over each control period; the statics are checked against the
virtual work of the potential energy, computed from the bodies' positions (no Jacobian).
"""

from __future__ import annotations

import numpy as np
import pytest

from kinematics import Delta, Planar3PRR, Planar3RPR, Planar3RRR, StewartGough
from kinematics.dynamics import STANDARD_GRAVITY, RobotDynamics, default_inertia
from robot_control.computed_torque import ComputedTorqueController, MinimumJerkPath, minimum_jerk

#: Each robot with a twist step from its home pose to the target (translations [m], rotations [rad]).
ROBOTS = {
    "3-RPR": (Planar3RPR, [0.08, -0.05, 0.3]),
    "hexapod": (StewartGough, [0.04, -0.03, 0.05, 0.08, -0.06, 0.15]),
    "Delta": (Delta, [0.08, -0.06, -0.1]),
    "3-RRR": (Planar3RRR, [0.01, -0.01, 0.05]),
    "3-PRR": (Planar3PRR, [0.01, 0.01, -0.05]),
}

#: Closed-loop bandwidth ω [rad/s] (K_p = ω², K_d = 2ω), move time and rest after it [s].
BANDWIDTH, MOVE, SETTLE = 30.0, 0.6, 0.2


def setup(name: str):
    """The robot, its default inertia (planar robots stood up: gravity −y) and the move's end poses."""
    robot_class, step = ROBOTS[name]
    robot = robot_class()
    inertia = default_inertia(robot)
    if robot.pose_space.name == "planar":
        inertia = inertia.replace(gravity=(0.0, -STANDARD_GRAVITY))
    start = robot.home_pose()
    return robot, inertia, start, robot.retract(start, np.array(step))


def scaled(inertia, factor: float):
    """Every mass and inertia of ``inertia`` times ``factor`` (the geometry of the bodies kept)."""
    names = ("platform_mass", "platform_inertia", "actuator_mass", "actuator_inertia", "distal_mass", "distal_inertia")
    return inertia.replace(**{name: factor * getattr(inertia, name) for name in names})


def simulate(robot, plant_inertia, controller, path, duration: float, dt: float):
    """Run the loop from rest at the path's start; per step: pose error, command. Returns (errors, commands, x)."""
    plant = RobotDynamics(robot, plant_inertia)
    x = path(0.0).x
    q, xdot = robot.inverse_kinematics(x), np.zeros_like(x)
    errors, commands = [], []
    for i in range(round(duration / dt)):
        command = controller.compute(q, x, xdot, *path(i * dt))
        errors.append(command.pose_error)
        commands.append(command)
        q, x, xdot = plant.step(x, xdot, command.tau, dt)
    return np.array(errors), commands, x


def split(robot, error):
    """(translation norm [m], rotation norm [deg]) of twist steps, shape (..., m) → two arrays of shape (...)."""
    rotations = list(robot.pose_space.rotation_columns)
    translations = [i for i in range(robot.n_pose) if i not in rotations]
    return np.linalg.norm(error[..., translations], axis=-1), np.degrees(np.linalg.norm(error[..., rotations], axis=-1))


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, fresh for each test."""
    return np.random.default_rng(41)


# -- tracking ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["3-RPR", "hexapod", "Delta"])
def test_exact_model_tracks_a_minimum_jerk_move(name):
    """With the plant's own model the error stays at the sampling error (τ held over dt): O(dt), no drift."""
    robot, inertia, start, end = setup(name)
    controller = ComputedTorqueController.critically_damped(robot, inertia, bandwidth=BANDWIDTH)
    path = MinimumJerkPath.point_to_point(robot, start, end, MOVE)
    errors, commands, x = simulate(robot, inertia, controller, path, MOVE + SETTLE, dt=0.0025)
    translation, rotation = split(robot, errors)
    assert translation.max() <= 1e-4 and rotation.max() <= 0.01
    final_translation, final_rotation = split(robot, robot.pose_difference(end, x))
    assert final_translation <= 1e-4 and final_rotation <= 0.05
    assert not any(command.saturated for command in commands)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_command_imposes_the_error_dynamics(name, rng):
    """At fast random states the plant's ẍ under the unclipped τ is ẍ_d + K_d (ẋ_d − ẋ) + K_p (x_d ⊖ x).

    Speeds of about 1 m/s and 2 rad/s make the velocity-product terms c(x, ẋ) count.
    """
    robot, inertia, start, end = setup(name)
    x = robot.retract(start, 0.2 * np.array(ROBOTS[name][1]) * rng.uniform(-1.0, 1.0, (3, robot.n_pose)))
    q = robot.inverse_kinematics(x)
    xdot = rng.uniform(-1.0, 1.0, x.shape) * np.where(robot.pose_scale < 1.0, 2.0, 1.0)
    reference = MinimumJerkPath.point_to_point(robot, start, end, 0.5)(0.2)
    kp, kd = rng.uniform(50.0, 500.0, robot.n_pose), rng.uniform(5.0, 50.0, robot.n_pose)
    command = ComputedTorqueController(robot, inertia, kp=kp, kd=kd).compute(q, x, xdot, *reference)
    acceleration = RobotDynamics(robot, inertia).forward_dynamics(q, x, xdot, command.tau)
    wanted = reference.xddot + kd * (reference.xdot - xdot) + kp * robot.pose_difference(reference.x, x)
    np.testing.assert_allclose(acceleration, wanted, rtol=1e-9, atol=1e-9 * np.abs(wanted).max())


@pytest.mark.parametrize(("name", "factor"), [("3-RPR", 1.15), ("hexapod", 0.85), ("Delta", 0.8)])
def test_mass_error_leaves_the_gravity_offset_of_a_pd(name, factor):
    """With every mass × ``factor`` in the model the robot settles at the sag (1/factor − 1) g / K_p of a PD.

    The model's weight is off by (factor − 1) G and its K_p by the factor, so at rest factor · M K_p e = (1 −
    factor) G, e = (1/factor − 1) M⁻¹ G / K_p: about |1/factor − 1| g / ω² (2.7 mm at −20 %, ω = 30 rad/s), up to
    some 15 % more where leg bodies that pivot as the platform moves make M⁻¹ G differ from g (measured: final
    offset 1.0–1.16 × that sag, largest error along the move 1.1–1.2 ×).
    """
    robot, inertia, start, end = setup(name)
    controller = ComputedTorqueController.critically_damped(robot, scaled(inertia, factor), bandwidth=BANDWIDTH)
    path = MinimumJerkPath.point_to_point(robot, start, end, MOVE)
    errors, _, x = simulate(robot, inertia, controller, path, MOVE + 0.4, dt=0.005)
    sag = abs(1.0 / factor - 1.0) * STANDARD_GRAVITY / BANDWIDTH**2
    final_translation, final_rotation = split(robot, robot.pose_difference(end, x))
    assert 0.8 * sag <= final_translation <= 1.3 * sag
    assert final_rotation <= 0.02
    assert split(robot, errors)[0].max() <= 1.4 * sag


def test_force_limits_clip_and_flag():
    """Limits under the move's peak effort: |τ| never exceeds them, the flag marks exactly the clipped steps."""
    robot, inertia, start, end = setup("Delta")
    limit = 5.2  # N·m; holding needs 4.7 at home, the move's peak is 5.6
    controller = ComputedTorqueController.critically_damped(robot, inertia, bandwidth=BANDWIDTH, force_limits=limit)
    path = MinimumJerkPath.point_to_point(robot, start, end, MOVE)
    _, commands, x = simulate(robot, inertia, controller, path, MOVE + 0.2, dt=0.005)
    tau = np.array([c.tau for c in commands])
    tau_model = np.array([c.tau_model for c in commands])
    saturated = np.array([c.saturated for c in commands])
    assert np.abs(tau).max() <= limit and np.abs(tau_model).max() > limit
    assert saturated.any()
    np.testing.assert_array_equal(saturated, (np.abs(tau_model) > limit).any(axis=-1))
    np.testing.assert_array_equal(tau[~saturated], tau_model[~saturated])
    assert split(robot, robot.pose_difference(end, x))[0] <= 1e-4  # recovers once the limits release it


# -- statics ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(ROBOTS))
def test_at_rest_at_the_target_tau_does_the_virtual_work_of_gravity(name, rng):
    """At rest on the target τ = holding_forces, and τ·δq = δV for small displacements (V from body positions)."""
    robot, inertia, start, end = setup(name)
    targets = np.stack([start, end])
    q = robot.inverse_kinematics(targets)
    controller = ComputedTorqueController(robot, inertia, kp=100.0, kd=20.0)
    command = controller.compute(q, targets, np.zeros_like(targets), targets)
    dynamics = RobotDynamics(robot, inertia)
    np.testing.assert_allclose(command.tau, dynamics.holding_forces(q, targets), rtol=1e-12, atol=1e-12)
    assert np.abs(command.tau).max() > 1e-2
    step = 1e-5 * rng.standard_normal(targets.shape)
    plus, minus = robot.retract(targets, step), robot.retract(targets, -step)
    dq = robot.inverse_kinematics(plus) - robot.inverse_kinematics(minus)
    dq = np.where(np.array(robot.actuator_kinds) == "crank", np.angle(np.exp(1j * dq)), dq)
    work = np.sum(command.tau * dq, axis=-1)
    dV = dynamics.potential_energy(robot.inverse_kinematics(plus), plus) - dynamics.potential_energy(
        robot.inverse_kinematics(minus), minus
    )
    np.testing.assert_allclose(work, dV, rtol=0, atol=1e-6 * np.abs(command.tau * dq).sum(axis=-1).max())


def test_batch_equals_loop(rng):
    """Commands for a batch of states equal the commands of each state alone."""
    robot, inertia, start, end = setup("hexapod")
    controller = ComputedTorqueController(robot, inertia, kp=[400.0] * 3 + [900.0] * 3, kd=40.0, force_limits=60.0)
    x = robot.retract(start, 0.02 * rng.standard_normal((4, 6)))
    q, xdot = robot.inverse_kinematics(x), 0.1 * rng.standard_normal((4, 6))
    reference = MinimumJerkPath.point_to_point(robot, start, end, 0.5)(0.2)
    batch = controller.compute(q, x, xdot, *reference)
    for i in range(4):
        single = controller.compute(q[i], x[i], xdot[i], *reference)
        for got, want in zip(single, batch, strict=True):
            np.testing.assert_allclose(got, want[i], rtol=1e-12, atol=1e-12)


# -- references -----------------------------------------------------------------------------------------------


def test_minimum_jerk_profile():
    """s(0) = 0, s(1) = 1, rest at both ends, symmetric; clipped outside [0, 1]."""
    s, ds, dds = minimum_jerk(np.array([-0.5, 0.0, 0.5, 1.0, 2.0]))
    np.testing.assert_allclose(s, [0.0, 0.0, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(ds, [0.0, 0.0, 1.875, 0.0, 0.0])
    np.testing.assert_allclose(dds, 0.0, atol=1e-12)


def test_path_rates_are_the_derivatives_on_the_manifold():
    """ẋ_d and ẍ_d of a spatial path equal central differences of x_d ⊖ (twist steps) and of ẋ_d."""
    robot, _, start, end = setup("hexapod")
    path = MinimumJerkPath.point_to_point(robot, start, end, 0.5)
    h = 1e-5
    for t in (0.1, 0.27, 0.4):
        reference = path(t)
        velocity = robot.pose_difference(path(t + h).x, path(t - h).x) / (2 * h)
        np.testing.assert_allclose(reference.xdot, velocity, rtol=0, atol=1e-8)
        np.testing.assert_allclose(reference.xddot, (path(t + h).xdot - path(t - h).xdot) / (2 * h), atol=1e-6)
    for t, pose in ((-1.0, start), (0.0, start), (0.5, end), (2.0, end)):
        reference = path(t)
        np.testing.assert_allclose(robot.pose_difference(reference.x, pose), 0.0, atol=1e-12)
        np.testing.assert_allclose(reference.xdot, 0.0, atol=1e-12)


def test_path_through_a_waypoint_stops_there_and_batches():
    """Start → waypoint → target: at rest on the waypoint between the segments; a batch equals its paths."""
    robot, _, start, end = setup("3-RPR")
    waypoint = start + np.array([0.05, 0.05, -0.2])
    path = MinimumJerkPath(robot, [start, waypoint, end], [0.4, 0.6])
    assert path.duration == pytest.approx(1.0)
    for t in (0.4 - 1e-12, 0.4):
        np.testing.assert_allclose(path(t).x, waypoint, atol=1e-9)
        np.testing.assert_allclose(path(t).xdot, 0.0, atol=1e-6)
    np.testing.assert_allclose(path(0.7).x, start + (waypoint - start) + 0.5 * (end - waypoint))
    other = MinimumJerkPath(robot, [end, start, waypoint], [0.4, 0.6])
    both = MinimumJerkPath(robot, [[start, waypoint, end], [end, start, waypoint]], [0.4, 0.6])
    for t in (0.1, 0.55):
        for single, got in zip((path(t), other(t)), zip(*both(t), strict=True), strict=True):
            np.testing.assert_allclose(np.array(got), np.array(single), rtol=1e-12)


# -- validation ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"kp": -1.0}, r"kp must be > 0 and finite \[1/s²\], got -1.0"),
        ({"kd": [1.0, 2.0]}, r"kd must be a number or have shape \(3,\) \[1/s\], got shape \(2,\)"),
        ({"kp": np.nan}, r"kp must be > 0 and finite"),
        ({"kd": np.inf}, r"kd must be > 0 and finite"),
        ({"force_limits": [1.0, 0.0, 1.0]}, r"force_limits must be > 0 \[N or N·m\], got 0.0"),
    ],
)
def test_bad_gains_and_limits_are_refused(changes, match):
    """Gains and limits must be positive numbers or one per coordinate; the message names the quantity."""
    arguments = {"kp": 100.0, "kd": 20.0, "force_limits": [1.0, np.inf, 2.0]} | changes
    with pytest.raises(ValueError, match=match):
        ComputedTorqueController(Planar3RPR(), **arguments)


def test_bad_states_and_paths_are_refused():
    """Shapes, finiteness and batch broadcasting of the state, the reference and the path."""
    robot = Planar3RPR()
    x = robot.home_pose()
    q = robot.inverse_kinematics(x)
    controller = ComputedTorqueController(robot, kp=100.0, kd=20.0)
    with pytest.raises(
        ValueError, match=r"xdot must have shape \(\.\.\., 3\) holding a platform twist, got shape \(2,\)"
    ):
        controller.compute(q, x, [0.0, 0.0], x)
    with pytest.raises(ValueError, match=r"target must be finite, got nan at index \(1,\)"):
        controller.compute(q, x, np.zeros(3), [0.5, np.nan, 0.0])
    with pytest.raises(ValueError, match=r"batch shapes do not broadcast: q \(2, 3\), x \(3, 3\)"):
        controller.compute(np.stack([q, q]), np.stack([x, x, x]), np.zeros(3), x)
    with pytest.raises(ValueError, match=r"bandwidth must be a finite number > 0 \[rad/s\], got 0.0"):
        ComputedTorqueController.critically_damped(robot, bandwidth=0.0)
    with pytest.raises(
        ValueError, match=r"waypoints must have shape \(\.\.\., K \+ 1, 3\) with K ≥ 1, got shape \(1, 3\)"
    ):
        MinimumJerkPath(robot, [x], 1.0)
    with pytest.raises(ValueError, match=r"durations must be > 0 and finite \[s\], got -0.5"):
        MinimumJerkPath(robot, [x, x, x], [1.0, -0.5])
    with pytest.raises(ValueError, match=r"t must be a finite number \[s\], got nan"):
        MinimumJerkPath(robot, [x, x], 1.0)(float("nan"))
