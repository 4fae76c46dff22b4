"""Crank and slider actuators and the translational pose space: the Delta, the 3-RRR and the 3-PRR.

Each robot is checked against formulas written independently of ``kinematics.family``: SymPy for the 3-RRR's
Jacobians, central differences for the others, the Delta's per-arm inverse kinematics in the arm's own rotated
frame (a circle-circle intersection) and its forward kinematics by trilateration; then the identities every
mechanism meets (J_f J_i = I, virtual work, batch = stacked singles) and both kinds of singularity.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import sympy as sp

from kinematics import Delta, DistanceConstraintMechanism, Planar3PRR, Planar3RRR, SingularConfigurationError
from kinematics.delta import DEFAULT_DELTA

N_CONFIGURATIONS = 1000


def reachable_poses(robot: DistanceConstraintMechanism, count: int, seed: int, spread: np.ndarray) -> tuple:
    """(q, x) of ``count`` random poses around the home pose that every leg reaches and that are regular."""
    rng = np.random.default_rng(seed)
    x = robot.home_pose() + rng.uniform(-1.0, 1.0, (4 * count, robot.n_pose)) * spread
    q = robot.inverse_kinematics(x, validate=False)
    ok = np.isfinite(q).all(axis=-1)
    q, x = q[ok], x[ok]
    k2 = robot.inverse_condition_number(q, x, validate=False)
    k1 = robot.actuator_condition_number(q, x, validate=False)
    ok = (k2 > 1e-3) & (k1 > 1e-3)
    assert ok.sum() >= count
    return q[ok][:count], x[ok][:count]


SPREADS = {
    "delta": np.array([0.4, 0.4, 0.15]),
    "3rrr": np.array([0.08, 0.08, 0.4]),
    "3prr": np.array([0.08, 0.08, 0.4]),
}
ROBOTS = {"delta": Delta, "3rrr": Planar3RRR, "3prr": Planar3PRR}


@pytest.fixture(params=sorted(ROBOTS))
def member(request: pytest.FixtureRequest) -> tuple[DistanceConstraintMechanism, np.ndarray, np.ndarray]:
    """(robot, q, x): each new member with 1000 regular configurations."""
    robot = ROBOTS[request.param]()
    q, x = reachable_poses(robot, N_CONFIGURATIONS, 1, SPREADS[request.param])
    return robot, q, x


# -- Jacobians ------------------------------------------------------------------------------------


def test_jacobians_against_central_differences(member) -> None:
    """J_q = ∂Φ/∂q (diagonal) and J_x = ∂Φ/∂x match central differences on 1000 configurations."""
    robot, q, x = member
    J_q, J_x = robot.jacobians(q, x)
    h = 1e-6
    for j in range(robot.n_actuators):
        dq = np.zeros(robot.n_actuators)
        dq[j] = h
        column = (robot.constraints(q + dq, x) - robot.constraints(q - dq, x)) / (2 * h)
        np.testing.assert_allclose(J_q[..., j], column, atol=1e-7)
    for j in range(robot.n_pose):
        dx = np.zeros(robot.n_pose)
        dx[j] = h
        column = (robot.constraints(q, x + dx) - robot.constraints(q, x - dx)) / (2 * h)
        np.testing.assert_allclose(J_x[..., j], column, atol=1e-7)
    off = J_q * (1 - np.eye(robot.n_actuators))
    assert np.abs(off).max() == 0.0


def test_3rrr_jacobians_against_sympy() -> None:
    """The 3-RRR's Φ, J_q, J_x equal SymPy's derivatives of ‖p + R(φ) P_i − B_i − a (cos q u_i + sin q v_i)‖² − l²."""
    robot = Planar3RRR()
    q_sym = sp.symbols("q0:3")
    X, Y, PHI = sp.symbols("x y phi")
    R = sp.Matrix([[sp.cos(PHI), -sp.sin(PHI)], [sp.sin(PHI), sp.cos(PHI)]])
    _, _, a, ell = robot.dimensions
    phi = []
    for i in range(3):
        B = sp.Matrix(robot.base[i].tolist())
        P = sp.Matrix(robot.platform[i].tolist())
        u, v = (sp.Matrix(axis.tolist()) for axis in robot.crank_axes[i])
        elbow = B + a * (sp.cos(q_sym[i]) * u + sp.sin(q_sym[i]) * v)
        d = sp.Matrix([X, Y]) + R * P - elbow
        phi.append(d.dot(d) - ell**2)
    Phi = sp.Matrix(phi)
    f = sp.lambdify((q_sym, (X, Y, PHI)), [Phi, Phi.jacobian(q_sym), Phi.jacobian([X, Y, PHI])], "numpy")
    q, x = reachable_poses(robot, N_CONFIGURATIONS, 2, SPREADS["3rrr"])
    J_q, J_x = robot.jacobians(q, x)
    constraints = robot.constraints(q, x + 0.01)
    for i in range(N_CONFIGURATIONS):
        _, ref_q, ref_x = (np.array(v, dtype=float) for v in f(q[i], x[i] + np.array([0.0, 0.0, 0.0])))
        np.testing.assert_allclose(J_q[i], ref_q, atol=1e-12)
        np.testing.assert_allclose(J_x[i], ref_x, atol=1e-12)
        np.testing.assert_allclose(constraints[i], np.array(f(q[i], x[i] + 0.01)[0], dtype=float).ravel(), atol=1e-13)


# -- the identities every mechanism meets -------------------------------------------------------------


def test_forward_times_inverse_jacobian_is_identity(member) -> None:
    """J_f J_i = I and J_i J_f = I away from both kinds of singularity."""
    robot, q, x = member
    J_f, J_i = robot.forward_jacobian(q, x), robot.inverse_jacobian(q, x)
    eye = np.eye(robot.n_pose)
    assert np.abs(J_f @ J_i - eye).max() < 1e-9
    assert np.abs(J_i @ J_f - eye).max() < 1e-9


def test_virtual_work(member) -> None:
    """τ · q̇ = w · ẋ with w = J_iᵀ τ (``platform_wrench``) and ẋ = J_f q̇; ``actuator_forces`` inverts it."""
    robot, q, x = member
    rng = np.random.default_rng(3)
    tau = rng.normal(size=q.shape)
    q_rate = rng.normal(size=q.shape)
    w = robot.platform_wrench(q, x, tau)
    x_rate = np.einsum("nij,nj->ni", robot.forward_jacobian(q, x), q_rate)
    np.testing.assert_allclose(np.sum(tau * q_rate, axis=-1), np.sum(w * x_rate, axis=-1), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(robot.actuator_forces(q, x, w), tau, rtol=1e-8, atol=1e-8)


def test_batch_equals_stacked_singles(member) -> None:
    """Every batched method gives, row for row, what it gives for one configuration."""
    robot, q, x = member
    q, x = q[:20], x[:20]
    batched = {
        "constraints": robot.constraints(q, x),
        "forward_jacobian": robot.forward_jacobian(q, x),
        "inverse_jacobian": robot.inverse_jacobian(q, x),
        "inverse_kinematics": robot.inverse_kinematics(x),
        "inverse_condition_number": robot.inverse_condition_number(q, x),
        "actuator_condition_number": robot.actuator_condition_number(q, x),
        "actuator_mobility": robot.actuator_mobility(q, x),
        "platform_mobility": robot.platform_mobility(q, x),
        "anchors": robot.anchors(q),
    }
    for i in range(len(q)):
        single = {
            "constraints": robot.constraints(q[i], x[i]),
            "forward_jacobian": robot.forward_jacobian(q[i], x[i]),
            "inverse_jacobian": robot.inverse_jacobian(q[i], x[i]),
            "inverse_kinematics": robot.inverse_kinematics(x[i]),
            "inverse_condition_number": robot.inverse_condition_number(q[i], x[i]),
            "actuator_condition_number": robot.actuator_condition_number(q[i], x[i]),
            "actuator_mobility": robot.actuator_mobility(q[i], x[i]),
            "platform_mobility": robot.platform_mobility(q[i], x[i]),
            "anchors": robot.anchors(q[i]),
        }
        for name, value in single.items():
            np.testing.assert_allclose(batched[name][i], value, rtol=1e-12, atol=1e-15, err_msg=name)


def test_inverse_kinematics_closes_the_constraints_and_newton_returns_the_pose(member) -> None:
    """Φ(IK(x), x) = 0, and Newton's forward kinematics from a guess 1 cm / 0.05 rad away returns x."""
    robot, q, x = member
    assert np.abs(robot.constraints(q, x)).max() < 1e-13
    guess = x + np.random.default_rng(4).uniform(-1.0, 1.0, x.shape) * np.where(robot.pose_scale == 1.0, 0.01, 0.05)
    result = robot.forward_kinematics(q, guess)
    assert result.converged.all()
    np.testing.assert_allclose(result.x, x, atol=1e-9)


