"""The distance-constraint family: its planar member is the 3-RPR, value for value."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from kinematics import DistanceConstraintMechanism, Planar3RPR
from tests.kinematics.helpers import geometry, max_relative_error, random_poses, regular_configurations

N_CONFIGURATIONS = 500

#: The lesson's geometry (None) and two random 3-RPR geometries of fixed seeds.
PLANAR_SEEDS = [None, 101, 202]

#: Values the family member must reproduce, as (robot, q, x) → array; q and x are regular configurations.
COMPARED: dict[str, Callable[[DistanceConstraintMechanism, np.ndarray, np.ndarray], np.ndarray]] = {
    "constraints": lambda r, q, x: r.constraints(q, x),
    "J_q": lambda r, q, x: r.jacobians(q, x)[0],
    "J_x": lambda r, q, x: r.jacobians(q, x)[1],
    "forward_jacobian": lambda r, q, x: r.forward_jacobian(q, x),
    "inverse_jacobian": lambda r, q, x: r.inverse_jacobian(q, x),
    "inverse_condition_number": lambda r, q, x: np.asarray(r.inverse_condition_number(q, x)),
    "inverse_kinematics": lambda r, q, x: r.inverse_kinematics(x),
    "leg_vectors": lambda r, q, x: r.leg_vectors(x),
}


@pytest.fixture(params=PLANAR_SEEDS, ids=lambda seed: "lesson" if seed is None else f"seed {seed}")
def planar_pair(request: pytest.FixtureRequest) -> tuple[Planar3RPR, DistanceConstraintMechanism]:
    """A 3-RPR and the family member built from its base and platform alone."""
    robot = geometry(request.param)
    member = DistanceConstraintMechanism(base=robot.base, platform=robot.platform, pose_space="planar")
    return robot, member


def test_planar_member_has_the_3rpr_geometry(planar_pair: tuple) -> None:
    """Same points, characteristic length, pose scaling and home pose by default."""
    robot, member = planar_pair
    np.testing.assert_array_equal(member.base, robot.base)
    np.testing.assert_array_equal(member.platform, robot.platform)
    assert member.characteristic_length == robot.characteristic_length
    np.testing.assert_array_equal(member.pose_scale, robot.pose_scale)
    assert (member.n_actuators, member.n_pose, member.pose_space.name) == (3, 3, "planar")


@pytest.mark.parametrize("name", list(COMPARED))
def test_planar_member_equals_3rpr(name: str, planar_pair: tuple, rng: np.random.Generator) -> None:
    """Each value of the family member equals the 3-RPR's on 500 regular poses, to 1e-12 relative."""
    robot, member = planar_pair
    Q, X = regular_configurations(robot, rng, N_CONFIGURATIONS)
    Q = Q * rng.uniform(0.95, 1.05, Q.shape)  # off the manifold too, so Φ ≠ 0
    ours, theirs = COMPARED[name](robot, Q, X), COMPARED[name](member, Q, X)
    assert theirs.shape == ours.shape
    assert max_relative_error(theirs, ours) < 1e-12


def test_planar_member_constraints_off_the_regular_set(planar_pair: tuple, rng: np.random.Generator) -> None:
    """Φ and the Jacobians agree on arbitrary poses and leg lengths, singular ones included."""
    robot, member = planar_pair
    X = random_poses(robot, rng, N_CONFIGURATIONS)
    Q = rng.uniform(0.2, 1.5, (N_CONFIGURATIONS, 3))
    np.testing.assert_allclose(member.constraints(Q, X), robot.constraints(Q, X), rtol=1e-12, atol=1e-14)
    for ours, theirs in zip(robot.jacobians(Q, X), member.jacobians(Q, X), strict=True):
        assert max_relative_error(theirs, ours) < 1e-12


def test_planar_member_forward_kinematics_equals_3rpr(planar_pair: tuple, rng: np.random.Generator) -> None:
    """Newton from the same guesses reaches the same poses in the same number of steps."""
    robot, member = planar_pair
    Q, X = regular_configurations(robot, rng, 100)
    guess = X + rng.uniform(-1.0, 1.0, X.shape) * [0.02, 0.02, 0.05]
    ours, theirs = robot.forward_kinematics(Q, guess), member.forward_kinematics(Q, guess)
    assert np.all(ours.converged) and np.all(theirs.converged)
    np.testing.assert_allclose(theirs.x, ours.x, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(theirs.iterations, ours.iterations)


def test_planar_member_singularities_equal_3rpr(planar_pair: tuple, rng: np.random.Generator) -> None:
    """Mobility, the inverse condition number and det J_x agree on arbitrary poses (no regularity filter)."""
    robot, member = planar_pair
    X = random_poses(robot, rng, 200)
    Q = robot.inverse_kinematics(X)
    np.testing.assert_array_equal(member.platform_mobility(Q, X), robot.platform_mobility(Q, X))
    for ours, theirs in zip(robot.singularity_measures(Q, X), member.singularity_measures(Q, X), strict=True):
        np.testing.assert_allclose(theirs, ours, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("pose_space, shape", [("planar", (3, 2)), ("spatial", (6, 3))])
def test_pose_space_sets_the_point_shape(pose_space: str, shape: tuple[int, int]) -> None:
    """A pose space fixes the number and dimension of the points; other shapes are refused."""
    wrong = (6, 3) if shape == (3, 2) else (3, 2)
    with pytest.raises(
        ValueError, match=rf"base anchors must have shape \({shape[0]}, {shape[1]}\), got \({wrong[0]}, {wrong[1]}\)"
    ):
        DistanceConstraintMechanism(base=np.ones(wrong), platform=np.ones(shape), pose_space=pose_space)


def test_planar_member_refuses_bad_input() -> None:
    """Unknown pose spaces or actuators, coincident points and bad leg lengths raise ValueError."""
    base, platform = Planar3RPR().base, Planar3RPR().platform
    with pytest.raises(ValueError, match="pose_space must be one of"):
        DistanceConstraintMechanism(base=base, platform=platform, pose_space="plane")
    with pytest.raises(ValueError, match="actuators must be one of"):
        DistanceConstraintMechanism(base=base, platform=platform, pose_space="planar", actuators="winch")
    with pytest.raises(ValueError, match="link_lengths are required"):
        DistanceConstraintMechanism(base=base, platform=platform, pose_space="planar", actuators="crank")
    with pytest.raises(ValueError, match="platform points must be pairwise distinct"):
        DistanceConstraintMechanism(base=base, platform=platform[[0, 1, 1]], pose_space="planar")
    member = DistanceConstraintMechanism(base=base, platform=platform, pose_space="planar")
    with pytest.raises(ValueError, match=r"leg lengths q must be > 0"):
        member.constraints(np.array([0.5, 0.0, 0.5]), np.array([0.5, 0.3, 0.1]))
    with pytest.raises(ValueError, match=r"x must have shape \(\.\.\., 3\)"):
        member.constraints(np.array([0.5, 0.5, 0.5]), np.zeros(6))
