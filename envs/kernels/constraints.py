"""The constraint-level math of the family in compiled code: Φ, J_x, J_q, inverse and forward kinematics, k.

With d_i = p + R P_i − B_i (leg kind: A_i = B_i, ℓ_i = q_i), the kernels use

    Φ_i = d_iᵀ d_i − q_i²,   J_x = 2 A with row i of A = (d_iᵀ, ((R P_i) × d_i)ᵀ) restricted to the twist,
    J_q = −2 diag(q),        J_f = −J_x⁻¹ J_q = A⁻¹ diag(q),   J_i = diag(1/q) A,

as ``kinematics.DistanceConstraintMechanism`` (the NumPy reference they are tested against). Systems are
solved and conditioned by ``envs.kernels.linalg`` (closed forms for m = 3; pivoted elimination and a one-sided
Jacobi SVD for m = 6), accurate near singular matrices. Each robot works in one work array (rows ``W_*``,
``_work``), allocated once per chunk of robots, not per robot.
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels import three
from envs.kernels.cache import drop_stale_caches
from envs.kernels.layout import (
    C_B,
    C_LAM,
    C_LEGS,
    C_N,
    C_NEWTON_TOL,
    C_P,
    C_SCALE,
    C_SPATIAL,
    C_TRANSLATIONAL,
    W_A,
    W_CA,
    W_CD,
    W_CELL,
    W_CQ,
    W_CSPEED,
    W_DQ,
    W_ELL,
    W_H,
    W_LU,
    W_RHS,
    W_SIZE,
    W_SOL,
    W_SPEED,
    W_SQ,
    W_XM,
)
from envs.kernels.linalg import condition_at_least6, inverse_condition6, solve3, solve6
from envs.kernels.pose import _all_finite, _frame, _retract
from envs.kernels.setup import jit, jit_inline

__all__ = ["W_A", "W_SIZE", "forward_batch", "singularity_batch"]

drop_stale_caches(__file__)


@jit
def _work():
    """A work array of the kernels (rows ``W_*``, 6 columns), its anchor cache marked empty."""
    w = np.empty((W_SIZE, 6))
    w[W_CQ, :] = np.nan
    return w


@jit_inline
def _rotated_point(c, i, r00, r01, r02, r10, r11, r12, r20, r21, r22):
    """R P_i, platform point i in {B} axes (R's entries row by row, as ``pose._frame`` gives them)."""
    P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
    return (
        r00 * P0 + r01 * P1 + r02 * P2,
        r10 * P0 + r11 * P1 + r12 * P2,
        r20 * P0 + r21 * P1 + r22 * P2,
    )


@jit_inline
def _rows_legs(c, q, x, w):
    """``_rows`` of a leg-actuated robot: the anchors are the B_i; ℓ_i = q_i and −(J_q)_ii / 2 = q_i."""
    n = int(c[C_N])
    p0, p1, p2, r00, r01, r02, r10, r11, r12, r20, r21, r22 = _frame(c, x)
    spatial = c[C_SPATIAL] != 0.0
    sq = w[W_SQ]
    for i in range(n):
        rp0, rp1, rp2 = _rotated_point(c, i, r00, r01, r02, r10, r11, r12, r20, r21, r22)
        d0 = p0 + rp0 - c[C_B + 3 * i]
        d1 = p1 + rp1 - c[C_B + 3 * i + 1]
        d2 = p2 + rp2 - c[C_B + 3 * i + 2]
        m2 = rp0 * d1 - rp1 * d0  # ((R P_i) × d_i)_z
        row = w[W_A + i]
        if spatial:
            row[0], row[1], row[2] = d0, d1, d2
            row[3] = rp1 * d2 - rp2 * d1
            row[4] = rp2 * d0 - rp0 * d2
            row[5] = m2
        else:
            row[0], row[1], row[2] = d0, d1, m2
        sq[i] = d0 * d0 + d1 * d1 + d2 * d2
        w[W_ELL, i] = q[i]
        w[W_DQ, i] = q[i]


@jit
def _rows_actuated(c, q, x, w):
    """``_rows`` of a robot with cranks or sliders: the anchors A_i(q_i) move with q (see ``_rows``)."""
    n = int(c[C_N])
    p0, p1, p2, r00, r01, r02, r10, r11, r12, r20, r21, r22 = _frame(c, x)
    spatial = c[C_SPATIAL] != 0.0
    translational = c[C_TRANSLATIONAL] != 0.0
    sq = w[W_SQ]
    for i in range(n):
        rp0, rp1, rp2 = _rotated_point(c, i, r00, r01, r02, r10, r11, r12, r20, r21, r22)
        qi = q[i]
        if w[W_CQ, i] == qi:  # the cache (never equal while NaN)
            A0, A1, A2 = w[W_CA, i], w[W_CA + 1, i], w[W_CA + 2, i]
            D0, D1, D2 = w[W_CD, i], w[W_CD + 1, i], w[W_CD + 2, i]
            ell, speed = w[W_CELL, i], w[W_CSPEED, i]
        else:
            A0, A1, A2, D0, D1, D2, ell, speed = three.anchor(c, i, qi)
            w[W_CA, i], w[W_CA + 1, i], w[W_CA + 2, i] = A0, A1, A2
            w[W_CD, i], w[W_CD + 1, i], w[W_CD + 2, i] = D0, D1, D2
            w[W_CELL, i], w[W_CSPEED, i] = ell, speed
            w[W_CQ, i] = qi
        d0 = p0 + rp0 - A0
        d1 = p1 + rp1 - A1
        d2 = p2 + rp2 - A2
        w[W_ELL, i] = ell
        w[W_DQ, i] = d0 * D0 + d1 * D1 + d2 * D2 + ell * c[C_LAM + i]
        w[W_SPEED, i] = speed
        row = w[W_A + i]
        if spatial:
            row[0], row[1], row[2] = d0, d1, d2
            row[3] = rp1 * d2 - rp2 * d1
            row[4] = rp2 * d0 - rp0 * d2
            row[5] = rp0 * d1 - rp1 * d0
        elif translational:
            row[0], row[1], row[2] = d0, d1, d2
        else:
            row[0], row[1], row[2] = d0, d1, rp0 * d1 - rp1 * d0
        sq[i] = d0 * d0 + d1 * d1 + d2 * d2


@jit
def _rows(c, q, x, w):
    """Rows of A = J_x / 2 at (q, x) into w[W_A:], and d_iᵀ d_i into w[W_SQ].

    w[W_ELL] and w[W_DQ] get ℓ_i(q_i) and d_iᵀ A_i′ + ℓ_i ℓ_i′ (= −(J_q)_ii / 2); for legs (``C_LEGS``) both are
    q_i and the anchors are B_i, otherwise the anchors move with q and w[W_SPEED] gets ‖(A_i′, ℓ_i′)‖.
    """
    if c[C_LEGS] != 0.0:
        _rows_legs(c, q, x, w)
    else:
        _rows_actuated(c, q, x, w)


@jit_inline
def _link_length(c, q, w, i):
    """ℓ_i(q_i) at the rows last computed (q_i for a leg)."""
    return w[W_ELL, i]


@jit
def _leg_lengths(c, x, out):
    """Actuator coordinates of the pose x (the closed-form inverse kinematics) into out (n,), without rows.

    Leg lengths ‖p + R P_i − B_i‖ for legs; a crank's angle or a slider's position on its chosen branch
    (NaN where it cannot reach).
    """
    p0, p1, p2, r00, r01, r02, r10, r11, r12, r20, r21, r22 = _frame(c, x)
    legs = c[C_LEGS] != 0.0
    for i in range(int(c[C_N])):
        P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
        d0 = p0 + r00 * P0 + r01 * P1 + r02 * P2 - c[C_B + 3 * i]
        d1 = p1 + r10 * P0 + r11 * P1 + r12 * P2 - c[C_B + 3 * i + 1]
        d2 = p2 + r20 * P0 + r21 * P1 + r22 * P2 - c[C_B + 3 * i + 2]
        out[i] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) if legs else three.ik_leg(c, i, d0, d1, d2)


