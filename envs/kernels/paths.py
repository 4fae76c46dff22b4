"""The operations of the step on each row path: pose vectors in registers or in work arrays.

``envs.kernels.step`` writes the step once (predict, correct, measure, terminate) in terms of the operations
below; each takes the row path first, a compile-time constant (``envs.kernels.packing.ROW_PATHS``), by which an
overload (``numba.extending.overload``) chooses its code:

- ``PLANAR_LEGS`` and ``THREE``, three actuators on the planar or translational pose space: every vector (strokes
  q, pose x, rates) is a tuple of three floats that lives in registers, and the algebra is
  ``envs.kernels.three``'s closed forms; the two paths differ only in their anchors (a leg's is fixed:
  A_i = B_i, ℓ_i = q_i; a crank's or a slider's moves with q_i).
- ``WORK_ARRAYS``, any pose space: every vector is a row of the robot's work array (``constraints._work``, rows
  ``W_*``) and the algebra is ``envs.kernels.constraints``' (6 × 6 pivoted elimination and Jacobi SVD).

Values that the operations pass between them: ``vector`` (a tuple of three floats or a work row, read-only to the
caller), ``anchors`` (the anchors at some q: ``three.anchors``' tuple on the register paths, an unused 0 on the
work path, whose anchors are cached in the work array) and ``rows`` (A = J_x / 2 and its companions at some
(q, x): ``three.rows``' tuple, or 0 on the work path, whose rows are in the work array). An operation that returns
a vector is given ``out``, the work row it writes the vector to on the work path (the register paths ignore it).
"""

from __future__ import annotations

from numba.extending import overload

from envs.kernels import pose, three
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import (
    _actuator_condition,
    _leg_lengths,
    _newton,
    _residual,
    _rows,
    _singularity,
    _twist_rate,
)
from envs.kernels.layout import C_DT, C_LMAX, C_LMIN, C_RATE, C_TRANSLATIONAL, W_A, W_DIFF, W_Y
from envs.kernels.packing import _OVERLOAD_OPTIONS, PLANAR_LEGS, WORK_ARRAYS, _literal_path

__all__ = [
    "anchors_at",
    "axpy",
    "commanded",
    "inverse_kinematics",
    "jump",
    "keep",
    "lerp",
    "measure",
    "metric",
    "newton",
    "pose_rate",
    "residual",
    "retract",
    "rk4_mean",
    "rows_at",
    "vector",
]

drop_stale_caches(__file__)


def _compiled_only(*args):
    raise NotImplementedError("compiled only (see its overload)")


# -- the vectors: load, keep, combine ----------------------------------------------------------------------


def vector(path, row):
    """Row ``row`` (m,) of a state array as a vector of the path (a tuple on the register paths, the row itself)."""
    return _compiled_only()


