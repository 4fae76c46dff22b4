"""Equations of motion of the distance-constraint family against oracles written from body positions alone.

The oracles place every body from the pose (platform points, closed-form inverse kinematics, anchors), take
velocities by finite differences of positions and orientations along a path, and sum ½ m v² + ½ ωᵀ I ω: they
use none of ``kinematics.dynamics``' Jacobians or accelerations.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinematics import Delta, DistanceConstraintMechanism, Planar3RPR, StewartGough
from kinematics.dynamics import (
    STANDARD_GRAVITY,
    InertialParameters,
    RobotDynamics,
    default_inertia,
    rod_from_end_masses,
)
from tests.kinematics.helpers import DYNAMICS_PRESETS

PRESETS = DYNAMICS_PRESETS

#: Gravity for the tests: planar robots stood up, spatial ones with a tilt so that every component acts.
GRAVITY = {2: np.array([0.0, -STANDARD_GRAVITY]), 3: np.array([1.0, -2.0, -9.5])}

STENCIL = (np.array([-2.0, -1.0, 1.0, 2.0]), np.array([1.0, -8.0, 8.0, -1.0]) / 12.0)  # 4th-order first derivative


def make(name: str) -> tuple[object, RobotDynamics]:
    """The preset and its dynamics with the default inertia."""
    robot = PRESETS[name][0]()
    return robot, RobotDynamics(robot)


def random_poses(robot, name: str, rng: np.random.Generator, count: int, margin: float = 0.1) -> np.ndarray:
    """Poses around the home pose, away from singularities (both condition numbers above ``margin``)."""
    _, translation, rotation = PRESETS[name]
    m = robot.n_pose
    rotations = list(robot.pose_space.rotation_columns)
    kept = []
    while len(kept) < count:
        step = rng.uniform(-translation, translation, m)
        step[rotations] = rng.uniform(-rotation, rotation, len(rotations))
        x = robot.retract(robot.home_pose(), step)
        q = robot.inverse_kinematics(x, validate=False)
        if not np.isfinite(q).all():
            continue
        if min(robot.inverse_condition_number(q, x), robot.actuator_condition_number(q, x)) > margin:
            kept.append(x)
    return np.array(kept)


# -- the oracle: bodies placed from the pose --------------------------------------------------------


def body_positions(robot, inertia: InertialParameters, X: np.ndarray) -> dict[str, np.ndarray]:
    """Every body's centre of mass (and orientation) at poses X of shape (K, m), from the geometry alone."""
    d = robot.pose_space.point_dim
    R = robot.rotation_matrix(X).reshape(len(X), d, d)
    P = robot.platform_points_in_base(X)
    q = robot.inverse_kinematics(X)
    A = robot.anchors(q)
    link = P - A
    u = link / np.linalg.norm(link, axis=-1, keepdims=True)
    kinds = np.array(robot.actuator_kinds)[:, None]
    radii = np.where(robot.crank_radii > 0, robot.crank_radii, 1.0)[:, None]
    arm = robot.base + inertia.actuator_com[:, None] * (A - robot.base) / radii
    return {
        "R": R,
        "platform": X[:, :d] + R @ inertia.platform_com,
        "u": u,
        "anchor": A,
        "distal": P - inertia.distal_com[:, None] * u,
        "actuator": np.where(
            kinds == "leg", robot.base + inertia.actuator_com[:, None] * u, np.where(kinds == "crank", arm, A)
        ),
    }


def oracle_potential(robot, inertia: InertialParameters, X: np.ndarray) -> np.ndarray:
    """V = −Σ m g·r over the platform, actuator bodies and distal rods, shape (K,)."""
    b = body_positions(robot, inertia, X)
    g = inertia.gravity
    return -(
        inertia.platform_mass * b["platform"] @ g
        + (b["actuator"] @ g) @ inertia.actuator_mass
        + (b["distal"] @ g) @ inertia.distal_mass
    )