def test_equality_hash_repr_and_pickle() -> None:
    """A robot equals its pickled copy and the robot its repr builds; other geometries or branches differ."""
    for robot in (Delta(), Planar3RRR(elbows=(1, -1, 1)), Planar3PRR(branches=-1)):
        assert pickle.loads(pickle.dumps(robot)) == robot
        assert hash(pickle.loads(pickle.dumps(robot))) == hash(robot)
        rebuilt = eval(repr(robot), {"Delta": Delta, "Planar3RRR": Planar3RRR, "Planar3PRR": Planar3PRR})
        assert rebuilt == robot
    assert Delta() != Delta(elbows="in")
    assert Planar3RRR() != Planar3RRR(elbows=1)
    assert Planar3RRR() != Planar3RRR(link=0.15)


# -- the Delta ------------------------------------------------------------------------------------


def delta_ik_per_arm(p: np.ndarray, base_radius: float, platform_radius: float, a: float, ell: float) -> np.ndarray:
    """The widely published per-arm solution: rotate p into arm i's frame, intersect two circles in its plane.

    In arm i's frame (azimuth 120°·i turned back to 0) the motor is at (R_b, 0, 0) and the arm turns in the
    x–z plane; the forearm's sphere of radius l about the plate joint E = p' + (r_p, 0, 0) cuts that plane in a
    circle of radius √(l² − E_y²) about (E_x, E_z). The elbow is where it meets the arm's circle of radius a
    about the motor; the elbow-out one is the farther from the base's axis.
    """
    q = np.empty(p.shape)
    for i in range(3):
        angle = -np.radians(120.0 * i)
        c, s = np.cos(angle), np.sin(angle)
        ex = c * p[:, 0] - s * p[:, 1] + platform_radius
        ey = s * p[:, 0] + c * p[:, 1]
        ez = p[:, 2]
        r2 = np.sqrt(ell * ell - ey * ey)  # the forearm's circle in the arm's plane
        # circles: centre m1 = (R_b, 0) radius a, centre m2 = (ex, ez) radius r2 (coordinates (x, z))
        dx, dz = ex - base_radius, ez
        dist = np.hypot(dx, dz)
        along = (a * a - r2 * r2 + dist * dist) / (2 * dist)
        h = np.sqrt(a * a - along * along)
        mx, mz = base_radius + along * dx / dist, along * dz / dist
        candidates = [(mx + h * dz / dist, mz - h * dx / dist), (mx - h * dz / dist, mz + h * dx / dist)]
        elbow = np.where(
            (candidates[0][0] > candidates[1][0])[:, None], np.stack(candidates[0], -1), np.stack(candidates[1], -1)
        )
        q[:, i] = np.arctan2(-elbow[:, 1], elbow[:, 0] - base_radius)  # angle below the outward horizontal
    return q


