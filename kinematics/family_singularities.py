"""Singularities of the distance-constraint family: Type II and Type I measures, and the maps they guard."""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics._validation import FloatArray, batch_vector
from kinematics.linalg import batched_solve, singular_value_ratio
from kinematics.mechanism import ParallelMechanism, _check_broadcast, _scalarize

__all__ = ["FamilySingularities"]


class FamilySingularities(ParallelMechanism):
    """The singularity measures of ``kinematics.family.DistanceConstraintMechanism``, its base class.

    Type II (J_x singular): ``link_jacobian`` and ``inverse_condition_number``; Type I (J_q singular: a crank's
    link in line with its arm, a slider's link square to its rail): ``actuator_condition_number`` and
    ``actuator_mobility``, which guard J_i, the platform wrench and the actuator forces; and the architecture
    singularity that the constructor refuses. The link terms (``_link_terms``, ``_rows_x``, ``_jacobians``,
    ``_inverse_kinematics``) and the geometry are the subclass's.
    """

    def _check_architecture(self) -> None:
        """Refuse a design whose J_x is singular at every pose (an *architecture singularity*)."""
        rng = np.random.default_rng(0)
        home = self.home_pose()
        spread = np.full(self.n_pose, 0.1 * self._l_c)  # [m] for translations
        spread[list(self._space.rotation_columns)] = 0.3  # [rad] for rotations
        x = home + rng.uniform(-1.0, 1.0, size=(32, self.n_pose)) * spread
        q = self._inverse_kinematics(x)
        reachable = np.isfinite(q).all(axis=-1) & (q[..., self._lam == 1.0] > 0).all(axis=-1)
        if not reachable.any():  # pragma: no cover - no pose near home is reachable
            return
        k = self.inverse_condition_number(q[reachable], x[reachable], validate=False)
        if float(np.max(k)) < 1e-9:
            raise ValueError(
                f"architecture-singular design: J_x is singular at every one of {int(reachable.sum())} random "
                f"poses around the home pose {home.tolist()} (largest inverse condition number "
                f"{float(np.max(k)):.3g}); for example, similar base and platform hexagons with legs joining "
                "corresponding vertices"
            )

    def link_jacobian(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """The homogeneous Type II Jacobian diag(1/(2ℓ_i)) J_x diag(pose_scale).

        Row i is link i's unit Plücker line (u_i, ((R P_i) × u_i)/ℓ_c), u_i = d_i/ℓ_i; for a leg-actuated
        robot it equals ``homogeneous_jacobian`` (J_i diag(pose_scale)), and unlike J_i it stays finite at a
        Type I singularity.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            Shape (..., n, m), dimensionless.
        """
        q, x = self._qx(q, x, validate)
        d, _, ell = self._link_terms(q, x)
        return self._rows_x(x, d) / (2.0 * ell[..., None]) * self._pose_scale

    def inverse_condition_number(self, q: Any, x: Any, *, validate: bool = True) -> Any:
        """Closeness to a Type II singularity: σ_min/σ_max of ``link_jacobian``, in [0, 1].

        For leg-actuated robots this is ``ParallelMechanism.inverse_condition_number`` (σ_min/σ_max of
        J_i diag(pose_scale), the same matrix); with cranks or sliders the link Jacobian keeps the measure
        free of the Type I one (``actuator_condition_number``).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            σ_min/σ_max, shape (...) (a float for a single configuration).
        """
        if self._all_legs:
            return super().inverse_condition_number(q, x, validate=validate)
        return _scalarize(singular_value_ratio(self.link_jacobian(q, x, validate=validate)))

    def singularity_measures(self, q: Any, x: Any, *, validate: bool = True) -> tuple[Any, Any]:
        """(``inverse_condition_number``, det J_x), see ``ParallelMechanism.singularity_measures``."""
        if self._all_legs:
            return super().singularity_measures(q, x, validate=validate)
        q, x = self._qx(q, x, validate)
        _, J_x = self._jacobians(q, x)
        return self.inverse_condition_number(q, x, validate=False), _scalarize(np.linalg.det(J_x))

    def _actuator_measures(self, q: FloatArray, x: FloatArray) -> FloatArray:
        """|d_iᵀ A_i′ + ℓ_i ℓ_i′| / (ℓ_i ‖(A_i′, ℓ_i′)‖) of each leg, shape (..., n)."""
        d, dA, ell = self._link_terms(q, x)
        along = np.einsum("...ij,...ij->...i", d, dA) + ell * self._lam
        speed = np.sqrt(np.einsum("...ij,...ij->...i", dA, dA) + self._lam)
        return np.abs(along) / (ell * speed)

    def actuator_condition_number(self, q: Any, x: Any, *, validate: bool = True) -> Any:
        """Closeness to a Type I singularity, in [0, 1]: min_i |d_iᵀ A_i′ + ℓ_i ℓ_i′| / (ℓ_i ‖(A_i′, ℓ_i′)‖).

        The cosine of the angle between link i and the direction in which its actuator moves the anchor
        (for a crank, the arm's tangent: 0 when the link is in line with the arm, stretched or folded; for
        a slider, the rail: 0 when the link is square to it); 1 for an extensible leg. J_q is singular
        exactly where it is 0.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            The smallest over the legs, shape (...) (a float for a single configuration).
        """
        q, x = self._qx(q, x, validate)
        return _scalarize(np.min(self._actuator_measures(q, x), axis=-1))

    def actuator_mobility(self, q: Any, x: Any, *, rtol: float = 1e-9, validate: bool = True) -> Any:
        """Actuator motions that do not move the platform to first order: n − rank(J_q) (> 0 at Type I).

        J_q is diagonal, so this counts the legs whose normalised entry (``actuator_condition_number``'s
        per-leg cosine) is at most ``rtol``.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            rtol: Cosines at most rtol count as zero.
            validate: Check inputs.

        Returns:
            Mobility, shape (...) (int); 0 at a regular configuration.
        """
        q, x = self._qx(q, x, validate)
        return _scalarize(np.sum(self._actuator_measures(q, x) <= rtol, axis=-1))

    def _raise_if_type1(self, q: FloatArray, x: FloatArray, what: str) -> None:
        self._raise_below(
            np.min(self._actuator_measures(q, x), axis=-1),
            f"J_q is singular (Type I singularity) where {what} is asked for: actuator condition number",
        )

    def inverse_jacobian(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """Map platform velocity to actuator rates: q̇ = J_i ẋ, J_i = −J_q⁻¹ J_x (a solve).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs and raise at a Type I singularity.

        Returns:
            J_i, shape (..., n, m). Row i is ∂q̇_i/∂ẋ.

        Raises:
            SingularConfigurationError: If J_q is singular (a Type I singularity: a crank's link in line with
                its arm, a slider's link square to its rail) and ``validate``.
        """
        q, x = self._qx(q, x, validate)
        if validate and not self._all_legs:
            self._raise_if_type1(q, x, "J_i = −J_q⁻¹ J_x")
        J_q, J_x = self._jacobians(q, x)
        return -batched_solve(J_q, J_x)

    def platform_wrench(self, q: Any, x: Any, tau: Any, *, validate: bool = True) -> FloatArray:
        """Wrench the actuator efforts exert on the platform: w = J_iᵀ τ (see ``ParallelMechanism``).

        Raises:
            SingularConfigurationError: At a Type I singularity (``validate``), where J_i is not defined.
        """
        if validate and not self._all_legs:
            self._raise_if_type1(*self._qx(q, x, True), "the platform wrench")
        return super().platform_wrench(q, x, tau, validate=validate)

    def actuator_forces(self, q: Any, x: Any, wrench: Any, *, validate: bool = True) -> FloatArray:
        """Actuator efforts that balance a platform wrench (see ``ParallelMechanism.actuator_forces``).

        With cranks or sliders, τ = J_fᵀ w = −J_qᵀ J_x⁻ᵀ w, which needs only J_x regular and so stays
        defined at a Type I singularity (where the locked actuator there carries no effort along its link).
        """
        if self._all_legs:
            return super().actuator_forces(q, x, wrench, validate=validate)
        q, x = self._qx(q, x, validate)
        if validate:
            wrench = batch_vector("wrench", wrench, self.n_pose, "a platform wrench")
            _check_broadcast(q=q, x=x, wrench=wrench)
        J_q, J_x = self._jacobians(q, x)
        if validate:
            self._raise_if_singular(J_x, "actuator forces")
        J_xT = np.swapaxes(J_x, -1, -2)
        batch = np.broadcast_shapes(J_xT.shape[:-2], wrench.shape[:-1])
        y = batched_solve(
            np.broadcast_to(J_xT, batch + J_xT.shape[-2:]),
            np.broadcast_to(wrench, batch + wrench.shape[-1:])[..., None],
        )
        return -np.einsum("...ii,...i->...i", np.broadcast_to(J_q, batch + J_q.shape[-2:]), y[..., 0])