def oracle_kinetic(robot, inertia: InertialParameters, x0: np.ndarray, xi: np.ndarray, xidot: np.ndarray, h=1e-4):
    """T at the chart point retract(x0, ξ) moving with chart velocity ξ̇, shape (K,) for ξ, ξ̇ of shape (K, m).

    Body velocities are 4th-order central differences of body positions along t ↦ retract(x0, ξ + t ξ̇).
    """
    K, m = xi.shape
    offsets, weights = STENCIL
    X = robot.retract(x0, (xi[None] + h * offsets[:, None, None] * xidot[None]).reshape(-1, m)).reshape(4, K, m)
    bodies = [body_positions(robot, inertia, X[j]) for j in range(4)]
    at = body_positions(robot, inertia, robot.retract(x0, xi))

    def rate(key: str) -> np.ndarray:
        return sum(w * b[key] for w, b in zip(weights, bodies)) / h

    d = robot.pose_space.point_dim
    T = 0.5 * inertia.platform_mass * np.sum(rate("platform") ** 2, axis=-1)
    if robot.pose_space.name != "translational":
        W = rate("R") @ np.swapaxes(at["R"], -1, -2)  # Ṙ Rᵀ = [ω]×
        if d == 2:
            T += 0.5 * inertia.platform_inertia[0, 0] * W[:, 1, 0] ** 2
        else:
            omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=-1)
            I_world = at["R"] @ inertia.platform_inertia @ np.swapaxes(at["R"], -1, -2)
            T += 0.5 * np.einsum("Ka,Kab,Kb->K", omega, I_world, omega)
    u, udot = at["u"], rate("u")
    if d == 2:  # the z component of u × u̇
        rod_omega2 = (u[..., 0] * udot[..., 1] - u[..., 1] * udot[..., 0]) ** 2
    else:
        rod_omega2 = np.sum(np.cross(u, udot) ** 2, axis=-1)
    kinds = np.array(robot.actuator_kinds)
    leg, crank, slider = kinds == "leg", kinds == "crank", kinds == "slider"
    anchor_speed2 = np.sum(rate("anchor") ** 2, axis=-1)
    actuator_speed2 = np.sum(rate("actuator") ** 2, axis=-1)
    radii = np.where(crank, robot.crank_radii, 1.0)
    per_leg = (
        leg * (inertia.actuator_mass * actuator_speed2 + inertia.actuator_inertia * rod_omega2)
        + crank * inertia.actuator_inertia * anchor_speed2 / radii**2  # ½ J q̇², q̇ = |Ȧ| / a
        + slider * inertia.actuator_mass * anchor_speed2
        + inertia.distal_mass * np.sum(rate("distal") ** 2, axis=-1)
        + inertia.distal_inertia * rod_omega2
    )
    return T + 0.5 * per_leg.sum(axis=-1)


def derivative(f, eps: float) -> np.ndarray:
    """4th-order central derivative at 0 of f(s), s a scalar."""
    offsets, weights = STENCIL
    return sum(w * f(eps * o) for w, o in zip(weights, offsets)) / eps


# -- Lagrange ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(PRESETS))
def test_mass_matrix_is_the_hessian_of_the_kinetic_energy(name, rng):
    """M(x) equals ∂²T/∂ẋ² of the oracle's kinetic energy (polarisation of the quadratic form)."""
    robot, dyn = make(name)
    m = robot.n_pose
    eye = np.eye(m)
    for x0 in random_poses(robot, name, rng, 2):
        zeros = np.zeros((m, m))
        diagonal = oracle_kinetic(robot, dyn.inertia, x0, zeros, eye)
        pairs = (eye[:, None, :] + eye[None, :, :]).reshape(-1, m)
        both = oracle_kinetic(robot, dyn.inertia, x0, np.zeros_like(pairs), pairs).reshape(m, m)
        M_oracle = both - diagonal[:, None] - diagonal[None, :]  # T(e_j + e_k) − T(e_j) − T(e_k)
        M = dyn.mass_matrix(robot.inverse_kinematics(x0), x0)
        np.testing.assert_allclose(M, M_oracle, rtol=0, atol=1e-7 * np.abs(M_oracle).max())
        assert np.linalg.eigvalsh(M).min() > 0


