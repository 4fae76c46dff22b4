"""Generic constraint-based kinematics of a fully parallel mechanism Φ(q, x) = 0.

A concrete mechanism supplies the constraint-level math (Φ, J_q, J_x, closed-form inverse kinematics
and which pose coordinates are rotations); everything that follows from J_q and J_x is written here,
once, for any mechanism: J_f, J_i, Newton forward kinematics, instantaneous DOF, platform mobility,
statics and conditioning.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinematics._validation import FloatArray, batch_vector, positive_scalar
from kinematics.linalg import (
    batched_solve,
    determinant,
    hadamard_ratio,
    singular_value_ratio,
    solve3_with_hadamard,
)

__all__ = ["ForwardKinematicsResult", "ParallelMechanism", "SingularConfigurationError"]


class SingularConfigurationError(ValueError):
    """A Jacobian that must be inverted is singular (to working precision) at the given configuration."""


@dataclass(frozen=True)
class ForwardKinematicsResult:
    """Outcome of the iterative forward kinematics (the Robotics Toolbox's ``IKSolution`` pattern).

    Attributes:
        x: Platform pose reached by Newton's method, shape (..., m) [m, rad].
        converged: Whether max_i |Φ_i| ≤ tolerance was reached, shape (...) (bool).
        iterations: Newton steps taken, shape (...) (int).
        residual: max_i |Φ_i(q, x)| at the returned pose, shape (...) [units of Φ, m² for the 3-RPR].
    """

    x: FloatArray
    converged: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray

    def __bool__(self) -> bool:
        """True when every configuration of the batch converged."""
        return bool(np.all(self.converged))


def _scalarize(arr: np.ndarray) -> Any:
    """Turn a 0-d array into a NumPy scalar, leave batched arrays alone."""
    return arr[()] if arr.ndim == 0 else arr


def _check_broadcast(**arrays: np.ndarray) -> None:
    """Raise a ``ValueError`` naming each batch shape (all axes but the last) if they do not broadcast."""
    shapes = [arr.shape[:-1] for arr in arrays.values()]
    if all(shape == shapes[0] for shape in shapes):
        return
    try:
        np.broadcast_shapes(*shapes)
    except ValueError:
        named = [f"{name} {arr.shape[:-1]}" for name, arr in arrays.items()]
        raise ValueError(f"batch shapes of {', '.join(named[:-1])} and {named[-1]} do not broadcast") from None


class ParallelMechanism(abc.ABC):
    """A fully parallel mechanism with n actuators, an m-coordinate pose and k = m holonomic constraints.

    Subclasses implement ``_constraints``, ``_jacobians``, ``_inverse_kinematics``, ``_check_actuators``
    and set ``n_actuators``, ``n_pose``, ``n_constraints`` and ``pose_scale`` (the column scaling that
    makes the inverse Jacobian dimensionally homogeneous: 1 for a translation, 1/ℓ_c for a rotation).

    Every public method validates its inputs (shape (..., n) or (..., m), finite values, admissible
    actuator coordinates) unless called with ``validate=False``, the fast path for inner loops whose
    inputs were validated once at their own boundary.
    """

    n_actuators: int
    n_pose: int
    n_constraints: int
    q_description: str
    x_description: str

    def __init__(self, pose_scale: FloatArray, singular_tolerance: float) -> None:
        """Store the homogenising column scale and the tolerance below which J_x counts as singular.

        Args:
            pose_scale: Column scaling of J_i, shape (m,): 1 for translations, 1/ℓ_c [1/m] for rotations.
            singular_tolerance: Hadamard ratio |det Ĵ_x| / ∏_i ‖row_i(Ĵ_x)‖ of the homogenised
                Ĵ_x = J_x · diag(pose_scale) below which ``forward_jacobian`` and ``actuator_forces``
                raise ``SingularConfigurationError``.
        """
        scale = np.array(pose_scale, dtype=np.float64)
        scale.setflags(write=False)
        self._pose_scale = scale
        self._singular_tolerance = float(singular_tolerance)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore a pickled mechanism; unpickled arrays are writeable, so make them read-only again."""
        self.__dict__.update(state)
        for value in state.values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)

    # -- what a concrete mechanism provides -------------------------------------------------------

    @abc.abstractmethod
    def _constraints(self, q: FloatArray, x: FloatArray) -> FloatArray:
        """Φ(q, x), shape (..., k), no validation."""

    @abc.abstractmethod
    def _jacobians(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(J_q, J_x), shapes (..., k, n) and (..., k, m), no validation."""

    def _forward_jacobian_batch(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """Optional fast path for a batch: (J_f of shape (..., m, n), Hadamard ratio of J_x·diag(pose_scale)).

        A mechanism may override it to compute both from shared intermediate terms, without building
        J_q and J_x; ``None`` (the default) selects the generic solve. Where J_x is exactly singular the
        rows of J_f are NaN, as with ``batched_solve``.
        """
        return None

    def _newton_terms(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(Φ, J_x) at once, for Newton's method; override to share work between the two."""
        return self._constraints(q, x), self._jacobians(q, x)[1]

    def _retract(self, x: FloatArray, step: FloatArray) -> FloatArray:
        """The pose reached from x by a step in velocity coordinates; x + step unless the pose space is curved."""
        return x + step

    @abc.abstractmethod
    def _inverse_kinematics(self, x: FloatArray) -> FloatArray:
        """Closed-form q(x), shape (..., n), no validation."""

    @abc.abstractmethod
    def _check_actuators(self, q: FloatArray) -> None:
        """Raise ``ValueError`` if actuator coordinates are inadmissible (for example a leg length ≤ 0)."""

    # -- validation -------------------------------------------------------------------------------

    @property
    def pose_scale(self) -> FloatArray:
        """Column scaling that homogenises J_i, shape (m,): 1 for translations, 1/ℓ_c for rotations."""
        return self._pose_scale

    @property
    def singular_tolerance(self) -> float:
        """Inverse condition number below which J_x is treated as singular."""
        return self._singular_tolerance

    def _q(self, q: Any) -> FloatArray:
        arr = batch_vector("q", q, self.n_actuators, self.q_description)
        self._check_actuators(arr)
        return arr

    def _x(self, x: Any, name: str = "x") -> FloatArray:
        return batch_vector(name, x, self.n_pose, self.x_description)

    def _qx(self, q: Any, x: Any, validate: bool) -> tuple[FloatArray, FloatArray]:
        if validate and self._valid_single(q, x):
            return q, x
        if validate:
            q, x = self._q(q), self._x(x)
            _check_broadcast(q=q, x=x)
        return q, x

    def _valid_single(self, q: Any, x: Any) -> bool:
        """Fast acceptance of one well-formed configuration (float64 vectors); anything else goes the long way."""
        if not (
            type(q) is np.ndarray
            and type(x) is np.ndarray
            and q.dtype == np.float64
            and x.dtype == np.float64
            and q.shape == (self.n_actuators,)
            and x.shape == (self.n_pose,)
        ):
            return False
        values = q.tolist()
        if not all(math.isfinite(v) for v in values + x.tolist()):
            return False
        try:
            self._check_actuators(q)
        except ValueError:
            return False
        return True

    # -- constraint level -------------------------------------------------------------------------

    def constraints(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """Evaluate the holonomic constraints Φ(q, x).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check shapes and values (set False only in validated inner loops).

        Returns:
            Φ, shape (..., k); zero on the constraint manifold.
        """
        q, x = self._qx(q, x, validate)
        return self._constraints(q, x)

    def jacobians(self, q: Any, x: Any, *, validate: bool = True) -> tuple[FloatArray, FloatArray]:
        """Constraint Jacobians J_q = ∂Φ/∂q and J_x = ∂Φ/∂x.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check shapes and values.

        Returns:
            (J_q, J_x), shapes (..., k, n) and (..., k, m).
        """
        q, x = self._qx(q, x, validate)
        return self._jacobians(q, x)

    def inverse_kinematics(self, x: Any, *, validate: bool = True) -> FloatArray:
        """Closed-form inverse kinematics q(x).

        Args:
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check shape and values.

        Returns:
            q, shape (..., n).
        """
        if validate:
            x = self._x(x)
        return self._inverse_kinematics(x)

    # -- velocity level ---------------------------------------------------------------------------

    def _singularity_measure(self, J_x: FloatArray) -> FloatArray:
        """Hadamard ratio of J_x with rotation columns scaled by 1/ℓ_c: 0 iff J_x is singular."""
        return hadamard_ratio(J_x, self._pose_scale)

    def _raise_if_singular(self, J_x: FloatArray | None, what: str, ratio: Any = None) -> None:
        ratio = np.asarray(self._singularity_measure(J_x) if ratio is None else ratio)
        what = f"J_x is singular (Type II singularity) where {what} is asked for: Hadamard ratio |det Ĵ_x|/∏‖rows‖"
        self._raise_below(ratio, what)

    def _raise_below(self, measure: Any, message: str) -> None:
        """Raise ``SingularConfigurationError`` where a measure is below the tolerance (or NaN), naming where."""
        measure = np.asarray(measure)
        if measure.size == 0 or measure.min() >= self._singular_tolerance:
            return
        bad = ~(measure >= self._singular_tolerance)  # NaN counts as singular
        idx = tuple(int(i) for i in np.argwhere(np.atleast_1d(bad))[0])
        raise SingularConfigurationError(
            f"{message} = {float(np.nanmin(measure)):.3g} < singular_tolerance {self._singular_tolerance:.3g}"
            + (f" at batch index {idx}" if np.ndim(bad) else "")
        )

    def forward_jacobian(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """Map actuator rates to platform velocity: ẋ = J_f q̇, with J_f = −J_x⁻¹ J_q (a solve).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs and raise at a singular J_x.

        Returns:
            J_f, shape (..., m, n). Row j is ∂ẋ_j/∂q̇.

        Raises:
            SingularConfigurationError: If J_x is singular (a Type II singularity) and ``validate``.
        """
        q, x = self._qx(q, x, validate)
        if q.ndim > 1 or x.ndim > 1:
            fused = self._forward_jacobian_batch(q, x)
            if fused is not None:  # the mechanism's own pipeline: J_f and the singularity check share work
                J_f, ratio = fused
                if validate:
                    self._raise_if_singular(None, "J_f = −J_x⁻¹ J_q", ratio)
                return J_f
        J_q, J_x = self._jacobians(q, x)
        if J_x.shape == (3, 3):  # one configuration: the solve and the check share the cofactors
            J_f, ratio = solve3_with_hadamard(J_x, J_q, self._pose_scale)
            if validate:
                self._raise_if_singular(J_x, "J_f = −J_x⁻¹ J_q", ratio)
            return -J_f
        if validate:
            self._raise_if_singular(J_x, "J_f = −J_x⁻¹ J_q")
        return -batched_solve(J_x, J_q)

    def inverse_jacobian(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """Map platform velocity to actuator rates: q̇ = J_i ẋ, with J_i = −J_q⁻¹ J_x (a solve).

        Args:
            q: Actuator coordinates, shape (..., n); J_q is regular for admissible q.
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            J_i, shape (..., n, m). Row i is ∂q̇_i/∂ẋ.
        """
        q, x = self._qx(q, x, validate)
        J_q, J_x = self._jacobians(q, x)
        return -batched_solve(J_q, J_x)

    def homogeneous_jacobian(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """Dimensionally homogeneous inverse Jacobian J_i · diag(pose_scale).

        Rotation columns of J_i [m/rad] are divided by the characteristic length ℓ_c, so every entry
        is dimensionless and q̇ = J_h (ẋ, ẏ, ℓ_c φ̇) (Merlet 2006, §6.2; Angeles 1997).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            J_h, shape (..., n, m).
        """
        return self.inverse_jacobian(q, x, validate=validate) * self._pose_scale

    def inverse_condition_number(self, q: Any, x: Any, *, validate: bool = True) -> Any:
        """Closeness to a Type II singularity: σ_min/σ_max of the homogeneous Jacobian, in [0, 1].

        The raw cond(J_x) of squared constraints mixes m and m² and depends on the leg lengths, so it
        is not a sound singularity measure (Merlet 2006, *Parallel Robots*, §6.2; Merlet 1994,
        "Jacobian, manipulability and condition number of parallel robots"). We use the inverse
        condition number of J_h = J_i · diag(1, 1, 1/ℓ_c) (see ``homogeneous_jacobian``), whose rows
        are the unit leg direction u_i and the moment arm ((R P_i) × u_i)/ℓ_c: 1 when the mechanism is
        isotropic, 0 at a Type II singularity (Angeles 1997; Gosselin & Angeles 1990).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            σ_min/σ_max, shape (...) (a float for a single configuration).
        """
        return _scalarize(singular_value_ratio(self.homogeneous_jacobian(q, x, validate=validate)))

    def singularity_measures(self, q: Any, x: Any, *, validate: bool = True) -> tuple[Any, Any]:
        """The inverse condition number and det J_x from a single evaluation of the Jacobians.

        The inverse condition number measures the distance to a Type II singularity; the sign of
        det J_x identifies the working mode (it flips when a Type II singularity is crossed).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            (``inverse_condition_number``, shape (...); det J_x, shape (...)).
        """
        q, x = self._qx(q, x, validate)
        J_q, J_x = self._jacobians(q, x)
        ratio = singular_value_ratio(-batched_solve(J_q, J_x) * self._pose_scale)
        return _scalarize(ratio), _scalarize(determinant(J_x))

    def raw_condition_number(self, q: Any, x: Any, *, validate: bool = True) -> Any:
        """cond(J_x) = σ_max/σ_min of the raw constraint Jacobian, as used in the lesson.

        Unit-dependent (mixes m and m²); prefer ``inverse_condition_number`` as a singularity measure.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            cond(J_x) ≥ 1, shape (...); inf at an exact singularity.
        """
        _, J_x = self.jacobians(q, x, validate=validate)
        ratio = singular_value_ratio(J_x)
        with np.errstate(divide="ignore"):
            return _scalarize(np.where(ratio > 0, 1.0 / np.where(ratio > 0, ratio, 1.0), np.inf))

    # -- configuration level ----------------------------------------------------------------------

    def forward_kinematics(
        self,
        q: Any,
        x_guess: Any,
        *,
        tolerance: float = 1e-12,
        max_iterations: int = 30,
        validate: bool = True,
    ) -> ForwardKinematicsResult:
        """Solve Φ(q, x) = 0 for x by Newton's method from ``x_guess`` (stays in its assembly mode).

        Each step solves J_x δ = Φ and sets x ← x − δ (on the rotation group for spatial poses: J_x is
        taken with respect to the platform twist, see ``_retract``); a configuration stops once max_i |Φ_i| ≤
        ``tolerance``. A singular J_x or a non-finite iterate stops that configuration, unconverged.
        Failure is reported in the result, never raised.

        Args:
            q: Actuator coordinates, shape (..., n).
            x_guess: Starting pose, shape (..., m); the result is the solution Newton reaches from it,
                which is the one of the same assembly mode when the guess is close.
            tolerance: Convergence threshold on max_i |Φ_i| [units of Φ, m² for the 3-RPR].
            max_iterations: Maximum number of Newton steps.
            validate: Check inputs.

        Returns:
            ForwardKinematicsResult with x (..., m), converged (...), iterations (...), residual (...).
        """
        if validate:
            q = self._q(q)
            x_guess = self._x(x_guess, "x_guess")
            _check_broadcast(q=q, x_guess=x_guess)
            if isinstance(max_iterations, bool) or not (
                isinstance(max_iterations, (int, np.integer)) and max_iterations >= 0
            ):
                raise ValueError(f"max_iterations must be an integer ≥ 0, got {max_iterations!r}")
            tolerance = positive_scalar("tolerance", tolerance)
        shape = np.broadcast_shapes(q.shape[:-1], x_guess.shape[:-1])
        q = np.broadcast_to(q, shape + q.shape[-1:])
        x = np.array(np.broadcast_to(x_guess, shape + x_guess.shape[-1:]), dtype=np.float64)
        iterations = np.zeros(shape, dtype=np.int64)
        residual = np.full(shape, np.inf)
        active = np.ones(shape, dtype=bool)
        for it in range(max_iterations + 1):
            q_a, x_a = q[active], x[active]
            phi, J_x = self._newton_terms(q_a, x_a)
            res_a = np.max(np.abs(phi), axis=-1)
            residual[active] = res_a
            step = res_a > tolerance  # NaN compares False: a non-finite residual stops there
            if it == max_iterations or not step.any():
                break
            x_new = self._retract(x_a[step], -batched_solve(J_x[step], phi[step][..., None])[..., 0])
            ok = np.isfinite(x_new).all(axis=-1)
            moved = np.flatnonzero(step)[ok]
            x_a[moved] = x_new[ok]
            x[active] = x_a
            index = np.flatnonzero(active.ravel())[moved]
            iterations.ravel()[index] += 1
            active = np.zeros(shape, dtype=bool)
            active.ravel()[index] = True
        converged = residual <= tolerance
        return ForwardKinematicsResult(
            x=x,
            converged=_scalarize(converged),
            iterations=_scalarize(iterations),
            residual=_scalarize(residual),
        )

    # -- rank, mobility -------------------------------------------------------------------------

    @staticmethod
    def _rank(M: FloatArray, rtol: float) -> FloatArray:
        """Numerical rank of each row-normalised matrix of a batch (σ > rtol·σ_max)."""
        norms = np.linalg.norm(M, axis=-1, keepdims=True)
        sigma = np.linalg.svd(M / np.where(norms > 0, norms, 1.0), compute_uv=False)
        return np.sum(sigma > rtol * sigma[..., :1], axis=-1)

    def instantaneous_dof(self, q: Any, x: Any, *, rtol: float = 1e-9, validate: bool = True) -> Any:
        """Instantaneous degrees of freedom n + m − rank(J_c), J_c = [J_q  J_x] (lesson §3, problem 1).

        The rank is taken on J_c with rows normalised and rotation columns scaled by 1/ℓ_c, so the
        tolerance does not depend on units.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            rtol: Singular values below rtol·σ_max count as zero.
            validate: Check inputs.

        Returns:
            DOF, shape (...) (int).
        """
        J_q, J_x = self.jacobians(q, x, validate=validate)
        J_q, J_x = np.broadcast_arrays(J_q, J_x * self._pose_scale)
        J_c = np.concatenate([J_q, J_x], axis=-1)
        return _scalarize(self.n_actuators + self.n_pose - self._rank(J_c, rtol))

    def platform_mobility(self, q: Any, x: Any, *, rtol: float = 1e-9, validate: bool = True) -> Any:
        """Platform motions with the actuators locked: m − rank(J_x) (> 0 at a Type II singularity).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            rtol: Singular values below rtol·σ_max count as zero.
            validate: Check inputs.

        Returns:
            Mobility, shape (...) (int); 0 at a regular configuration.
        """
        _, J_x = self.jacobians(q, x, validate=validate)
        return _scalarize(self.n_pose - self._rank(J_x * self._pose_scale, rtol))

    # -- statics --------------------------------------------------------------------------------

    def platform_wrench(self, q: Any, x: Any, tau: Any, *, validate: bool = True) -> FloatArray:
        """Wrench the actuator forces exert on the platform: w = J_iᵀ τ (lesson problem 5).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            tau: Actuator forces (positive pushes the leg longer) [N], shape (..., n).
            validate: Check inputs.

        Returns:
            w, shape (..., m), dual to x (for planar robots: f_x [N], f_y [N], m_z [N·m] in {B}).
        """
        if validate:
            q, x = self._qx(q, x, validate)
            tau = batch_vector("tau", tau, self.n_actuators, "actuator forces [N]")
            _check_broadcast(q=q, x=x, tau=tau)
        J_i = self.inverse_jacobian(q, x, validate=False)
        return np.einsum("...ij,...i->...j", J_i, tau)

    def actuator_forces(self, q: Any, x: Any, wrench: Any, *, validate: bool = True) -> FloatArray:
        """Actuator forces that balance a platform wrench: solve J_iᵀ τ = w.

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            wrench: Platform wrench dual to x (planar: f_x [N], f_y [N], m_z [N·m]), shape (..., m).
            validate: Check inputs and raise at a singular J_x.

        Returns:
            τ [N], shape (..., n).

        Raises:
            SingularConfigurationError: At a Type II singularity, where some wrenches cannot be
                balanced by finite actuator forces.
        """
        q, x = self._qx(q, x, validate)
        if validate:
            wrench = batch_vector("wrench", wrench, self.n_pose, "a platform wrench")
            _check_broadcast(q=q, x=x, wrench=wrench)
        J_q, J_x = self._jacobians(q, x)
        if validate:
            self._raise_if_singular(J_x, "actuator forces")
        J_iT = np.swapaxes(-batched_solve(J_q, J_x), -1, -2)
        batch = np.broadcast_shapes(J_iT.shape[:-2], wrench.shape[:-1])
        J_iT = np.broadcast_to(J_iT, batch + J_iT.shape[-2:])
        w = np.broadcast_to(wrench, batch + wrench.shape[-1:])
        return batched_solve(J_iT, w[..., None])[..., 0]
