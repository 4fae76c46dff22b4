"""Jacobians of the planar 3-RPR against SymPy, finite differences, the lesson's formulas and statics."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import sympy as sp

from kinematics import Planar3RPR
from tests.kinematics.helpers import (
    GEOMETRY_SEEDS,
    central_difference,
    geometry,
    lesson_jacobians,
    max_relative_error,
    random_poses,
    regular_configurations,
)

N_CONFIGURATIONS = 1000

SymbolicJacobians = Callable[[Planar3RPR, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@pytest.fixture(scope="module")
def symbolic_jacobians() -> SymbolicJacobians:
    """The lesson's §7 SymPy derivation, with the geometry as symbols too, lambdified for batches."""
    x, y, phi = sp.symbols("x y phi", real=True)
    L = sp.symbols("L1:4", positive=True)
    B = [sp.Matrix(sp.symbols(f"B{i}x B{i}y", real=True)) for i in (1, 2, 3)]
    P = [sp.Matrix(sp.symbols(f"P{i}x P{i}y", real=True)) for i in (1, 2, 3)]
    p = sp.Matrix([x, y])
    R = sp.Matrix([[sp.cos(phi), -sp.sin(phi)], [sp.sin(phi), sp.cos(phi)]])
    d = [p + R * P_i - B_i for B_i, P_i in zip(B, P, strict=True)]
    Phi = sp.Matrix([d_i.dot(d_i) - L_i**2 for d_i, L_i in zip(d, L, strict=True)])
    Jq_sym = Phi.jacobian(sp.Matrix(L))
    Jx_sym = Phi.jacobian(sp.Matrix([x, y, phi]))
    args = (*L, x, y, phi, *(c for B_i in B for c in B_i), *(c for P_i in P for c in P_i))
    Jq_fun = sp.lambdify(args, list(Jq_sym), "numpy")
    Jx_fun = sp.lambdify(args, list(Jx_sym), "numpy")

    def evaluate(robot: Planar3RPR, Q: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        values = (*Q.T, *X.T, *robot.base.ravel(), *robot.platform.ravel())
        batch = np.empty(len(Q))  # constant entries (the zeros of J_q) broadcast to the batch

        def as_batch(entries: list) -> np.ndarray:
            columns = np.broadcast_arrays(*entries, batch)[:-1]
            return np.stack(columns, axis=-1).astype(float).reshape(len(Q), 3, 3)

        return as_batch(Jq_fun(*values)), as_batch(Jx_fun(*values))

    return evaluate


@pytest.fixture(scope="module")
def lesson_section7() -> Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The lesson's §7 code as printed (numeric default geometry), returning (J_f, J_q, J_x)."""
    x, y, phi = sp.symbols("x y phi", real=True)
    L1, L2, L3 = sp.symbols("L1 L2 L3", positive=True)
    B1 = sp.Matrix([0.0, 0.0])
    B2 = sp.Matrix([1.0, 0.0])
    B3 = sp.Matrix([0.5, sp.sqrt(3) / 2])
    P1 = sp.Matrix([0.0, -0.2])
    P2 = sp.Matrix([0.2, 0.0])
    P3 = sp.Matrix([-0.2, 0.0])
    p = sp.Matrix([x, y])
    R = sp.Matrix([[sp.cos(phi), -sp.sin(phi)], [sp.sin(phi), sp.cos(phi)]])

    def leg_vector(B: sp.Matrix, P: sp.Matrix) -> sp.Matrix:
        return p + R * P - B

    d1, d2, d3 = leg_vector(B1, P1), leg_vector(B2, P2), leg_vector(B3, P3)
    Phi = sp.Matrix([d1.dot(d1) - L1**2, d2.dot(d2) - L2**2, d3.dot(d3) - L3**2])
    Jq_sym = Phi.jacobian(sp.Matrix([L1, L2, L3]))
    Jx_sym = Phi.jacobian(sp.Matrix([x, y, phi]))
    Jq_fun = sp.lambdify((L1, L2, L3, x, y, phi), Jq_sym, "numpy")
    Jx_fun = sp.lambdify((L1, L2, L3, x, y, phi), Jx_sym, "numpy")

    def jacobians_3rpr(L_vals: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        Jq = np.array(Jq_fun(*L_vals, *pose), dtype=float)
        Jx = np.array(Jx_fun(*L_vals, *pose), dtype=float)
        Jf = -np.linalg.inv(Jx) @ Jq
        return Jf, Jq, Jx

    return jacobians_3rpr


@pytest.fixture(params=GEOMETRY_SEEDS, ids=lambda s: "lesson" if s is None else f"random{s}")
def any_robot(request: pytest.FixtureRequest) -> Planar3RPR:
    """The lesson's geometry and a few random geometries."""
    return geometry(request.param)


@pytest.fixture
def configurations(any_robot: Planar3RPR, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """1000 consistent configurations (q = IK(x), x) of ``any_robot``, singular or not."""
    X = random_poses(any_robot, rng, N_CONFIGURATIONS)
    return any_robot.inverse_kinematics(X), X


@pytest.fixture
def regular(any_robot: Planar3RPR, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """1000 consistent configurations of ``any_robot`` with inverse condition number > 0.05."""
    return regular_configurations(any_robot, rng, N_CONFIGURATIONS)


# -- J_q and J_x ------------------------------------------------------------------------------------


def test_constraints_vanish_on_inverse_kinematics(any_robot, configurations):
    """Φ(IK(x), x) = 0 for every sampled pose."""
    Q, X = configurations
    assert np.max(np.abs(any_robot.constraints(Q, X))) <= 1e-14


def test_jacobians_equal_sympy_derivation(any_robot, configurations, symbolic_jacobians):
    """J_q and J_x equal the SymPy derivation of Φ (geometry as symbols) to 1e-9 relative."""
    Q, X = configurations
    J_q, J_x = any_robot.jacobians(Q, X)
    ref_q, ref_x = symbolic_jacobians(any_robot, Q, X)
    assert J_q.shape == J_x.shape == (N_CONFIGURATIONS, 3, 3)
    assert max_relative_error(J_q, ref_q) <= 1e-9
    assert max_relative_error(J_x, ref_x) <= 1e-9


def test_jacobians_equal_central_differences_of_constraints(any_robot, configurations):
    """J_q and J_x equal central differences of ``constraints`` to 1e-9 relative."""
    Q, X = configurations
    J_q, J_x = any_robot.jacobians(Q, X)
    fd_q = central_difference(lambda q: any_robot.constraints(q, X), Q, 1e-5)
    fd_x = central_difference(lambda x: any_robot.constraints(Q, x), X, 1e-5)
    assert max_relative_error(J_q, fd_q) <= 1e-9
    assert max_relative_error(J_x, fd_x) <= 1e-9


def test_jacobians_equal_lesson_formulas(any_robot, configurations):
    """J_q = −2 diag(L) exactly; J_x rows are (2 d_ix, 2 d_iy, 2 d_iᵀ S R(φ) P_i)."""
    Q, X = configurations
    J_q, J_x = any_robot.jacobians(Q, X)
    ref_q, ref_x = lesson_jacobians(any_robot, Q, X)
    np.testing.assert_array_equal(J_q, ref_q)
    assert max_relative_error(J_x, ref_x) <= 1e-12


def test_default_geometry_matches_lesson_section7_code(robot, rng, lesson_section7):
    """The lesson's own §7 code (numeric geometry, np.linalg.inv) gives our J_q, J_x and J_f."""
    Q, X = regular_configurations(robot, rng, N_CONFIGURATIONS)
    J_q, J_x = robot.jacobians(Q, X)
    J_f = robot.forward_jacobian(Q, X)
    ref = [lesson_section7(q, x) for q, x in zip(Q, X, strict=True)]
    ref_f, ref_q, ref_x = (np.array(m) for m in zip(*ref, strict=True))
    np.testing.assert_array_equal(J_q, ref_q)
    assert max_relative_error(J_x, ref_x) <= 1e-12
    assert max_relative_error(J_f, ref_f) <= 1e-9


# -- J_f and J_i --------------------------------------------------------------------------------------


def test_forward_and_inverse_jacobians_are_mutual_inverses(any_robot, regular):
    """J_f J_i = I_m and J_i J_f = I_n (lesson §4.2, problem 2)."""
    Q, X = regular
    J_f = any_robot.forward_jacobian(Q, X)
    J_i = any_robot.inverse_jacobian(Q, X)
    eye = np.broadcast_to(np.eye(3), J_f.shape)
    np.testing.assert_allclose(J_f @ J_i, eye, rtol=0, atol=1e-9)
    np.testing.assert_allclose(J_i @ J_f, eye, rtol=0, atol=1e-9)


def test_forward_jacobian_is_the_derivative_of_forward_kinematics(any_robot, regular):
    """J_f equals central differences of x(q) = forward_kinematics(q, x_guess=x).x.

    The step is small because x(q) curves sharply near a fold of the workspace (two assembly modes
    about to merge), and the truncation error of central differences grows with that curvature.
    """
    Q, X = regular

    def fk(q: np.ndarray) -> np.ndarray:
        result = any_robot.forward_kinematics(q, X)
        assert np.all(result.converged)
        return result.x

    fd = central_difference(fk, Q, 1e-7)
    assert max_relative_error(any_robot.forward_jacobian(Q, X), fd) <= 1e-6


def test_inverse_jacobian_is_the_derivative_of_inverse_kinematics(any_robot, configurations):
    """J_i = −J_q⁻¹ J_x equals the Jacobian of the closed-form IK map (lesson problem 4)."""
    Q, X = configurations
    fd = central_difference(any_robot.inverse_kinematics, X, 1e-6)
    assert max_relative_error(any_robot.inverse_jacobian(Q, X), fd) <= 1e-8


def test_homogeneous_jacobian_rows_are_leg_directions_and_moment_arms(any_robot, configurations):
    """Row i of J_h is (u_i, ((R P_i) × u_i)/ℓ_c) with u_i the unit leg vector."""
    Q, X = configurations
    d = any_robot.leg_vectors(X)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    RP = any_robot.platform_points_in_base(X) - X[:, None, :2]
    moment = RP[..., 0] * u[..., 1] - RP[..., 1] * u[..., 0]
    expected = np.concatenate([u, moment[..., None] / any_robot.characteristic_length], axis=-1)
    np.testing.assert_allclose(any_robot.homogeneous_jacobian(Q, X), expected, rtol=0, atol=1e-12)


# -- statics ------------------------------------------------------------------------------------------


def test_virtual_work_balances(any_robot, regular, rng):
    """τ·δq = w·δx for w = platform_wrench(q, x, τ) and δq = J_i δx (lesson problem 5)."""
    Q, X = regular
    tau = rng.normal(size=Q.shape) * 100.0
    dx = rng.normal(size=X.shape) * 1e-3
    dq = np.einsum("nij,nj->ni", any_robot.inverse_jacobian(Q, X), dx)
    w = any_robot.platform_wrench(Q, X, tau)
    work_actuators = np.sum(tau * dq, axis=-1)
    work_platform = np.sum(w * dx, axis=-1)
    scale = np.linalg.norm(tau, axis=-1) * np.linalg.norm(dq, axis=-1)
    assert np.max(np.abs(work_actuators - work_platform) / scale) <= 1e-12


def test_single_leg_force_pushes_along_the_leg(any_robot, configurations):
    """A unit force in leg i gives f = u_i and m_z = (R P_i) × u_i on the platform."""
    Q, X = configurations
    d = any_robot.leg_vectors(X)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    RP = any_robot.platform_points_in_base(X) - X[:, None, :2]
    for i in range(3):
        w = any_robot.platform_wrench(Q, X, np.eye(3)[i])
        np.testing.assert_allclose(w[:, :2], u[:, i], rtol=0, atol=1e-12)
        moment = RP[:, i, 0] * u[:, i, 1] - RP[:, i, 1] * u[:, i, 0]
        np.testing.assert_allclose(w[:, 2], moment, rtol=0, atol=1e-12)


def test_actuator_forces_invert_platform_wrench(any_robot, regular, rng):
    """actuator_forces(q, x, platform_wrench(q, x, τ)) = τ, and the other way round."""
    Q, X = regular
    tau = rng.normal(size=Q.shape) * 100.0
    w = any_robot.platform_wrench(Q, X, tau)
    assert max_relative_error(any_robot.actuator_forces(Q, X, w), tau) <= 1e-9
    wrench = rng.normal(size=X.shape) * 10.0
    tau_balancing = any_robot.actuator_forces(Q, X, wrench)
    assert max_relative_error(any_robot.platform_wrench(Q, X, tau_balancing), wrench) <= 1e-9


# -- the fused batched J_f (several blocks) against the generic solve ---------------------------------


def generic_forward_jacobian(robot: Planar3RPR, Q: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """J_f = −J_x⁻¹ J_q by LAPACK on the stacked matrices, and the Hadamard ratio of the generic code."""
    from kinematics.linalg import hadamard_ratio

    J_q, J_x = robot.jacobians(Q, X)
    return -np.linalg.solve(J_x, J_q), hadamard_ratio(J_x, robot.pose_scale)


@pytest.mark.parametrize("seed", GEOMETRY_SEEDS[:2])
def test_fused_batched_forward_jacobian_equals_the_generic_solve(seed, rng):
    """More configurations than one block (4096), near-singular ones included: same J_f and ratio."""
    robot = geometry(seed)
    X = random_poses(robot, rng, 9001)
    Q = robot.inverse_kinematics(X) + rng.normal(0.0, 1e-3, (9001, 3))  # J_f exists off the manifold too
    J_f, ratio = robot._forward_jacobian_batch(Q, X)
    ref_f, ref_ratio = generic_forward_jacobian(robot, Q, X)
    assert J_f.shape == (9001, 3, 3) and ratio.shape == (9001,)
    np.testing.assert_allclose(ratio, ref_ratio, rtol=1e-9, atol=1e-15)
    well = ref_ratio > 1e-6  # far enough from det = 0 for both solves to agree to rounding
    assert well.mean() > 0.9
    assert max_relative_error(J_f[well], ref_f[well]) <= 1e-8
    np.testing.assert_array_equal(robot.forward_jacobian(Q[well], X[well]), J_f[well])


@pytest.mark.parametrize("n", [1, 4097])
def test_fused_batched_forward_jacobian_with_one_configuration_in_a_block(robot, rng, n):
    """A batch of one, and a last block of one, give the single-call result."""
    X = random_poses(robot, rng, n)
    Q = robot.inverse_kinematics(X)
    J_f = robot.forward_jacobian(Q, X)
    assert J_f.shape == (n, 3, 3)
    np.testing.assert_allclose(J_f[-1], robot.forward_jacobian(Q[-1], X[-1]), rtol=1e-9, atol=1e-12)


def test_fused_batched_forward_jacobian_broadcasts_and_marks_exact_singularity(robot):
    """Leg lengths q (3,) against x (N, 3) and 2-D batches; det A = 0 exactly gives NaN or raises."""
    X = np.array([[0.5, 0.3, 0.1], [0.45, 0.35, -0.2], [0.0, 0.2, 0.0]])  # last: d_1 = p + P_1 − B_1 = 0
    q = np.array([0.6, 0.5, 0.55])
    J_f = robot.forward_jacobian(q, X, validate=False)
    assert J_f.shape == (3, 3, 3)
    assert np.isnan(J_f[2]).all() and np.isfinite(J_f[:2]).all()
    for k in range(2):
        np.testing.assert_allclose(J_f[k], robot.forward_jacobian(q, X[k]), rtol=1e-12, atol=1e-14)
    two_d = robot.forward_jacobian(np.broadcast_to(q, (2, 2, 3)), np.broadcast_to(X[:2], (2, 2, 3)))
    np.testing.assert_array_equal(two_d, np.broadcast_to(J_f[:2], (2, 2, 3, 3)))
    from kinematics import SingularConfigurationError

    with pytest.raises(SingularConfigurationError, match=r"batch index \(2,\)"):
        robot.forward_jacobian(q, X)