def delta_fk_trilateration(centres: np.ndarray, ell: float) -> np.ndarray:
    """Trilateration: the two points at distance l from three centres (each (N, 3)), lower z first, (N, 2, 3)."""
    c1, c2, c3 = centres[:, 0], centres[:, 1], centres[:, 2]
    ex = (c2 - c1) / np.linalg.norm(c2 - c1, axis=-1, keepdims=True)
    i = np.sum(ex * (c3 - c1), axis=-1)
    ey = c3 - c1 - i[:, None] * ex
    ey /= np.linalg.norm(ey, axis=-1, keepdims=True)
    ez = np.cross(ex, ey)
    d = np.linalg.norm(c2 - c1, axis=-1)
    j = np.sum(ey * (c3 - c1), axis=-1)
    u = d / 2.0  # equal radii
    v = (i * i + j * j) / (2 * j) - i / j * u
    w = np.sqrt(ell * ell - u * u - v * v)
    points = [c1 + u[:, None] * ex + v[:, None] * ey + sign * w[:, None] * ez for sign in (1.0, -1.0)]
    lower_first = points[0][:, 2] <= points[1][:, 2]
    lower = np.where(lower_first[:, None], points[0], points[1])
    upper = np.where(lower_first[:, None], points[1], points[0])
    return np.stack([lower, upper], axis=1)


def test_delta_kinematics_against_per_arm_and_trilateration() -> None:
    """IK equals the per-arm solution and FK (both branches) trilateration on 1000 poses; FK(IK(p)) = p."""
    robot = Delta()
    dims = (DEFAULT_DELTA[k] for k in ("base_radius", "platform_radius", "upper_arm", "forearm"))
    R_b, r_p, a, ell = dims
    _, x = reachable_poses(robot, N_CONFIGURATIONS, 5, SPREADS["delta"])
    q = robot.inverse_kinematics(x)
    np.testing.assert_allclose(q, delta_ik_per_arm(x, R_b, r_p, a, ell), atol=1e-12)
    both = robot.sphere_intersections(q)
    np.testing.assert_allclose(both, delta_fk_trilateration(robot.anchors(q) - robot.platform, ell), atol=1e-10)
    np.testing.assert_allclose(robot.forward_kinematics_closed_form(q), x, atol=1e-12)
    assert (both[:, 1, 2] > 0).all()  # the other solution is the plate flipped above the base
    assert robot.forward_kinematics_closed_form(q[0], upper=True)[2] == pytest.approx(both[0, 1, 2])


