"""Type II singularities of the planar 3-RPR: constructed singular poses and regular ones."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics import Planar3RPR, SingularConfigurationError
from tests.kinematics.helpers import GEOMETRY_SEEDS, geometry, regular_configurations

POSE = np.array([0.4, 0.3, 0.35])


def concurrent_legs_robot(common_point: np.ndarray, t: np.ndarray) -> Planar3RPR:
    """A robot whose three leg lines meet at ``common_point`` when the platform is at ``POSE``.

    Base anchor i lies on the line through the world platform point A_i and C: B_i = A_i + t_i (A_i − C).
    """
    A = Planar3RPR().platform_points_in_base(POSE)
    return Planar3RPR(base=A + t[:, None] * (A - common_point), platform=Planar3RPR().platform)


def parallel_legs_robot(direction: np.ndarray, t: np.ndarray) -> Planar3RPR:
    """A robot whose three legs are parallel to ``direction`` at ``POSE``: B_i = A_i + t_i u."""
    A = Planar3RPR().platform_points_in_base(POSE)
    u = direction / np.linalg.norm(direction)
    return Planar3RPR(base=A + t[:, None] * u, platform=Planar3RPR().platform)


SINGULAR_ROBOTS = {
    "concurrent-inside": lambda: concurrent_legs_robot(np.array([0.42, 0.28]), np.array([2.0, 3.0, 2.5])),
    "concurrent-outside": lambda: concurrent_legs_robot(np.array([1.5, -0.7]), np.array([0.8, 1.7, 0.6])),
    "parallel": lambda: parallel_legs_robot(np.array([1.0, 2.0]), np.array([0.5, 0.9, 1.3])),
    "parallel-negative": lambda: parallel_legs_robot(np.array([-1.0, 3.0]), np.array([-0.5, -1.4, -0.8])),
}


@pytest.fixture(params=sorted(SINGULAR_ROBOTS))
def singular_robot(request: pytest.FixtureRequest) -> Planar3RPR:
    """A robot built so that ``POSE`` is a Type II singularity."""
    return SINGULAR_ROBOTS[request.param]()


def test_constructed_bases_are_valid_triangles(singular_robot):
    """The constructed base anchors are far from collinear (the robots are genuine)."""
    (ax, ay), (bx, by) = singular_robot.base[1:] - singular_robot.base[0]
    twice_area = abs(ax * by - ay * bx)
    assert twice_area > 0.05


def test_leg_lines_are_concurrent_or_parallel(singular_robot):
    """The legs at POSE are concurrent (three lines through one point) or all parallel."""
    d = singular_robot.leg_vectors(POSE)
    A = singular_robot.platform_points_in_base(POSE)
    normal = np.stack([-d[:, 1], d[:, 0]], axis=-1) / np.linalg.norm(d, axis=-1, keepdims=True)
    lines = np.column_stack([normal, -np.sum(normal * A, axis=-1)])  # n·X − n·A_i = 0, homogeneous
    assert abs(np.linalg.det(lines)) < 1e-12


def test_singular_pose_has_a_platform_motion_with_locked_actuators(singular_robot):
    """J_x has a null vector: the rotation about the common point, or a translation across the legs."""
    q = singular_robot.inverse_kinematics(POSE)
    _, J_x = singular_robot.jacobians(q, POSE)
    _, _, Vt = np.linalg.svd(J_x * singular_robot.pose_scale)
    null = Vt[-1] * singular_robot.pose_scale  # back to (ẋ, ẏ, φ̇)
    assert np.linalg.norm(J_x @ null) <= 1e-12 * np.linalg.norm(J_x) * np.linalg.norm(null)


def test_type2_singularity_measures(singular_robot):
    """Inverse condition number ≈ 0, mobility 1, instantaneous DOF 3, raw condition number huge."""
    q = singular_robot.inverse_kinematics(POSE)
    assert singular_robot.inverse_condition_number(q, POSE) < 1e-9
    assert singular_robot.platform_mobility(q, POSE) == 1
    assert singular_robot.instantaneous_dof(q, POSE) == 3
    assert singular_robot.raw_condition_number(q, POSE) > 1e12


def test_forward_jacobian_raises_at_type2_singularity(singular_robot):
    """forward_jacobian refuses to invert a singular J_x."""
    q = singular_robot.inverse_kinematics(POSE)
    with pytest.raises(SingularConfigurationError, match=r"Type II singularity.*singular_tolerance"):
        singular_robot.forward_jacobian(q, POSE)


def test_actuator_forces_raise_at_type2_singularity(singular_robot):
    """actuator_forces refuses: some wrenches cannot be balanced by finite forces."""
    q = singular_robot.inverse_kinematics(POSE)
    with pytest.raises(SingularConfigurationError, match=r"Type II singularity.*actuator forces"):
        singular_robot.actuator_forces(q, POSE, [1.0, 0.0, 0.0])


def test_singularity_error_is_a_value_error_and_names_the_batch_index(singular_robot):
    """SingularConfigurationError is a ValueError; in a batch it names the first singular index."""
    q = singular_robot.inverse_kinematics(POSE)
    X = np.stack([POSE + np.array([0.01, 0.0, 0.0]), POSE, POSE])
    Q = np.stack([q, q, q])
    with pytest.raises(ValueError, match=r"at batch index \(1,\)"):
        singular_robot.forward_jacobian(Q, X)


def test_singular_pose_is_fine_where_no_inverse_of_J_x_is_needed(singular_robot):
    """The inverse Jacobian, wrench and constraints stay defined at a Type II singularity."""
    q = singular_robot.inverse_kinematics(POSE)
    assert np.max(np.abs(singular_robot.constraints(q, POSE))) < 1e-14
    assert np.all(np.isfinite(singular_robot.inverse_jacobian(q, POSE)))
    assert np.all(np.isfinite(singular_robot.platform_wrench(q, POSE, [1.0, 2.0, 3.0])))


@pytest.mark.parametrize("seed", GEOMETRY_SEEDS)
def test_regular_poses(seed, rng):
    """Regular poses: mobility 0, DOF 3, inverse condition in (0, 1], raw condition finite ≥ 1."""
    robot = geometry(seed)
    Q, X = regular_configurations(robot, rng, 500, min_inverse_condition=1e-3)
    icn = robot.inverse_condition_number(Q, X)
    assert np.all((icn > 0) & (icn <= 1))
    assert np.all(robot.platform_mobility(Q, X) == 0)
    assert np.all(robot.instantaneous_dof(Q, X) == 3)
    raw = robot.raw_condition_number(Q, X)
    assert np.all(np.isfinite(raw) & (raw >= 1))
    assert np.all(np.isfinite(robot.forward_jacobian(Q, X)))


def test_inverse_condition_number_tends_to_zero_towards_the_singularity():
    """Approaching a constructed singular pose along a path, the measure decreases towards 0."""
    robot = SINGULAR_ROBOTS["concurrent-inside"]()
    offsets = np.array([1e-1, 1e-2, 1e-3, 1e-4, 0.0])
    X = POSE + offsets[:, None] * np.array([0.0, 0.0, 1.0])
    icn = robot.inverse_condition_number(robot.inverse_kinematics(X), X)
    assert np.all(np.diff(icn) < 0)
    assert icn[-1] < 1e-9 < icn[-2]


@pytest.mark.parametrize("unit", [1e-3, 1e-2, 1e2, 1e3, 1e4, 1e6])
def test_singularity_measures_do_not_depend_on_the_unit_of_length(unit):
    """Scaling every length (m → mm, km, …) leaves the homogenised measures and decisions unchanged.

    J_x is made dimensionless by dividing its rotation column by ℓ_c (as J_h is), so a regular pose
    stays regular and a singular pose stays singular in any unit.
    """
    robot = Planar3RPR()
    scaled = Planar3RPR(robot.base * unit, robot.platform * unit)
    x = np.array([0.5, 0.3, 0.1])
    q = robot.inverse_kinematics(x)
    x_scaled, q_scaled = x * [unit, unit, 1.0], q * unit
    assert scaled.inverse_condition_number(q_scaled, x_scaled) == pytest.approx(
        robot.inverse_condition_number(q, x), rel=1e-12
    )
    assert scaled.platform_mobility(q_scaled, x_scaled) == 0
    assert scaled.instantaneous_dof(q_scaled, x_scaled) == 3
    J_f = scaled.forward_jacobian(q_scaled, x_scaled)  # must not raise at a well-conditioned pose
    np.testing.assert_allclose(J_f * [[1.0], [1.0], [unit]], robot.forward_jacobian(q, x), rtol=1e-9)

    singular = SINGULAR_ROBOTS["concurrent-outside"]()
    singular_scaled = Planar3RPR(singular.base * unit, singular.platform * unit)
    pose = POSE * [unit, unit, 1.0]
    q_singular = singular_scaled.inverse_kinematics(pose)
    assert singular_scaled.platform_mobility(q_singular, pose) == 1
    with pytest.raises(SingularConfigurationError):
        singular_scaled.forward_jacobian(q_singular, pose)