@jit
def _inverse_kinematics(c, x, w, out):
    """Actuator coordinates of the pose x into out (n,), and the rows of A there into w."""
    if c[C_LEGS] != 0.0:
        _rows(c, out, x, w)
        for i in range(int(c[C_N])):
            out[i] = math.sqrt(w[W_SQ, i])
            w[W_ELL, i] = out[i]
            w[W_DQ, i] = out[i]
        return
    _leg_lengths(c, x, out)
    _rows(c, out, x, w)


@jit
def _solve(w, m, src, rhs, sol):
    """Solve (rows ``src`` of w) u = rhs into sol (m = 3: adjugate; m = 6: pivoted elimination); returns det.

    Where the matrix is exactly singular, sol is NaN and det 0.
    """
    if m == 3:
        a = w[src]
        b = w[src + 1]
        c = w[src + 2]
        u0, u1, u2, det = solve3(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], rhs[0], rhs[1], rhs[2])
        sol[0], sol[1], sol[2] = u0, u1, u2
        return det
    return solve6(w[src : src + 6], rhs, w[W_LU : W_LU + 6], sol)


@jit
def _twist_rate(c, q, rate, w, src, out):
    """Out = J_f(q, x) q̇ = A⁻¹ (−J_q / 2) q̇ from the rows ``src`` of A at (q, x); NaN where J_x is singular."""
    m = int(c[C_N])
    rhs = w[W_RHS]
    for i in range(m):
        rhs[i] = w[W_DQ, i] * rate[i]
    _solve(w, m, src, rhs, out)