@pytest.mark.parametrize("name", list(PRESETS))
def test_velocity_terms_are_the_euler_lagrange_expression(name, rng):
    """c(x, ẋ) = d/dt ∂T/∂ξ̇ − ∂T/∂ξ at ξ = 0, ξ̈ = 0 in the chart ξ ↦ retract(x, ξ), by finite differences.

    At ξ = 0 the chart velocity is the twist and ξ̈ is the twist rate (the chart's dexp is I + O(ξ), whose
    first-order term contracts ξ̇ with itself to zero), so the chart's Lagrange equations give c itself.
    """
    robot, dyn = make(name)
    inertia = dyn.inertia.replace(gravity=np.zeros(dyn.inertia.point_dim))
    dyn = RobotDynamics(robot, inertia)
    m = robot.n_pose
    eye = np.eye(m)
    eps = 3e-4
    for x0 in random_poses(robot, name, rng, 2):
        v = rng.uniform(-1.0, 1.0, m)

        def momentum(s: float, x0=x0, v=v) -> np.ndarray:  # ∂T/∂ξ̇ at ξ = s v, exact differences of a quadratic
            xi = np.broadcast_to(s * v, (m, m))
            up = oracle_kinetic(robot, inertia, x0, xi, v + eye)
            down = oracle_kinetic(robot, inertia, x0, xi, v - eye)
            return 0.5 * (up - down)

        def energy_along_axes(s: float, x0=x0, v=v) -> np.ndarray:  # T at ξ = s e_k, for every k
            return oracle_kinetic(robot, inertia, x0, s * eye, np.broadcast_to(v, (m, m)))

        c_oracle = derivative(momentum, eps) - derivative(energy_along_axes, eps)
        c = dyn.bias_forces(robot.inverse_kinematics(x0), x0, v)
        scale = np.abs(dyn.mass_matrix(robot.inverse_kinematics(x0), x0)).max() * np.dot(v, v)
        np.testing.assert_allclose(c, c_oracle, rtol=0, atol=1e-6 * scale)


def test_kinetic_energy_matches_the_oracle(rng):
    """T = ½ ẋᵀ M ẋ equals the sum of the bodies' energies on the hexapod and the Delta."""
    for name in ("hexapod", "Delta"):
        robot, dyn = make(name)
        X = random_poses(robot, name, rng, 3)
        V = rng.uniform(-1.0, 1.0, X.shape)
        T = dyn.kinetic_energy(robot.inverse_kinematics(X), X, V)
        expected = np.array(
            [oracle_kinetic(robot, dyn.inertia, x, np.zeros((1, len(x))), v[None])[0] for x, v in zip(X, V)]
        )
        np.testing.assert_allclose(T, expected, rtol=1e-9)


# -- statics ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(PRESETS))
def test_holding_forces_do_the_virtual_work_of_gravity(name, rng):
    """τ·δq = δV for small feasible displacements: the actuators' work equals the change of potential energy."""
    robot, _ = make(name)
    inertia = default_inertia(robot).replace(gravity=GRAVITY[robot.pose_space.point_dim])
    dyn = RobotDynamics(robot, inertia)
    X = random_poses(robot, name, rng, 3)
    Q = robot.inverse_kinematics(X)
    tau = dyn.holding_forces(Q, X)
    assert np.abs(tau).max() > 1e-3
    step = 1e-5 * rng.standard_normal(X.shape)
    plus, minus = robot.retract(X, step), robot.retract(X, -step)
    dq = robot.inverse_kinematics(plus) - robot.inverse_kinematics(minus)
    dq = np.where(np.array(robot.actuator_kinds) == "crank", np.angle(np.exp(1j * dq)), dq)
    work = np.sum(tau * dq, axis=-1)
    dV = oracle_potential(robot, inertia, plus) - oracle_potential(robot, inertia, minus)
    np.testing.assert_allclose(work, dV, rtol=0, atol=1e-6 * np.abs(tau * dq).sum(axis=-1).max())
    np.testing.assert_allclose(dyn.potential_energy(Q, X), oracle_potential(robot, inertia, X), rtol=1e-12, atol=1e-12)