@overload(vector, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _vector(path, row):
    if _literal_path(path) == WORK_ARRAYS:
        return lambda path, row: row
    return lambda path, row: (row[0], row[1], row[2])


def keep(path, v, out):
    """The vector v, kept: on the work path copied into ``out`` (a work row that later operations do not write)."""
    return _compiled_only()


@overload(keep, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _keep(path, v, out):
    if _literal_path(path) == WORK_ARRAYS:

        def copy(path, v, out):
            out = out[: v.shape[0]]
            for j in range(v.shape[0]):
                out[j] = v[j]
            return out

        return copy
    return lambda path, v, out: v


def lerp(path, a, b, f, out):
    """A + f (b − a), element by element (the strokes of a substep)."""
    return _compiled_only()


@overload(lerp, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _lerp(path, a, b, f, out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, a, b, f, out):
            out = out[: a.shape[0]]
            for j in range(a.shape[0]):
                out[j] = a[j] + f * (b[j] - a[j])
            return out

        return rows
    return lambda path, a, b, f, out: (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


def axpy(path, a, s, b, out):
    """A + s b, element by element."""
    return _compiled_only()


@overload(axpy, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _axpy(path, a, s, b, out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, a, s, b, out):
            out = out[: a.shape[0]]
            for j in range(a.shape[0]):
                out[j] = a[j] + s * b[j]
            return out

        return rows
    return lambda path, a, s, b, out: (a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2])


def rk4_mean(path, v, k1, k2, k3, out):
    """(v + 2 k1 + 2 k2 + k3) / 6: the mean rate of a classical Runge–Kutta step from its four stage rates."""
    return _compiled_only()


@overload(rk4_mean, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _rk4_mean(path, v, k1, k2, k3, out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, v, k1, k2, k3, out):
            out = out[: v.shape[0]]
            for j in range(v.shape[0]):
                out[j] = (v[j] + 2.0 * k1[j] + 2.0 * k2[j] + k3[j]) / 6.0
            return out

        return rows

    def registers(path, v, k1, k2, k3, out):
        return (
            (v[0] + 2.0 * k1[0] + 2.0 * k2[0] + k3[0]) / 6.0,
            (v[1] + 2.0 * k1[1] + 2.0 * k2[1] + k3[1]) / 6.0,
            (v[2] + 2.0 * k1[2] + 2.0 * k2[2] + k3[2]) / 6.0,
        )

    return registers


def commanded(path, c, q, action, a_out, nq_out, qr_out):
    """(applied action, strokes at the end of the period, achieved stroke rates [/s]) of an action row.

    The action is clipped to [−1, 1], the strokes q + a · rate · dt to the stroke limits.
    """
    return _compiled_only()


@overload(commanded, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _commanded(path, c, q, action, a_out, nq_out, qr_out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, c, q, action, a_out, nq_out, qr_out):
            dt = c[C_DT]
            lo, hi = c[C_LMIN], c[C_LMAX]
            stroke = c[C_RATE] * dt
            m = q.shape[0]
            a, nq, qr = a_out[:m], nq_out[:m], qr_out[:m]
            for j in range(m):
                a[j] = min(max(action[j], -1.0), 1.0)
                nq[j] = min(max(q[j] + a[j] * stroke, lo), hi)
                qr[j] = (nq[j] - q[j]) / dt
            return a, nq, qr

        return rows

    def registers(path, c, q, action, a_out, nq_out, qr_out):
        dt = c[C_DT]
        lo, hi = c[C_LMIN], c[C_LMAX]
        stroke = c[C_RATE] * dt
        a0 = min(max(action[0], -1.0), 1.0)
        a1 = min(max(action[1], -1.0), 1.0)
        a2 = min(max(action[2], -1.0), 1.0)
        n0 = min(max(q[0] + a0 * stroke, lo), hi)
        n1 = min(max(q[1] + a1 * stroke, lo), hi)
        n2 = min(max(q[2] + a2 * stroke, lo), hi)
        return (a0, a1, a2), (n0, n1, n2), ((n0 - q[0]) / dt, (n1 - q[1]) / dt, (n2 - q[2]) / dt)

    return registers


# -- the pose space: retraction, metric --------------------------------------------------------------------


def retract(path, c, x, v, h, out):
    """X ⊕ h v: p + h δp and R ← exp([h δθ]×) R (``pose._retract``; planar and translational: x + h v)."""
    return _compiled_only()


@overload(retract, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _retract(path, c, x, v, h, out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, c, x, v, h, out):
            out = out[: x.shape[0]]
            pose._retract(c, x, v, h, out)
            return out

        return rows
    return lambda path, c, x, v, h, out: (x[0] + h * v[0], x[1] + h * v[1], x[2] + h * v[2])


def metric(path, c, v):
    """‖(δp, ℓ_c δθ)‖ of a twist step [m] (``pose._metric``)."""
    return _compiled_only()


@overload(metric, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _metric(path, c, v):
    if _literal_path(path) == WORK_ARRAYS:
        return lambda path, c, v: pose._metric(c, v)
    return lambda path, c, v: three._metric(c, c[C_TRANSLATIONAL] != 0.0, v[0], v[1], v[2])


def jump(path, c, y, x, w):
    """‖y ⊖ x‖: the size of Newton's correction from the predicted pose x to y [m]."""
    return _compiled_only()


@overload(jump, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _jump(path, c, y, x, w):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, c, y, x, w):
            diff = w[W_DIFF, : x.shape[0]]
            pose._difference(c, y, x, diff)
            return pose._metric(c, diff)

        return rows
    return lambda path, c, y, x, w: three._metric(c, c[C_TRANSLATIONAL] != 0.0, y[0] - x[0], y[1] - x[1], y[2] - x[2])


# -- the constraints: anchors, rows of A, rates, Newton's correction, conditioning -------------------------


def anchors_at(path, c, q):
    """The anchors A_i(q_i), A_i′ and ℓ_i(q_i) at the strokes q (work path: 0, the work array caches them)."""
    return _compiled_only()


@overload(anchors_at, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _anchors_at(path, c, q):
    chosen = _literal_path(path)
    if chosen == WORK_ARRAYS:
        return lambda path, c, q: 0
    if chosen == PLANAR_LEGS:
        return lambda path, c, q: three.leg_anchors(c, q[0], q[1], q[2])
    return lambda path, c, q: three.anchors(c, q[0], q[1], q[2])


def rows_at(path, c, q, anchors, x, w):
    """The rows of A = J_x / 2 (and d_iᵀ d_i, −(J_q)_ii / 2) at (q, x); the work path writes them into w."""
    return _compiled_only()


@overload(rows_at, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _rows_at(path, c, q, anchors, x, w):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, c, q, anchors, x, w):
            _rows(c, q, x, w)
            return 0

        return rows
    return lambda path, c, q, anchors, x, w: three.rows(c, anchors, x[0], x[1], x[2])


def pose_rate(path, c, q, rows, rate, w, out):
    """ẋ = J_f q̇ = A⁻¹ ((−J_q / 2) q̇) from the ``rows`` at (q, x); NaN where J_x is exactly singular."""
    return _compiled_only()


@overload(pose_rate, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _pose_rate(path, c, q, rows, rate, w, out):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, q, rows, rate, w, out):
            out = out[: rate.shape[0]]
            _twist_rate(c, q, rate, w, W_A, out)
            return out

        return work
    return lambda path, c, q, rows, rate, w, out: three._rate(rows, rate[0], rate[1], rate[2])


def newton(path, c, q, anchors, guess, w, tolerance, max_iterations):
    """Newton's method on Φ(q, x) = 0 from ``guess``: (x, residual max_i |Φ_i| [m²], rows at x).

    Each step solves J_x δ = Φ and sets x ← x ⊖ δ; it stops once the residual is within ``tolerance``, at a
    non-finite residual or iterate, or after ``max_iterations`` steps (``constraints._newton``).
    """
    return _compiled_only()


@overload(newton, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _newton_of(path, c, q, anchors, guess, w, tolerance, max_iterations):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, q, anchors, guess, w, tolerance, max_iterations):
            out = w[W_Y, : guess.shape[0]]
            return out, _newton(c, q, guess, w, out, tolerance, max_iterations), 0

        return work

    def registers(path, c, q, anchors, guess, w, tolerance, max_iterations):
        y0, y1, y2, residual, a = three._newton(c, anchors, guess[0], guess[1], guess[2], tolerance, max_iterations)
        return (y0, y1, y2), residual, a

    return registers


def measure(path, c, q, anchors, rows, w):
    """(k, sign(det J_x), k_I) from the ``rows`` at (q, x): the Type II measure, the working mode, the Type I measure.

    k is σ_min/σ_max of the link Jacobian diag(1/ℓ) A diag(pose_scale); k_I = min_i |(J_q)_ii| / (2 ℓ_i
    ‖(A_i′, ℓ_i′)‖), 1 for legs.
    """
    return _compiled_only()


@overload(measure, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _measure(path, c, q, anchors, rows, w):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, q, anchors, rows, w):
            k, sign = _singularity(c, q, w, W_A)
            return k, sign, _actuator_condition(c, w)

        return work
    return lambda path, c, q, anchors, rows, w: three.singularity(c, anchors, rows, 0.0)


def inverse_kinematics(path, c, x, out):
    """The actuator coordinates of the pose x in closed form, on each actuator's branch (NaN where out of reach)."""
    return _compiled_only()


@overload(inverse_kinematics, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _inverse_kinematics(path, c, x, out):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, x, out):
            out = out[: x.shape[0]]
            _leg_lengths(c, x, out)
            return out

        return work
    return lambda path, c, x, out: three.inverse_kinematics(c, x[0], x[1], x[2])


def residual(path, c, q, anchors, rows, w):
    """max_i |Φ_i| = max_i |d_iᵀ d_i − ℓ_i²| [m²] from the ``rows`` at (q, x) (NaN if one is NaN)."""
    return _compiled_only()


@overload(residual, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _residual_of(path, c, q, anchors, rows, w):
    if _literal_path(path) == WORK_ARRAYS:
        return lambda path, c, q, anchors, rows, w: _residual(c, q, w)
    return lambda path, c, q, anchors, rows, w: three._residual(anchors, rows)