@jit
def _homogeneous_lane(c, q, w, src, H, lane):
    """Lane ``lane`` of H (see ``inverse_condition6_lanes``) = J_i diag(pose_scale) from the rows ``src`` of A (m = 6).

    J_i diag(pose_scale) = diag(1/q) A diag(pose_scale); column j of it goes to H[j, :, lane]. Returns
    sign(det J_x) = sign(det A), by pivoted elimination of A.
    """
    for i in range(6):
        inv = 1.0 / _link_length(c, q, w, i)
        row = w[src + i]
        for j in range(6):
            H[j, i, lane] = row[j] * inv * c[C_SCALE + j]
    det = _solve(w, np.int64(6), src, w[W_RHS], w[W_SOL])  # m as int64: one compiled _solve for every caller
    return 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)


@jit_inline
def _link_condition3(c, q, w, src, at_least):
    """``three.link_condition3`` of the rows ``src`` of A (m = 3)."""
    a, b, d = w[src], w[src + 1], w[src + 2]
    ell0, ell1, ell2 = _link_length(c, q, w, 0), _link_length(c, q, w, 1), _link_length(c, q, w, 2)
    return three.link_condition3(
        c, a[0], a[1], a[2], b[0], b[1], b[2], d[0], d[1], d[2], ell0, ell1, ell2, at_least
    )  # fmt: skip


@jit
def _singularity(c, q, w, src):
    """(inverse condition number of J_i diag(pose_scale), sign(det J_x)) from the rows ``src`` of A.

    The link Jacobian diag(1/ℓ) A diag(pose_scale) (legs: J_i diag(pose_scale), ℓ = q); its σ_min/σ_max in
    closed form (m = 3) or by a
    one-sided Jacobi SVD (m = 6; ``inverse_condition6``, bit for bit what the batched step's
    ``inverse_condition6_lanes`` gives). sign(det J_x) = sign(det A).
    """
    if int(c[C_N]) == 3:
        return _link_condition3(c, q, w, src, 0.0)
    Ht = w[W_H : W_H + 6]  # column j of the link Jacobian as row j: one lane of ``_homogeneous_lane``
    # lane 0 as int64, not a constant: the batched step's lanes (``step._transition_lanes``) share its compile
    sign = _homogeneous_lane(c, q, w, src, Ht.reshape((6, 6, 1)), np.int64(0))
    return inverse_condition6(Ht), sign


@jit
def _singularity_at_least(c, q, w, src, at_least):
    """``_singularity``, or (``at_least``, sign(det J_x)) where k ≥ ``at_least`` > 0 is proven instead of computed.

    The certificate only compares k with its threshold: ``linalg.condition_at_least6`` (m = 6) proves k ≥ the
    threshold at a tenth of the SVD's cost, ``condition_at_least3`` (m = 3) without the closed form's acos and
    cosines, and k is computed where they do not. k and the proof decide alike, so the certificate certifies the
    same segments; its values above the threshold are then lower bounds. With ``at_least`` ≤ 0, exactly
    ``_singularity``.
    """
    if not at_least > 0.0:
        return _singularity(c, q, w, src)
    if int(c[C_N]) == 3:
        return _link_condition3(c, q, w, src, at_least)
    Ht = w[W_H : W_H + 6]  # as in ``_singularity``; the proof's work rows W_LU are free once the sign is known
    sign = _homogeneous_lane(c, q, w, src, Ht.reshape((6, 6, 1)), np.int64(0))
    if condition_at_least6(Ht, w[W_LU : W_LU + 6], at_least):
        return at_least, sign
    return inverse_condition6(Ht), sign