def test_holding_forces_hold_the_platform_still(rng):
    """With τ = holding_forces and ẋ = 0 the platform does not accelerate."""
    for name in ("hexapod", "Delta"):
        robot, dyn = make(name)
        X = random_poses(robot, name, rng, 2)
        Q = robot.inverse_kinematics(X)
        a = dyn.forward_dynamics(Q, X, np.zeros_like(X), dyn.holding_forces(Q, X))
        assert np.abs(a).max() < 1e-10


# -- energy ------------------------------------------------------------------------------------------------


def run_energy(robot, dyn: RobotDynamics, X: np.ndarray, V: np.ndarray, dt: float, duration: float):
    """Integrate with τ = 0; stop before a singularity (a condition number < 0.2). Returns (E(t), T(t), time)."""
    tau = np.zeros((len(X), robot.n_actuators))
    Q = robot.inverse_kinematics(X)

    def energy(Q, X, V):
        T = dyn.kinetic_energy(Q, X, V)
        return T + dyn.potential_energy(Q, X), T

    E0, T0 = energy(Q, X, V)
    energies, kinetic, t = [E0], [T0], 0.0
    while t < duration - 1e-12:
        state = dyn.step(X, V, tau, dt)
        measures = np.minimum(
            robot.inverse_condition_number(state.q, state.x), robot.actuator_condition_number(state.q, state.x)
        )
        if measures.min() < 0.2:
            break
        Q, X, V = state
        t += dt
        E, T = energy(Q, X, V)
        energies.append(E)
        kinetic.append(T)
        assert np.abs(robot.constraints(Q, X)).max() < 1e-12
    return np.array(energies), np.array(kinetic), t


@pytest.mark.parametrize("name", ["3-RPR", "Delta"])
def test_kinetic_energy_is_conserved_without_gravity(name, rng):
    """No gravity, no actuator effort: T drifts by ≤ 1e-6 relative over 10 s (RKMK4, dt = 10 ms)."""
    robot, _ = make(name)
    inertia = default_inertia(robot).replace(gravity=np.zeros(robot.pose_space.point_dim))
    dyn = RobotDynamics(robot, inertia)
    X = random_poses(robot, name, rng, 2)
    V = 0.02 * rng.uniform(-1.0, 1.0, X.shape)
    E, _, t = run_energy(robot, dyn, X, V, dt=0.01, duration=10.0)
    assert t > 10.0 - 1e-9
    assert np.abs(E - E[0]).max() <= 1e-6 * E[0].min()


def dissipation_balance(dyn: RobotDynamics, X: np.ndarray, V: np.ndarray, power, dt: float, steps: int) -> None:
    """With τ = 0, E(t) + ∫ P dt = E(0) to 1e-6 of the largest kinetic energy.

    P = ``power(Q, X, V)`` (N,) is the friction's, integrated by Simpson's rule over ``steps`` (even) steps of
    ``dt``; the friction takes at least a tenth of that kinetic energy.
    """
    robot = dyn.mechanism
    Q = robot.inverse_kinematics(X)
    tau = np.zeros_like(Q)

    def sample(Q, X, V):
        T = dyn.kinetic_energy(Q, X, V)
        return T + dyn.potential_energy(Q, X), T, power(Q, X, V)

    samples = [sample(Q, X, V)]
    for _ in range(steps):
        Q, X, V = dyn.step(X, V, tau, dt)
        samples.append(sample(Q, X, V))
    E, T, P = (np.array(values) for values in zip(*samples))
    W = np.zeros_like(E)  # ∫ P dt at the even samples
    W[2::2] = np.cumsum(dt / 3.0 * (P[0:-2:2] + 4.0 * P[1:-1:2] + P[2::2]), axis=0)
    assert (W[-1] >= 0.1 * T.max(axis=0)).all(), (W[-1], T.max(axis=0))
    np.testing.assert_allclose(E[::2] + W[::2], np.broadcast_to(E[0], E[::2].shape), rtol=0, atol=1e-6 * T.max())


