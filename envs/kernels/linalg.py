"""Compiled small dense linear algebra for the kernels: closed forms for 3 × 3, fixed-size loops for 6 × 6.

Every robot of the distance-constraint family has m = 3 (planar, translational) or m = 6 (spatial) pose
coordinates, so the kernels need square systems and conditioning of those two sizes only. 3 × 3 systems are
solved by the adjugate (Cramer's rule) and the inverse condition number comes from the eigenvalues of MᵀM in
closed form (with a one-sided Jacobi SVD where two nearly coincide); 6 × 6 systems use Gaussian elimination
with partial pivoting and a one-sided Jacobi SVD (Hestenes) in tournament order, run on up to ``LANES``
matrices side by side: the loop over the matrices has no branches, so LLVM vectorises it (one matrix per SIMD
lane, 3.9 times faster per matrix than one at a time on the hexapod's Jacobians) and each matrix gets bit for
bit the result it gets alone. Loop bounds are module constants, so Numba unrolls them.
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels.setup import jit, jit_inline

__all__ = [
    "LANES",
    "condition_at_least3",
    "condition_at_least6",
    "inverse_condition6",
    "inverse_condition6_lanes",
    "singular_value_ratio3",
    "solve3",
    "solve6",
]

_SIX = 6
#: Tournament (round-robin) order of the 15 column pairs of a 6-column matrix: 5 rounds of 3 disjoint pairs.
_PAIRS6 = (
    (0, 5), (1, 4), (2, 3),
    (0, 4), (5, 3), (1, 2),
    (0, 3), (4, 2), (5, 1),
    (0, 2), (3, 1), (4, 5),
    (0, 1), (2, 5), (3, 4),
)  # fmt: skip
_EPS2 = 2.220446049250313e-16**2
_CONVERGED = 1e-10


@jit
def solve3(a00, a01, a02, a10, a11, a12, a20, a21, a22, r0, r1, r2):
    """Solve A u = r by the adjugate; returns (u0, u1, u2, det A); u is NaN when det A = 0."""
    c00 = a11 * a22 - a12 * a21
    c01 = a12 * a20 - a10 * a22
    c02 = a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    if det == 0.0:
        return np.nan, np.nan, np.nan, det
    c10 = a02 * a21 - a01 * a22
    c11 = a00 * a22 - a02 * a20
    c12 = a01 * a20 - a00 * a21
    c20 = a01 * a12 - a02 * a11
    c21 = a02 * a10 - a00 * a12
    c22 = a00 * a11 - a01 * a10
    u0 = (c00 * r0 + c10 * r1 + c20 * r2) / det
    u1 = (c01 * r0 + c11 * r1 + c21 * r2) / det
    u2 = (c02 * r0 + c12 * r1 + c22 * r2) / det
    return u0, u1, u2, det


@jit_inline
def _jacobi_rotation(alpha, beta, gamma):
    """(cos, sin) of the Hestenes rotation of two columns with squared norms α, β and inner product γ ≠ 0."""
    zeta = (beta - alpha) / (2.0 * gamma)
    if abs(zeta) > 1e150:
        t = 0.5 / zeta
    else:
        t = math.copysign(1.0, zeta) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
    cs = 1.0 / math.sqrt(1.0 + t * t)
    return cs, cs * t


@jit
def _jacobi_pair(a0, a1, a2, b0, b1, b2):
    """One Hestenes rotation making columns a and b orthogonal; returns the new columns and whether it rotated."""
    alpha = a0 * a0 + a1 * a1 + a2 * a2
    beta = b0 * b0 + b1 * b1 + b2 * b2
    gamma = a0 * b0 + a1 * b1 + a2 * b2
    if abs(gamma) <= 2.220446049250313e-16 * math.sqrt(alpha * beta):
        return a0, a1, a2, b0, b1, b2, False
    cs, sn = _jacobi_rotation(alpha, beta, gamma)
    u0, u1, u2 = cs * a0 - sn * b0, cs * a1 - sn * b1, cs * a2 - sn * b2
    v0, v1, v2 = sn * a0 + cs * b0, sn * a1 + cs * b1, sn * a2 + cs * b2
    return u0, u1, u2, v0, v1, v2, True


@jit
def _singular_value_ratio(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """σ_min/σ_max of a 3 × 3 matrix by one-sided Jacobi SVD; 0 for the zero matrix, NaN if not finite."""
    u0, u1, u2 = m00, m10, m20
    v0, v1, v2 = m01, m11, m21
    w0, w1, w2 = m02, m12, m22
    for _ in range(60):
        u0, u1, u2, v0, v1, v2, r1 = _jacobi_pair(u0, u1, u2, v0, v1, v2)
        u0, u1, u2, w0, w1, w2, r2 = _jacobi_pair(u0, u1, u2, w0, w1, w2)
        v0, v1, v2, w0, w1, w2, r3 = _jacobi_pair(v0, v1, v2, w0, w1, w2)
        if not (r1 or r2 or r3):
            break
    s0 = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    s1 = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    s2 = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if s0 != s0 or s1 != s1 or s2 != s2:
        return np.nan
    top = max(s0, max(s1, s2))
    if top == 0.0:
        return 0.0
    return min(s0, min(s1, s2)) / top


@jit_inline
def _gram3(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """The Gram matrix G = MᵀM of a 3 × 3 matrix M: (g00, g11, g22, g01, g02, g12)."""
    return (
        m00 * m00 + m10 * m10 + m20 * m20,
        m01 * m01 + m11 * m11 + m21 * m21,
        m02 * m02 + m12 * m12 + m22 * m22,
        m00 * m01 + m10 * m11 + m20 * m21,
        m00 * m02 + m10 * m12 + m20 * m22,
        m01 * m02 + m11 * m12 + m21 * m22,
    )


@jit
def singular_value_ratio3(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """σ_min/σ_max of a 3 × 3 matrix M in closed form; 0 for a singular or zero M, NaN if not finite.

    σ_max² ≥ σ_mid² are the two largest eigenvalues of G = MᵀM, from the trigonometric solution of its
    characteristic cubic (both have full relative accuracy); σ_min = |det M| / (σ_max σ_mid), so the
    ratio |det M| / (σ_max² σ_mid) keeps the relative accuracy of det M instead of losing it in λ_min(G).
    """
    g00, g11, g22, g01, g02, g12 = _gram3(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    det = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * (m10 * m21 - m11 * m20)
    if not math.isfinite(det + g00 + g11 + g22):
        return np.nan
    mean = (g00 + g11 + g22) / 3.0
    off = g01 * g01 + g02 * g02 + g12 * g12
    d0, d1, d2 = g00 - mean, g11 - mean, g22 - mean
    p = math.sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off) / 6.0)
    if p == 0.0:  # G = mean · I: all singular values equal
        return 1.0 if mean > 0.0 else 0.0
    # r = det((G − mean I) / p) / 2, in [−1, 1]
    r = (d0 * (d1 * d2 - g12 * g12) - g01 * (g01 * d2 - g12 * g02) + g02 * (g01 * g12 - d1 * g02)) / (2.0 * p * p * p)
    r = min(max(r, -1.0), 1.0)
    angle = math.acos(r) / 3.0
    top = mean + 2.0 * p * math.cos(angle)
    low = mean + 2.0 * p * math.cos(angle + 2.0 * math.pi / 3.0)
    mid = 3.0 * mean - top - low
    if 1.0 - abs(r) < 1e-6 or not mid >= 1e-4 * top:
        # Two eigenvalues of G (nearly) coincide, where the cubic's roots lose accuracy, or the two
        # smallest singular values are both tiny: take the one-sided Jacobi SVD instead.
        return _singular_value_ratio(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    return min(abs(det) / (top * math.sqrt(mid)), 1.0)


@jit
def solve6(A, b, lu, x):
    """Solve A x = b for a 6 × 6 A (rows of ``A``) by elimination with partial pivoting; returns det A.

    Args:
        A: The matrix, shape (≥ 6, ≥ 6) (its leading 6 × 6 block); left unchanged.
        b: Right-hand side, shape (≥ 6,).
        lu: Work rows, shape (≥ 6, ≥ 6).
        x: The solution, shape (≥ 6,) (NaN where A is exactly singular, and det 0 returned).
    """
    for i in range(_SIX):
        for j in range(_SIX):
            lu[i, j] = A[i, j]
        x[i] = b[i]
    det = 1.0
    for k in range(_SIX):
        p = k
        best = abs(lu[k, k])
        for i in range(k + 1, _SIX):
            v = abs(lu[i, k])
            if v > best:
                best, p = v, i
        if not best > 0.0:
            for i in range(_SIX):
                x[i] = np.nan
            return 0.0 if best == 0.0 else np.nan
        if p != k:
            for j in range(_SIX):
                lu[k, j], lu[p, j] = lu[p, j], lu[k, j]
            x[k], x[p] = x[p], x[k]
            det = -det
        pivot = lu[k, k]
        det *= pivot
        inv = 1.0 / pivot
        for i in range(k + 1, _SIX):
            f = lu[i, k] * inv
            for j in range(k + 1, _SIX):
                lu[i, j] -= f * lu[k, j]
            x[i] -= f * x[k]
    for i in range(_SIX - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, _SIX):
            s -= lu[i, j] * x[j]
        x[i] = s / lu[i, i]
    return det


#: Matrices that ``inverse_condition6_lanes`` conditions side by side: one per lane of the vectorised loop
#: (16 fill two AVX-512 or four AVX2 registers; at 8 LLVM's cost model keeps the scalar loop).
LANES = 16


@jit_inline
def _rotate_pair(H, j, k, count, worst, active):
    """One Jacobi rotation of columns j and k of each of ``count`` matrices, lane by lane, without branches.

    A lane rotates when it is active and its columns are not orthogonal to rounding (cos² > ε²); otherwise its
    rotation is the identity (t = 0), which leaves its columns bit for bit. Without branches the loop over the
    lanes vectorises (AVX2 / AVX-512), with results equal bit for bit to one matrix at a time.
    """
    for lane in range(count):
        a0, a1, a2 = H[j, 0, lane], H[j, 1, lane], H[j, 2, lane]
        a3, a4, a5 = H[j, 3, lane], H[j, 4, lane], H[j, 5, lane]
        b0, b1, b2 = H[k, 0, lane], H[k, 1, lane], H[k, 2, lane]
        b3, b4, b5 = H[k, 3, lane], H[k, 4, lane], H[k, 5, lane]
        alpha = a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3 + a4 * a4 + a5 * a5
        beta = b0 * b0 + b1 * b1 + b2 * b2 + b3 * b3 + b4 * b4 + b5 * b5
        gamma = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 + a4 * b4 + a5 * b5
        g2 = gamma * gamma
        ab = alpha * beta
        rotate = (g2 > _EPS2 * ab) & (active[lane] != 0.0)
        zeta = (beta - alpha) / (2.0 * (gamma if rotate else 1.0))
        size = abs(zeta)
        t = math.copysign(1.0, zeta) / (size + math.sqrt(1.0 + zeta * zeta))
        t = (0.5 / zeta) if size > 1e150 else t
        t = t if rotate else 0.0
        cs = 1.0 / math.sqrt(1.0 + t * t)
        sn = cs * t
        cos2 = g2 / (ab if rotate else 1.0)
        worst[lane] = max(worst[lane], cos2 if rotate else 0.0)
        H[j, 0, lane], H[k, 0, lane] = cs * a0 - sn * b0, sn * a0 + cs * b0
        H[j, 1, lane], H[k, 1, lane] = cs * a1 - sn * b1, sn * a1 + cs * b1
        H[j, 2, lane], H[k, 2, lane] = cs * a2 - sn * b2, sn * a2 + cs * b2
        H[j, 3, lane], H[k, 3, lane] = cs * a3 - sn * b3, sn * a3 + cs * b3
        H[j, 4, lane], H[k, 4, lane] = cs * a4 - sn * b4, sn * a4 + cs * b4
        H[j, 5, lane], H[k, 5, lane] = cs * a5 - sn * b5, sn * a5 + cs * b5


@jit
def inverse_condition6_lanes(H, count, out, worst, active):
    """σ_min/σ_max of ``count`` 6 × 6 matrices side by side (H overwritten); 0 for zero, NaN if not finite.

    One-sided Jacobi (Hestenes) on the columns in tournament order; a matrix stops after the first sweep that
    meets no pair of its columns with cos² ≥ 1e-10 (the others go on), and its singular values are its final
    column norms (high relative accuracy, as LAPACK's: 1e-15 against it on the hexapod's Jacobians). Each
    matrix gets exactly the rotations it would get alone, so the results do not depend on its neighbours.

    Args:
        H: Column c of matrix ``lane`` is H[c, :, lane], shape (6, 6, L) with L ≥ count, float64.
        count: Matrices in use (lanes 0..count−1).
        out: Their inverse condition numbers, shape (≥ count,).
        worst: Work array: each matrix's largest cos² of a sweep, shape (≥ count,).
        active: Work array: 1 while a matrix is still rotated, shape (≥ count,).
    """
    for lane in range(count):
        active[lane] = 1.0
    for _ in range(40):
        for lane in range(count):
            worst[lane] = 0.0  # largest cos² of the angle between two columns met in this sweep
        # The tournament: 5 rounds of 3 disjoint pairs, spelled out so that each pair's indices are constants.
        _rotate_pair(H, 0, 5, count, worst, active)
        _rotate_pair(H, 1, 4, count, worst, active)
        _rotate_pair(H, 2, 3, count, worst, active)
        _rotate_pair(H, 0, 4, count, worst, active)
        _rotate_pair(H, 5, 3, count, worst, active)
        _rotate_pair(H, 1, 2, count, worst, active)
        _rotate_pair(H, 0, 3, count, worst, active)
        _rotate_pair(H, 4, 2, count, worst, active)
        _rotate_pair(H, 5, 1, count, worst, active)
        _rotate_pair(H, 0, 2, count, worst, active)
        _rotate_pair(H, 3, 1, count, worst, active)
        _rotate_pair(H, 4, 5, count, worst, active)
        _rotate_pair(H, 0, 1, count, worst, active)
        _rotate_pair(H, 2, 5, count, worst, active)
        _rotate_pair(H, 3, 4, count, worst, active)
        # Quadratic convergence: once every cos² of a sweep is below 1e-10 the columns this sweep left are
        # orthogonal to about 1e-10, and their norms, the singular values, are exact to rounding (their error
        # is second order in the angles). This saves the sweep that would only confirm it.
        going = False
        for lane in range(count):
            if not worst[lane] >= _CONVERGED:
                active[lane] = 0.0
            going = going or active[lane] != 0.0
        if not going:
            break
    for lane in range(count):
        low = np.inf
        top = 0.0
        finite = True
        for j in range(_SIX):
            s = 0.0
            for i in range(_SIX):
                s += H[j, i, lane] * H[j, i, lane]
            finite = finite and s == s
            low = min(low, s)
            top = max(top, s)
        out[lane] = (0.0 if top == 0.0 else math.sqrt(low / top)) if finite else np.nan


#: Relative slack of ``condition_at_least3`` and ``condition_at_least6``: a proven k exceeds the bound by ~5e-7 of it,
#: far beyond the rounding of the factorisation and of the closed form or the Jacobi SVD (~1e-15), so that the proof
#: and ``singular_value_ratio3`` / ``inverse_condition6`` decide alike.
PROOF_SLACK = 1e-6


@jit_inline
def condition_at_least3(m00, m01, m02, m10, m11, m12, m20, m21, m22, t):
    """Whether σ_min/σ_max ≥ t > 0 is proven for the 3 × 3 matrix M (``condition_at_least6``'s proof).

    With the Gram matrix G = MᵀM and U = min(‖G‖_∞, tr G) ≥ λ_max(G) = σ_max², positive pivots of the LDLᵀ
    factorisation of G − t² (1 + ``PROOF_SLACK``) U I show σ_min² > t² U ≥ t² σ_max². No acos, cos or square root,
    against ``singular_value_ratio3``'s trigonometric cubic; every k > 3^(1/4) t is provable (U ≤ √3 σ_max²).
    False proves nothing (k may still be ≥ t); so do a zero or a non-finite M.
    """
    g00, g11, g22, g01, g02, g12 = _gram3(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    top = max(g00 + abs(g01) + abs(g02), max(abs(g01) + g11 + abs(g12), abs(g02) + abs(g12) + g22))
    shift = t * t * (1.0 + PROOF_SLACK) * min(top, g00 + g11 + g22)
    d0 = g00 - shift
    if not d0 > 0.0:  # not positive definite, or NaN
        return False
    l10, l20 = g01 / d0, g02 / d0
    d1 = g11 - shift - g01 * l10
    if not d1 > 0.0:
        return False
    e = g12 - g02 * l10
    return g22 - shift - g02 * l20 - e * e / d1 > 0.0


@jit
def condition_at_least6(H, G, t):
    """Whether σ_min/σ_max ≥ t > 0 is proven for the 6 × 6 matrix whose *columns* are the rows of ``H`` (kept).

    With the Gram matrix G = HᵀH and U = ‖G‖_∞ ≥ λ_max(G) = σ_max², a Cholesky factorisation of
    G − t² (1 + ``PROOF_SLACK``) U I that succeeds shows σ_min² > t² U ≥ t² σ_max². 0.14 µs against
    ``inverse_condition6``'s 1.7 µs on the hexapod's Jacobians, whose certified segments it proves at every point
    (U ≤ 1.3 σ_max² there); every k > 6^(1/4) t is provable (U ≤ √6 σ_max²).
    False proves nothing (k may still be ≥ t); so do a zero or a non-finite H.

    Args:
        H: Shape (6, 6), float64; H[j] is column j.
        G: Work array, shape (6, 6), float64 (overwritten).
        t: The bound, > 0.
    """
    for j in range(_SIX):
        for k in range(j, _SIX):
            s = 0.0
            for i in range(_SIX):
                s += H[j, i] * H[k, i]
            G[j, k] = s
            G[k, j] = s
    top = 0.0
    for j in range(_SIX):
        row = 0.0
        for k in range(_SIX):
            row += abs(G[j, k])
        top = max(top, row)
    shift = t * t * (1.0 + PROOF_SLACK) * top
    for j in range(_SIX):  # Cholesky of G − shift I, lower triangle in place
        d = G[j, j] - shift
        for k in range(j):
            d -= G[j, k] * G[j, k]
        if not d > 0.0:  # not positive definite, or NaN
            return False
        d = math.sqrt(d)
        G[j, j] = d
        for i in range(j + 1, _SIX):
            s = G[i, j]
            for k in range(j):
                s -= G[i, k] * G[j, k]
            G[i, j] = s / d
    return True


@jit
def inverse_condition6(H):
    """σ_min/σ_max of a 6 × 6 matrix whose *columns* are the rows of ``H`` (overwritten); 0 for zero, NaN if not finite.

    The algorithm of ``inverse_condition6_lanes`` (see there) for one matrix, in its plain form (the lanes' form
    costs more than it saves for a single matrix: 1.95 against 1.39 µs); a test holds the two equal bit for bit.
    """
    for _ in range(40):
        worst = 0.0  # largest cos² of the angle between two columns met in this sweep
        for p in range(15):
            j, l2 = _PAIRS6[p]
            alpha = 0.0
            beta = 0.0
            gamma = 0.0
            for i in range(_SIX):
                a = H[j, i]
                b = H[l2, i]
                alpha += a * a
                beta += b * b
                gamma += a * b
            if not gamma * gamma > _EPS2 * alpha * beta:
                continue
            worst = max(worst, gamma * gamma / (alpha * beta))
            cs, sn = _jacobi_rotation(alpha, beta, gamma)
            for i in range(_SIX):
                a = H[j, i]
                b = H[l2, i]
                H[j, i] = cs * a - sn * b
                H[l2, i] = sn * a + cs * b
        # Quadratic convergence: once every cos² of a sweep is below 1e-10 the columns this sweep left are
        # orthogonal to about 1e-10, and their norms, the singular values, are exact to rounding (their error
        # is second order in the angles). This saves the sweep that would only confirm it.
        if not worst >= _CONVERGED:
            break
    low = np.inf
    top = 0.0
    for j in range(_SIX):
        s = 0.0
        for i in range(_SIX):
            s += H[j, i] * H[j, i]
        if s != s:
            return np.nan
        low = min(low, s)
        top = max(top, s)
    if top == 0.0:
        return 0.0
    return math.sqrt(low / top)