@jit
def _actuator_condition(c, w):
    """Type I measure at the rows last computed: min_i |d_iᵀ A_i′ + ℓ_i ℓ_i′| / (ℓ_i ‖(A_i′, ℓ_i′)‖); 1 for legs."""
    if c[C_LEGS] != 0.0:
        return 1.0
    k1 = np.inf
    for i in range(int(c[C_N])):
        v = abs(w[W_DQ, i]) / (w[W_ELL, i] * w[W_SPEED, i])
        if v != v:
            return np.nan
        k1 = min(k1, v)
    return k1


@jit
def _residual(c, q, w):
    """max_i |d_iᵀ d_i − ℓ_i²| at the rows last computed (NaN if any is NaN)."""
    res = 0.0
    for i in range(int(c[C_N])):
        ell = _link_length(c, q, w, i)
        v = abs(w[W_SQ, i] - ell * ell)
        if v != v:
            return np.nan
        res = max(res, v)
    return res


@jit
def _newton(c, q, guess, w, out, tolerance, max_iterations):
    """Newton's method on Φ(q, x) = 0 from ``guess`` into ``out`` (on the rotation group); returns the residual.

    Each step solves J_x δ = Φ (A δ = Φ / 2) and sets x ← x ⊖ δ; it stops once max_i |Φ_i| ≤ tolerance, at
    a non-finite residual or iterate, or after ``max_iterations`` steps. The rows of A at ``out`` are left in w.
    """
    m = int(c[C_N])
    for j in range(m):
        out[j] = guess[j]
    _rows(c, q, out, w)
    residual = _residual(c, q, w)
    rhs, sol, tmp = w[W_RHS], w[W_SOL], w[W_XM]
    for _ in range(max_iterations):
        if not residual > tolerance:
            break
        for i in range(m):
            ell = _link_length(c, q, w, i)
            rhs[i] = 0.5 * (w[W_SQ, i] - ell * ell)
        _solve(w, m, W_A, rhs, sol)
        _retract(c, out, sol, -1.0, tmp)
        if not _all_finite(tmp, m):
            break
        for j in range(m):
            out[j] = tmp[j]
        _rows(c, q, out, w)
        residual = _residual(c, q, w)
    return residual


@jit_inline
def _row(cs, i):
    """Robot i's constants: row i of per-robot constants (shape (N, C_SIZE)), or the one row all share ((1, C_SIZE))."""
    return cs[i] if cs.shape[0] > 1 else cs[0]


@jit
def singularity_batch(c, q, x):
    """(inverse condition number of J_i diag(pose_scale), sign(det J_x)) of N configurations, each shape (N,)."""
    o_k, o_sign = np.empty(q.shape[0]), np.empty(q.shape[0])
    w = _work()
    for i in range(q.shape[0]):
        _rows(c, q[i], x[i], w)
        o_k[i], o_sign[i] = _singularity(c, q[i], w, W_A)
    return o_k, o_sign


@jit
def forward_batch(cs, q, guess, max_iterations):
    """Forward kinematics of N robots by Newton's method from ``guess``: the pose each q assembles at near it.

    What a real controller computes from its encoders, warm-started from its previous estimate (and what a robot
    whose geometry differs from the nominal one assembles at for the strokes the nominal inverse kinematics
    gave). Near a Type II singularity the pose is ill-determined by q and the iteration may fail.

    Args:
        cs: Packed constants, shape (N, C_SIZE) or (1, C_SIZE).
        q: Actuator coordinates [m, or rad for cranks], shape (N, n).
        guess: Starting poses, shape (N, m).
        max_iterations: Most Newton iterations.

    Returns:
        (poses (N, m), residuals max_i |Φ_i| [m²] (N,), k (N,), k_I (N,), sign(det J_x) (N,)); a robot whose
        iteration did not reach the tolerance ``C_NEWTON_TOL`` keeps its guess and gets residual NaN.
    """
    n, m = guess.shape
    o_x, o_res, o_k, o_k1, o_sign = np.empty((n, m)), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    w = _work()
    for i in range(n):
        c = _row(cs, i)
        res = _newton(c, q[i], guess[i], w, o_x[i], c[C_NEWTON_TOL], max_iterations)
        if not res <= c[C_NEWTON_TOL]:
            for j in range(m):
                o_x[i, j] = guess[i, j]
            res = np.nan
        _rows(c, q[i], o_x[i], w)
        o_k[i], o_sign[i] = _singularity(c, q[i], w, W_A)
        o_k1[i] = _actuator_condition(c, w)
        o_res[i] = res
    return o_x, o_res, o_k, o_k1, o_sign