@pytest.mark.parametrize("name", ["3-RPR", "hexapod", "Delta"])
def test_viscous_friction_dissipates_its_power(name, rng):
    """Drives with viscous friction B, τ = 0, under gravity: E(t) + ∫ q̇ᵀ B q̇ dt = E(0).

    The dissipated work is integrated by Simpson's rule over 1 ms steps, q̇ = J_i ẋ from the kinematics; the
    friction takes at least a tenth of the largest kinetic energy (B chosen per robot), and the balance holds to
    1e-6 of it. A friction with the wrong sign, the wrong Jacobian or none breaks the balance.
    """
    robot, _ = make(name)
    damping = {"3-RPR": 20.0, "hexapod": 200.0, "Delta": 0.5}[name]
    inertia = default_inertia(robot).replace(gravity=GRAVITY[robot.pose_space.point_dim], actuator_damping=damping)
    X = random_poses(robot, name, rng, 2, margin=0.3)
    V = 0.2 * rng.uniform(-1.0, 1.0, X.shape) * robot.pose_scale

    def power(Q, X, V):
        qdot = np.einsum("Nim,Nm->Ni", robot.inverse_jacobian(Q, X), V)
        return np.einsum("Ni,i,Ni->N", qdot, inertia.actuator_damping, qdot)

    dissipation_balance(RobotDynamics(robot, inertia), X, V, power, dt=1e-3, steps=100)