def test_delta_centre_is_regular_and_a_stretched_arm_is_type_one() -> None:
    """At the workspace centre both measures are well away from 0; an arm in line with its forearm is Type I."""
    robot = Delta()
    home = robot.home_pose()
    q = robot.inverse_kinematics(home)
    np.testing.assert_allclose(np.degrees(q), 30.0, atol=1e-12)
    assert robot.inverse_condition_number(q, home) > 0.3
    assert robot.actuator_condition_number(q, home) > 0.9
    assert robot.actuator_mobility(q, home) == 0 and robot.platform_mobility(q, home) == 0
    # stretch arm 0: its plate joint in its vertical plane (y = 0), a + l from its motor, low on the far side
    R_b, r_p, a, ell = robot.dimensions
    z = -1.5
    p = np.array([R_b - r_p - np.sqrt((a + ell) ** 2 - z * z), 0.0, z])
    q = robot.inverse_kinematics(p)  # every arm reaches
    arm = robot.anchors(q)[0] - robot.base[0]
    forearm = robot.link_vectors(q, p)[0]
    assert arm @ forearm / (a * ell) == pytest.approx(1.0, abs=1e-12)  # in line: stretched straight
    assert robot.actuator_condition_number(q, p) < 1e-6
    assert robot.actuator_mobility(q, p, rtol=1e-6) == 1
    assert robot.platform_mobility(q, p) == 0  # not Type II: the plate stays locked by the motors
    with pytest.raises(SingularConfigurationError, match="Type I"):
        robot.inverse_jacobian(q, p)
    robot.forward_jacobian(q, p)  # J_x is regular: J_f exists (it loses rank)
    assert np.linalg.matrix_rank(robot.forward_jacobian(q, p), tol=1e-6) == 2


# -- the 3-RRR and the 3-PRR ------------------------------------------------------------------------------


def test_3rrr_has_eight_inverse_kinematics_solutions_and_returns_the_chosen_one() -> None:
    """The eight elbow combinations all close the constraints at the same pose, with different crank angles."""
    x = np.array([0.02, -0.01, 0.1])
    solutions = []
    for code in range(8):
        elbows = tuple(1 if code >> i & 1 else -1 for i in range(3))
        robot = Planar3RRR(elbows=elbows)
        q = robot.inverse_kinematics(x)
        assert np.abs(robot.constraints(q, x)).max() < 1e-14
        solutions.append(q)
    assert len({tuple(np.round(s, 9)) for s in solutions}) == 8


@pytest.mark.parametrize(("straight", "crank", "link"), [("stretched", 0.14, 0.16), ("folded", 0.1, 0.27)])
def test_3rrr_leg_stretched_or_folded_is_type_one(straight: str, crank: float, link: float) -> None:
    """A pose where leg 0's crank and link are in line (|B P| = a + l or l − a) has actuator mobility 1."""
    robot = Planar3RRR(crank=crank, link=link)
    _, _, a, ell = robot.dimensions
    # move the platform (φ = 0) along the line B_0 → centre until |B_0 P_0| = a + l (stretched) or l − a (folded)
    B, P = robot.base[0], robot.platform[0]
    inward = -B / np.linalg.norm(B)
    p = B + ((a + ell) if straight == "stretched" else (ell - a)) * inward - P
    x = np.array([p[0], p[1], 0.0])
    q = robot.inverse_kinematics(x)  # every leg reaches
    assert np.abs(robot.constraints(q, x)).max() < 1e-13
    arm = robot.anchors(q)[0] - B
    link_vector = robot.link_vectors(q, x)[0]
    cosine = (arm @ link_vector) / (np.linalg.norm(arm) * np.linalg.norm(link_vector))
    assert abs(cosine) == pytest.approx(1.0, abs=1e-9)  # in line, by the geometry alone
    assert robot.actuator_condition_number(q, x) < 1e-6
    assert robot.actuator_mobility(q, x, rtol=1e-6) == 1
    with pytest.raises(SingularConfigurationError, match="Type I"):
        robot.inverse_jacobian(q, x)


