"""The Stewart–Gough platform (6-UPS): Jacobians, statics, forward kinematics and singularities from the math.

References checked here: Fichter's singularity of the symmetric hexapod (Fichter, IJRR 5(2), 1986), Merlet's
line-geometry singularities (IJRR 8(5), 1989) and Dietmaier's platform with 40 real assembly modes (Advances in
Robot Kinematics, 1998; data from the fkSGP solver, see ``data/dietmaier.json``).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.spatial.transform import Rotation

from kinematics import DistanceConstraintMechanism, SingularConfigurationError, StewartGough
from tests.kinematics.helpers import max_relative_error

N_CONFIGURATIONS = 1000
DATA = Path(__file__).parent / "data"


# -- geometries, poses and independent reference formulas ---------------------------------------------


def asymmetric_geometry() -> tuple[np.ndarray, np.ndarray]:
    """A fixed, irregular 6-6 geometry (B, P), each (6, 3) [m]: non-planar, no symmetry."""
    rng = np.random.default_rng(6)
    theta = np.radians(60.0 * np.arange(6)) + rng.uniform(-0.35, 0.35, 6)
    psi = np.radians(60.0 * np.arange(6) + 30.0) + rng.uniform(-0.35, 0.35, 6)
    base = rng.uniform(0.4, 0.7, (6, 1)) * np.column_stack([np.cos(theta), np.sin(theta), np.zeros(6)])
    platform = rng.uniform(0.15, 0.35, (6, 1)) * np.column_stack([np.cos(psi), np.sin(psi), np.zeros(6)])
    base[:, 2] = rng.uniform(-0.05, 0.05, 6)
    platform[:, 2] = rng.uniform(-0.05, 0.05, 6)
    return base, platform


def semi_regular(radius: float, half_angle_deg: float) -> np.ndarray:
    """Points at ``radius`` in z = 0 at angles 120°·k ∓ half_angle (k = 0, 1, 2), shape (6, 3)."""
    angles = np.radians([120.0 * k + s * half_angle_deg for k in range(3) for s in (-1.0, 1.0)])
    return radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(6)])


GEOMETRIES = {"default": None, "asymmetric": asymmetric_geometry()}


@pytest.fixture(scope="module", params=list(GEOMETRIES))
def hexapod(request: pytest.FixtureRequest) -> StewartGough:
    """The documented default hexapod and an asymmetric one."""
    geometry = GEOMETRIES[request.param]
    return StewartGough() if geometry is None else StewartGough(base=geometry[0], platform=geometry[1])


@pytest.fixture(scope="module")
def default_hexapod() -> StewartGough:
    """The documented symmetric hexapod."""
    return StewartGough()


def random_poses(
    robot: StewartGough, rng: np.random.Generator, n: int, angles: tuple[float, float] = (0.0, 0.5)
) -> np.ndarray:
    """``n`` poses within 0.1 m of the home position, rotated by ``angles`` [rad] about random axes, (n, 6)."""
    home = robot.home_pose()
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    r = axis * rng.uniform(*angles, (n, 1))
    return np.column_stack([home[:3] + rng.uniform(-0.1, 0.1, (n, 3)), r])


def regular_configurations(
    robot: StewartGough,
    rng: np.random.Generator,
    n: int,
    min_inverse_condition: float = 0.05,
    angles: tuple[float, float] = (0.0, 0.5),
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` consistent configurations (q = IK(x), x) away from Type II singularities, (n, 6) each."""
    kept = np.empty((0, 6))
    while len(kept) < n:
        X = random_poses(robot, rng, 2 * n, angles)
        k = robot.inverse_condition_number(robot.inverse_kinematics(X), X)
        kept = np.concatenate([kept, X[k > min_inverse_condition]])
    X = kept[:n]
    return robot.inverse_kinematics(X), X


def rotation(x: np.ndarray) -> np.ndarray:
    """R = exp([r]×) of poses by SciPy, shape (..., 3, 3)."""
    r = np.asarray(x)[..., 3:]
    return Rotation.from_rotvec(r.reshape(-1, 3)).as_matrix().reshape(r.shape[:-1] + (3, 3))


