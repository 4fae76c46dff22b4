"""Three actuators of any kind on the planar or translational pose space, in scalars: the register path's algebra.

A robot of the distance-constraint family with three actuators and a three-coordinate pose, (x, y, φ) (planar)
or p = (x, y, z) (translational, R = I), has 3 × 3 algebra that fits in registers: here it is written out for
one robot in scalars, with closed forms (the adjugate for the systems, the trigonometric solution of the cubic for
k; ``envs.kernels.linalg``), where other robots go through 6 × 6 work arrays (``envs.kernels.constraints``). The
step (``envs.kernels.step``) runs on these through ``envs.kernels.paths``. The anchor of each leg is computed once
per value of q (Newton's iterations move x at fixed q); a leg's is fixed (``leg_anchors``). The math, with
d_i = p + R P_i − A_i(q_i):

    Φ_i = d_iᵀ d_i − ℓ_i(q_i)²,   J_x = 2 A,   A_i = (d_ix, d_iy, (R P_i)_x d_iy − (R P_i)_y d_ix) (planar)
                                                 or d_iᵀ (translational),
    −(J_q)_ii / 2 = d_iᵀ A_i′(q_i) + ℓ_i ℓ_i′,   J_f = A⁻¹ diag(−J_q / 2).

Every function reads the geometry and the settings from ``c``, the family's packed constants
(``envs.kernels.layout``): A_i(q) = B_i + a_i (cos q u_i + sin q v_i) + q e_i and ℓ_i(q) = λ_i q + l_i.
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels.cache import drop_stale_caches
from envs.kernels.layout import (
    C_A,
    C_B,
    C_BRANCH,
    C_E,
    C_ELL,
    C_LAM,
    C_LC,
    C_LEGS,
    C_P,
    C_SCALE,
    C_TRANSLATIONAL,
    C_U,
    C_V,
)
from envs.kernels.linalg import condition_at_least3, singular_value_ratio3, solve3
from envs.kernels.pose import _wrap
from envs.kernels.setup import jit, jit_inline

__all__ = ["anchor", "anchors", "ik_leg", "inverse_kinematics", "leg_anchors", "link_condition3", "rows", "singularity"]

drop_stale_caches(__file__)


@jit
def ik_leg(c, i, w0, w1, w2):
    """Closed-form q_i of leg i whose platform point is at B_i + w (NaN where a crank or slider cannot reach)."""
    ww = w0 * w0 + w1 * w1 + w2 * w2
    if c[C_LAM + i] != 0.0:
        return math.sqrt(ww)
    ell = c[C_ELL + i]
    branch = c[C_BRANCH + i]
    a = c[C_A + i]
    if a == 0.0:  # slider: ‖w − q e‖² = l²
        we = w0 * c[C_E + 3 * i] + w1 * c[C_E + 3 * i + 1] + w2 * c[C_E + 3 * i + 2]
        disc = we * we - ww + ell * ell
        if disc < 0.0:
            if disc < -1e-12 * (ww + ell * ell):
                return np.nan
            disc = 0.0
        return we + branch * math.sqrt(disc)
    wu = w0 * c[C_U + 3 * i] + w1 * c[C_U + 3 * i + 1] + w2 * c[C_U + 3 * i + 2]
    wv = w0 * c[C_V + 3 * i] + w1 * c[C_V + 3 * i + 1] + w2 * c[C_V + 3 * i + 2]
    ratio = (ww + a * a - ell * ell) / (2.0 * a * math.hypot(wu, wv))
    if not abs(ratio) <= 1.0 + 1e-12:
        return np.nan
    ratio = min(max(ratio, -1.0), 1.0)
    return _wrap(math.atan2(wv, wu) + branch * math.acos(ratio))


@jit
def anchor(c, i, qi):
    """Leg i's anchor A_i(q_i), its derivative A_i′ (each 3 numbers), ℓ_i(q_i) and ‖(A_i′, ℓ_i′)‖."""
    a = c[C_A + i]
    cs, sn = math.cos(qi), math.sin(qi)
    lam = c[C_LAM + i]
    b0, b1, b2 = c[C_B + 3 * i], c[C_B + 3 * i + 1], c[C_B + 3 * i + 2]
    u0, u1, u2 = c[C_U + 3 * i], c[C_U + 3 * i + 1], c[C_U + 3 * i + 2]
    v0, v1, v2 = c[C_V + 3 * i], c[C_V + 3 * i + 1], c[C_V + 3 * i + 2]
    e0, e1, e2 = c[C_E + 3 * i], c[C_E + 3 * i + 1], c[C_E + 3 * i + 2]
    A0 = b0 + a * (cs * u0 + sn * v0) + qi * e0
    A1 = b1 + a * (cs * u1 + sn * v1) + qi * e1
    A2 = b2 + a * (cs * u2 + sn * v2) + qi * e2
    D0 = a * (cs * v0 - sn * u0) + e0
    D1 = a * (cs * v1 - sn * u1) + e1
    D2 = a * (cs * v2 - sn * u2) + e2
    speed = math.sqrt(D0 * D0 + D1 * D1 + D2 * D2 + lam)
    return A0, A1, A2, D0, D1, D2, lam * qi + c[C_ELL + i], speed


