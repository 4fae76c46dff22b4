"""The planar 3-RPR parallel manipulator of the lesson's section 5 (squared leg-length constraints)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from kinematics._validation import FloatArray, check_distinct, point_set, positive_scalar
from kinematics.family import DistanceConstraintMechanism

#: Configurations per block of the fused batched J_f (temporaries of 32 kB stay in cache).
_FUSED_BLOCK = 4096

__all__ = ["DEFAULT_BASE", "DEFAULT_PLATFORM", "Planar3RPR"]

#: The lesson's base anchors B_i in {B} [m], shape (3, 2) (section 7).
DEFAULT_BASE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2.0]])
#: The lesson's platform points P_i in {P} [m], shape (3, 2) (section 7).
DEFAULT_PLATFORM = np.array([[0.0, -0.2], [0.2, 0.0], [-0.2, 0.0]])
DEFAULT_BASE.setflags(write=False)
DEFAULT_PLATFORM.setflags(write=False)


def _cross2(a: FloatArray, b: FloatArray) -> FloatArray:
    """z-component of the planar cross product a × b over the last axis, shape (...)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


class Planar3RPR(DistanceConstraintMechanism):
    """Planar 3-RPR manipulator: three legs B_i → P_i with actuated prismatic strokes L_i.

    The planar, leg-actuated member of the distance-constraint family (``DistanceConstraintMechanism``
    with ``pose_space="planar"``), with the lesson's geometry as default, a fused batched J_f and every
    assembly mode (``assembly_modes``). Its constraint-level math is tested equal to the family's.

    Constraints (lesson §5.1): Φ_i(q, x) = d_iᵀ d_i − L_i², d_i = p + R(φ) P_i − B_i, with
    q = (L_1, L_2, L_3) [m] and x = (x [m], y [m], φ [rad]) the pose of {P} in {B}.
    Jacobians (lesson §5.2): J_q = −2 diag(L_1, L_2, L_3), and row i of J_x is
    (2 d_ix, 2 d_iy, 2 d_iᵀ S R(φ) P_i) with S = [[0, −1], [1, 0]].

    Args:
        base: Base anchors B_i in {B} [m], shape (3, 2); must not be coincident or collinear.
            Default: the lesson's (0, 0), (1, 0), (0.5, √3/2).
        platform: Platform points P_i in {P} [m], shape (3, 2); must be pairwise distinct.
            Default: the lesson's (0, −0.2), (0.2, 0), (−0.2, 0).
        characteristic_length: ℓ_c [m] that divides the rotation column of J_i to make it
            dimensionless. Default: the largest distance from the platform origin to a P_i.
        singular_tolerance: Inverse condition number of the homogenised J_x below which inverting
            it raises ``SingularConfigurationError``. Default 1e-12.
    """

    n_actuators = 3
    n_pose = 3
    n_constraints = 3
    q_description = "leg lengths (L_1, L_2, L_3) [m]"
    x_description = "a pose (x [m], y [m], φ [rad])"

    def __init__(
        self,
        base: Any = None,
        platform: Any = None,
        *,
        characteristic_length: float | None = None,
        singular_tolerance: float = 1e-12,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        B = point_set("base anchors", DEFAULT_BASE if base is None else base, 3, 2)
        P = point_set("platform points", DEFAULT_PLATFORM if platform is None else platform, 3, 2)
        check_distinct("base anchors", B)
        check_distinct("platform points", P)
        extent = float(np.max(np.linalg.norm(B - B.mean(axis=0), axis=1)))
        twice_area = abs(_cross2(B[1] - B[0], B[2] - B[0]))
        if twice_area <= 1e-9 * extent**2:
            raise ValueError(
                "base anchors must not be collinear: the triangle B_1 B_2 B_3 has area "
                f"{twice_area / 2:.3g} m², expected > {0.5e-9 * extent**2:.3g} m²"
            )
        if characteristic_length is None:
            characteristic_length = float(np.max(np.linalg.norm(P, axis=1)))
            if characteristic_length <= 0:  # pragma: no cover - excluded by distinct points
                raise ValueError("platform points are all at the origin; give characteristic_length")
        l_c = positive_scalar("characteristic_length", characteristic_length)
        tol = positive_scalar("singular_tolerance", singular_tolerance)
        super().__init__(
            B, P, pose_space="planar", characteristic_length=l_c, singular_tolerance=tol, check_architecture=False
        )
        self.q_description = "leg lengths (L_1, L_2, L_3) [m]"
        self._B_list = B.tolist()
        self._P_list = P.tolist()

    # -- geometry ---------------------------------------------------------------------------------

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        return (
            f"Planar3RPR(base={self._B.tolist()}, platform={self._P.tolist()}, "
            f"characteristic_length={self._l_c!r}, singular_tolerance={self.singular_tolerance!r})"
        )

    def _rotated_platform(self, x: FloatArray) -> FloatArray:
        """R(φ) P_i in {B} axes, shape (..., 3, 2)."""
        RPx, RPy = self._rotated_platform_xy(x)
        return np.stack([RPx, RPy], axis=-1)

    def _rotated_platform_xy(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Components of R(φ) P_i in {B} axes, each shape (..., 3)."""
        phi = x[..., 2:3]
        c, s = np.cos(phi), np.sin(phi)
        Px, Py = self._P[:, 0], self._P[:, 1]
        return c * Px - s * Py, s * Px + c * Py

    # -- the constraint-level math ----------------------------------------------------------------

    def _legs(self, x: FloatArray) -> tuple[bool, list[tuple[Any, Any, Any, Any]]]:
        """Per leg i: ((R P_i)_x, (R P_i)_y, d_ix, d_iy) in {B} [m].

        Written on components so that one configuration runs on Python floats (no array overhead)
        and a batch on arrays of shape (...), through the same lines.
        """
        single = x.size == 3
        if single:
            px, py, phi = x.ravel().tolist()
            c, s = math.cos(phi), math.sin(phi)
        else:
            px, py, phi = x[..., 0], x[..., 1], x[..., 2]
            c, s = np.cos(phi), np.sin(phi)
        legs = []
        for (Bx, By), (Px, Py) in zip(self._B_list, self._P_list):
            RPx = c * Px - s * Py
            RPy = s * Px + c * Py
            legs.append((RPx, RPy, px + RPx - Bx, py + RPy - By))
        return single, legs

    def _assemble(self, single: bool, entries: list[Any], batch: tuple[int, ...], tail: tuple[int, ...]) -> FloatArray:
        """Stack per-component results into shape batch + tail."""
        if single:
            return np.array(entries).reshape(batch + tail)
        return np.stack(entries, axis=-1).reshape(batch + tail)

    def _constraints(self, q: FloatArray, x: FloatArray) -> FloatArray:
        single, legs = self._legs(x)
        squared = [dx * dx + dy * dy for _, _, dx, dy in legs]  # d_iᵀ d_i
        return self._assemble(single, squared, x.shape[:-1], (3,)) - q * q

    def _jacobian_x(self, single: bool, legs: list, batch: tuple[int, ...]) -> FloatArray:
        rows = []
        for RPx, RPy, dx, dy in legs:
            # Row i: 2 (d_ix, d_iy, d_iᵀ S R P_i) with d_iᵀ S R P_i = d_iy (R P_i)_x − d_ix (R P_i)_y.
            rows += [2.0 * dx, 2.0 * dy, 2.0 * (dy * RPx - dx * RPy)]
        return self._assemble(single, rows, batch, (3, 3))

    def _forward_jacobian_batch(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """J_f and the Hadamard ratio of a batch, straight from the leg components.

        With J_q = −2 diag(L) and J_x = 2A, where row i of A is (d_ix, d_iy, m_i) and
        m_i = d_iy (R P_i)_x − d_ix (R P_i)_y, the factors 2 cancel: J_f = −J_x⁻¹ J_q = A⁻¹ diag(L),
        so J_f[j, i] = adj(A)[j, i] L_i / det A. The Hadamard ratio of J_x·diag(1, 1, 1/ℓ_c) is
        |det A|/(ℓ_c ∏_i ‖(d_ix, d_iy, m_i/ℓ_c)‖), row-scale invariant. One pass over arrays of the
        batch shape, without stacking J_q and J_x: the cofactors serve both the solve and the check.

        Args:
            q: Leg lengths [m], shape (..., 3).
            x: Poses (x [m], y [m], φ [rad]) of {P} in {B}, shape (..., 3); broadcasts with q.

        Returns:
            (J_f of shape (..., 3, 3), NaN where det A = 0; the ratio in [0, 1], shape (...)).
        """
        shape = np.broadcast_shapes(q.shape[:-1], x.shape[:-1])
        x = np.broadcast_to(x, shape + (3,)).reshape(-1, 3)
        q = np.broadcast_to(q, shape + (3,)).reshape(-1, 3)
        n = x.shape[0]
        J_f, ratio = np.empty((n, 3, 3)), np.empty(n)
        # Blocks small enough for every temporary to stay in cache (and off fresh, page-faulting memory).
        for start in range(0, n, _FUSED_BLOCK):
            block = slice(start, start + _FUSED_BLOCK)
            self._forward_jacobian_block(q[block], x[block], J_f[block], ratio[block])
        return J_f.reshape(shape + (3, 3)), ratio.reshape(shape)

    def _forward_jacobian_block(self, q: FloatArray, x: FloatArray, J_f: FloatArray, ratio: FloatArray) -> None:
        """Fill J_f (b, 3, 3) and ratio (b,) for q, x of shape (b, 3); see ``_forward_jacobian_batch``."""
        px, py, phi = x.T
        c, s = np.cos(phi), np.sin(phi)
        inv_lc = 1.0 / self._l_c
        rows, squared = [], None
        for (Bx, By), (Px, Py) in zip(self._B_list, self._P_list):
            RPx = c * Px
            RPx -= s * Py
            RPy = s * Px
            RPy += c * Py
            dx = px + RPx
            dx -= Bx
            dy = py + RPy
            dy -= By
            m = dy * RPx
            m -= dx * RPy  # row i of A = J_x / 2: (d_ix, d_iy, m_i)
            rows.append((dx, dy, m))
            row_squared = dx * dx  # ‖(d_ix, d_iy, m_i/ℓ_c)‖², for the Hadamard ratio
            row_squared += dy * dy
            m_scaled = m * inv_lc
            row_squared += m_scaled * m_scaled
            squared = row_squared if squared is None else np.multiply(squared, row_squared, out=squared)
        (a, b, c_), (d, e, f), (g, h, i) = rows

        def minor(p: Any, q_: Any, r: Any, t: Any) -> Any:
            out = p * q_
            out -= r * t
            return out

        cof = (
            (minor(e, i, f, h), minor(c_, h, b, i), minor(b, f, c_, e)),
            (minor(f, g, d, i), minor(a, i, c_, g), minor(c_, d, a, f)),
            (minor(d, h, e, g), minor(b, g, a, h), minor(a, e, b, d)),
        )
        det = a * cof[0][0]
        det += b * cof[1][0]
        det += c_ * cof[2][0]
        np.sqrt(squared, out=squared)
        abs_det = np.abs(det)
        abs_det *= inv_lc
        ratio[...] = 0.0
        np.divide(abs_det, squared, out=ratio, where=squared > 0)
        with np.errstate(divide="ignore", invalid="ignore"):  # det A = 0 is marked NaN below
            inv_det = 1.0 / det
            for col in range(3):
                weight = q[:, col] * inv_det  # L_i / det A
                for row in range(3):
                    np.multiply(cof[row][col], weight, out=J_f[:, row, col])
        if len(ratio) and not ratio.min() > 0:  # the ratio is 0 where det A is: only then look for exact zeros
            J_f[det == 0] = np.nan

    def _newton_terms(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        single, legs = self._legs(x)
        squared = [dx * dx + dy * dy for _, _, dx, dy in legs]
        phi = self._assemble(single, squared, x.shape[:-1], (3,)) - q * q
        return phi, self._jacobian_x(single, legs, x.shape[:-1])

    def _jacobians(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        single, legs = self._legs(x)
        J_x = self._jacobian_x(single, legs, x.shape[:-1])
        if q.ndim == 1 and x.ndim == 1:
            return np.diag(-2.0 * q), J_x  # J_q = −2 diag(L_1, L_2, L_3)
        shape = np.broadcast_shapes(q.shape, x.shape)[:-1] + (3, 3)
        J_q = np.zeros(shape)
        np.einsum("...ii->...i", J_q)[...] = -2.0 * q  # J_q = −2 diag(L_1, L_2, L_3)
        if J_x.shape != shape:
            J_x = np.broadcast_to(J_x, shape)
        return J_q, J_x

    def _inverse_kinematics(self, x: FloatArray) -> FloatArray:
        return np.linalg.norm(self.leg_vectors(x, validate=False), axis=-1)

    # -- all assembly modes -----------------------------------------------------------------------

    def assembly_modes(self, q: Any, *, tolerance: float = 1e-10, n_samples: int = 64) -> FloatArray:
        """Every real solution x of Φ(q, x) = 0 for one set of leg lengths (at most 6).

        Elimination: subtracting Φ_1 from Φ_2 and Φ_3 leaves M(φ) p = r(φ), linear in p, so
        p = adj(M) r / det M. Substituting into Φ_1 gives the scalar equation
        f(φ) = ‖adj(M) r + det(M) a_1‖² − det(M)² L_1² = 0 with a_i = R(φ) P_i − B_i, a
        trigonometric polynomial of degree ≤ 6 in φ (Gosselin & Sefrioui 1991 reduce it to a
        degree-6 polynomial in tan(φ/2)). Its Fourier coefficients are obtained exactly from
        equally spaced samples; the roots of z⁶ f(z) on the unit circle are the real solutions.
        Each root is polished by Newton's method on the full system and duplicates are merged.

        Args:
            q: Leg lengths (L_1, L_2, L_3) [m], shape (3,).
            tolerance: A returned pose satisfies max_i |Φ_i| ≤ tolerance [m²].
            n_samples: Samples of f on [0, 2π) (≥ 13 for the degree-12 polynomial).

        Returns:
            Poses (x [m], y [m], φ [rad] in (−π, π]), shape (k, 3), 0 ≤ k ≤ 6, sorted by φ.
        """
        q = self._q(q)
        if q.shape != (3,):
            raise ValueError(f"assembly_modes takes one set of leg lengths, shape (3,), got {q.shape}")
        if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 13):
            raise ValueError(f"n_samples must be an integer ≥ 13, got {n_samples!r}")
        phi = 2.0 * np.pi * np.arange(n_samples) / n_samples
        f = self._elimination_polynomial(q, phi)
        coeffs = np.fft.fft(f) / n_samples  # c_j for f(φ) = Σ_j c_j e^{ijφ}, j = −6..6
        laurent = np.array([coeffs[j % n_samples] for j in range(6, -7, -1)])
        scale = np.max(np.abs(laurent))
        if scale == 0:  # pragma: no cover - f ≡ 0 only for degenerate architectures
            return np.empty((0, 3))
        laurent = np.trim_zeros(np.where(np.abs(laurent) > 1e-14 * scale, laurent, 0), "f")
        roots = np.roots(laurent)
        candidates = []
        for z in roots[np.abs(np.abs(roots) - 1.0) < 1e-3]:
            angle = float(np.angle(z))
            p = self._position_from_angle(q, angle)
            if p is not None:
                candidates.append([p[0], p[1], angle])
        if not candidates:
            return np.empty((0, 3))
        result = self.forward_kinematics(q, np.array(candidates), tolerance=tolerance / 10, validate=False)
        keep = result.x[np.atleast_1d(result.residual) <= tolerance]
        keep[:, 2] = np.angle(np.exp(1j * keep[:, 2]))
        unique: list[FloatArray] = []
        for sol in keep[np.argsort(keep[:, 2])]:
            if all(self._pose_distance(sol, other) > 1e-7 for other in unique):
                unique.append(sol)
        return np.array(unique).reshape(-1, 3)

    def _pose_distance(self, a: FloatArray, b: FloatArray) -> float:
        dphi = np.angle(np.exp(1j * (a[2] - b[2])))
        return float(np.hypot(np.hypot(a[0] - b[0], a[1] - b[1]), self._l_c * dphi))

    def _linear_system(self, q: FloatArray, phi: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """M(φ) (…, 2, 2), r(φ) (…, 2) and a_i(φ) (…, 3, 2) of the elimination."""
        x = np.stack([np.zeros_like(phi), np.zeros_like(phi), phi], axis=-1)
        a = self._rotated_platform(x) - self._B
        M = 2.0 * (a[..., 1:, :] - a[..., :1, :])
        aa = np.sum(a * a, axis=-1)
        r = (q[1:] ** 2 - q[0] ** 2) - (aa[..., 1:] - aa[..., :1])
        return M, r, a

    def _elimination_polynomial(self, q: FloatArray, phi: FloatArray) -> FloatArray:
        M, r, a = self._linear_system(q, phi)
        det = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
        adj_r = np.stack(
            [
                M[..., 1, 1] * r[..., 0] - M[..., 0, 1] * r[..., 1],
                -M[..., 1, 0] * r[..., 0] + M[..., 0, 0] * r[..., 1],
            ],
            axis=-1,
        )
        v = adj_r + det[..., None] * a[..., 0, :]
        return np.sum(v * v, axis=-1) - det**2 * q[0] ** 2

    def _position_from_angle(self, q: FloatArray, angle: float) -> FloatArray | None:
        M, r, _ = self._linear_system(q, np.array(angle))
        if abs(np.linalg.det(M)) < 1e-12 * max(1.0, float(np.max(np.abs(M))) ** 2):
            return None
        return np.linalg.solve(M, r)
