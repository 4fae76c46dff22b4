"""The equations of motion of the family in compiled code: M(x), c + G and ẍ of one robot on each row path.

The reference is ``kinematics.dynamics.RobotDynamics`` (its state, twist convention, bodies and Kane's form
M ẍ + c + G = J_iᵀ τ); these kernels gather the same terms leg by leg at the leg's platform point. With the
platform point P_i = p + r_i (r_i = R P_i in {B} axes), d_i = P_i − A_i(q_i), ℓ_i = λ_i q_i + l_i, u_i = d_i / ℓ_i
and V_i = K_i ẋ the velocity of P_i, every body of leg i moves linearly with V_i:

    g_i = d_i / (d_iᵀ A_i′ + λ_i ℓ_i),   q̇_i = g_iᵀ V_i   (row i of J_i is (K_iᵀ g_i)ᵀ),
    h_i = A_i′ + λ_i u_i,                 u̇_i = (I − h_i g_iᵀ) V_i / ℓ_i,

so the leg's kinetic energy is ½ V_iᵀ S_i V_i with the 3 × 3 leg inertia at P_i

    S_i = s_I I + s_g g_i g_iᵀ + s_x (g_i h_iᵀ + h_i g_iᵀ),   α = W_U + m_d c_d², β = m_d c_d,
    s_I = m_d + α / ℓ² − 2 β / ℓ,   s_g = W_Q + α |h|² / ℓ²,   s_x = β / ℓ − α / ℓ²

(weights of ``envs.kernels.dynamics_layout``), and its velocity-product and gravity terms are one force F_i at
P_i, from q̈_i⁰ and ü_i⁰, the accelerations at ẍ = 0 (``_leg``). Then

    M = Σ_i K_iᵀ S_i K_i + platform,   c + G = Σ_i K_iᵀ F_i + platform,   J_iᵀ τ = Σ_i τ_i K_iᵀ g_i,

where K_iᵀ f is the generalised force of a force f at P_i (spatial (f, r_i × f); planar (f_x, f_y,
(r_i × f)_z); translational f), and the platform is a point mass at its centre of mass plus its rotational
inertia R I Rᵀ (spatial, with the gyroscopic ω × (R I Rᵀ ω); planar I_zz). The terms s_I K_iᵀ K_i of all the
points add up from their moments Σ s_I, Σ s_I r and Σ s_I r rᵀ (``_moments``).
Points are 3-D throughout (a planar robot's z is 0); the twist's angular part is ω = (0, 0, φ̇) (planar),
ω (spatial) or 0 (translational), so a point's velocity is v + ω × r and its acceleration at constant twist
ω × (ω × r) on every pose space.

Row paths (``envs.kernels.paths``): on ``PLANAR_LEGS`` and ``THREE`` (three actuators, m = 3) every vector is a
tuple of three floats and M a tuple of three rows, in registers; on ``WORK_ARRAYS`` (any pose space) they are
rows of the robot's dynamics work array (``_dynamics_work``, rows ``D_*``). ``equations``, ``solve_acceleration``
and ``acceleration`` are the operations an integrator calls; ``envs.kernels.dynamics_batch`` runs N robots of
one geometry.
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import overload

from envs.kernels import paths, three
from envs.kernels.cache import drop_stale_caches
from envs.kernels.dynamics_layout import (
    C_INERTIA_SIZE,
    D_BIAS,
    D_FORCE,
    D_GRAV,
    D_JT,
    D_LU,
    D_M,
    D_RHS,
    D_SIZE,
    I_AMASS,
    I_ARM,
    I_COM,
    I_DAMP,
    I_DCOM,
    I_DMASS,
    I_GRAVITY,
    I_INERTIA,
    I_JDAMP,
    I_LEVER,
    I_MASS,
    I_WQ,
    I_WU,
    pack_inertia,
)
from envs.kernels.layout import C_B, C_E, C_LAM, C_LEGS, C_N, C_P, C_SPATIAL, C_TRANSLATIONAL
from envs.kernels.linalg import solve3, solve6
from envs.kernels.packing import _OVERLOAD_OPTIONS, WORK_ARRAYS, _literal_path
from envs.kernels.pose import _frame
from envs.kernels.setup import jit, jit_inline

__all__ = [
    "C_INERTIA_SIZE",
    "acceleration",
    "equations",
    "pack_inertia",
    "solve_acceleration",
]

drop_stale_caches(__file__)


# -- one leg, in scalars (every path) ---------------------------------------------------------------------


@jit_inline
def _anchor(c, i, qi):
    """Leg i's anchor at qi: (A_i (3), A_i′ (3), A_i″ (3), ℓ_i) [m, m per unit of q, per unit of q²]."""
    if c[C_LEGS] != 0.0:  # A_i = B_i, ℓ_i = q_i
        return c[C_B + 3 * i], c[C_B + 3 * i + 1], c[C_B + 3 * i + 2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, qi
    A0, A1, A2, D0, D1, D2, ell, _speed = three.anchor(c, i, qi)
    e0, e1, e2 = c[C_E + 3 * i], c[C_E + 3 * i + 1], c[C_E + 3 * i + 2]
    # A_i″ = −a_i (cos q u_i + sin q v_i) = −(A_i − B_i − q e_i)
    DD0 = c[C_B + 3 * i] + qi * e0 - A0
    DD1 = c[C_B + 3 * i + 1] + qi * e1 - A1
    DD2 = c[C_B + 3 * i + 2] + qi * e2 - A2
    return A0, A1, A2, D0, D1, D2, DD0, DD1, DD2, ell


@jit_inline
def _leg(c, ci, i, qi, P0, P1, P2, V0, V1, V2, a0, a1, a2, split):
    """Leg i's inertia and forces at its platform point: (s_I, s_g, s_x, g_i (3), h_i (3), F_i (3), F_i,G (3)).

    Inlined with ``_anchor`` into the two callers (``_terms3``, ``_terms_work``): as a call of its own, the
    arguments and the 15 results of every leg went through memory (a sixth of the hexapod's M and c + G).

    Reads leg i's geometry from ``c`` and its bodies from ``ci``; qi is its actuator coordinate, (P0, P1, P2) the
    point P_i in {B} [m], (V0, V1, V2) its velocity K_i ẋ [m/s] and (a0, a1, a2) its acceleration at ẍ = 0
    [m/s²]. Returns the coefficients of S_i (module docstring), g_i, h_i, F_i [N], the force at P_i whose
    generalised force K_iᵀ F_i is the leg's share of c + G, and with ``split`` F_i,G, gravity's part of it (F_i at
    rest; else zeros).
    """
    A0, A1, A2, D0, D1, D2, DD0, DD1, DD2, ell = _anchor(c, i, qi)
    lam = c[C_LAM + i]
    d0, d1, d2 = P0 - A0, P1 - A1, P2 - A2
    inv = 1.0 / ell
    u0, u1, u2 = d0 * inv, d1 * inv, d2 * inv
    denominator = d0 * D0 + d1 * D1 + d2 * D2 + lam * ell
    g0, g1, g2 = d0 / denominator, d1 / denominator, d2 / denominator
    qd = g0 * V0 + g1 * V1 + g2 * V2
    # ḋ = V − A′ q̇; u̇ = (ḋ − ℓ̇ u) / ℓ
    dd0, dd1, dd2 = V0 - D0 * qd, V1 - D1 * qd, V2 - D2 * qd
    ld = lam * qd
    ud0, ud1, ud2 = (dd0 - ld * u0) * inv, (dd1 - ld * u1) * inv, (dd2 - ld * u2) * inv
    # d/dt² (‖d‖² − ℓ²) = 0 at ẍ = 0
    numerator = (
        d0 * a0 + d1 * a1 + d2 * a2
        - (d0 * DD0 + d1 * DD1 + d2 * DD2) * qd * qd
        + dd0 * dd0 + dd1 * dd1 + dd2 * dd2
        - ld * ld
    )  # fmt: skip
    qdd = numerator / denominator
    ldd = lam * qdd
    qd2 = qd * qd
    udd0 = (a0 - D0 * qdd - DD0 * qd2 - ldd * u0 - 2.0 * ld * ud0) * inv
    udd1 = (a1 - D1 * qdd - DD1 * qd2 - ldd * u1 - 2.0 * ld * ud1) * inv
    udd2 = (a2 - D2 * qdd - DD2 * qd2 - ldd * u2 - 2.0 * ld * ud2) * inv
    h0, h1, h2 = D0 + lam * u0, D1 + lam * u1, D2 + lam * u2
    w_q, w_u = ci[I_WQ + i], ci[I_WU + i]
    m_d, c_d = ci[I_DMASS + i], ci[I_DCOM + i]
    m_a = ci[I_AMASS + i]
    alpha = w_u + m_d * c_d * c_d
    beta = m_d * c_d
    s_i = m_d + alpha * inv * inv - 2.0 * beta * inv
    s_g = w_q + alpha * (h0 * h0 + h1 * h1 + h2 * h2) * inv * inv
    s_x = beta * inv - alpha * inv * inv
    gx, gy, gz = ci[I_GRAVITY], ci[I_GRAVITY + 1], ci[I_GRAVITY + 2]
    # the rod: f_d = m_d (a_d − g) with a_d = a − c_d ü; L_uᵀ y = (y − g (h·y)) / ℓ
    fd0 = m_d * (a0 - c_d * udd0 - gx)
    fd1 = m_d * (a1 - c_d * udd1 - gy)
    fd2 = m_d * (a2 - c_d * udd2 - gz)
    lever = m_a * ci[I_LEVER + i]
    y0 = w_u * udd0 - c_d * fd0 - lever * gx
    y1 = w_u * udd1 - c_d * fd1 - lever * gy
    y2 = w_u * udd2 - c_d * fd2 - lever * gz
    # passive joint friction b ω, ω = u × u̇ − w⊥ q̇ (RobotDynamics._joint_map): J_uᵀ (b ω × u) + J_qᵀ (−b w⊥·ω)
    b_j = ci[I_JDAMP + i]
    wdotw = 0.0
    if b_j != 0.0:
        norm = D0 * D0 + D1 * D1 + D2 * D2
        scale = 1.0 / norm if norm > 0.0 else 0.0
        w0, w1, w2 = (D1 * DD2 - D2 * DD1) * scale, (D2 * DD0 - D0 * DD2) * scale, (D0 * DD1 - D1 * DD0) * scale
        wu = w0 * u0 + w1 * u1 + w2 * u2
        w0, w1, w2 = w0 - wu * u0, w1 - wu * u1, w2 - wu * u2
        o0 = u1 * ud2 - u2 * ud1 - w0 * qd
        o1 = u2 * ud0 - u0 * ud2 - w1 * qd
        o2 = u0 * ud1 - u1 * ud0 - w2 * qd
        y0 += b_j * (o1 * u2 - o2 * u1)
        y1 += b_j * (o2 * u0 - o0 * u2)
        y2 += b_j * (o0 * u1 - o1 * u0)
        wdotw = b_j * (w0 * o0 + w1 * o1 + w2 * o2)
    hy = h0 * y0 + h1 * y1 + h2 * y2
    # the drive's viscous friction b q̇ acts along the actuator like its inertia's w_q q̈
    along = w_q * qdd + ci[I_DAMP + i] * qd - wdotw - m_a * ci[I_ARM + i] * (D0 * gx + D1 * gy + D2 * gz) - hy * inv
    F0 = fd0 + y0 * inv + along * g0
    F1 = fd1 + y1 * inv + along * g1
    F2 = fd2 + y2 * inv + along * g2
    G0 = G1 = G2 = 0.0
    if split:  # gravity alone: the terms above at rest (V = a = 0), in the same order
        fg0, fg1, fg2 = m_d * -gx, m_d * -gy, m_d * -gz
        y0, y1, y2 = -c_d * fg0 - lever * gx, -c_d * fg1 - lever * gy, -c_d * fg2 - lever * gz
        along = -(m_a * ci[I_ARM + i] * (D0 * gx + D1 * gy + D2 * gz)) - (h0 * y0 + h1 * y1 + h2 * y2) * inv
        G0, G1, G2 = fg0 + y0 * inv + along * g0, fg1 + y1 * inv + along * g1, fg2 + y2 * inv + along * g2
    return s_i, s_g, s_x, g0, g1, g2, h0, h1, h2, F0, F1, F2, G0, G1, G2


# -- three actuators, planar or translational: registers --------------------------------------------------


@jit
def _wrench3(translational, r0, r1, f0, f1, f2):
    """K ᵀ f of a force f at the point p + r: planar (f_x, f_y, (r × f)_z), translational f."""
    if translational:
        return f0, f1, f2
    return f0, f1, r0 * f1 - r1 * f0


@jit
def _update3(M, s_i, r0, r1, translational, s_g, G, s_x, H):
    """M + s_I KᵀK + s_g G Gᵀ + s_x (G Hᵀ + H Gᵀ), M symmetric as (M00, M01, M02, M11, M12, M22)."""
    k02, k12, k22 = (0.0, 0.0, 1.0) if translational else (-r1, r0, r0 * r0 + r1 * r1)
    return (
        M[0] + s_i + s_g * G[0] * G[0] + 2.0 * s_x * G[0] * H[0],
        M[1] + s_g * G[0] * G[1] + s_x * (G[0] * H[1] + H[0] * G[1]),
        M[2] + s_i * k02 + s_g * G[0] * G[2] + s_x * (G[0] * H[2] + H[0] * G[2]),
        M[3] + s_i + s_g * G[1] * G[1] + 2.0 * s_x * G[1] * H[1],
        M[4] + s_i * k12 + s_g * G[1] * G[2] + s_x * (G[1] * H[2] + H[1] * G[2]),
        M[5] + s_i * k22 + s_g * G[2] * G[2] + 2.0 * s_x * G[2] * H[2],
    )


@jit
def _terms3(c, ci, q, x, xdot, tau, split):
    """(M as (M00, M01, M02, M11, M12, M22), c + G, J_iᵀ τ, G, J_iᵀ's columns) of three actuators (tuples).

    Planar or translational. G (gravity's share of c + G; zeros unless ``split``) and the columns K_iᵀ g_i of
    J_iᵀ are what the holding forces solve J_iᵀ τ_h = G with (``envs.kernels.force``).
    """
    translational = c[C_TRANSLATIONAL] != 0.0
    if translational:
        cs, sn, p2, v2, w = 1.0, 0.0, x[2], xdot[2], 0.0
    else:
        cs, sn, p2, v2, w = math.cos(x[2]), math.sin(x[2]), 0.0, 0.0, xdot[2]
    p0, p1, v0, v1 = x[0], x[1], xdot[0], xdot[1]
    gx, gy, gz = ci[I_GRAVITY], ci[I_GRAVITY + 1], ci[I_GRAVITY + 2]
    w2 = w * w
    zero = (0.0, 0.0, 0.0)
    # the platform: a point mass at its centre of mass, and I_zz (planar)
    c0, c1 = ci[I_COM], ci[I_COM + 1]
    r0, r1 = cs * c0 - sn * c1, sn * c0 + cs * c1
    mass = ci[I_MASS]
    M = _update3((0.0, 0.0, 0.0, 0.0, 0.0, 0.0), mass, r0, r1, translational, 0.0, zero, 0.0, zero)
    if not translational:
        M = (M[0], M[1], M[2], M[3], M[4], M[5] + ci[I_INERTIA + 8])
    b = _wrench3(translational, r0, r1, mass * (-w2 * r0 - gx), mass * (-w2 * r1 - gy), -mass * gz)
    grav = _wrench3(translational, r0, r1, mass * -gx, mass * -gy, -mass * gz)
    columns0 = columns1 = columns2 = zero
    for i in range(3):
        P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
        r0, r1 = cs * P0 - sn * P1, sn * P0 + cs * P1
        s_i, s_g, s_x, g0, g1, g2, h0, h1, h2, F0, F1, F2, Fg0, Fg1, Fg2 = _leg(
            c, ci, i, q[i], p0 + r0, p1 + r1, p2 + P2, v0 - w * r1, v1 + w * r0, v2, -w2 * r0, -w2 * r1, 0.0, split
        )
        G = _wrench3(translational, r0, r1, g0, g1, g2)
        H = _wrench3(translational, r0, r1, h0, h1, h2)
        M = _update3(M, s_i, r0, r1, translational, s_g, G, s_x, H)
        W = _wrench3(translational, r0, r1, F0, F1, F2)
        b = (b[0] + W[0], b[1] + W[1], b[2] + W[2])
        if split:
            W = _wrench3(translational, r0, r1, Fg0, Fg1, Fg2)
            grav = (grav[0] + W[0], grav[1] + W[1], grav[2] + W[2])
        if i == 0:
            columns0 = G
        elif i == 1:
            columns1 = G
        else:
            columns2 = G
    columns = (columns0, columns1, columns2)
    return M, b, _generalised3(tau, columns), grav, columns


@jit
def _generalised3(tau, columns):
    """J_iᵀ τ = Σ_i τ_i K_iᵀ g_i of three actuators from J_iᵀ's columns (``_terms3``), summed leg by leg."""
    a, b, d = columns
    f = (0.0 + tau[0] * a[0], 0.0 + tau[0] * a[1], 0.0 + tau[0] * a[2])
    f = (f[0] + tau[1] * b[0], f[1] + tau[1] * b[1], f[2] + tau[1] * b[2])
    return f[0] + tau[2] * d[0], f[1] + tau[2] * d[1], f[2] + tau[2] * d[2]


# -- any pose space: work arrays ----------------------------------------------------------------------------


@jit
def _dynamics_work():
    """A work array of the equations of motion of one robot (rows ``D_*``, 6 columns)."""
    return np.zeros((D_SIZE, 6))


@jit
def _wrench(spatial, translational, r0, r1, r2, f0, f1, f2):
    """K ᵀ f of a force f at the point p + r, in the twist's coordinates, padded to 6 numbers."""
    if spatial:
        return f0, f1, f2, r1 * f2 - r2 * f1, r2 * f0 - r0 * f2, r0 * f1 - r1 * f0
    if translational:
        return f0, f1, f2, 0.0, 0.0, 0.0
    return f0, f1, r0 * f1 - r1 * f0, 0.0, 0.0, 0.0


@jit
def _moments(moments, s, r0, r1, r2):
    """The moments (Σ s, Σ s r (3), Σ s r rᵀ (6: xx, xy, xz, yy, yz, zz)) with the point p + r of weight s added."""
    return (
        moments[0] + s,
        moments[1] + s * r0, moments[2] + s * r1, moments[3] + s * r2,
        moments[4] + s * r0 * r0, moments[5] + s * r0 * r1, moments[6] + s * r0 * r2,
        moments[7] + s * r1 * r1, moments[8] + s * r1 * r2, moments[9] + s * r2 * r2,
    )  # fmt: skip


@jit
def _add_moments(M, spatial, translational, moments):
    """The upper triangle of M += Σ s KᵀK over the points of ``_moments``.

    Spatial KᵀK = [[I, −[r]×], [[r]×, |r|² I − r rᵀ]]; planar the (x, y, φ) block of it; translational I.
    """
    s, x, y, z, xx, xy, xz, yy, yz, zz = moments
    M[0, 0] += s
    M[1, 1] += s
    if spatial:
        M[2, 2] += s
        M[0, 4] += z
        M[0, 5] -= y
        M[1, 3] -= z
        M[1, 5] += x
        M[2, 3] += y
        M[2, 4] -= x
        M[3, 3] += yy + zz
        M[3, 4] -= xy
        M[3, 5] -= xz
        M[4, 4] += xx + zz
        M[4, 5] -= yz
        M[5, 5] += xx + yy
    elif translational:
        M[2, 2] += s
    else:
        M[0, 2] -= y
        M[1, 2] += x
        M[2, 2] += xx + yy


@jit
def _add_leg(M, m, s_g, s_x, G, H):
    """The upper triangle of M += s_g G Gᵀ + s_x (G Hᵀ + H Gᵀ) for 6-tuples G, H (m used)."""
    if m == 6:  # constant bounds: the tuples stay in registers (with ``_add_forces``, a fifth of the hexapod's M)
        for j in range(6):
            gj, hj = s_g * G[j] + s_x * H[j], s_x * G[j]
            for k in range(j, 6):
                M[j, k] += gj * G[k] + hj * H[k]
        return
    for j in range(m):
        gj, hj = s_g * G[j] + s_x * H[j], s_x * G[j]
        for k in range(j, m):
            M[j, k] += gj * G[k] + hj * H[k]


@jit
def _add_forces(bias, force, m, W, t, G):
    """Add W to ``bias`` and t G to ``force`` for 6-tuples W, G (m used)."""
    if m == 6:  # constant bounds, as in ``_add_leg``
        for j in range(6):
            bias[j] += W[j]
            force[j] += t * G[j]
        return
    for j in range(m):
        bias[j] += W[j]
        force[j] += t * G[j]


@jit
def _terms_work(c, ci, q, x, xdot, tau, wd, split):
    """M into rows D_M, c + G into row D_BIAS and J_iᵀ τ into row D_FORCE of wd, on any pose space.

    With ``split`` also gravity's share G into row D_GRAV and J_iᵀ into rows D_JT (column i: K_iᵀ g_i), what the
    holding forces solve J_iᵀ τ_h = G with (``envs.kernels.force``).
    """
    m = int(c[C_N])
    spatial = c[C_SPATIAL] != 0.0
    translational = c[C_TRANSLATIONAL] != 0.0
    p0, p1, p2, r00, r01, r02, r10, r11, r12, r20, r21, r22 = _frame(c, x)
    if spatial:
        v0, v1, v2, w0, w1, w2 = xdot[0], xdot[1], xdot[2], xdot[3], xdot[4], xdot[5]
    elif translational:
        v0, v1, v2, w0, w1, w2 = xdot[0], xdot[1], xdot[2], 0.0, 0.0, 0.0
    else:
        v0, v1, v2, w0, w1, w2 = xdot[0], xdot[1], 0.0, 0.0, 0.0, xdot[2]
    M, bias, force, grav, jt = wd[D_M : D_M + m], wd[D_BIAS], wd[D_FORCE], wd[D_GRAV], wd[D_JT : D_JT + m]
    for j in range(m):
        bias[j] = 0.0
        force[j] = 0.0
        grav[j] = 0.0
        for k in range(m):
            M[j, k] = 0.0
    gx, gy, gz = ci[I_GRAVITY], ci[I_GRAVITY + 1], ci[I_GRAVITY + 2]
    # the platform: a point mass at its centre of mass ...
    c0, c1, c2 = ci[I_COM], ci[I_COM + 1], ci[I_COM + 2]
    r0, r1, r2 = r00 * c0 + r01 * c1 + r02 * c2, r10 * c0 + r11 * c1 + r12 * c2, r20 * c0 + r21 * c1 + r22 * c2
    a0, a1, a2 = _omega_omega(w0, w1, w2, r0, r1, r2)
    mass = ci[I_MASS]
    moments = _moments((0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), mass, r0, r1, r2)
    W = _wrench(spatial, translational, r0, r1, r2, mass * (a0 - gx), mass * (a1 - gy), mass * (a2 - gz))
    Wg = _wrench(spatial, translational, r0, r1, r2, mass * -gx, mass * -gy, mass * -gz)
    for j in range(m):
        bias[j] += W[j]
        grav[j] += Wg[j]
    # ... and its rotational inertia R I Rᵀ (planar: I_zz)
    if spatial:
        R = (r00, r01, r02, r10, r11, r12, r20, r21, r22)
        x0, _, _ = _inertia_times(R, ci, 1.0, 0.0, 0.0)  # the upper triangle of R I Rᵀ, by columns
        y0, y1, _ = _inertia_times(R, ci, 0.0, 1.0, 0.0)
        z0, z1, z2 = _inertia_times(R, ci, 0.0, 0.0, 1.0)
        M[3, 3], M[3, 4], M[3, 5] = M[3, 3] + x0, M[3, 4] + y0, M[3, 5] + z0
        M[4, 4], M[4, 5], M[5, 5] = M[4, 4] + y1, M[4, 5] + z1, M[5, 5] + z2
        l0, l1, l2 = _inertia_times(R, ci, w0, w1, w2)  # the gyroscopic moment ω × (R I Rᵀ ω)
        bias[3] += w1 * l2 - w2 * l1
        bias[4] += w2 * l0 - w0 * l2
        bias[5] += w0 * l1 - w1 * l0
    elif not translational:
        M[2, 2] += ci[I_INERTIA + 8]
    for i in range(m):
        P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
        r0 = r00 * P0 + r01 * P1 + r02 * P2
        r1 = r10 * P0 + r11 * P1 + r12 * P2
        r2 = r20 * P0 + r21 * P1 + r22 * P2
        a0, a1, a2 = _omega_omega(w0, w1, w2, r0, r1, r2)
        V0, V1, V2 = v0 + w1 * r2 - w2 * r1, v1 + w2 * r0 - w0 * r2, v2 + w0 * r1 - w1 * r0
        s_i, s_g, s_x, g0, g1, g2, h0, h1, h2, F0, F1, F2, Fg0, Fg1, Fg2 = _leg(
            c, ci, i, q[i], p0 + r0, p1 + r1, p2 + r2, V0, V1, V2, a0, a1, a2, split
        )
        G = _wrench(spatial, translational, r0, r1, r2, g0, g1, g2)
        H = _wrench(spatial, translational, r0, r1, r2, h0, h1, h2)
        moments = _moments(moments, s_i, r0, r1, r2)
        _add_leg(M, m, s_g, s_x, G, H)
        W = _wrench(spatial, translational, r0, r1, r2, F0, F1, F2)
        # J_iᵀ τ summed here, in ``_generalised_work``'s order: a pass over D_JT after the loop costs the hexapod's
        # force step 2.5 %
        _add_forces(bias, force, m, W, tau[i], G)
        if split:
            Wg = _wrench(spatial, translational, r0, r1, r2, Fg0, Fg1, Fg2)
            for j in range(m):
                grav[j] += Wg[j]
                jt[j, i] = G[j]
    _add_moments(M, spatial, translational, moments)
    for j in range(m):  # the lower triangle
        for k in range(j):
            M[j, k] = M[k, j]


@jit
def _generalised_work(tau, jt, m, out):
    """J_iᵀ τ into out from J_iᵀ (rows D_JT of ``_terms_work`` with ``split``), summed leg by leg."""
    for j in range(m):
        total = 0.0
        for k in range(m):
            total += tau[k] * jt[j, k]
        out[j] = total


@jit
def _omega_omega(w0, w1, w2, r0, r1, r2):
    """ω × (ω × r): the acceleration of the point p + r at constant twist."""
    c0, c1, c2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0
    return w1 * c2 - w2 * c1, w2 * c0 - w0 * c2, w0 * c1 - w1 * c0


@jit
def _inertia_times(R, ci, w0, w1, w2):
    """(R I Rᵀ) ω, with I the platform's inertia in {P} axes (packed row-major) and R row-major."""
    b0 = R[0] * w0 + R[3] * w1 + R[6] * w2  # Rᵀ ω
    b1 = R[1] * w0 + R[4] * w1 + R[7] * w2
    b2 = R[2] * w0 + R[5] * w1 + R[8] * w2
    k0 = ci[I_INERTIA] * b0 + ci[I_INERTIA + 1] * b1 + ci[I_INERTIA + 2] * b2
    k1 = ci[I_INERTIA + 3] * b0 + ci[I_INERTIA + 4] * b1 + ci[I_INERTIA + 5] * b2
    k2 = ci[I_INERTIA + 6] * b0 + ci[I_INERTIA + 7] * b1 + ci[I_INERTIA + 8] * b2
    return R[0] * k0 + R[1] * k1 + R[2] * k2, R[3] * k0 + R[4] * k1 + R[5] * k2, R[6] * k0 + R[7] * k1 + R[8] * k2


@jit
def _solve_work(wd, m, out):
    """ẍ = M⁻¹ (J_iᵀ τ − c − G) from the rows of wd into out (m = 3: adjugate; m = 6: pivoted elimination)."""
    rhs = wd[D_RHS]
    for j in range(m):
        rhs[j] = wd[D_FORCE, j] - wd[D_BIAS, j]
    if m == 3:
        a, b, d = wd[D_M], wd[D_M + 1], wd[D_M + 2]
        u0, u1, u2, _ = solve3(a[0], a[1], a[2], b[0], b[1], b[2], d[0], d[1], d[2], rhs[0], rhs[1], rhs[2])
        out[0], out[1], out[2] = u0, u1, u2
        return
    solve6(wd[D_M : D_M + 6], rhs, wd[D_LU : D_LU + 6], out)


# -- the operations, per row path -------------------------------------------------------------------------


def equations(path, c, ci, q, x, xdot, tau, wd):
    """(M, c + G, J_iᵀ τ) of one robot at (q, x, ẋ) under the efforts τ.

    Register paths: M as a tuple of three rows, the others tuples of three; work path: an (m, m) and two (m,)
    views of the rows of ``wd`` (``_dynamics_work``), valid until its next use.
    """
    return paths._compiled_only()


@overload(equations, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _equations(path, c, ci, q, x, xdot, tau, wd):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, ci, q, x, xdot, tau, wd):
            m = x.shape[0]
            _terms_work(c, ci, q, x, xdot, tau, wd, np.bool_(False))  # a bool, not a literal: one compilation
            return wd[D_M : D_M + m, :m], wd[D_BIAS, :m], wd[D_FORCE, :m]

        return work

    def registers(path, c, ci, q, x, xdot, tau, wd):
        M, b, f, _, _ = _terms3(c, ci, q, x, xdot, tau, np.bool_(False))
        return ((M[0], M[1], M[2]), (M[1], M[3], M[4]), (M[2], M[4], M[5])), b, f

    return registers


def solve_acceleration(path, M, bias, force, wd, out):
    """ẍ = M⁻¹ (J_iᵀ τ − c − G) from ``equations``' values (the work path writes it to ``out``, a work row)."""
    return paths._compiled_only()


@overload(solve_acceleration, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _solve_acceleration(path, M, bias, force, wd, out):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, M, bias, force, wd, out):
            m = bias.shape[0]
            out = out[:m]
            _solve_work(wd, m, out)
            return out

        return work

    def registers(path, M, bias, force, wd, out):
        a, b, d = M
        u0, u1, u2, _ = solve3(
            a[0], a[1], a[2], b[0], b[1], b[2], d[0], d[1], d[2],
            force[0] - bias[0], force[1] - bias[1], force[2] - bias[2],
        )  # fmt: skip
        return u0, u1, u2

    return registers


def acceleration(path, c, ci, q, x, xdot, tau, wd, out):
    """The platform's twist rate ẍ = M⁻¹ (J_iᵀ τ − c − G) at (q, x, ẋ): a vector of the path (``out`` a work row)."""
    return paths._compiled_only()


@overload(acceleration, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _acceleration(path, c, ci, q, x, xdot, tau, wd, out):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, ci, q, x, xdot, tau, wd, out):  # the rows of wd, without ``equations``' views of them
            m = x.shape[0]
            out = out[:m]
            _terms_work(c, ci, q, x, xdot, tau, wd, np.bool_(False))
            _solve_work(wd, m, out)
            return out

        return work

    def of(path, c, ci, q, x, xdot, tau, wd, out):
        M, bias, force = equations(path, c, ci, q, x, xdot, tau, wd)
        return solve_acceleration(path, M, bias, force, wd, out)

    return of