def joint_angular_velocities(robot, X: np.ndarray, V: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """The rod's angular velocity less the arm's, across the rod, by central differences along the twist: (N, n, 3).

    u_i = d_i / ℓ_i from ``link_vectors`` at x ± h ẋ (``retract``) and q from the inverse kinematics; the arm turns
    with w_i q̇_i, w_i = U_i × V_i of a crank's axes (else 0); ω_i = u_i × u̇_i − w_i q̇_i less its component along
    u_i (the rod's free spin). Planar vectors are lifted to 3-D.
    """

    def lift(a: np.ndarray) -> np.ndarray:
        return a if a.shape[-1] == 3 else np.concatenate([a, np.zeros_like(a[..., :1])], axis=-1)

    def rod_and_strokes(x):
        q = robot.inverse_kinematics(x)
        d = lift(robot.link_vectors(q, x))
        return d / np.linalg.norm(d, axis=-1, keepdims=True), q

    u, _ = rod_and_strokes(X)
    (u_up, q_up), (u_down, q_down) = rod_and_strokes(robot.retract(X, h * V)), rod_and_strokes(robot.retract(X, -h * V))
    udot, qdot = (u_up - u_down) / (2.0 * h), (q_up - q_down) / (2.0 * h)
    kinds = np.array(robot.actuator_kinds)
    axes = lift(robot.crank_axes)
    w = np.where((kinds == "crank")[:, None], np.cross(axes[:, 0], axes[:, 1]), 0.0)
    omega = np.cross(u, udot) - w * qdot[..., None]
    return omega - np.einsum("Nid,Nid->Ni", omega, u)[..., None] * u


@pytest.mark.parametrize(
    ("name", "damping"), [("3-RPR", 3.0), ("hexapod", 20.0), ("Delta", 0.6), ("3-RRR", 0.03), ("3-PRR", 0.1)]
)
def test_passive_joint_friction_dissipates_its_power(name, damping, rng):
    """Friction b at each chain's passive joint (base joint or elbow), τ = 0, gravity: E(t) + ∫ b Σ|ω_i|² dt = E(0).

    ω_i, the rod's angular velocity less the crank arm's, by differences of the kinematics (not the dynamics'
    velocity maps); Simpson's rule over 0.25 ms steps; the friction takes a tenth of the largest kinetic energy
    or more, and the balance holds to 1e-6 of it.
    """
    robot, _ = make(name)
    inertia = default_inertia(robot).replace(gravity=GRAVITY[robot.pose_space.point_dim], joint_damping=damping)
    X = random_poses(robot, name, rng, 2, margin=0.3)
    V = 0.2 * rng.uniform(-1.0, 1.0, X.shape) * robot.pose_scale

    def power(Q, X, V):
        omega = joint_angular_velocities(robot, X, V)
        return damping * np.einsum("Nid,Nid->N", omega, omega)

    dissipation_balance(RobotDynamics(robot, inertia), X, V, power, dt=2.5e-4, steps=200)


@pytest.mark.parametrize(("name", "dt"), [("hexapod", 1e-3), ("Delta", 1e-3), ("3-RRR", 2.5e-4)])
def test_total_energy_is_conserved_under_gravity(name, dt, rng):
    """Gravity, τ = 0, starting slow: T + V drifts by ≤ 1e-6 of the largest T until near a singularity.

    RKMK4 with dt = 1 ms (0.25 ms for the 3-RRR, whose 0.14 m links under g make it four times quicker); the
    robots fall from near rest and the run stops where a condition number drops below 0.2 (after 0.1 to 0.3 s).
    """
    robot, _ = make(name)
    inertia = default_inertia(robot).replace(gravity=GRAVITY[robot.pose_space.point_dim])
    dyn = RobotDynamics(robot, inertia)
    X = random_poses(robot, name, rng, 2, margin=0.3)
    V = 0.01 * rng.uniform(-1.0, 1.0, X.shape)
    E, T, t = run_energy(robot, dyn, X, V, dt=dt, duration=1.0)
    assert t >= 0.05
    assert np.abs(E - E[0]).max() <= 1e-6 * T.max()


def test_integrator_has_order_four_on_the_rotation_group(rng):
    """Hexapod, no gravity, turning at ~1 rad/s: halving dt divides the error after 0.2 s by about 2⁴."""
    robot, _ = make("hexapod")
    dyn = RobotDynamics(robot, default_inertia(robot).replace(gravity=np.zeros(3)))
    x0 = random_poses(robot, "hexapod", rng, 1)
    v0 = np.concatenate([0.05 * rng.uniform(-1.0, 1.0, (1, 3)), rng.uniform(-1.0, 1.0, (1, 3))], axis=-1)
    tau = np.zeros((1, 6))

    def run(steps: int) -> tuple[np.ndarray, np.ndarray]:
        state = dyn.step(x0, v0, tau, 0.2, substeps=steps)
        return state.x, state.xdot

    x_ref, v_ref = run(64)
    errors = []
    for steps in (8, 16):
        x, v = run(steps)
        errors.append(np.abs(robot.pose_difference(x, x_ref)).max() + np.abs(v - v_ref).max())
    assert errors[0] / errors[1] > 12.0


# -- the data --------------------------------------------------------------------------------------------


def test_batch_equals_loop(rng):
    """Batched results equal the stacked single ones."""
    robot, dyn = make("hexapod")
    X = random_poses(robot, "hexapod", rng, 3)
    Q = robot.inverse_kinematics(X)
    V = rng.standard_normal(X.shape)
    tau = rng.standard_normal(Q.shape)
    batched = dyn.forward_dynamics(Q, X, V, tau)
    single = np.array([dyn.forward_dynamics(q, x, v, t) for q, x, v, t in zip(Q, X, V, tau)])
    np.testing.assert_allclose(batched, single, rtol=1e-12, atol=1e-12)
    assert dyn.mass_matrix(Q[0], X[0]).shape == (6, 6)


@pytest.mark.parametrize("name", list(PRESETS))
def test_dict_and_json_round_trip(name):
    """to_dict → JSON → from_dict gives the same parameters."""
    _, dyn = make(name)
    data = json.loads(json.dumps(dyn.inertia.to_dict()))
    assert InertialParameters.from_dict(data) == dyn.inertia


def test_codourey_end_masses_are_a_rod():
    """Two end point masses are the rod rod_from_end_masses returns: same mass, centre and inertia."""
    m, c, inertia = rod_from_end_masses(0.2, 0.1, 1.2)
    assert m == pytest.approx(0.3)
    assert c == pytest.approx(0.2 * 1.2 / 0.3)
    assert inertia == pytest.approx(0.2 * (1.2 - c) ** 2 + 0.1 * c**2)


def valid(**changes) -> dict:
    """The 3-RPR's default inertial data with some fields changed."""
    data = default_inertia(Planar3RPR()).to_dict()
    data.update(changes)
    return data


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"platform_mass": -1.0}, r"platform_mass must be a finite number > 0 \[kg\], got -1.0"),
        ({"actuator_mass": [1.0, -0.5, 1.0]}, r"actuator_mass must be ≥ 0 \[kg\], got -0.5 for leg 2"),
        ({"distal_mass": [1.0, 1.0, -2.0]}, r"distal_mass must be ≥ 0 \[kg\], got -2.0 for leg 3"),
        ({"distal_inertia": [0.0, -1e-3, 0.0]}, r"distal_inertia must be ≥ 0 \[kg·m²\], got -0.001 for leg 2"),
        ({"platform_inertia": -0.1}, r"platform_inertia must be positive definite, got eigenvalues \[-0.1\]"),
        ({"gravity": [0.0, 0.0, -9.81]}, r"gravity must have shape \(2,\) like platform_com, got shape \(3,\)"),
        ({"actuator_com": [0.1, 0.1]}, r"actuator_com must be a number or have shape \(3,\), got shape \(2,\)"),
        ({"gravity": [0.0, np.inf]}, r"gravity must be finite"),
        (
            {"actuator_damping": [0.0, -3.0, 0.0]},
            r"actuator_damping must be ≥ 0 \[N·s/m or N·m·s/rad\], got -3.0 for leg 2",
        ),
        ({"actuator_damping": np.nan}, r"actuator_damping must be finite"),
        ({"joint_damping": [0.0, 0.0, -1.0]}, r"joint_damping must be ≥ 0 \[N·m·s/rad\], got -1.0 for leg 3"),
    ],
)
def test_bad_inertial_data_is_refused(changes, match):
    """Negative masses, a non-PD inertia, a wrong gravity: ValueError naming the value."""
    with pytest.raises(ValueError, match=match):
        InertialParameters(**valid(**changes))


