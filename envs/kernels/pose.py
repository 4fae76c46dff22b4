"""Poses of the family in compiled code: rotations (quaternions, rotation vectors) and the pose-space operations.

Points are handled in 3-D throughout (a planar robot's points have z = 0 and its pose (x, y, φ) is p = (x, y, 0),
R = R_z(φ)), so a planar and a spatial robot run through the same lines; the only branch is on the pose space,
where the twist has three coordinates (v_x, v_y, ω_z) or six (v, ω). A spatial pose stores the rotation vector r;
every update of it goes through unit quaternions (R ← exp([δθ]×) R), so the integrator and Newton's method work
on the rotation group, never on Euler angles.
"""

from __future__ import annotations

import math

from envs.kernels.cache import drop_stale_caches
from envs.kernels.layout import (
    C_LC,
    C_SPATIAL,
    C_TRANSLATIONAL,
)
from envs.kernels.setup import jit

__all__ = []

drop_stale_caches(__file__)


_TWO_PI = 2.0 * math.pi


@jit
def _quat_from_rotvec(r0, r1, r2):
    """Unit quaternion of the rotation vector r (exp([r]×)), with the series near r = 0."""
    t2 = r0 * r0 + r1 * r1 + r2 * r2
    if t2 < 1e-12:
        w = 1.0 - t2 / 8.0
        s = 0.5 - t2 / 48.0
    else:
        t = math.sqrt(t2)
        w = math.cos(0.5 * t)
        s = math.sin(0.5 * t) / t
    return w, s * r0, s * r1, s * r2


@jit
def _rotvec_from_quat(w, x, y, z):
    """Rotation vector (|r| ≤ π) of a unit quaternion (either sign)."""
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        return 0.0, 0.0, 0.0
    scale = 2.0 * math.atan2(n, w) / n
    return scale * x, scale * y, scale * z


@jit
def _quat_mul(a0, a1, a2, a3, b0, b1, b2, b3):
    """Hamilton product a ⊗ b (the rotation b, then a)."""
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


@jit
def _compose_rotvec(s0, s1, s2, r0, r1, r2):
    """Rotation vector of exp([s]×) exp([r]×)."""
    a0, a1, a2, a3 = _quat_from_rotvec(s0, s1, s2)
    b0, b1, b2, b3 = _quat_from_rotvec(r0, r1, r2)
    w, x, y, z = _quat_mul(a0, a1, a2, a3, b0, b1, b2, b3)
    return _rotvec_from_quat(w, x, y, z)


@jit
def _relative_rotvec(a0, a1, a2, b0, b1, b2):
    """Rotation vector δθ with exp([δθ]×) exp([b]×) = exp([a]×)."""
    qa0, qa1, qa2, qa3 = _quat_from_rotvec(a0, a1, a2)
    qb0, qb1, qb2, qb3 = _quat_from_rotvec(b0, b1, b2)
    w, x, y, z = _quat_mul(qa0, qa1, qa2, qa3, qb0, -qb1, -qb2, -qb3)
    return _rotvec_from_quat(w, x, y, z)


@jit
def _wrap(angle):
    """Wrap an angle to [−π, π): (angle + π) % 2π − π, bit for bit as Python's ``%`` computes it.

    Within (−2π, 4π) of angle + π, where the step's angles are, the remainder is one exact addition (Sterbenz)
    instead of Numba's call of ``fmod`` and its sign fix-up.
    """
    a = angle + math.pi
    if 0.0 <= a < _TWO_PI:
        pass
    elif -_TWO_PI < a < 0.0:
        a += _TWO_PI
    elif _TWO_PI <= a < 2.0 * _TWO_PI:
        a -= _TWO_PI
    else:
        a = a % _TWO_PI
    return a - math.pi


@jit
def _frame(c, x):
    """Position p of {P} and the rotation R (row by row) of the pose x: (p0, p1, p2, r00, …, r22)."""
    if c[C_SPATIAL] != 0.0:
        w, a, b, d = _quat_from_rotvec(x[3], x[4], x[5])
        r00, r01, r02 = 1.0 - 2.0 * (b * b + d * d), 2.0 * (a * b - d * w), 2.0 * (a * d + b * w)
        r10, r11, r12 = 2.0 * (a * b + d * w), 1.0 - 2.0 * (a * a + d * d), 2.0 * (b * d - a * w)
        r20, r21, r22 = 2.0 * (a * d - b * w), 2.0 * (b * d + a * w), 1.0 - 2.0 * (a * a + b * b)
        return x[0], x[1], x[2], r00, r01, r02, r10, r11, r12, r20, r21, r22
    if c[C_TRANSLATIONAL] != 0.0:
        return x[0], x[1], x[2], 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
    cs, sn = math.cos(x[2]), math.sin(x[2])
    return x[0], x[1], 0.0, cs, -sn, 0.0, sn, cs, 0.0, 0.0, 0.0, 1.0


@jit
def _retract(c, x, step, scale, out):
    """Out = x ⊕ scale · step: p + scale δp and R ← exp([scale δθ]×) R (planar: x + scale · step)."""
    out[0] = x[0] + scale * step[0]
    out[1] = x[1] + scale * step[1]
    out[2] = x[2] + scale * step[2]
    if c[C_SPATIAL] != 0.0:
        out[3], out[4], out[5] = _compose_rotvec(scale * step[3], scale * step[4], scale * step[5], x[3], x[4], x[5])


@jit
def _difference(c, x, y, out):
    """Out = the twist step from y to x ((p_x − p_y, δθ) with exp([δθ]×) R_y = R_x; planar: x − y)."""
    out[0], out[1], out[2] = x[0] - y[0], x[1] - y[1], x[2] - y[2]
    if c[C_SPATIAL] != 0.0:
        out[3], out[4], out[5] = _relative_rotvec(x[3], x[4], x[5], y[3], y[4], y[5])


@jit
def _metric(c, step):
    """‖(δp, ℓ_c δθ)‖ of a twist step [m]."""
    lc = c[C_LC]
    if c[C_SPATIAL] != 0.0:
        a = step[0] * step[0] + step[1] * step[1] + step[2] * step[2]
        b = step[3] * step[3] + step[4] * step[4] + step[5] * step[5]
        return math.sqrt(a + lc * lc * b)
    if c[C_TRANSLATIONAL] != 0.0:
        return math.sqrt(step[0] * step[0] + step[1] * step[1] + step[2] * step[2])
    return math.sqrt(step[0] * step[0] + step[1] * step[1] + lc * lc * step[2] * step[2])


@jit
def _all_finite(v, m):
    for j in range(m):
        if not math.isfinite(v[j]):
            return False
    return True
