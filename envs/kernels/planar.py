"""The family core on the planar pose space, in scalars: the step of every planar robot of the family.

A planar robot of the distance-constraint family has three legs and the pose (x, y, φ) (``envs.kernels.packing``
packs the family's constants, ``envs.kernels.layout`` their offsets). Its 3 × 3 algebra fits in
registers, so here it is written out for one robot in scalars, with closed forms (the adjugate for the systems,
the trigonometric solution of the cubic for k; ``envs.kernels.linalg``), where the spatial pose space goes
through 6 × 6 work arrays. ``envs.kernels.step`` steps every planar leg robot through ``transition_row``, so a
planar robot's dynamics exist once. The math, with d_i = p + R(φ) P_i − B_i (a leg: A_i = B_i, ℓ_i = q_i):

    Φ_i = d_iᵀ d_i − q_i²,   J_x = 2 A,   A_i = (d_ix, d_iy, d_iy (R P_i)_x − d_ix (R P_i)_y),
    J_q = −2 diag(q),        J_f = A⁻¹ diag(q),   J_i = diag(1/q) A.

Every function reads the geometry and the settings from ``c``, the family's packed constants (points at
``C_P + 3 i`` and ``C_B + 3 i``, z ignored).
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels import layout, linalg, setup
from envs.kernels.cache import drop_stale_caches
from envs.kernels.layout import (
    _ACTUATOR_SINGULAR,
    _ASSEMBLY_MODE_CHANGE,
    _NEWTON_FAILED,
    _OUT_OF_BOUNDS,
    _SINGULAR,
    _SINGULARITY_CROSSED,
    C_B,
    C_DT,
    C_HARD,
    C_HARD1,
    C_HIGH,
    C_JUMP,
    C_LC,
    C_LMAX,
    C_LMIN,
    C_LOW,
    C_MAX_SUBSTEP,
    C_MAX_SUBSTEPS,
    C_NEWTON_IT,
    C_NEWTON_TOL,
    C_P,
    C_PENALTY,
    C_RATE,
    C_RK4,
    C_SAFE,
    C_SCALE,
    C_SUCC_O,
    C_SUCC_P,
    C_WA,
    C_WO,
    C_WP,
    C_WS,
)
from envs.kernels.linalg import singular_value_ratio3, solve3
from envs.kernels.setup import jit, jit_inline

__all__ = ["is_success", "observation_row", "reward_terms", "termination_reason", "transition_row"]

_TWO_PI = 2.0 * math.pi

drop_stale_caches(__file__, [layout.__file__, linalg.__file__, setup.__file__])


@jit
def rows(c, px, py, phi):
    """Rows of A = J_x / 2 and the squared leg lengths d_iᵀ d_i at the pose (px, py, phi)."""
    cs = math.cos(phi)
    sn = math.sin(phi)
    rpx = cs * c[C_P + 0] - sn * c[C_P + 1]
    rpy = sn * c[C_P + 0] + cs * c[C_P + 1]
    dx0 = px + rpx - c[C_B + 0]
    dy0 = py + rpy - c[C_B + 1]
    m0 = dy0 * rpx - dx0 * rpy
    rpx = cs * c[C_P + 3] - sn * c[C_P + 4]
    rpy = sn * c[C_P + 3] + cs * c[C_P + 4]
    dx1 = px + rpx - c[C_B + 3]
    dy1 = py + rpy - c[C_B + 4]
    m1 = dy1 * rpx - dx1 * rpy
    rpx = cs * c[C_P + 6] - sn * c[C_P + 7]
    rpy = sn * c[C_P + 6] + cs * c[C_P + 7]
    dx2 = px + rpx - c[C_B + 6]
    dy2 = py + rpy - c[C_B + 7]
    m2 = dy2 * rpx - dx2 * rpy
    sq0, sq1, sq2 = dx0 * dx0 + dy0 * dy0, dx1 * dx1 + dy1 * dy1, dx2 * dx2 + dy2 * dy2
    return dx0, dy0, m0, dx1, dy1, m1, dx2, dy2, m2, sq0, sq1, sq2


@jit
def max_abs3(a, b, c):
    """max(|a|, |b|, |c|), NaN if any is NaN (as ``np.max``)."""
    a, b, c = abs(a), abs(b), abs(c)
    if a != a or b != b or c != c:
        return np.nan
    return max(a, max(b, c))


@jit
def pose_rate_rows(a, q0, q1, q2, r0, r1, r2):
    """ẋ = J_f q̇ = A⁻¹ (L ∘ q̇) from the rows ``a`` of A at x (as ``rows``); NaN where J_x is singular."""
    u0, u1, u2, _ = solve3(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], q0 * r0, q1 * r1, q2 * r2)
    return u0, u1, u2


@jit
def pose_rate(c, q0, q1, q2, x0, x1, x2, r0, r1, r2):
    """ẋ = J_f(q, x) q̇ = A⁻¹ (L ∘ q̇) [m/s, m/s, rad/s]; NaN where J_x is exactly singular."""
    return pose_rate_rows(rows(c, x0, x1, x2), q0, q1, q2, r0, r1, r2)


@jit
def singularity_rows(c, q0, q1, q2, a):
    """(inverse condition number of J_i diag(pose_scale), sign(det J_x)) from the rows ``a`` of A at x."""
    s0, s1, s2 = c[C_SCALE], c[C_SCALE + 1], c[C_SCALE + 2]
    k = singular_value_ratio3(
        a[0] / q0 * s0, a[1] / q0 * s1, a[2] / q0 * s2,
        a[3] / q1 * s0, a[4] / q1 * s1, a[5] / q1 * s2,
        a[6] / q2 * s0, a[7] / q2 * s1, a[8] / q2 * s2,
    )  # fmt: skip
    det = a[0] * (a[4] * a[8] - a[5] * a[7]) + a[1] * (a[5] * a[6] - a[3] * a[8]) + a[2] * (a[3] * a[7] - a[4] * a[6])
    sign = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)
    return k, sign


@jit
def newton(c, q0, q1, q2, x0, x1, x2, tolerance, max_iterations):
    """Newton's method on Φ(q, x) = 0 from x (as ``Planar3RPR.forward_kinematics``).

    Each step solves J_x δ = Φ and sets x ← x − δ; it stops once max_i |Φ_i| ≤ tolerance, at a
    non-finite residual or iterate, or after ``max_iterations`` steps.

    Returns:
        (x0, x1, x2, residual, rows of A at the returned x (as ``rows``)).
    """
    a = rows(c, x0, x1, x2)
    residual = max_abs3(a[9] - q0 * q0, a[10] - q1 * q1, a[11] - q2 * q2)
    for _ in range(max_iterations):
        if not residual > tolerance:  # NaN stops too
            break
        # J_x δ = Φ with J_x = 2A.
        f0, f1, f2 = a[9] - q0 * q0, a[10] - q1 * q1, a[11] - q2 * q2
        d0, d1, d2, _ = solve3(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], f0, f1, f2)
        n0, n1, n2 = x0 - 0.5 * d0, x1 - 0.5 * d1, x2 - 0.5 * d2
        if not (math.isfinite(n0) and math.isfinite(n1) and math.isfinite(n2)):
            break
        x0, x1, x2 = n0, n1, n2
        a = rows(c, x0, x1, x2)
        residual = max_abs3(a[9] - q0 * q0, a[10] - q1 * q1, a[11] - q2 * q2)
    return x0, x1, x2, residual, a


@jit
def substeps(c, r0, r1, r2):
    """Substeps so that each predicts at most ``max_substep`` of motion ‖(Δx, Δy, ℓ_c Δφ)‖ [m]."""
    dt = c[C_DT]
    m0 = r0 * dt
    m1 = r1 * dt
    m2 = r2 * dt * c[C_LC]
    count = np.ceil(math.sqrt(m0 * m0 + m1 * m1 + m2 * m2) / c[C_MAX_SUBSTEP])
    cap = c[C_MAX_SUBSTEPS]
    if not math.isfinite(count):
        return int(cap)
    return int(min(max(count, 1.0), cap))


@jit_inline
def termination_reason(c, failed, jump, sign, mode, k, out, k1):
    """The step's termination reason code (0: none), first match in the order of ``TERMINATION_REASONS``.

    Args:
        c: Packed constants of the family.
        failed: Whether the correction onto Φ = 0 failed.
        jump: Largest correction of the step [m].
        sign: sign(det J_x) at the new pose.
        mode: The episode's sign(det J_x) (its working mode).
        k: Inverse condition number at the new pose (Type II measure).
        out: Whether the pose left its bounds.
        k1: Actuator condition number at the new pose (Type I measure; 1 for legs).
    """
    if failed:
        return _NEWTON_FAILED
    if jump > c[C_JUMP]:
        return _ASSEMBLY_MODE_CHANGE
    if sign != mode:
        return _SINGULARITY_CROSSED
    if k < c[C_HARD]:
        return _SINGULAR
    if out:
        return _OUT_OF_BOUNDS
    if k1 < c[C_HARD1]:
        return _ACTUATOR_SINGULAR
    return 0


@jit_inline
def transition_row(c, state, action, i, moved):
    """Advance robot i by one control period (predict, correct, measure, terminate); writes its row of ``moved``.

    ``state`` and ``moved`` as the input and the output of ``step.transition_batch``.
    """
    q, x, _, det_sign, residual = state
    o_q, o_x, o_k, o_k1, o_res, o_a, o_qr, o_reason, o_jump = moved
    dt = c[C_DT]
    lo, hi = c[C_LMIN], c[C_LMAX]
    lc = c[C_LC]
    q0, q1, q2 = q[i, 0], q[i, 1], q[i, 2]
    x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
    a0 = min(max(action[i, 0], -1.0), 1.0)
    a1 = min(max(action[i, 1], -1.0), 1.0)
    a2 = min(max(action[i, 2], -1.0), 1.0)
    stroke = c[C_RATE] * dt
    n0 = min(max(q0 + a0 * stroke, lo), hi)
    n1 = min(max(q1 + a1 * stroke, lo), hi)
    n2 = min(max(q2 + a2 * stroke, lo), hi)
    r0, r1, r2 = (n0 - q0) / dt, (n1 - q1) / dt, (n2 - q2) / dt
    start_rows = rows(c, x0, x1, x2)
    a = start_rows
    v0, v1, v2 = pose_rate_rows(start_rows, q0, q1, q2, r0, r1, r2)
    count = substeps(c, v0, v1, v2)
    h = dt / count
    rk4 = c[C_RK4] != 0.0
    tolerance, iterations = c[C_NEWTON_TOL], int(c[C_NEWTON_IT])
    kq0, kq1, kq2, kx0, kx1, kx2 = q0, q1, q2, x0, x1, x2
    res = residual[i]
    jump = 0.0
    failed = False
    for k in range(count):
        frac = (k + 1) / count
        t0, t1, t2 = q0 + frac * (n0 - q0), q1 + frac * (n1 - q1), q2 + frac * (n2 - q2)
        if k > 0:  # at the pose Newton's method just returned, whose rows it computed
            v0, v1, v2 = pose_rate_rows(a, kq0, kq1, kq2, r0, r1, r2)
        if rk4:
            hh = 0.5 * h
            m0, m1, m2 = kq0 + hh * r0, kq1 + hh * r1, kq2 + hh * r2
            b0, b1, b2 = pose_rate(c, m0, m1, m2, kx0 + hh * v0, kx1 + hh * v1, kx2 + hh * v2, r0, r1, r2)
            e0, e1, e2 = pose_rate(c, m0, m1, m2, kx0 + hh * b0, kx1 + hh * b1, kx2 + hh * b2, r0, r1, r2)
            f0, f1, f2 = pose_rate(
                c, kq0 + h * r0, kq1 + h * r1, kq2 + h * r2, kx0 + h * e0, kx1 + h * e1, kx2 + h * e2, r0, r1, r2
            )
            s = h / 6.0
            p0 = kx0 + s * (v0 + 2.0 * b0 + 2.0 * e0 + f0)
            p1 = kx1 + s * (v1 + 2.0 * b1 + 2.0 * e1 + f1)
            p2 = kx2 + s * (v2 + 2.0 * b2 + 2.0 * e2 + f2)
        else:
            p0, p1, p2 = kx0 + h * v0, kx1 + h * v1, kx2 + h * v2
        if not (math.isfinite(p0) and math.isfinite(p1) and math.isfinite(p2)):
            failed = True
            break
        y0, y1, y2, fres, a = newton(c, t0, t1, t2, p0, p1, p2, tolerance, iterations)
        if not fres <= tolerance:
            failed = True
            break
        g0, g1, g2 = y0 - p0, y1 - p1, lc * (y2 - p2)
        jump = max(jump, math.sqrt(g0 * g0 + g1 * g1 + g2 * g2))
        kq0, kq1, kq2, kx0, kx1, kx2, res = t0, t1, t2, y0, y1, y2, fres
    if failed:
        kq0, kq1, kq2, kx0, kx1, kx2, res = q0, q1, q2, x0, x1, x2, residual[i]
        a = start_rows
    k_new, sign = singularity_rows(c, kq0, kq1, kq2, a)
    out = False
    for j, value in enumerate((kx0, kx1, kx2)):
        if value < c[C_LOW + j] or value > c[C_HIGH + j]:
            out = True
    reason = termination_reason(c, failed, jump, sign, det_sign[i], k_new, out, 1.0)
    o_q[i, 0], o_q[i, 1], o_q[i, 2] = kq0, kq1, kq2
    o_x[i, 0], o_x[i, 1], o_x[i, 2] = kx0, kx1, kx2
    o_k[i] = k_new
    o_k1[i] = 1.0  # legs: no Type I singularity
    o_res[i] = res
    o_a[i, 0], o_a[i, 1], o_a[i, 2] = a0, a1, a2
    o_qr[i, 0], o_qr[i, 1], o_qr[i, 2] = r0, r1, r2
    o_reason[i] = reason
    o_jump[i] = jump


# -- reward terms and the observation of a planar robot -----------------------------------------------


@jit
def wrap(angle):
    """Wrap to [−π, π) (Python's floating modulo, as ``np.mod``)."""
    return (angle + math.pi) % _TWO_PI - math.pi


@jit
def errors(x0, x1, x2, g0, g1, g2):
    """(‖p* − p‖ [m], |wrap(φ* − φ)| [rad])."""
    return math.hypot(g0 - x0, g1 - x1), abs(wrap(g2 - x2))


@jit
def is_success(c, position_error, orientation_error):
    """Whether the errors are within the success tolerances."""
    return position_error <= c[C_SUCC_P] and orientation_error <= c[C_SUCC_O]


@jit_inline
def reward_terms(c, pose, target, k, action, reason):
    """(tracking, singularity, action, termination) reward terms and the two errors.

    ``pose`` and ``target`` are (x, y, φ), ``action`` the three applied actions, each a tuple of floats.
    """
    x0, x1, x2 = pose
    g0, g1, g2 = target
    a0, a1, a2 = action
    ep, eo = errors(x0, x1, x2, g0, g1, g2)
    tracking = -(c[C_WP] * ep + c[C_WO] * c[C_LC] * eo)
    gap = max(c[C_SAFE] - k, 0.0) / c[C_SAFE]
    singular = -c[C_WS] * (gap * gap)
    act = -c[C_WA] * (a0 * a0 + a1 * a1 + a2 * a2)
    term = -c[C_PENALTY] * (1.0 if reason != 0 else 0.0)
    return tracking, singular, act, term, ep, eo


@jit_inline
def clip32(o_obs, i, j, value, low, high):
    """o_obs[i, j] = float32(clip(value, low[j], high[j])) (the clip in float64, as ``np.clip``)."""
    o_obs[i, j] = np.float32(min(max(value, np.float64(low[j])), np.float64(high[j])))


@jit_inline
def observation_row(c, observation, q, x, k, target, velocity, i, o_obs):
    """Row i of the observation, clipped to [low, high], float32.

    The planar layout of ``envs.kernels.packing.observation_layout``. ``observation`` is (low, high,
    with_velocity) (``step.evaluate_batch``); ``target`` and ``velocity`` are the target's (x, y, φ) and its
    rate, tuples of floats.
    """
    low, high, with_velocity = observation
    g0, g1, g2 = target
    v0, v1, v2 = velocity
    x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
    lo, hi = c[C_LMIN], c[C_LMAX]
    span = hi - lo
    legs = rows(c, g0, g1, g2)  # the target's inverse kinematics: L_j* = ‖d_j(x*)‖
    # The columns in one tuple, clipped in one loop (one compiled clip, not one per column).
    values = (
        x0, x1, math.cos(x2), math.sin(x2),
        g0, g1, math.cos(g2), math.sin(g2),
        g0 - x0, g1 - x1, wrap(g2 - x2),
        2.0 * (q[i, 0] - lo) / span - 1.0, 2.0 * (q[i, 1] - lo) / span - 1.0, 2.0 * (q[i, 2] - lo) / span - 1.0,
        (math.sqrt(legs[9]) - q[i, 0]) / span, (math.sqrt(legs[10]) - q[i, 1]) / span,
        (math.sqrt(legs[11]) - q[i, 2]) / span,
        k[i],
        v0, v1, v2,
    )  # fmt: skip
    for j in range(21 if with_velocity else 18):
        clip32(o_obs, i, j, values[j], low, high)