def test_3rrr_distal_links_through_one_point_is_type_two() -> None:
    """Elbows placed so that the three distal links' lines meet in one point C: platform mobility 1 (Type II)."""
    robot = Planar3RRR()
    _, _, a, _ = robot.dimensions
    x = np.zeros(3)
    P = robot.platform  # φ = 0, p = 0: the platform points in {B}
    C = np.array([0.03, -0.02])
    elbows, lengths = np.empty((3, 2)), np.empty(3)
    for i in range(3):
        u = (P[i] - C) / np.linalg.norm(P[i] - C)
        # the elbow A = P_i + t u on the line C P_i, at the crank's reach a from B_i: a quadratic in t
        w = P[i] - robot.base[i]
        t = max(np.roots([1.0, 2.0 * (u @ w), w @ w - a * a]).real)
        elbows[i], lengths[i] = P[i] + t * u, t
    arm = elbows - robot.base
    u, v = robot.crank_axes[:, 0], robot.crank_axes[:, 1]
    q = np.arctan2(np.sum(arm * v, axis=-1), np.sum(arm * u, axis=-1))
    concurrent = DistanceConstraintMechanism(
        robot.base,
        robot.platform,
        pose_space="planar",
        actuators="crank",
        link_lengths=lengths,
        crank_radii=a,
        crank_axes=robot.crank_axes,
        home=x,
        check_architecture=False,
    )
    np.testing.assert_allclose(concurrent.anchors(q), elbows, atol=1e-15)
    assert np.abs(concurrent.constraints(q, x)).max() < 1e-14
    assert concurrent.inverse_condition_number(q, x) < 1e-9
    assert concurrent.platform_mobility(q, x) == 1
    assert concurrent.actuator_condition_number(q, x) > 0.1  # not Type I
    with pytest.raises(SingularConfigurationError, match="Type II"):
        concurrent.forward_jacobian(q, x)


def test_3prr_link_square_to_its_rail_is_type_one() -> None:
    """A slider whose link is perpendicular to its rail cannot move the platform along the link: Type I."""
    robot = Planar3PRR()
    _, _, ell = robot.dimensions
    B, e, P = robot.base[0], robot.rails[0], robot.platform[0]
    normal = np.array([-e[1], e[0]])
    normal *= np.sign(normal @ (-B))  # towards the inside of the triangle
    carriage = B + 0.26 * e
    p = carriage + ell * normal - P
    x = np.array([p[0], p[1], 0.0])
    q = robot.inverse_kinematics(x, validate=False)
    q[0] = 0.26  # both branches coincide there
    assert np.abs(robot.constraints(q, x)).max() < 1e-12
    assert robot.actuator_condition_number(q, x) < 1e-9
    assert robot.actuator_mobility(q, x) == 1


# -- bad input -----------------------------------------------------------------------------------------


def test_bad_input_is_refused_with_the_expected_and_actual_values() -> None:
    """Bad geometry, actuation data and unreachable poses raise precise errors."""
    with pytest.raises(ValueError, match="forearm must be longer"):
        Delta(forearm=0.3)
    with pytest.raises(ValueError, match="elbows must be 'out' or 'in', got 'up'"):
        Delta(elbows="up")
    with pytest.raises(ValueError, match="elbows must be \\+1 or −1"):
        Planar3RRR(elbows=(1, 0, 1))
    with pytest.raises(ValueError, match=r"home pose .* must be reachable"):
        Planar3RRR(crank=0.05, link=0.05)
    with pytest.raises(ValueError, match="pose out of reach: leg 1"):
        Delta().inverse_kinematics([0.0, 0.0, -3.0])
    base = Planar3RRR().base
    with pytest.raises(ValueError, match="crank_radii are required"):
        DistanceConstraintMechanism(base, base * 0.2, pose_space="planar", actuators="crank", link_lengths=0.1)
    with pytest.raises(ValueError, match=r"crank_axes .* required"):
        DistanceConstraintMechanism(
            Delta().base,
            Delta().platform,
            pose_space="translational",
            actuators="crank",
            link_lengths=1.0,
            crank_radii=0.5,
        )
    with pytest.raises(ValueError, match="must be unit vectors"):
        DistanceConstraintMechanism(
            base, base * 0.2, pose_space="planar", actuators="slider", link_lengths=0.1, rails=[2.0, 0.0]
        )
    with pytest.raises(ValueError, match="link_lengths must be > 0"):
        DistanceConstraintMechanism(
            base, base * 0.2, pose_space="planar", actuators="slider", link_lengths=-1.0, rails=[1.0, 0.0]
        )
    with pytest.raises(ValueError, match=r"q must have shape \(\.\.\., 3\)"):
        Delta().forward_jacobian([0.1, 0.2], [0.0, 0.0, -1.3])