def twist_step(x: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Pose reached by a twist step (δp, δθ) in {B}: p + δp and R → exp([δθ]×) R, shape (..., 6)."""
    x, step = (np.array(a) for a in np.broadcast_arrays(x, step))
    turned = Rotation.from_rotvec(step[..., 3:].reshape(-1, 3)) * Rotation.from_rotvec(x[..., 3:].reshape(-1, 3))
    return np.concatenate([x[..., :3] + step[..., :3], turned.as_rotvec().reshape(x.shape[:-1] + (3,))], axis=-1)


def leg_vectors(robot: StewartGough, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d_i = p + R P_i − B_i, R P_i), each (N, 6, 3), written independently of the package."""
    RP = np.einsum("nab,ib->nia", rotation(x), robot.platform)
    return x[:, None, :3] + RP - robot.base, RP


def central_difference(f: Callable[[np.ndarray], np.ndarray], z: np.ndarray, h: float, move: Callable) -> np.ndarray:
    """Central difference of a batched map f along the 6 directions e_j moved by ``move(z, h e_j)``, (N, k, 6)."""
    columns = []
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        columns.append((f(move(z, e)) - f(move(z, -e))) / (2.0 * h))
    return np.stack(columns, axis=-1)


def pose_error(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Pose distance max |p_x − p_y| + max |R_x − R_y| (rotations compared as matrices), shape (N,)."""
    return np.max(np.abs(x[..., :3] - y[..., :3]), axis=-1) + np.max(np.abs(rotation(x) - rotation(y)), axis=(-2, -1))


# -- geometry and the rotation convention -------------------------------------------------------------


def test_default_geometry_is_the_documented_hexapod(default_hexapod: StewartGough) -> None:
    """Base at radius 0.5 m, pairs at 120°·k ± 12°; platform at 0.3 m, 120°·k ± 48°; leg i joins same-side points."""
    B, P = default_hexapod.base, default_hexapod.platform
    np.testing.assert_allclose(np.linalg.norm(B, axis=1), 0.5, rtol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(P, axis=1), 0.3, rtol=1e-15)
    assert np.all(B[:, 2] == 0.0) and np.all(P[:, 2] == 0.0)
    base_angle = np.degrees(np.arctan2(B[:, 1], B[:, 0]))
    platform_angle = np.degrees(np.arctan2(P[:, 1], P[:, 0]))
    # each leg turns 36° away from the 120°·k axis of its base pair, to the same side as its base anchor
    offset = (base_angle + 180.0) % 120.0 - 60.0  # ±12°
    np.testing.assert_allclose(np.abs(offset), 12.0, atol=1e-12)
    turn = (platform_angle - base_angle + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(turn, 3.0 * offset, atol=1e-12)
    np.testing.assert_array_equal(default_hexapod.home_pose(), [0.0, 0.0, 0.5, 0.0, 0.0, 0.0])
    q = default_hexapod.inverse_kinematics(default_hexapod.home_pose())
    np.testing.assert_allclose(q, q[0], rtol=1e-14)
    assert abs(q[0] - 0.59) < 0.005


def test_geometry_is_read_only(hexapod: StewartGough) -> None:
    """The base and platform arrays cannot be changed in place."""
    for points in (hexapod.base, hexapod.platform):
        assert points.shape == (6, 3)
        with pytest.raises(ValueError, match="read-only"):
            points[0, 0] = 1.0


def test_rotation_matrix_is_scipy_rotvec(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """R(x) = Rotation.from_rotvec(r).as_matrix(), including angles near π."""
    X = random_poses(hexapod, rng, 200)
    axis = rng.normal(size=(50, 3))
    X[:50, 3:] = axis / np.linalg.norm(axis, axis=1, keepdims=True) * rng.uniform(2.5, np.pi, (50, 1))
    np.testing.assert_allclose(hexapod.rotation_matrix(X), rotation(X), rtol=0, atol=1e-15)
    np.testing.assert_allclose(hexapod.rotation_matrix(X[7]), rotation(X[7]), rtol=0, atol=1e-15)


def test_inverse_kinematics_is_the_leg_lengths(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """q_i = ‖p + R P_i − B_i‖; leg_vectors and platform_points_in_base agree; Φ(IK(x), x) = 0."""
    X = random_poses(hexapod, rng, 500)
    d, RP = leg_vectors(hexapod, X)
    np.testing.assert_allclose(hexapod.leg_vectors(X), d, rtol=0, atol=1e-15)
    np.testing.assert_allclose(hexapod.platform_points_in_base(X), X[:, None, :3] + RP, rtol=0, atol=1e-15)
    q = hexapod.inverse_kinematics(X)
    np.testing.assert_allclose(q, np.linalg.norm(d, axis=-1), rtol=1e-15)
    assert np.max(np.abs(hexapod.constraints(q, X))) < 1e-15


def test_constraints_are_squared_distance_minus_squared_length(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """Φ_i = ‖d_i‖² − q_i² for q off the constraint manifold too."""
    X = random_poses(hexapod, rng, 500)
    q = rng.uniform(0.2, 1.2, (500, 6))
    d, _ = leg_vectors(hexapod, X)
    np.testing.assert_allclose(hexapod.constraints(q, X), np.sum(d * d, axis=-1) - q * q, rtol=1e-13, atol=1e-15)


# -- Jacobians ----------------------------------------------------------------------------------------


def test_jacobians_match_central_differences_on_the_rotation_group(
    hexapod: StewartGough, rng: np.random.Generator
) -> None:
    """J_x against Φ(p + h e_j, R) and Φ(p, exp(h [e_j]×) R); J_q against Φ(q ± h e_j), 1000 poses."""
    X = random_poses(hexapod, rng, N_CONFIGURATIONS)
    X[:100, 3:] *= 6.0  # rotations up to 3 rad: the perturbation may cross |r| = π
    Q = rng.uniform(0.3, 1.2, (N_CONFIGURATIONS, 6))
    J_q, J_x = hexapod.jacobians(Q, X)
    assert J_q.shape == J_x.shape == (N_CONFIGURATIONS, 6, 6)
    fd_x = central_difference(lambda x: hexapod.constraints(Q, x), X, 1e-5, twist_step)
    fd_q = central_difference(lambda q: hexapod.constraints(q, X), Q, 1e-5, lambda q, e: q + e)
    assert max_relative_error(J_x, fd_x) < 1e-7
    assert max_relative_error(J_q, fd_q) < 1e-7


def test_jacobian_rows_are_the_documented_formula(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """J_q = −2 diag(q); row i of J_x = 2 (d_iᵀ, ((R P_i) × d_i)ᵀ)."""
    X = random_poses(hexapod, rng, 300)
    Q = rng.uniform(0.3, 1.2, (300, 6))
    d, RP = leg_vectors(hexapod, X)
    J_q, J_x = hexapod.jacobians(Q, X)
    np.testing.assert_array_equal(J_q, -2.0 * Q[:, :, None] * np.eye(6))
    np.testing.assert_allclose(J_x, 2.0 * np.concatenate([d, np.cross(RP, d)], axis=-1), rtol=0, atol=1e-14)


SymbolicJacobians = Callable[[StewartGough, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@pytest.fixture(scope="module")
def symbolic_jacobians() -> SymbolicJacobians:
    """Φ of the 6-UPS in SymPy with R = exp([θ]×) R_0, differentiated in (p, θ) and q at θ = 0, lambdified.

    The geometry B, P, the pose (p, R_0) and q are symbols. exp([θ]×) is its power series up to [θ]×³: the
    terms dropped are O(|θ|⁴) and do not change the derivative at θ = 0, which is the twist Jacobian.
    """
    p = sp.Matrix(sp.symbols("p_x p_y p_z", real=True))
    theta = sp.Matrix(sp.symbols("theta_x theta_y theta_z", real=True))
    q = sp.Matrix(sp.symbols("q1:7", positive=True))
    R0 = sp.Matrix(3, 3, sp.symbols("R0_0:9", real=True))
    B = sp.Matrix(6, 3, sp.symbols("B0:18", real=True))
    P = sp.Matrix(6, 3, sp.symbols("P0:18", real=True))
    K = sp.Matrix([[0, -theta[2], theta[1]], [theta[2], 0, -theta[0]], [-theta[1], theta[0], 0]])
    R = (sp.eye(3) + K + K * K / 2 + K * K * K / 6) * R0
    Phi = []
    for i in range(6):
        d = p + R * P[i, :].T - B[i, :].T
        Phi.append(d.dot(d) - q[i] ** 2)
    Phi = sp.Matrix(Phi)
    at_identity = dict.fromkeys(theta, 0)
    J_x = Phi.jacobian(sp.Matrix([*p, *theta])).subs(at_identity)
    J_q = Phi.jacobian(q).subs(at_identity)
    args = (*q, *p, *R0, *B, *P)
    J_x_fun = sp.lambdify(args, J_x, "numpy")
    J_q_fun = sp.lambdify(args, J_q, "numpy")

    def evaluate(robot: StewartGough, q_num: np.ndarray, x_num: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        values = (*q_num, *x_num[:3], *rotation(x_num).ravel(), *robot.base.ravel(), *robot.platform.ravel())
        return np.array(J_q_fun(*values), dtype=float), np.array(J_x_fun(*values), dtype=float)

    return evaluate


def test_jacobians_match_sympy(
    hexapod: StewartGough, symbolic_jacobians: SymbolicJacobians, rng: np.random.Generator
) -> None:
    """J_q and J_x equal the symbolic derivatives of Φ(q, p, exp([θ]×) R_0) at θ = 0, on a handful of poses."""
    X = random_poses(hexapod, rng, 6)
    X[0, 3:] = [0.0, 0.0, 3.0]  # close to a half turn
    Q = rng.uniform(0.3, 1.2, (6, 6))
    J_q, J_x = hexapod.jacobians(Q, X)
    for k in range(len(X)):
        J_q_ref, J_x_ref = symbolic_jacobians(hexapod, Q[k], X[k])
        np.testing.assert_allclose(J_q[k], J_q_ref, rtol=0, atol=1e-12 * np.max(np.abs(J_q_ref)))
        np.testing.assert_allclose(J_x[k], J_x_ref, rtol=0, atol=1e-12 * np.max(np.abs(J_x_ref)))


def test_forward_jacobian_inverts_inverse_jacobian(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """J_f J_i = I and J_i J_f = I (6×6) away from singularities."""
    Q, X = regular_configurations(hexapod, rng, 300)
    J_f = hexapod.forward_jacobian(Q, X)
    J_i = hexapod.inverse_jacobian(Q, X)
    assert J_f.shape == J_i.shape == (300, 6, 6)
    np.testing.assert_allclose(J_f @ J_i, np.broadcast_to(np.eye(6), (300, 6, 6)), rtol=0, atol=1e-10)
    np.testing.assert_allclose(J_i @ J_f, np.broadcast_to(np.eye(6), (300, 6, 6)), rtol=0, atol=1e-10)


def test_forward_jacobian_predicts_the_motion_under_leg_rates(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """The twist J_f q̇ moves the platform so that the leg lengths change at q̇ (to first order)."""
    Q, X = regular_configurations(hexapod, rng, 200)
    qdot = rng.normal(size=(200, 6))
    twist = np.einsum("nij,nj->ni", hexapod.forward_jacobian(Q, X), qdot)
    h = 1e-6
    rate = (
        hexapod.inverse_kinematics(twist_step(X, h * twist)) - hexapod.inverse_kinematics(twist_step(X, -h * twist))
    ) / (2.0 * h)
    assert max_relative_error(rate, qdot) < 1e-6


def test_inverse_jacobian_rows_are_unit_pluecker_lines(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """Row i of J_i is the leg's line (u_i, (R P_i) × u_i), u_i the unit leg direction."""
    X = random_poses(hexapod, rng, 300)
    Q = hexapod.inverse_kinematics(X)
    d, RP = leg_vectors(hexapod, X)
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    np.testing.assert_allclose(
        hexapod.inverse_jacobian(Q, X), np.concatenate([u, np.cross(RP, u)], axis=-1), atol=1e-14
    )
    scale = np.array([1.0, 1.0, 1.0, *(3 * [1.0 / hexapod.characteristic_length])])
    J_h = hexapod.homogeneous_jacobian(Q, X)
    np.testing.assert_allclose(J_h, hexapod.inverse_jacobian(Q, X) * scale, atol=1e-14)
    sigma = np.linalg.svd(J_h, compute_uv=False)
    np.testing.assert_allclose(hexapod.inverse_condition_number(Q, X), sigma[:, -1] / sigma[:, 0], rtol=1e-10)


# -- statics ------------------------------------------------------------------------------------------


def test_virtual_work(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """τ · q̇ = w · (v, ω) with w = platform_wrench(τ) and (v, ω) = J_f q̇."""
    Q, X = regular_configurations(hexapod, rng, 300)
    tau = rng.normal(size=(300, 6)) * 100.0
    qdot = rng.normal(size=(300, 6)) * 0.1
    twist = np.einsum("nij,nj->ni", hexapod.forward_jacobian(Q, X), qdot)
    wrench = hexapod.platform_wrench(Q, X, tau)
    actuator_power = np.sum(tau * qdot, axis=-1)
    platform_power = np.sum(wrench * twist, axis=-1)
    np.testing.assert_allclose(platform_power, actuator_power, rtol=1e-9, atol=1e-9 * np.max(np.abs(actuator_power)))


def test_platform_wrench_sums_the_leg_forces(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """The wrench is w = Σ τ_i (u_i, (R P_i) × u_i): leg forces along the legs, moments about the origin of {P}."""
    X = random_poses(hexapod, rng, 300)
    Q = hexapod.inverse_kinematics(X)
    tau = rng.normal(size=(300, 6)) * 100.0
    d, RP = leg_vectors(hexapod, X)
    forces = tau[..., None] * d / np.linalg.norm(d, axis=-1, keepdims=True)
    expected = np.concatenate([forces.sum(axis=1), np.cross(RP, forces).sum(axis=1)], axis=-1)
    np.testing.assert_allclose(hexapod.platform_wrench(Q, X, tau), expected, rtol=0, atol=1e-11)


def test_actuator_forces_balance_the_platform_wrench(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """actuator_forces(platform_wrench(τ)) = τ."""
    Q, X = regular_configurations(hexapod, rng, 300)
    tau = rng.normal(size=(300, 6)) * 100.0
    back = hexapod.actuator_forces(Q, X, hexapod.platform_wrench(Q, X, tau))
    np.testing.assert_allclose(back, tau, rtol=0, atol=1e-9 * np.max(np.abs(tau)))


# -- batching and broadcasting ------------------------------------------------------------------------

BATCHED: dict[str, Callable[[StewartGough, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, ...]]] = {
    "constraints": lambda r, q, x, v: (r.constraints(q, x),),
    "jacobians": lambda r, q, x, v: r.jacobians(q, x),
    "forward_jacobian": lambda r, q, x, v: (r.forward_jacobian(q, x),),
    "inverse_jacobian": lambda r, q, x, v: (r.inverse_jacobian(q, x),),
    "inverse_condition_number": lambda r, q, x, v: (np.asarray(r.inverse_condition_number(q, x)),),
    "singularity_measures": lambda r, q, x, v: tuple(np.asarray(a) for a in r.singularity_measures(q, x)),
    "platform_mobility": lambda r, q, x, v: (np.asarray(r.platform_mobility(q, x)),),
    "instantaneous_dof": lambda r, q, x, v: (np.asarray(r.instantaneous_dof(q, x)),),
    "platform_wrench": lambda r, q, x, v: (r.platform_wrench(q, x, v),),
    "actuator_forces": lambda r, q, x, v: (r.actuator_forces(q, x, v),),
    "forward_kinematics": lambda r, q, x, v: tuple(np.asarray(a) for a in vars(r.forward_kinematics(q, x)).values()),
    "inverse_kinematics": lambda r, q, x, v: (r.inverse_kinematics(x),),
    "rotation_matrix": lambda r, q, x, v: (r.rotation_matrix(x),),
}


@pytest.mark.parametrize("name", list(BATCHED))
def test_batch_equals_stacked_singles(name: str, hexapod: StewartGough, rng: np.random.Generator) -> None:
    """method(batch)[k] == method(configuration k) for 8 configurations near the constraint manifold."""
    Q, X = regular_configurations(hexapod, rng, 8)
    X = X + rng.normal(size=X.shape) * 1e-3  # slightly off the manifold, so forward kinematics iterates
    V = rng.normal(size=(8, 6)) * 10.0
    method = BATCHED[name]
    batched = method(hexapod, Q, X, V)
    singles = [method(hexapod, Q[k], X[k], V[k]) for k in range(8)]
    for j, out in enumerate(batched):
        stacked = np.stack([single[j] for single in singles])
        assert out.shape == stacked.shape
        np.testing.assert_allclose(out, stacked, rtol=1e-12, atol=1e-12)


def test_q_broadcasts_against_x(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """Broadcasting: q (6,) against x (N, 6), x (6,) against q (N, 6), and 2-D batches."""
    Q, X = regular_configurations(hexapod, rng, 5)
    q = Q[0]
    phi = hexapod.constraints(q, X)
    J_q, J_x = hexapod.jacobians(q, X)
    J_f = hexapod.forward_jacobian(q, X)
    assert phi.shape == (5, 6) and J_q.shape == J_x.shape == J_f.shape == (5, 6, 6)
    for k in range(5):
        np.testing.assert_allclose(phi[k], hexapod.constraints(q, X[k]), rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(J_q[k], hexapod.jacobians(q, X[k])[0], rtol=1e-14)
        np.testing.assert_allclose(J_x[k], hexapod.jacobians(q, X[k])[1], rtol=1e-14)
        np.testing.assert_allclose(J_f[k], hexapod.forward_jacobian(q, X[k]), rtol=1e-12, atol=1e-12)
    assert hexapod.constraints(Q, X[0]).shape == (5, 6)
    np.testing.assert_allclose(hexapod.constraints(Q, X[0])[3], hexapod.constraints(Q[3], X[0]), rtol=1e-14)
    grid_q, grid_x = Q[None, :, :], np.stack([X, X + 0.01])[:, :1, :]  # (1, 5, 6) against (2, 1, 6)
    assert hexapod.constraints(grid_q, grid_x).shape == (2, 5, 6)
    assert hexapod.forward_kinematics(grid_q, grid_x).x.shape == (2, 5, 6)
    np.testing.assert_allclose(hexapod.constraints(grid_q, grid_x)[1, 2], hexapod.constraints(Q[2], X[0] + 0.01))


# -- forward kinematics -------------------------------------------------------------------------------


def test_forward_kinematics_inverts_inverse_kinematics(hexapod: StewartGough, rng: np.random.Generator) -> None:
    """FK(IK(x), x ⊕ small twist) returns x (rotations compared as matrices), rotation vectors in |r| ≤ π."""
    Q, X = regular_configurations(hexapod, rng, 250)
    Q_turned, X_turned = regular_configurations(hexapod, rng, 50, angles=(3.0, np.pi))  # Newton crosses |r| = π
    Q, X = np.concatenate([Q, Q_turned]), np.concatenate([X, X_turned])
    step = np.column_stack([rng.uniform(-0.01, 0.01, (300, 3)), rng.uniform(-0.02, 0.02, (300, 3))])
    result = hexapod.forward_kinematics(Q, twist_step(X, step))
    assert np.all(result.converged)
    assert np.all(result.residual <= 1e-12)
    assert np.all(result.iterations <= 8)
    assert np.max(pose_error(result.x, X)) < 1e-9
    assert np.all(np.linalg.norm(result.x[:, 3:], axis=-1) <= np.pi + 1e-12)


def test_forward_kinematics_at_the_solution_takes_no_step(default_hexapod: StewartGough) -> None:
    """Starting on the manifold, Newton stops at once and returns the guess."""
    x = np.array([0.02, -0.01, 0.55, 0.05, -0.03, 0.2])
    result = default_hexapod.forward_kinematics(default_hexapod.inverse_kinematics(x), x)
    assert bool(result.converged) and int(result.iterations) == 0
    np.testing.assert_array_equal(result.x, x)


# -- singularities ------------------------------------------------------------------------------------

FICHTER_HEIGHTS = [0.2, 0.35, 0.5, 0.8, 1.2]


@pytest.mark.parametrize("turn_deg", [90.0, -90.0])
@pytest.mark.parametrize("z", FICHTER_HEIGHTS)
def test_fichter_singularity(default_hexapod: StewartGough, z: float, turn_deg: float) -> None:
    """Centred and turned by ±90° about the vertical, the symmetric hexapod is Type II singular at every height.

    The lost motion is a screw about the vertical axis (the only twists left fixed by the 3-fold symmetry).
    """
    x = np.array([0.0, 0.0, z, 0.0, 0.0, np.radians(turn_deg)])
    q = default_hexapod.inverse_kinematics(x)
    k, _ = default_hexapod.singularity_measures(q, x)
    assert k <= 1e-9
    assert default_hexapod.inverse_condition_number(q, x) <= 1e-9
    assert default_hexapod.platform_mobility(q, x) == 1
    assert default_hexapod.instantaneous_dof(q, x) == 6  # [J_q J_x] keeps rank 6: J_q = −2 diag(q) is regular
    _, J_x = default_hexapod.jacobians(q, x)
    null_twist = np.linalg.svd(J_x)[2][-1]
    np.testing.assert_allclose(null_twist[[0, 1, 3, 4]], 0.0, atol=1e-9)
    with pytest.raises(SingularConfigurationError, match="Type II"):
        default_hexapod.forward_jacobian(q, x)
    with pytest.raises(SingularConfigurationError, match="Type II"):
        default_hexapod.actuator_forces(q, x, np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0]))


@pytest.mark.parametrize("z", FICHTER_HEIGHTS)
def test_fichter_hexapod_is_well_conditioned_unturned(default_hexapod: StewartGough, z: float) -> None:
    """At 0° (and at ±45°) the same centred poses are regular; det J_x changes sign across ±90°."""
    for turn_deg, bound in ((0.0, 0.1), (45.0, 0.05), (-45.0, 0.05)):
        x = np.array([0.0, 0.0, z, 0.0, 0.0, np.radians(turn_deg)])
        q = default_hexapod.inverse_kinematics(x)
        assert default_hexapod.inverse_condition_number(q, x) > bound
        assert default_hexapod.platform_mobility(q, x) == 0
    turns = np.radians([80.0, 100.0, -80.0, -100.0])
    X = np.column_stack([np.zeros((4, 2)), np.full(4, z), np.zeros((4, 2)), turns])
    _, det = default_hexapod.singularity_measures(default_hexapod.inverse_kinematics(X), X)
    assert det[0] * det[1] < 0 and det[2] * det[3] < 0


@pytest.fixture(scope="module")
def line_singular_design() -> tuple[StewartGough, np.ndarray, np.ndarray]:
    """A hexapod and a pose at which all six leg lines meet one line L (through a, direction e).

    Leg i is drawn from B_i towards a point C_i of L, and its platform point is put on that segment, so at the
    pose x_s every leg line meets L; P_i is then read back into {P}. Returns (robot, x_s, singular twist).
    """
    rng = np.random.default_rng(1989)
    angles = np.radians(60.0 * np.arange(6)) + rng.uniform(-0.3, 0.3, 6)
    base = rng.uniform(0.45, 0.6, (6, 1)) * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(6)])
    a, e = np.array([0.05, -0.04, 0.0]), np.array([0.1, 0.05, 1.0])
    e /= np.linalg.norm(e)
    C = a + rng.uniform(0.9, 1.5, (6, 1)) * e
    W = base + rng.uniform(0.35, 0.55, (6, 1)) * (C - base)  # platform points in {B} at the singular pose
    x_s = np.array([0.03, -0.02, 0.55, 0.1, -0.05, 0.3])
    R_s = rotation(x_s)
    platform = (W - x_s[:3]) @ R_s  # P_i = R_sᵀ (W_i − p_s)
    twist = np.concatenate([np.cross(e, x_s[:3] - a), e])  # rotation about L
    return StewartGough(base=base, platform=platform), x_s, twist


def test_legs_meeting_a_common_line_are_singular(line_singular_design: tuple) -> None:
    """Six leg lines in a special linear complex (all meeting a line L): rank J_x ≤ 5, rotation about L is free."""
    robot, x_s, twist = line_singular_design
    q = robot.inverse_kinematics(x_s)
    assert robot.platform_mobility(q, x_s) >= 1
    k, _ = robot.singularity_measures(q, x_s)
    assert k <= 1e-9
    _, J_x = robot.jacobians(q, x_s)
    assert np.max(np.abs(J_x @ twist)) <= 1e-12 * np.max(np.abs(J_x))
    with pytest.raises(SingularConfigurationError):
        robot.forward_jacobian(q, x_s)


def test_line_singular_design_is_regular_elsewhere(line_singular_design: tuple, rng: np.random.Generator) -> None:
    """The singularity is one of the pose, not of the architecture: nearby poses are regular."""
    robot, x_s, _ = line_singular_design
    X = twist_step(x_s, rng.uniform(-1.0, 1.0, (20, 6)) * [0.03, 0.03, 0.03, 0.1, 0.1, 0.1])
    k = robot.inverse_condition_number(robot.inverse_kinematics(X), X)
    assert np.all(k > 1e-4)
    assert np.all(robot.platform_mobility(robot.inverse_kinematics(X), X) == 0)


# -- Dietmaier's 40 real assembly modes ---------------------------------------------------------------


@pytest.fixture(scope="module")
def dietmaier() -> tuple[StewartGough, np.ndarray, np.ndarray, dict]:
    """Dietmaier's platform, its leg lengths (6,), its 40 postures as poses (40, 6) and the raw data."""
    data = json.loads((DATA / "dietmaier.json").read_text())
    robot = StewartGough(base=data["base"], platform=data["platform"])
    postures = data["postures"]
    X = np.array([posture["position"] + posture["rotation_vector"] for posture in postures])
    return robot, np.array(data["leg_lengths"]), X, data


def test_dietmaier_postures_are_forty_distinct_rotations(dietmaier: tuple) -> None:
    """The data hold 40 proper rotations, their rotation vectors, and 40 pairwise distinct poses."""
    robot, _, X, data = dietmaier
    matrices = np.array([posture["rotation_matrix"] for posture in data["postures"]])
    assert matrices.shape == (40, 3, 3)
    np.testing.assert_allclose(
        matrices @ matrices.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (40, 3, 3)), atol=1e-14
    )
    np.testing.assert_allclose(np.linalg.det(matrices), 1.0, atol=1e-14)
    np.testing.assert_allclose(robot.rotation_matrix(X), matrices, atol=1e-14)
    gaps = pose_error(X[:, None, :], X[None, :, :]) + np.eye(40)
    assert np.min(gaps) > 0.1


def test_dietmaier_postures_have_the_leg_lengths(dietmaier: tuple) -> None:
    """IK of each of the 40 postures reproduces Dietmaier's six leg lengths; the published one is among them."""
    robot, q, X, data = dietmaier
    np.testing.assert_allclose(robot.inverse_kinematics(X), np.broadcast_to(q, (40, 6)), rtol=0, atol=1e-12)
    assert np.max(np.abs(robot.constraints(q, X))) < 1e-12
    published = data["published_posture"]
    R = np.array(published["rotation_matrix"])
    x = np.concatenate([published["position"], Rotation.from_matrix(R).as_rotvec()])
    assert np.min(pose_error(X, x)) < 1e-9


def test_dietmaier_newton_stays_in_each_assembly_mode(dietmaier: tuple, rng: np.random.Generator) -> None:
    """Newton from 1 mm and 1 mrad away from each of the 40 postures converges back to that posture."""
    robot, q, X, _ = dietmaier
    step = rng.uniform(-1e-3, 1e-3, (40, 6))
    result = robot.forward_kinematics(q, twist_step(X, step))
    assert np.all(result.converged)
    assert np.max(pose_error(result.x, X)) < 1e-9
    assert np.all(robot.platform_mobility(q, X) == 0)


# -- bad input ----------------------------------------------------------------------------------------

BASE, PLATFORM = semi_regular(0.5, 12.0), semi_regular(0.3, 48.0)


def _with(points: np.ndarray, index: tuple, value: float) -> np.ndarray:
    out = points.copy()
    out[index] = value
    return out


BAD_DESIGNS = {
    "base too few": ({"base": BASE[:5]}, r"base anchors must have shape \(6, 3\), got \(5, 3\)"),
    "platform planar": ({"platform": PLATFORM[:, :2]}, r"platform points must have shape \(6, 3\), got \(6, 2\)"),
    "base NaN": ({"base": _with(BASE, (2, 1), np.nan)}, "base anchors must be finite"),
    "platform inf": ({"platform": _with(PLATFORM, (0, 2), np.inf)}, "platform points must be finite"),
    "base coincident": ({"base": np.concatenate([BASE[:5], BASE[3:4]])}, "base anchors must be pairwise distinct"),
    "platform coincident": (
        {"platform": np.concatenate([PLATFORM[:1], PLATFORM[:5]])},
        "platform points must be pairwise distinct",
    ),
    "similar regular hexagons": (
        {"base": 0.5 * semi_regular(1.0, 30.0), "platform": 0.3 * semi_regular(1.0, 30.0)},
        "architecture-singular",
    ),
    "similar semi-regular hexagons": (
        {"base": semi_regular(0.5, 12.0), "platform": semi_regular(0.3, 12.0)},
        "architecture-singular",
    ),
}


@pytest.mark.parametrize("case", list(BAD_DESIGNS))
def test_bad_designs_are_refused(case: str) -> None:
    """Wrong shapes, non-finite or coincident points and architecture-singular designs raise ValueError."""
    kwargs, message = BAD_DESIGNS[case]
    with pytest.raises(ValueError, match=message):
        StewartGough(**kwargs)
    with pytest.raises(ValueError, match=message):
        DistanceConstraintMechanism(**({"base": BASE, "platform": PLATFORM} | kwargs), pose_space="spatial")


X_OK = np.array([0.0, 0.0, 0.5, 0.05, -0.02, 0.1])
Q_OK = StewartGough().inverse_kinematics(X_OK)

BAD_CALLS = {
    "q zero": (lambda r: r.constraints(_with(Q_OK, (2,), 0.0), X_OK), r"leg lengths q must be > 0"),
    "q negative": (lambda r: r.jacobians(_with(Q_OK, (5,), -0.4), X_OK), r"leg lengths q must be > 0"),
    "q negative in a batch": (
        lambda r: r.forward_jacobian(np.stack([Q_OK, -Q_OK]), X_OK),
        r"leg lengths q must be > 0",
    ),
    "q zero in forward kinematics": (
        lambda r: r.forward_kinematics(_with(Q_OK, (0,), 0.0), X_OK),
        r"leg lengths q must be > 0",
    ),
    "q short": (lambda r: r.constraints(Q_OK[:5], X_OK), r"q must have shape \(\.\.\., 6\)"),
    "x planar": (lambda r: r.constraints(Q_OK, X_OK[:3]), r"x must have shape \(\.\.\., 6\)"),
    "x in inverse kinematics": (lambda r: r.inverse_kinematics(np.zeros((4, 7))), r"x must have shape \(\.\.\., 6\)"),
    "x NaN": (lambda r: r.jacobians(Q_OK, _with(X_OK, (4,), np.nan)), "x must be finite"),
    "q NaN": (lambda r: r.constraints(_with(Q_OK, (1,), np.nan), X_OK), "q must be finite"),
    "x NaN in rotation_matrix": (lambda r: r.rotation_matrix(_with(X_OK, (3,), np.nan)), "x must be finite"),
    "batch shapes": (
        lambda r: r.constraints(np.broadcast_to(Q_OK, (3, 6)), np.broadcast_to(X_OK, (4, 6))),
        "do not broadcast",
    ),
    "wrench shape": (lambda r: r.actuator_forces(Q_OK, X_OK, np.zeros(3)), r"wrench must have shape \(\.\.\., 6\)"),
    "tau shape": (lambda r: r.platform_wrench(Q_OK, X_OK, np.zeros(5)), r"tau must have shape \(\.\.\., 6\)"),
}


@pytest.mark.parametrize("case", list(BAD_CALLS))
def test_bad_inputs_are_refused(case: str, default_hexapod: StewartGough) -> None:
    """Non-positive leg lengths, wrong shapes and NaN raise a ValueError naming the quantity."""
    call, message = BAD_CALLS[case]
    with pytest.raises(ValueError, match=message):
        call(default_hexapod)


def test_generic_pose_space_is_checked() -> None:
    """An unknown pose space, or points of the wrong dimension for it, are refused."""
    with pytest.raises(ValueError, match="pose_space must be one of"):
        DistanceConstraintMechanism(base=BASE, platform=PLATFORM, pose_space="spherical")
    with pytest.raises(ValueError, match=r"base anchors must have shape \(3, 2\), got \(6, 3\)"):
        DistanceConstraintMechanism(base=BASE, platform=PLATFORM, pose_space="planar")


# -- the generic family member ------------------------------------------------------------------------


def test_generic_spatial_mechanism_equals_stewart_gough(rng: np.random.Generator) -> None:
    """DistanceConstraintMechanism(B, P, pose_space="spatial") gives StewartGough(B, P)'s values."""
    B, P = asymmetric_geometry()
    robot = StewartGough(base=B, platform=P)
    generic = DistanceConstraintMechanism(base=B, platform=P, pose_space="spatial")
    assert generic.characteristic_length == robot.characteristic_length
    Q, X = regular_configurations(robot, rng, 200)
    Q_off = Q * rng.uniform(0.98, 1.02, Q.shape)
    tau = rng.normal(size=(200, 6))
    pairs = [
        (robot.inverse_kinematics(X), generic.inverse_kinematics(X)),
        (robot.constraints(Q_off, X), generic.constraints(Q_off, X)),
        *zip(robot.jacobians(Q_off, X), generic.jacobians(Q_off, X), strict=True),
        (robot.forward_jacobian(Q, X), generic.forward_jacobian(Q, X)),
        (robot.inverse_jacobian(Q, X), generic.inverse_jacobian(Q, X)),
        (robot.inverse_condition_number(Q, X), generic.inverse_condition_number(Q, X)),
        (robot.platform_wrench(Q, X, tau), generic.platform_wrench(Q, X, tau)),
        (robot.forward_kinematics(Q_off, X).x, generic.forward_kinematics(Q_off, X).x),
        (robot.platform_mobility(Q, X), generic.platform_mobility(Q, X)),
    ]
    for ours, theirs in pairs:
        np.testing.assert_allclose(theirs, ours, rtol=1e-12, atol=1e-14)