@jit_inline
def leg_anchors(c, q0, q1, q2):
    """``anchors`` of three extensible legs: A_i = B_i (fixed), A_i′ = 0, ℓ_i = q_i, ‖(A_i′, ℓ_i′)‖ = 1."""
    return (
        (c[C_B], c[C_B + 1], c[C_B + 2], 0.0, 0.0, 0.0, q0, 1.0),
        (c[C_B + 3], c[C_B + 4], c[C_B + 5], 0.0, 0.0, 0.0, q1, 1.0),
        (c[C_B + 6], c[C_B + 7], c[C_B + 8], 0.0, 0.0, 0.0, q2, 1.0),
    )


@jit_inline
def anchors(c, q0, q1, q2):
    """The three legs' ``anchor`` values at q = (q0, q1, q2): a tuple of three 8-tuples."""
    # The indices as int64, not as constants: Numba would compile ``anchor`` once per constant index.
    return anchor(c, np.int64(0), q0), anchor(c, np.int64(1), q1), anchor(c, np.int64(2), q2)


@jit_inline
def _leg(c, i, translational, cs, sn, x0, x1, x2, an):
    """(row of A, d_iᵀ d_i, d_iᵀ A_i′ + ℓ_i ℓ_i′) of leg i at the pose, from its ``anchor`` values ``an``."""
    P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
    A0, A1, A2, D0, D1, D2, ell, _speed = an
    if translational:
        # _frame: R = I, p = x (the products by 1 and 0 kept: the same results as the general formula).
        rp0 = 1.0 * P0 + 0.0 * P1 + 0.0 * P2
        rp1 = 0.0 * P0 + 1.0 * P1 + 0.0 * P2
        rp2 = 0.0 * P0 + 0.0 * P1 + 1.0 * P2
        d0 = x0 + rp0 - A0
        d1 = x1 + rp1 - A1
        d2 = x2 + rp2 - A2
        r0, r1, r2 = d0, d1, d2
    else:
        rp0 = cs * P0 + -sn * P1 + 0.0 * P2
        rp1 = sn * P0 + cs * P1 + 0.0 * P2
        rp2 = 0.0 * P0 + 0.0 * P1 + 1.0 * P2
        d0 = x0 + rp0 - A0
        d1 = x1 + rp1 - A1
        d2 = 0.0 + rp2 - A2
        r0, r1, r2 = d0, d1, rp0 * d1 - rp1 * d0
    sq = d0 * d0 + d1 * d1 + d2 * d2
    dq = d0 * D0 + d1 * D1 + d2 * D2 + ell * c[C_LAM + i]
    return r0, r1, r2, sq, dq


@jit
def rows(c, anc, x0, x1, x2):
    """Rows of A = J_x / 2 (9 numbers), d_iᵀ d_i (3) and −(J_q)_ii / 2 (3) at the pose, from ``anchors``."""
    translational = c[C_TRANSLATIONAL] != 0.0
    cs, sn = 1.0, 0.0
    if not translational:
        cs, sn = math.cos(x2), math.sin(x2)
    a00, a01, a02, sq0, dq0 = _leg(c, 0, translational, cs, sn, x0, x1, x2, anc[0])
    a10, a11, a12, sq1, dq1 = _leg(c, 1, translational, cs, sn, x0, x1, x2, anc[1])
    a20, a21, a22, sq2, dq2 = _leg(c, 2, translational, cs, sn, x0, x1, x2, anc[2])
    return a00, a01, a02, a10, a11, a12, a20, a21, a22, sq0, sq1, sq2, dq0, dq1, dq2


@jit_inline
def _rate(a, r0, r1, r2):
    """ẋ = A⁻¹ ((−J_q / 2) q̇) from ``rows`` a; NaN where J_x is exactly singular."""
    u0, u1, u2, _ = solve3(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[12] * r0, a[13] * r1, a[14] * r2)
    return u0, u1, u2


@jit_inline
def _residual(anc, a):
    """max_i |d_iᵀ d_i − ℓ_i²| (NaN if any is NaN)."""
    res = 0.0
    for v in (a[9] - anc[0][6] * anc[0][6], a[10] - anc[1][6] * anc[1][6], a[11] - anc[2][6] * anc[2][6]):
        v = abs(v)
        if v != v:
            return np.nan
        res = max(res, v)
    return res


@jit_inline
def _metric(c, translational, s0, s1, s2):
    """‖(δp, ℓ_c δφ)‖ (planar) or ‖δp‖ (translational) of a step [m]."""
    if translational:
        return math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    lc = c[C_LC]
    return math.sqrt(s0 * s0 + s1 * s1 + lc * lc * s2 * s2)


