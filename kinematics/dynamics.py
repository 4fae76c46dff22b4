"""Rigid-body dynamics of the distance-constraint family: the equations of motion and an integrator on the manifold.

The state is (x, ẋ): the platform pose x of the mechanism's pose space and the platform velocity ẋ in the
mechanism's twist convention (the one J_x, J_f and J_i refer to, see ``kinematics.family``):

    planar         ẋ = (ẋ, ẏ [m/s], φ̇ [rad/s]);
    translational  ẋ = ṗ [m/s] (the plate does not turn);
    spatial        ẋ = (v, ω): v [m/s] the velocity of the origin of {P}, ω [rad/s] the angular velocity with
                   Ṙ = [ω]× R, both in {B} axes (not ṙ, the rate of the rotation vector).

The actuator coordinates q are not a state: q = q(x) on the robot's own inverse-kinematics branch, q̇ = J_i ẋ.

The bodies and their inertial data are ``kinematics.inertia.InertialParameters``'s (with d_i = p + R P_i −
A_i(q_i), ℓ_i = ‖d_i‖, u_i = d_i / ℓ_i).

Every body's velocity is linear in ẋ, V_b = J_b(x) ẋ, so with the body's inertia M_b

    M(x) ẍ + c(x, ẋ) + G(x) = J_iᵀ τ,   M = Σ_b J_bᵀ M_b J_b,   c = Σ_b J_bᵀ (M_b J̇_b ẋ + gyroscopic),
    G = ∂V/∂x = −Σ_b m_b J_bᵀ g,

Kane's form of Lagrange's equations in twist coordinates. J̇_b ẋ is the acceleration of body b along the
motion of constant twist ẋ (ẍ = 0), written analytically: for a platform point ω × (ω × R P_i), for the
actuator q̈⁰ from the second derivative of Φ_i = 0, for the rods ü⁰ from that of u_i = d_i / ℓ_i. A rod's
rotational energy ½ I |u̇|² is that of a point of mass I moving with u (its angular velocity is u × u̇, of
norm |u̇|). τ are the actuator efforts dual to q (forces [N] for legs and sliders, torques [N·m] for cranks).
The drives' viscous friction (``actuator_damping`` B) takes B q̇ from τ: c includes J_iᵀ B J_i ẋ.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from kinematics._validation import FloatArray, as_float_array, batch_vector, check_finite
from kinematics.family import DistanceConstraintMechanism
from kinematics.inertia import STANDARD_GRAVITY, InertialParameters, default_inertia, rod_from_end_masses, uniform_rod
from kinematics.linalg import batched_solve

__all__ = [
    "STANDARD_GRAVITY",
    "DynamicsState",
    "InertialParameters",
    "RobotDynamics",
    "default_inertia",
    "rod_from_end_masses",
    "uniform_rod",
]


class DynamicsState(NamedTuple):
    """A state of the robot after an integration step.

    Attributes:
        q: Actuator coordinates on the robot's inverse-kinematics branch, shape (..., n).
        x: Platform pose, shape (..., m).
        xdot: Platform twist (see the module docstring), shape (..., m).
    """

    q: FloatArray
    x: FloatArray
    xdot: FloatArray


class _Kinematics(NamedTuple):
    """Velocity maps and constant-twist accelerations of every body, batch-flattened (N leading)."""

    J_platform: FloatArray  # (N, d, m): ẋ → velocity of the platform's centre of mass
    a_platform: FloatArray  # (N, d): its acceleration at ẍ = 0
    J_q: FloatArray  # (N, n, m): rows of J_i, ẋ → q̇
    qdd: FloatArray  # (N, n): q̈ at ẍ = 0
    J_u: FloatArray  # (N, n, d, m): ẋ → u̇_i
    udd: FloatArray  # (N, n, d): ü_i at ẍ = 0
    J_distal: FloatArray  # (N, n, d, m): ẋ → velocity of the distal rod's centre of mass
    a_distal: FloatArray  # (N, n, d)
    J_actuator: FloatArray  # (N, n, d, m): ẋ → velocity of the actuator body's centre of mass (for its weight)
    omega: FloatArray  # (N, r): platform angular velocity (r = 3 spatial, 1 planar, 0 translational)
    inertia_world: FloatArray  # (N, r, r): platform inertia about its centre of mass in {B} axes
    qdot: FloatArray  # (N, n): actuator rates q̇ = J_i ẋ
    J_joint: FloatArray | None  # (N, n, 3, m): ẋ → passive joints' relative angular velocity (None without friction)
    xdot: FloatArray  # (N, m): the platform twist


class RobotDynamics:
    """The equations of motion M(x) ẍ + c(x, ẋ) + G(x) = J_iᵀ τ of a distance-constraint robot.

    See the module docstring for the state, the bodies and the formulation. Every method takes the
    mechanism's (q, x) with q on the constraint manifold (Φ(q, x) = 0, e.g. ``inverse_kinematics(x)``) and
    broadcasts over leading batch dimensions.

    Args:
        mechanism: The robot's kinematics.
        inertia: Its inertial parameters; default ``default_inertia(mechanism)`` (presets only).

    Raises:
        ValueError: If the parameters' number of legs or point dimension differ from the mechanism's.
    """

    def __init__(self, mechanism: DistanceConstraintMechanism, inertia: InertialParameters | None = None) -> None:
        """Check that the parameters fit the mechanism (see the class docstring)."""
        if not isinstance(mechanism, DistanceConstraintMechanism):
            raise TypeError(f"mechanism must be a DistanceConstraintMechanism, got {type(mechanism).__name__}")
        inertia = default_inertia(mechanism) if inertia is None else inertia
        space = mechanism.pose_space
        if inertia.n_legs != mechanism.n_actuators or inertia.point_dim != space.point_dim:
            raise ValueError(
                f"inertial parameters for {inertia.n_legs} legs with {inertia.point_dim}-D points do not fit a "
                f"robot with {mechanism.n_actuators} legs and {space.point_dim}-D points"
            )
        self.mechanism = mechanism
        self.inertia = inertia
        self._space = space
        kinds = np.array(mechanism.actuator_kinds)
        self._leg = (kinds == "leg").astype(np.float64)
        self._crank = (kinds == "crank").astype(np.float64)
        self._slider = (kinds == "slider").astype(np.float64)
        self._lam = self._leg  # ℓ_i = λ_i q_i + l_i
        ine = inertia
        # Weight of q̇_i² (crank rotor, slider carriage) and of |u̇_i|² (leg cylinder, distal rod's rotation).
        self._w_q = self._crank * ine.actuator_inertia + self._slider * ine.actuator_mass
        self._w_u = self._leg * (ine.actuator_mass * ine.actuator_com**2 + ine.actuator_inertia) + ine.distal_inertia
        # Crank arm's centre of mass as a fraction of the arm: (c / a) A′ q̇ is its velocity.
        a = np.where(mechanism.crank_radii > 0, mechanism.crank_radii, 1.0)
        self._arm_fraction = self._crank * ine.actuator_com / a + self._slider

    # -- validation ---------------------------------------------------------------------------------

    def _state(self, q: Any, x: Any, xdot: Any = None) -> tuple[FloatArray, ...]:
        m, n = self.mechanism.n_pose, self.mechanism.n_actuators
        q = batch_vector("q", q, n, self.mechanism.q_description)
        x = batch_vector("x", x, m, self.mechanism.x_description)
        arrays = [q, x]
        if xdot is not None:
            arrays.append(batch_vector("xdot", xdot, m, "a platform twist"))
        try:
            batch = np.broadcast_shapes(*(arr.shape[:-1] for arr in arrays))
        except ValueError:
            shapes = ", ".join(str(arr.shape) for arr in arrays)
            raise ValueError(f"batch shapes of (q, x, xdot) do not broadcast: {shapes}") from None
        return tuple(np.broadcast_to(arr, batch + arr.shape[-1:]) for arr in arrays)

    def _tau(self, tau: Any, batch: tuple[int, ...]) -> FloatArray:
        n = self.mechanism.n_actuators
        tau = as_float_array("tau", tau)
        if tau.ndim == 0 or tau.shape[-1] != n:
            raise ValueError(f"tau must have shape (..., {n}) holding actuator efforts, got shape {tau.shape}")
        check_finite("tau", tau)
        try:
            return np.broadcast_to(tau, batch + (n,))
        except ValueError:
            raise ValueError(f"tau of shape {tau.shape} does not broadcast with the state's batch {batch}") from None

    # -- the bodies' velocity maps ------------------------------------------------------------------

    def _point_map(self, x: FloatArray, r: FloatArray) -> FloatArray:
        """ẋ → velocity of the points p + r (r in {B} axes, shape (N, k, d)), shape (N, k, d, m)."""
        N, k, d = r.shape
        name = self._space.name
        eye = np.broadcast_to(np.eye(d), (N, k, d, d))
        if name == "translational":
            return eye.copy()
        if name == "planar":  # v + φ̇ S r
            return np.concatenate([eye, np.stack([-r[..., 1], r[..., 0]], axis=-1)[..., None]], axis=-1)
        skew = np.zeros((N, k, 3, 3))  # v + ω × r = v − [r]× ω
        skew[..., 0, 1], skew[..., 0, 2], skew[..., 1, 2] = r[..., 2], -r[..., 1], r[..., 0]
        skew[..., 1, 0], skew[..., 2, 0], skew[..., 2, 1] = -r[..., 2], r[..., 1], -r[..., 0]
        return np.concatenate([eye, skew], axis=-1)

    def _point_acceleration(self, xdot: FloatArray, r: FloatArray) -> FloatArray:
        """Acceleration of the points p + r at constant twist, shape (N, k, d)."""
        name = self._space.name
        if name == "translational":
            return np.zeros_like(r)
        if name == "planar":
            return -(xdot[:, None, 2:3] ** 2) * r
        omega = np.broadcast_to(xdot[:, None, 3:], r.shape)
        return np.cross(omega, np.cross(omega, r))

    def _kinematics(self, q: FloatArray, x: FloatArray, xdot: FloatArray) -> _Kinematics:
        mech, ine = self.mechanism, self.inertia
        N = x.shape[0]
        R = self._space.rotation(x).reshape(N, self._space.point_dim, self._space.point_dim)
        RP = np.einsum("Nab,ib->Nia", R, mech.platform)
        P = x[:, None, : self._space.point_dim] + RP
        A, dA, ell = mech._anchor_terms(q)
        c, s = np.cos(q)[..., None], np.sin(q)[..., None]
        axes = mech.crank_axes
        ddA = -mech.crank_radii[:, None] * (c * axes[:, 0] + s * axes[:, 1])
        d = P - A
        u = d / ell[..., None]
        K = self._point_map(x, RP)
        aP = self._point_acceleration(xdot, RP)
        Pdot = np.einsum("Nidm,Nm->Nid", K, xdot)
        # q̇ = J_i ẋ, row i = d_iᵀ K_i / (d_i·A_i′ + λ_i ℓ_i)
        denominator = np.einsum("Nid,Nid->Ni", d, dA) + self._lam * ell
        J_q = np.einsum("Nid,Nidm->Nim", d, K) / denominator[..., None]
        qdot = np.einsum("Nim,Nm->Ni", J_q, xdot)
        ddot = Pdot - dA * qdot[..., None]
        # d/dt² (‖d‖² − ℓ²) = 0 at ẍ = 0
        numerator = (
            np.einsum("Nid,Nid->Ni", d, aP)
            - np.einsum("Nid,Nid->Ni", d, ddA) * qdot**2
            + np.einsum("Nid,Nid->Ni", ddot, ddot)
            - (self._lam * qdot) ** 2
        )
        qdd = numerator / denominator
        # u = d / ℓ: u̇ = (ḋ − ℓ̇ u) / ℓ, ü = (d̈ − ℓ̈ u − 2 ℓ̇ u̇) / ℓ
        ldot, lddot = self._lam * qdot, self._lam * qdd
        J_d = K - np.einsum("Nid,Nim->Nidm", dA, J_q)
        J_u = (J_d - np.einsum("i,Nid,Nim->Nidm", self._lam, u, J_q)) / ell[..., None, None]
        udot = (ddot - ldot[..., None] * u) / ell[..., None]
        dd_ddot = aP - dA * qdd[..., None] - ddA * (qdot**2)[..., None]
        udd = (dd_ddot - lddot[..., None] * u - 2.0 * ldot[..., None] * udot) / ell[..., None]
        c_rod = ine.distal_com[None, :, None]
        J_distal = K - c_rod[..., None] * J_u
        a_distal = aP - c_rod * udd
        J_actuator = self._leg[None, :, None, None] * ine.actuator_com[None, :, None, None] * J_u + np.einsum(
            "i,Nid,Nim->Nidm", self._arm_fraction, dA, J_q
        )
        Rc = np.einsum("Nab,b->Na", R, ine.platform_com)[:, None, :]
        J_platform = self._point_map(x, Rc)[:, 0]
        a_platform = self._point_acceleration(xdot, Rc)[:, 0]
        if self._space.name == "spatial":
            omega = xdot[:, 3:]
            inertia_world = np.einsum("Nab,bc,Ndc->Nad", R, ine.platform_inertia, R)
        elif self._space.name == "planar":
            omega = xdot[:, 2:]
            inertia_world = np.broadcast_to(ine.platform_inertia, (N, 1, 1))
        else:
            omega = np.zeros((N, 0))
            inertia_world = np.zeros((N, 0, 0))
        return _Kinematics(
            J_platform, a_platform, J_q, qdd, J_u, udd, J_distal, a_distal, J_actuator, omega, inertia_world, qdot,
            self._joint_map(u, J_u, dA, ddA, J_q) if self.inertia.joint_damping.any() else None, xdot,
        )  # fmt: skip

    @staticmethod
    def _joint_map(u: FloatArray, J_u: FloatArray, dA: FloatArray, ddA: FloatArray, J_q: FloatArray) -> FloatArray:
        """ẋ → ω_i, (N, n, 3, m): the rod's angular velocity less the crank arm's, across the rod.

        ω_i = u_i × u̇_i − w⊥_i q̇_i, the arm turning about w_i = A_i′ × A_i″ / |A_i′|² (a crank's axis; 0 for legs,
        whose A_i′ = 0, and for sliders, whose A_i″ = 0) and w⊥_i = w_i − (w_i·u_i) u_i: the spin about the rod's
        own axis, free and without inertia in this model, carries no friction. Planar vectors are lifted to 3-D.
        """
        if u.shape[-1] == 2:
            u, dA, ddA = (np.concatenate([a, np.zeros_like(a[..., :1])], axis=-1) for a in (u, dA, ddA))
            J_u = np.concatenate([J_u, np.zeros_like(J_u[..., :1, :])], axis=-2)
        norm = np.einsum("...d,...d->...", dA, dA)
        w = np.cross(dA, ddA) / np.where(norm > 0.0, norm, 1.0)[..., None]
        w = w - np.einsum("...d,...d->...", w, u)[..., None] * u
        return np.cross(u[..., :, None], J_u, axis=-2) - np.einsum("Nid,Nim->Nidm", w, J_q)

    # -- the terms of the equations of motion -------------------------------------------------------

    def _mass_matrix(self, k: _Kinematics) -> FloatArray:
        ine = self.inertia
        M = ine.platform_mass * np.einsum("Ndm,Ndk->Nmk", k.J_platform, k.J_platform)
        r = k.omega.shape[1]
        if r:
            M[:, -r:, -r:] += k.inertia_world
        M += np.einsum("i,Nim,Nik->Nmk", self._w_q, k.J_q, k.J_q)
        M += np.einsum("i,Nidm,Nidk->Nmk", self._w_u, k.J_u, k.J_u)
        M += np.einsum("i,Nidm,Nidk->Nmk", ine.distal_mass, k.J_distal, k.J_distal)
        return M

    def _velocity_terms(self, k: _Kinematics) -> FloatArray:
        ine = self.inertia
        c = ine.platform_mass * np.einsum("Ndm,Nd->Nm", k.J_platform, k.a_platform)
        r = k.omega.shape[1]
        if r == 3:
            c[:, 3:] += np.cross(k.omega, np.einsum("Nab,Nb->Na", k.inertia_world, k.omega))
        c += np.einsum("i,Nim,Ni->Nm", self._w_q, k.J_q, k.qdd)
        c += np.einsum("i,Nidm,Nid->Nm", self._w_u, k.J_u, k.udd)
        c += np.einsum("i,Nidm,Nid->Nm", ine.distal_mass, k.J_distal, k.a_distal)
        c += np.einsum("Nim,Ni->Nm", k.J_q, ine.actuator_damping * k.qdot)  # the drives' viscous friction J_iᵀ B q̇
        if k.J_joint is not None:  # the passive joints' viscous friction Σ_i b_i J_ω,iᵀ ω_i
            omega = np.einsum("Nidm,Nm->Nid", k.J_joint, k.xdot)
            c += np.einsum("i,Nidm,Nid->Nm", ine.joint_damping, k.J_joint, omega)
        return c

    def _gravity(self, k: _Kinematics) -> FloatArray:
        ine = self.inertia
        g = ine.gravity
        G = -ine.platform_mass * np.einsum("Ndm,d->Nm", k.J_platform, g)
        G -= np.einsum("i,Nidm,d->Nm", ine.actuator_mass, k.J_actuator, g)
        G -= np.einsum("i,Nidm,d->Nm", ine.distal_mass, k.J_distal, g)
        return G

    def _flat(self, *arrays: FloatArray) -> tuple[tuple[int, ...], list[FloatArray]]:
        batch = arrays[0].shape[:-1]
        return batch, [arr.reshape(-1, arr.shape[-1]) for arr in arrays]

    def mass_matrix(self, q: Any, x: Any) -> FloatArray:
        """The mass matrix M(x) = Σ_b J_bᵀ M_b J_b in twist coordinates, symmetric positive definite.

        Args:
            q: Actuator coordinates with Φ(q, x) = 0, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).

        Returns:
            M, shape (..., m, m) [kg, kg·m, kg·m² by the blocks of ẋ].
        """
        q, x = self._state(q, x)
        batch, (qf, xf) = self._flat(q, x)
        k = self._kinematics(qf, xf, np.zeros_like(xf))
        return self._mass_matrix(k).reshape(batch + 2 * (self.mechanism.n_pose,))

    def bias_forces(self, q: Any, x: Any, xdot: Any) -> FloatArray:
        """The velocity-product, friction and gravity terms c(x, ẋ) + G(x): M ẍ + c + G = J_iᵀ τ.

        Args:
            q: Actuator coordinates with Φ(q, x) = 0, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            xdot: Platform twist (module docstring), shape (..., m).

        Returns:
            c + G, a generalised force dual to the twist (planar: f_x, f_y [N], m_z [N·m]; spatial: force
            [N] and moment about the origin of {P} [N·m] in {B} axes), shape (..., m).
        """
        q, x, xdot = self._state(q, x, xdot)
        batch, (qf, xf, vf) = self._flat(q, x, xdot)
        k = self._kinematics(qf, xf, vf)
        return (self._velocity_terms(k) + self._gravity(k)).reshape(batch + (self.mechanism.n_pose,))

    def gravity_forces(self, q: Any, x: Any) -> FloatArray:
        """G(x) = ∂V/∂x = −Σ_b m_b J_bᵀ g, the generalised gravity term (same units as ``bias_forces``).

        Args:
            q: Actuator coordinates with Φ(q, x) = 0, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).

        Returns:
            G, shape (..., m).
        """
        q, x = self._state(q, x)
        batch, (qf, xf) = self._flat(q, x)
        return self._gravity(self._kinematics(qf, xf, np.zeros_like(xf))).reshape(batch + (self.mechanism.n_pose,))

    def holding_forces(self, q: Any, x: Any) -> FloatArray:
        """The actuator efforts that hold the platform still against gravity: J_iᵀ τ = G, τ = J_fᵀ G.

        Args:
            q: Actuator coordinates with Φ(q, x) = 0, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).

        Returns:
            τ, shape (..., n) [N for legs and sliders, N·m for cranks].

        Raises:
            SingularConfigurationError: At a Type II singularity.
        """
        G = self.gravity_forces(q, x)
        return self.mechanism.actuator_forces(q, x, G)

    def _acceleration(self, q: FloatArray, x: FloatArray, xdot: FloatArray, tau: FloatArray) -> FloatArray:
        """ẍ on flattened, validated arrays (N, ·)."""
        k = self._kinematics(q, x, xdot)
        rhs = np.einsum("Nim,Ni->Nm", k.J_q, tau) - self._velocity_terms(k) - self._gravity(k)
        return batched_solve(self._mass_matrix(k), rhs[..., None])[..., 0]

    def forward_dynamics(self, q: Any, x: Any, xdot: Any, tau: Any) -> FloatArray:
        """The platform's twist rate ẍ = M⁻¹ (J_iᵀ τ − c − G).

        Args:
            q: Actuator coordinates with Φ(q, x) = 0, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            xdot: Platform twist, shape (..., m).
            tau: Actuator efforts, shape (..., n) [N for legs and sliders, N·m for cranks].

        Returns:
            ẍ, shape (..., m) (planar: m/s², m/s², rad/s²; spatial: v̇ [m/s²], ω̇ [rad/s²] in {B}).

        Raises:
            ValueError: On a non-finite or misshapen ``tau`` (or state), naming it.
        """
        q, x, xdot = self._state(q, x, xdot)
        batch = q.shape[:-1]
        tau = self._tau(tau, batch)
        _, (qf, xf, vf, tf) = self._flat(q, x, xdot, tau)
        return self._acceleration(qf, xf, vf, tf).reshape(batch + (self.mechanism.n_pose,))

    def kinetic_energy(self, q: Any, x: Any, xdot: Any) -> FloatArray:
        """T = ½ ẋᵀ M(x) ẋ [J], shape (...) (arguments as ``bias_forces``)."""
        M = self.mass_matrix(q, x)
        xdot = np.broadcast_to(batch_vector("xdot", xdot, self.mechanism.n_pose, "a platform twist"), M.shape[:-1])
        return 0.5 * np.einsum("...m,...mk,...k->...", xdot, M, xdot)

    def potential_energy(self, q: Any, x: Any) -> FloatArray:
        """V = −Σ_b m_b g·r_b [J], zero with every centre of mass at the origin of {B}, shape (...).

        Args:
            q: Actuator coordinates with Φ(q, x) = 0, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).

        Returns:
            V, shape (...).
        """
        q, x = self._state(q, x)
        mech, ine = self.mechanism, self.inertia
        dim = self._space.point_dim
        R = self._space.rotation(x)
        P = mech.platform_points_in_base(x, validate=False)
        A = mech.anchors(q, validate=False)
        d = P - A
        u = d / np.linalg.norm(d, axis=-1, keepdims=True)
        platform = x[..., :dim] + np.einsum("...ab,b->...a", R, ine.platform_com)
        distal = P - ine.distal_com[:, None] * u
        arm = mech.base + self._arm_fraction[:, None] * (A - mech.base)
        cylinder = mech.base + ine.actuator_com[:, None] * u
        actuator = np.where(self._leg[:, None] > 0, cylinder, arm)
        g = ine.gravity
        return -(
            ine.platform_mass * (platform @ g)
            + np.einsum("i,...i->...", ine.actuator_mass, actuator @ g)
            + np.einsum("i,...i->...", ine.distal_mass, distal @ g)
        )

    # -- integration ----------------------------------------------------------------------------------

    def _dexp_inverse(self, xi: FloatArray, nu: FloatArray) -> FloatArray:
        """ξ̇ from the twist ν in the chart x = retract(x_0, ξ): identity but for spatial rotations.

        With R = exp([ξ]×) R_0, ω = J_l(ξ) ξ̇ (J_l the left Jacobian of SO(3)), so
        ξ̇ = ω − ½ ξ × ω + (1/θ² − (1 + cos θ) / (2 θ sin θ)) ξ × (ξ × ω), θ = |ξ|.
        """
        if self._space.name != "spatial":
            return nu
        theta = xi[:, 3:]
        omega = nu[:, 3:]
        angle = np.linalg.norm(theta, axis=-1, keepdims=True)
        small = angle < 1e-4
        safe = np.where(small, 1.0, angle)
        coefficient = np.where(
            small, 1.0 / 12.0 + angle**2 / 720.0, 1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe))
        )
        cross = np.cross(theta, omega)
        out = nu.copy()
        out[:, 3:] = omega - 0.5 * cross + coefficient * np.cross(theta, cross)
        return out

    def _rk4(self, x: FloatArray, xdot: FloatArray, tau: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
        """One Runge–Kutta–Munthe-Kaas step of order 4 in the chart ξ ↦ retract(x, ξ), q = IK(x) at each stage."""
        mech = self.mechanism
        xi_rates, nu_rates = [], []
        xi = np.zeros_like(x)
        nu = xdot
        for weight in (0.5, 0.5, 1.0, None):
            pose = x if not xi_rates else mech.retract(x, xi, validate=False)
            q = mech.inverse_kinematics(pose, validate=False)
            xi_rates.append(self._dexp_inverse(xi, nu))
            nu_rates.append(self._acceleration(q, pose, nu, tau))
            if weight is not None:
                xi = weight * dt * xi_rates[-1]
                nu = xdot + weight * dt * nu_rates[-1]
        xi = dt / 6.0 * (xi_rates[0] + 2.0 * xi_rates[1] + 2.0 * xi_rates[2] + xi_rates[3])
        nu = xdot + dt / 6.0 * (nu_rates[0] + 2.0 * nu_rates[1] + 2.0 * nu_rates[2] + nu_rates[3])
        return mech.retract(x, xi, validate=False), nu

    def step(self, x: Any, xdot: Any, tau: Any, dt: float, *, substeps: int = 1) -> DynamicsState:
        """Advance (x, ẋ) by dt with τ held constant: ``substeps`` RKMK4 steps of dt / substeps on the pose space.

        Each stage moves the pose with the mechanism's ``retract`` (on the rotation group for spatial poses) and
        takes q from the closed-form inverse kinematics on the robot's branches, so Φ(q, x) stays at round-off.
        The method has order 4; its energy error over a run is O(dt⁴).

        Args:
            x: Platform pose, shape (..., m).
            xdot: Platform twist, shape (..., m).
            tau: Actuator efforts, shape (..., n).
            dt: Time step [s], > 0.
            substeps: Number of RKMK4 steps in dt, ≥ 1.

        Returns:
            The state at t + dt (q, x, ẋ).

        Raises:
            ValueError: On bad inputs, naming them, or if a leg cannot reach the platform during the step.
        """
        mech = self.mechanism
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite number > 0 [s], got {dt!r}")
        if not (isinstance(substeps, int) and substeps >= 1):
            raise ValueError(f"substeps must be an integer ≥ 1, got {substeps!r}")
        x = batch_vector("x", x, mech.n_pose, mech.x_description)
        xdot = batch_vector("xdot", xdot, mech.n_pose, "a platform twist")
        batch = np.broadcast_shapes(x.shape[:-1], xdot.shape[:-1])
        tau = self._tau(tau, batch)
        _, (xf, vf, tf) = self._flat(*(np.broadcast_to(a, batch + a.shape[-1:]) for a in (x, xdot, tau)))
        h = dt / substeps
        for _ in range(substeps):
            xf, vf = self._rk4(xf, vf, tf, h)
        q = mech.inverse_kinematics(xf, validate=False)
        if not (np.isfinite(q).all() and np.isfinite(vf).all()):
            raise ValueError("the step left the workspace: a leg cannot reach its platform point (or ẋ diverged)")
        m, n = mech.n_pose, mech.n_actuators
        return DynamicsState(q.reshape(batch + (n,)), xf.reshape(batch + (m,)), vf.reshape(batch + (m,)))
