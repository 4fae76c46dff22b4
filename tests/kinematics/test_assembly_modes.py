"""All assembly modes of the planar 3-RPR against a multi-start Newton search."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics import Planar3RPR
from tests.kinematics.helpers import random_geometry, wrap_angle

#: A geometry and leg lengths with the maximum of six real assembly modes (found by random search).
SIX_MODE_BASE = [[0.53, -0.073], [0.413, -0.954], [0.442, 0.523]]
SIX_MODE_PLATFORM = [[-0.975, -0.298], [0.273, -0.725], [0.612, 0.945]]
SIX_MODE_Q = [1.61, 1.315, 1.611]

N_STARTS = 3000


def pose_distance(robot: Planar3RPR, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance between poses with φ wrapped and weighted by ℓ_c, broadcast over leading axes [m]."""
    dphi = wrap_angle(a[..., 2] - b[..., 2])
    return np.hypot(np.hypot(a[..., 0] - b[..., 0], a[..., 1] - b[..., 1]), robot.characteristic_length * dphi)


def multi_start_solutions(robot: Planar3RPR, q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Distinct converged Newton solutions from random starts over a box holding every solution."""
    reach = q.max() + np.max(np.linalg.norm(robot.platform, axis=1))
    low, high = robot.base.min(axis=0) - reach, robot.base.max(axis=0) + reach
    starts = np.column_stack(
        [
            rng.uniform(low[0], high[0], N_STARTS),
            rng.uniform(low[1], high[1], N_STARTS),
            rng.uniform(-np.pi, np.pi, N_STARTS),
        ]
    )
    result = robot.forward_kinematics(q, starts, max_iterations=60)
    found = result.x[result.converged]
    found[:, 2] = wrap_angle(found[:, 2])
    distinct: list[np.ndarray] = []
    for pose in found:
        if all(pose_distance(robot, pose, other) > 1e-6 for other in distinct):
            distinct.append(pose)
    return np.array(distinct).reshape(-1, 3)


def assert_valid_modes(robot: Planar3RPR, q: np.ndarray, modes: np.ndarray) -> None:
    """Shape (k, 3) with k ≤ 6, |Φ| ≤ 1e-10, φ in (−π, π] sorted, pairwise distinct."""
    assert modes.ndim == 2 and modes.shape[1] == 3
    assert len(modes) <= 6
    if len(modes):
        assert np.max(np.abs(robot.constraints(q, modes))) <= 1e-10
    assert np.all(modes[:, 2] > -np.pi) and np.all(modes[:, 2] <= np.pi)
    assert np.all(np.diff(modes[:, 2]) >= 0)
    gaps = pose_distance(robot, modes[:, None, :], modes[None, :, :])
    assert np.all(gaps[~np.eye(len(modes), dtype=bool)] > 1e-6)


def assert_none_missing(robot: Planar3RPR, modes: np.ndarray, found: np.ndarray) -> None:
    """Every solution found by the multi-start search is one of ``modes``."""
    assert len(found) > 0
    for pose in found:
        gap = np.min(pose_distance(robot, pose, modes), initial=np.inf)
        assert gap <= 1e-6, f"multi-start solution {pose} missing from assembly_modes: {modes}"


def arbitrary_geometry(rng: np.random.Generator) -> Planar3RPR:
    """Base anchors and platform points anywhere in [−1, 1]² (platforms as large as bases)."""
    while True:
        try:
            return Planar3RPR(rng.uniform(-1, 1, (3, 2)), rng.uniform(-1, 1, (3, 2)))
        except ValueError:  # pragma: no cover - a degenerate draw, draw again
            continue


@pytest.mark.parametrize("case", range(40))
def test_assembly_modes_are_complete_for_random_geometries(case):
    """On random geometries and leg lengths, no multi-start Newton solution is missing."""
    rng = np.random.default_rng(1000 + case)
    robot = Planar3RPR() if case == 0 else (random_geometry, arbitrary_geometry)[case % 2](rng)
    x0 = np.array([*(robot.base.mean(axis=0) + rng.uniform(-0.3, 0.3, 2)), rng.uniform(-np.pi, np.pi)])
    q = robot.inverse_kinematics(x0)
    modes = robot.assembly_modes(q)
    assert_valid_modes(robot, q, modes)
    assert np.min(pose_distance(robot, x0, modes)) <= 1e-8, "the pose q came from is a mode"
    assert len(modes) % 2 == 0, "real roots of the generic trigonometric polynomial come in pairs"
    assert_none_missing(robot, modes, multi_start_solutions(robot, q, rng))


def test_six_assembly_modes(rng):
    """A known case with the maximum of six real assembly modes: all are returned and found."""
    robot = Planar3RPR(SIX_MODE_BASE, SIX_MODE_PLATFORM)
    q = np.array(SIX_MODE_Q)
    modes = robot.assembly_modes(q)
    assert len(modes) == 6
    assert_valid_modes(robot, q, modes)
    found = multi_start_solutions(robot, q, rng)
    assert len(found) == 6
    assert_none_missing(robot, modes, found)


def test_default_geometry_lesson_pose(robot):
    """The lesson's example leg lengths around its example pose (§7) give valid, complete modes."""
    x0 = np.array([0.5, 0.3, 0.1])
    q = robot.inverse_kinematics(x0)
    modes = robot.assembly_modes(q)
    assert_valid_modes(robot, q, modes)
    assert np.min(pose_distance(robot, x0, modes)) <= 1e-8
    assert_none_missing(robot, modes, multi_start_solutions(robot, q, np.random.default_rng(7)))


def test_modes_are_consistent_with_forward_kinematics(robot, rng):
    """Newton started at each mode stays there: every mode is a fixed point of forward_kinematics."""
    q = robot.inverse_kinematics(np.array([0.45, 0.25, -0.3]))
    modes = robot.assembly_modes(q)
    result = robot.forward_kinematics(q, modes)
    assert np.all(result.converged)
    np.testing.assert_allclose(result.x, modes, rtol=0, atol=1e-9)