@jit
def _newton(c, anc, x0, x1, x2, tolerance, max_iterations):
    """Newton's method on Φ(q, x) = 0 at the q of ``anc`` from x: (x, residual, rows at x)."""
    a = rows(c, anc, x0, x1, x2)
    residual = _residual(anc, a)
    for _ in range(max_iterations):
        if not residual > tolerance:  # NaN stops too
            break
        f0 = 0.5 * (a[9] - anc[0][6] * anc[0][6])
        f1 = 0.5 * (a[10] - anc[1][6] * anc[1][6])
        f2 = 0.5 * (a[11] - anc[2][6] * anc[2][6])
        d0, d1, d2, _ = solve3(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], f0, f1, f2)
        n0, n1, n2 = x0 + -1.0 * d0, x1 + -1.0 * d1, x2 + -1.0 * d2
        if not (math.isfinite(n0) and math.isfinite(n1) and math.isfinite(n2)):
            break
        x0, x1, x2 = n0, n1, n2
        a = rows(c, anc, x0, x1, x2)
        residual = _residual(anc, a)
    return x0, x1, x2, residual, a


@jit_inline
def link_condition3(c, a00, a01, a02, a10, a11, a12, a20, a21, a22, l0, l1, l2, at_least):
    """(k, sign(det J_x)) of three legs from the rows a of A = J_x / 2 and the link lengths ℓ_i.

    k = σ_min/σ_max of the link Jacobian diag(1/ℓ) A diag(pose_scale) (closed form), sign(det J_x) = sign(det A).
    Where ``at_least`` > 0 and k ≥ ``at_least`` is proven (``linalg.condition_at_least3``), k is ``at_least``. The
    three-leg case of every pose space (``envs.kernels.constraints._singularity`` calls it too).
    """
    i0, i1, i2 = 1.0 / l0, 1.0 / l1, 1.0 / l2
    s0, s1, s2 = c[C_SCALE], c[C_SCALE + 1], c[C_SCALE + 2]
    m00, m01, m02 = a00 * i0 * s0, a01 * i0 * s1, a02 * i0 * s2
    m10, m11, m12 = a10 * i1 * s0, a11 * i1 * s1, a12 * i1 * s2
    m20, m21, m22 = a20 * i2 * s0, a21 * i2 * s1, a22 * i2 * s2
    if at_least > 0.0 and condition_at_least3(m00, m01, m02, m10, m11, m12, m20, m21, m22, at_least):
        k = at_least
    else:
        k = singular_value_ratio3(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    det = a00 * (a11 * a22 - a12 * a21) + a01 * (a12 * a20 - a10 * a22) + a02 * (a10 * a21 - a11 * a20)
    return k, (1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0))


@jit_inline
def singularity(c, anc, a, at_least):
    """(k of J_i diag(pose_scale), sign(det J_x), k_I) from ``rows`` a and ``anchors`` anc.

    k is ``at_least`` where ``at_least`` > 0 and k ≥ ``at_least`` is proven (``link_condition3``).
    """
    k, sign = link_condition3(
        c, a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], anc[0][6], anc[1][6], anc[2][6], at_least
    )
    if c[C_LEGS] != 0.0:
        return k, sign, 1.0
    k1 = np.inf
    for v in (
        abs(a[12]) / (anc[0][6] * anc[0][7]),
        abs(a[13]) / (anc[1][6] * anc[1][7]),
        abs(a[14]) / (anc[2][6] * anc[2][7]),
    ):
        if v != v:
            return k, sign, np.nan
        k1 = min(k1, v)
    return k, sign, k1


@jit_inline
def _ik_one(c, i, cs, sn, x0, x1, z):
    """``ik_leg`` of actuator i at the pose with rotation (cos φ, sin φ) and height z (planar: 0)."""
    P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
    w0 = x0 + cs * P0 - sn * P1 - c[C_B + 3 * i]
    w1 = x1 + sn * P0 + cs * P1 - c[C_B + 3 * i + 1]
    return ik_leg(c, i, w0, w1, z + P2 - c[C_B + 3 * i + 2])


@jit
def inverse_kinematics(c, x0, x1, x2):
    """The actuator coordinates (q_0, q_1, q_2) of the pose x, in closed form on each actuator's branch.

    Leg lengths ‖p + R P_i − B_i‖, crank angles or slider positions (``ik_leg``; NaN where one cannot reach).
    """
    translational = c[C_TRANSLATIONAL] != 0.0
    cs, sn = (1.0, 0.0) if translational else (math.cos(x2), math.sin(x2))
    z = x2 if translational else 0.0
    # The indices as int64, not as constants: Numba would compile ``ik_leg`` once per constant index.
    return (
        _ik_one(c, np.int64(0), cs, sn, x0, x1, z),
        _ik_one(c, np.int64(1), cs, sn, x0, x1, z),
        _ik_one(c, np.int64(2), cs, sn, x0, x1, z),
    )