def test_bad_spatial_inertia_is_refused():
    """A 3-D platform inertia must be symmetric and positive definite."""
    data = default_inertia(StewartGough()).to_dict()
    with pytest.raises(ValueError, match=r"platform_inertia must be symmetric"):
        InertialParameters(**{**data, "platform_inertia": [[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]})
    with pytest.raises(ValueError, match=r"platform_inertia must be positive definite, got eigenvalues \[-1.0"):
        InertialParameters(**{**data, "platform_inertia": np.diag([1.0, -1.0, 2.0])})
    with pytest.raises(ValueError, match=r"inertial parameters for 6 legs with 3-D points do not fit a robot with 3"):
        RobotDynamics(Delta(), InertialParameters(**data))


def test_bad_forces_and_steps_are_refused():
    """Non-finite or misshapen τ, a bad dt: ValueError naming them."""
    robot, dyn = make("3-RPR")
    x = robot.home_pose()
    q = robot.inverse_kinematics(x)
    with pytest.raises(
        ValueError, match=r"tau must be finite, got 1 non-finite value\(s\), first .*nan.* at index \(1,\)"
    ):
        dyn.forward_dynamics(q, x, np.zeros(3), [0.0, np.nan, 0.0])
    with pytest.raises(
        ValueError, match=r"tau must have shape \(\.\.\., 3\) holding actuator efforts, got shape \(2,\)"
    ):
        dyn.forward_dynamics(q, x, np.zeros(3), [0.0, 1.0])
    with pytest.raises(ValueError, match=r"dt must be a finite number > 0 \[s\], got 0.0"):
        dyn.step(x, np.zeros(3), np.zeros(3), 0.0)
    with pytest.raises(ValueError, match=r"default inertia exists for the presets"):
        default_inertia(DistanceConstraintMechanism(robot.base, robot.platform, pose_space="planar"))
