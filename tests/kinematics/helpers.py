"""Shared test helpers for the kinematics tests: random geometries, poses and reference formulas."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kinematics import Delta, Planar3PRR, Planar3RPR, Planar3RRR, StewartGough

#: The presets of the dynamics tests, each with the half-width of its random poses around the home pose
#: (translations [m], rotations [rad]).
DYNAMICS_PRESETS = {
    "3-RPR": (Planar3RPR, 0.1, 0.3),
    "hexapod": (StewartGough, 0.05, 0.15),
    "Delta": (Delta, 0.1, 0.0),
    "3-RRR": (Planar3RRR, 0.02, 0.1),
    "3-PRR": (Planar3PRR, 0.03, 0.1),
}

#: Seeds of the random geometries every geometry-parametrised test runs on (None is the lesson's).
GEOMETRY_SEEDS = [None, 101, 202, 303]

S = np.array([[0.0, -1.0], [1.0, 0.0]])


def rotation(phi: np.ndarray) -> np.ndarray:
    """R(φ) for a batch of angles, shape (..., 2, 2)."""
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


def wrap_angle(phi: np.ndarray) -> np.ndarray:
    """Angles wrapped to (−π, π]."""
    return np.angle(np.exp(1j * np.asarray(phi)))


def random_geometry(rng: np.random.Generator) -> Planar3RPR:
    """A random, well-shaped 3-RPR: base radius 0.6–1.4 m, platform radius 0.1–0.4 m."""
    spread = np.array([0.0, 2.0 * np.pi / 3.0, 4.0 * np.pi / 3.0])
    while True:
        theta = rng.uniform(0.0, 2.0 * np.pi) + spread + rng.uniform(-0.5, 0.5, 3)
        base = rng.uniform(0.6, 1.4) * np.column_stack([np.cos(theta), np.sin(theta)])
        base += rng.uniform(-0.5, 0.5, 2)
        psi = rng.uniform(0.0, 2.0 * np.pi) + spread + rng.uniform(-0.6, 0.6, 3)
        platform = rng.uniform(0.1, 0.4) * np.column_stack([np.cos(psi), np.sin(psi)])
        try:
            return Planar3RPR(base, platform)
        except ValueError:  # pragma: no cover - a degenerate draw, draw again
            continue


def geometry(seed: int | None) -> Planar3RPR:
    """The lesson's robot for ``None``, else the random geometry of that seed."""
    return Planar3RPR() if seed is None else random_geometry(np.random.default_rng(seed))


def random_poses(robot: Planar3RPR, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` poses with the platform origin within 0.3 m of the base centroid, φ in [−1, 1], (n, 3)."""
    centre = robot.base.mean(axis=0)
    xy = centre + rng.uniform(-0.3, 0.3, (n, 2))
    return np.column_stack([xy, rng.uniform(-1.0, 1.0, n)])


def regular_configurations(
    robot: Planar3RPR, rng: np.random.Generator, n: int, min_inverse_condition: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` consistent configurations (q = IK(x), x) away from Type II singularities, (n, 3) each."""
    kept = np.empty((0, 3))
    while len(kept) < n:
        X = random_poses(robot, rng, 2 * n)
        icn = robot.inverse_condition_number(robot.inverse_kinematics(X), X)
        kept = np.concatenate([kept, X[icn > min_inverse_condition]])
    X = kept[:n]
    return robot.inverse_kinematics(X), X


def lesson_jacobians(robot: Planar3RPR, q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lesson's §5.2 formulas, written independently of the package: (J_q, J_x), each (N, 3, 3).

    J_q = −2 diag(L) and row i of J_x is (2 d_ix, 2 d_iy, 2 d_iᵀ S R(φ) P_i).
    """
    R = rotation(x[:, 2])  # (N, 2, 2)
    RP = np.einsum("nab,ib->nia", R, robot.platform)  # (N, 3, 2)
    d = x[:, None, :2] + RP - robot.base  # (N, 3, 2)
    SRP = np.einsum("ab,nib->nia", S, RP)
    J_x = np.concatenate([2.0 * d, 2.0 * np.sum(d * SRP, axis=-1, keepdims=True)], axis=-1)
    J_q = np.zeros((len(q), 3, 3))
    for i in range(3):
        J_q[:, i, i] = -2.0 * q[:, i]
    return J_q, J_x


def central_difference(f: Callable[[np.ndarray], np.ndarray], z: np.ndarray, step: float | np.ndarray) -> np.ndarray:
    """Central finite-difference Jacobian of a batched map f: (N, 3) → (N, k), shape (N, k, 3)."""
    steps = np.broadcast_to(np.asarray(step, dtype=float), (3,))
    columns = []
    for j in range(3):
        e = np.zeros(3)
        e[j] = steps[j]
        columns.append((f(z + e) - f(z - e)) / (2.0 * steps[j]))
    return np.stack(columns, axis=-1)


def max_relative_error(actual: np.ndarray, expected: np.ndarray) -> float:
    """Largest max|actual − expected| / max|expected| over the matrices (or vectors) of a batch."""
    actual, expected = np.broadcast_arrays(actual, expected)
    axes = tuple(range(1, expected.ndim))
    err = np.max(np.abs(actual - expected), axis=axes)
    scale = np.max(np.abs(expected), axis=axes)
    return float(np.max(err / scale))
