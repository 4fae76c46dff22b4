"""Force control in the compiled step: the efforts of an action and the integration of the equations of motion.

The step's second integrator (``envs.kernels.step._advance_of`` chooses it when the step is given a ``Dynamics``
record): the action is an offset from the holding force at the pose the period starts at, scaled so that ±1
reaches either drive limit (``envs.kernels.force.efforts_of_actions``),

    τ = clip(h + a (τ_max + |h|), −τ_max, τ_max),   h = clip(τ_h(x), ±τ_max),   J_iᵀ τ_h = G(x),

with a clipped to [−1, 1]: a zero action holds, the response is the same on both sides of it (exploration noise
does not bias the mean effort), and the actions reach every effort the drive has.

held over the control period, and the platform state (x, ẋ) moves by ``SUBSTEPS`` steps (more for a fast platform,
each moving at most ``max_substep`` at the period's starting speed, up to ``max_substeps``) of the fourth-order
Runge–Kutta–Munthe-Kaas method of ``kinematics.dynamics.RobotDynamics.step`` on M ẍ + c + G = J_iᵀ τ, each stage
moving the pose with the pose space's retraction (the rotation group for spatial robots) and taking q from the
closed-form inverse kinematics of the robot's own branches: Φ(q, x) stays at round-off. A stroke that passes
its hard stop ends the period there (the step then terminates, "out_of_bounds"). The rates reported are the mean
actuator rates of the period, (q(t + dt) − q(t)) / dt.
"""

from __future__ import annotations

import math

import numpy as np
from numba.core import types
from numba.extending import overload

from envs.kernels import paths
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _row
from envs.kernels.dynamics import (
    _dynamics_work,
    _generalised3,
    _generalised_work,
    _terms3,
    _terms_work,
    acceleration,
    solve_acceleration,
)
from envs.kernels.dynamics_layout import (
    D_APPLIED,
    D_BIAS,
    D_FORCE,
    D_GRAV,
    D_HOLD,
    D_JT,
    D_LU,
    D_M,
    D_MEAN,
    D_NEXT,
    D_NU,
    D_POSE,
    D_Q,
    D_RATE,
    D_STAGE,
    D_TAU,
    D_XD,
    D_XI,
    D_ZERO,
    I_LIMIT,
    I_SUBSTEPS,
)
from envs.kernels.layout import (
    C_DT,
    C_LMAX,
    C_LMIN,
    C_N,
    C_SPATIAL,
    W_KQ,
    W_KX,
)
from envs.kernels.linalg import solve3, solve6
from envs.kernels.packing import _OVERLOAD_OPTIONS, WORK_ARRAYS, _literal_path
from envs.kernels.pose import _all_finite
from envs.kernels.rate import advance_rate, substeps
from envs.kernels.records import Dynamics
from envs.kernels.setup import jit, jit_inline

__all__ = [
    "actions_of_efforts",
    "advance",
    "advance_force",
    "beyond_stops",
    "dexp_inverse",
    "efforts",
    "efforts_of_actions",
    "from_extra",
    "hold_rows",
    "holding",
    "motion_of",
    "start_period",
]

drop_stale_caches(__file__)


# -- the holding forces and the chart of the rotation group ---------------------------------------------


@jit
def _hold3(grav, columns):
    """τ_h with J_iᵀ τ_h = G from ``_terms3``' G and J_iᵀ's columns (a tuple; NaN where J_i is singular)."""
    a, b, d = columns
    t0, t1, t2, _ = solve3(a[0], b[0], d[0], a[1], b[1], d[1], a[2], b[2], d[2], grav[0], grav[1], grav[2])
    return t0, t1, t2


@jit
def _holding3(c, ci, q, x):
    """τ_h with J_iᵀ τ_h = G of three actuators, planar or translational (a tuple; NaN where J_i is singular)."""
    zero = (0.0, 0.0, 0.0)
    _, _, _, grav, columns = _terms3(c, ci, q, x, zero, zero, np.bool_(True))
    return _hold3(grav, columns)


@jit
def _hold_work(wd, m, out):
    """τ_h with J_iᵀ τ_h = G into out, from the rows D_JT and D_GRAV of wd that ``_terms_work`` filled."""
    if m == 3:
        a, b, d, G = wd[D_JT], wd[D_JT + 1], wd[D_JT + 2], wd[D_GRAV]
        out[0], out[1], out[2], _ = solve3(a[0], a[1], a[2], b[0], b[1], b[2], d[0], d[1], d[2], G[0], G[1], G[2])
    else:
        solve6(wd[D_JT : D_JT + 6], wd[D_GRAV], wd[D_LU : D_LU + 6], out)


@jit
def _holding_work(c, ci, q, x, wd, out):
    """τ_h with J_iᵀ τ_h = G into out, on any pose space."""
    m = int(c[C_N])
    zero = wd[D_ZERO, :m]
    _terms_work(c, ci, q, x, zero, zero, wd, np.bool_(True))
    _hold_work(wd, m, out)


def holding(path, c, ci, q, x, wd, out):
    """The holding forces τ_h, J_iᵀ τ_h = G(x): the efforts that hold the platform still at (q, x) against gravity.

    NaN where J_i is singular. A vector of the path (the work path writes it to ``out``, a row of ``wd``).
    """
    return paths._compiled_only()


@overload(holding, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _holding(path, c, ci, q, x, wd, out):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, ci, q, x, wd, out):
            out = out[: x.shape[0]]
            _holding_work(c, ci, q, x, wd, out)
            return out

        return work
    return lambda path, c, ci, q, x, wd, out: _holding3(c, ci, q, x)


def start_period(path, c, ci, q, x, xdot, action, wd):
    """(τ_h, τ, τ / τ_max, ẍ) at a control period's start, from one evaluation of the equations of motion.

    The holding forces at (q, x), the efforts of ``action`` on them (``efforts``) and the twist rate under those
    efforts at (q, x, ẋ): vectors of the path (the work path's are rows of ``wd``; ẍ is row D_STAGE).
    """
    return paths._compiled_only()


@overload(start_period, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _start_period(path, c, ci, q, x, xdot, action, wd):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, ci, q, x, xdot, action, wd):
            m = x.shape[0]
            _terms_work(c, ci, q, x, xdot, wd[D_ZERO, :m], wd, np.bool_(True))
            hold = wd[D_HOLD, :m]
            _hold_work(wd, m, hold)
            tau, applied = efforts(path, ci, hold, action, wd[D_TAU], wd[D_APPLIED])
            force = wd[D_FORCE, :m]
            _generalised_work(tau, wd[D_JT : D_JT + m], m, force)
            return (
                hold,
                tau,
                applied,
                solve_acceleration(path, wd[D_M : D_M + m, :m], wd[D_BIAS, :m], force, wd, wd[D_STAGE]),
            )

        return work

    def registers(path, c, ci, q, x, xdot, action, wd):
        zero = (0.0, 0.0, 0.0)
        M, bias, _, grav, (a, b, d) = _terms3(c, ci, q, x, xdot, zero, np.bool_(True))
        hold = _hold3(grav, (a, b, d))
        tau, applied = efforts(path, ci, hold, action, wd[D_TAU], wd[D_APPLIED])
        rows = ((M[0], M[1], M[2]), (M[1], M[3], M[4]), (M[2], M[4], M[5]))
        return hold, tau, applied, solve_acceleration(path, rows, bias, _generalised3(tau, (a, b, d)), wd, wd[D_STAGE])

    return registers


@jit
def _dexp_inverse6(direction, scale, nu, out):
    """ξ̇ of the spatial twist ν in the chart x = retract(x_0, ξ), ξ = scale · direction (``RobotDynamics``).

    ξ̇ = ω − ½ ξ × ω + (1/θ² − (1 + cos θ) / (2 θ sin θ)) ξ × (ξ × ω) on the rotation, θ = |ξ|; v unchanged.
    """
    for j in range(6):
        out[j] = nu[j]
    t0, t1, t2 = scale * direction[3], scale * direction[4], scale * direction[5]
    o0, o1, o2 = nu[3], nu[4], nu[5]
    angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if angle < 1e-4:
        coefficient = 1.0 / 12.0 + angle * angle / 720.0
    else:
        coefficient = 1.0 / (angle * angle) - (1.0 + math.cos(angle)) / (2.0 * angle * math.sin(angle))
    c0, c1, c2 = t1 * o2 - t2 * o1, t2 * o0 - t0 * o2, t0 * o1 - t1 * o0
    out[3] = o0 - 0.5 * c0 + coefficient * (t1 * c2 - t2 * c1)
    out[4] = o1 - 0.5 * c1 + coefficient * (t2 * c0 - t0 * c2)
    out[5] = o2 - 0.5 * c2 + coefficient * (t0 * c1 - t1 * c0)


def dexp_inverse(path, c, direction, scale, nu, out):
    """ξ̇ from the twist ν at ξ = scale · direction in the chart ξ ↦ retract(x_0, ξ): ν but for spatial rotations."""
    return paths._compiled_only()


@overload(dexp_inverse, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _dexp_inverse(path, c, direction, scale, nu, out):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, direction, scale, nu, out):
            m = nu.shape[0]
            out = out[:m]
            if c[C_SPATIAL] != 0.0:
                _dexp_inverse6(direction, scale, nu, out)
            else:
                for j in range(m):
                    out[j] = nu[j]
            return out

        return work
    return lambda path, c, direction, scale, nu, out: nu


# -- efforts and the integrator ------------------------------------------------------------------------------


@jit
def _effort(ci, j, hold, action):
    """(τ_j, τ_j / τ_max,j) of actuator j: the holding force plus the clipped action times τ_max + |h|, clipped."""
    limit = ci[I_LIMIT + j]
    h = min(max(hold, -limit), limit)
    a = min(max(action, -1.0), 1.0)
    tau = min(max(h + a * (limit + abs(h)), -limit), limit)
    return tau, tau / limit


def efforts(path, ci, hold, action, tau_out, applied_out):
    """(τ, τ / τ_max) of an action row: vectors of the path (the work path writes them to the two rows given)."""
    return paths._compiled_only()


@overload(efforts, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _efforts(path, ci, hold, action, tau_out, applied_out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, ci, hold, action, tau_out, applied_out):
            n = action.shape[0]
            tau, applied = tau_out[:n], applied_out[:n]
            for j in range(n):
                tau[j], applied[j] = _effort(ci, j, hold[j], action[j])
            return tau, applied

        return rows

    def registers(path, ci, hold, action, tau_out, applied_out):
        t0, a0 = _effort(ci, np.int64(0), hold[0], action[0])  # int64 indices: one compiled _effort
        t1, a1 = _effort(ci, np.int64(1), hold[1], action[1])
        t2, a2 = _effort(ci, np.int64(2), hold[2], action[2])
        return (t0, t1, t2), (a0, a1, a2)

    return registers


def mean_rate(path, q0, q1, dt, out):
    """(q1 − q0) / dt, element by element."""
    return paths._compiled_only()


@overload(mean_rate, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _mean_rate(path, q0, q1, dt, out):
    if _literal_path(path) == WORK_ARRAYS:

        def rows(path, q0, q1, dt, out):
            out = out[: q0.shape[0]]
            for j in range(q0.shape[0]):
                out[j] = (q1[j] - q0[j]) / dt
            return out

        return rows
    return lambda path, q0, q1, dt, out: ((q1[0] - q0[0]) / dt, (q1[1] - q0[1]) / dt, (q1[2] - q0[2]) / dt)


@jit
def beyond_stops(c, q):
    """Whether a stroke of q (n,) is beyond the hard stops [q_min, q_max]."""
    for j in range(len(q)):
        if q[j] < c[C_LMIN] or q[j] > c[C_LMAX]:
            return True
    return False


@jit_inline
def _rkmk4(path, c, ci, q, x, v, tau, h, wd, a0):
    """One RKMK4 step of h from (q, x, ẋ) with ẍ = a0 there, under τ: (pose, twist) at its end (rows D_NEXT)."""
    pose = paths.retract(path, c, x, v, 0.5 * h, wd[D_POSE])
    nu = paths.axpy(path, v, 0.5 * h, a0, wd[D_NU])
    r1 = dexp_inverse(path, c, v, 0.5 * h, nu, wd[D_XI + 1])
    a1 = acceleration(path, c, ci, paths.inverse_kinematics(path, c, pose, wd[D_Q]), pose, nu, tau, wd, wd[D_STAGE + 1])
    pose = paths.retract(path, c, x, r1, 0.5 * h, wd[D_POSE])
    nu = paths.axpy(path, v, 0.5 * h, a1, wd[D_NU])
    r2 = dexp_inverse(path, c, r1, 0.5 * h, nu, wd[D_XI + 2])
    a2 = acceleration(path, c, ci, paths.inverse_kinematics(path, c, pose, wd[D_Q]), pose, nu, tau, wd, wd[D_STAGE + 2])
    pose = paths.retract(path, c, x, r2, h, wd[D_POSE])
    nu = paths.axpy(path, v, h, a2, wd[D_NU])
    r3 = dexp_inverse(path, c, r2, h, nu, wd[D_XI + 3])
    a3 = acceleration(path, c, ci, paths.inverse_kinematics(path, c, pose, wd[D_Q]), pose, nu, tau, wd, wd[D_STAGE + 3])
    x1 = paths.retract(path, c, x, paths.rk4_mean(path, v, r1, r2, r3, wd[D_MEAN]), h, wd[D_NEXT])
    v1 = paths.axpy(path, v, h, paths.rk4_mean(path, a0, a1, a2, a3, wd[D_MEAN + 1]), wd[D_NEXT + 1])
    return x1, v1


@jit_inline
def advance_force(path, c, dynamics, i, q0, x0, action, w):
    """Move robot i through one control period under force control; writes its twist, efforts and holding forces.

    Args:
        path: The row path, a compile-time constant (``envs.kernels.paths``).
        c: The robot's packed constants.
        dynamics: The ``envs.kernels.records.Dynamics`` of the batch (inertia, twists in and out, efforts, work).
        i: The robot's row.
        q0: Its actuator coordinates (n,), a vector of the path, with Φ(q0, x0) = 0.
        x0: Its pose (m,), a vector of the path.
        action: Its action row (n,): offsets from the holding forces in units of the drive limits.
        w: Its work array (``constraints._work``).

    Returns:
        As ``rate.advance_rate``: (q, x, anchors, rows, τ / τ_max, mean actuator rates, residual, jump 0, failed). A
        robot whose state stops being finite (a leg that cannot reach its platform point, a singular M) stays
        where it was, at rest, and ``failed`` is set.
    """
    ci, wd = _row(dynamics.inertia, i), dynamics.work
    dt = c[C_DT]
    q = paths.keep(path, q0, w[W_KQ])
    x = paths.keep(path, x0, w[W_KX])
    v = paths.keep(path, paths.vector(path, dynamics.twist[i]), wd[D_XD])
    hold, tau, applied, a0 = start_period(path, c, ci, q, x, v, action, wd)
    # at least SUBSTEPS; more at speed, each moving at most max_substep (at most max_substeps): rate's rule
    count = max(substeps(c, paths.metric(path, c, v)), int(ci[I_SUBSTEPS]))
    h = dt / count
    failed = False
    for s in range(count):
        x1, v1 = _rkmk4(path, c, ci, q, x, v, tau, h, wd, a0)
        x = paths.keep(path, x1, w[W_KX])
        v = paths.keep(path, v1, wd[D_XD])
        q = paths.inverse_kinematics(path, c, x, w[W_KQ])
        m = len(x)
        if not (_all_finite(x, m) and _all_finite(v, m) and _all_finite(q, m)):
            failed = True
            break
        if beyond_stops(c, q):  # a drive hit its hard stop: the period (and the episode) ends here
            break
        if s + 1 < count:
            a0 = acceleration(path, c, ci, q, x, v, tau, wd, wd[D_STAGE])
    if failed:  # back at the start, at rest (rare: the episode then ends)
        q = paths.keep(path, q0, w[W_KQ])
        x = paths.keep(path, x0, w[W_KX])
        v = paths.axpy(path, x0, -1.0, x0, wd[D_XD])  # zeros
    anchors = paths.anchors_at(path, c, q)
    rows = paths.rows_at(path, c, q, anchors, x, w)
    rate = mean_rate(path, q0, q, dt, wd[D_RATE])
    o_twist, o_effort, o_hold = dynamics.o_twist, dynamics.effort, dynamics.hold
    for j in range(len(x)):
        o_twist[i, j] = v[j]
        o_effort[i, j] = tau[j]
        o_hold[i, j] = hold[j]
    residual = paths.residual(path, c, q, anchors, rows, w)
    return q, x, anchors, rows, applied, rate, residual, 0.0, failed or not math.isfinite(residual)


# -- the choice of integrator, and force control's arrays in the step ------------------------------------------


def advance(path, c, dynamics, i, q0, x0, action, residual, w):
    """Robot i's period: ``rate.advance_rate`` (``dynamics`` None) or ``advance_force`` (a ``Dynamics`` record)."""
    return paths._compiled_only()


@overload(advance, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _advance_of_control(path, c, dynamics, i, q0, x0, action, residual, w):
    if isinstance(dynamics, types.NoneType):
        return lambda path, c, dynamics, i, q0, x0, action, residual, w: advance_rate(
            path, c, q0, x0, action, residual, w
        )
    return lambda path, c, dynamics, i, q0, x0, action, residual, w: advance_force(
        path, c, dynamics, i, q0, x0, action, w
    )


def from_extra(extra):
    """The ``Dynamics`` of a batch from an entry kernel's extra arguments.

    () for rate control (None), or (inertia, twist, o_twist, effort, hold) for force control.
    """
    return paths._compiled_only()


@overload(from_extra, jit_options=_OVERLOAD_OPTIONS)
def _from_extra_of(extra):
    if len(extra) == 0:
        return lambda extra: None

    def given(extra):
        inertia, twist, o_twist, effort, hold = extra
        return Dynamics(inertia, twist, o_twist, effort, hold, _dynamics_work())

    return given


def motion_of(dynamics, q_rate):
    """What force control adds to the observation: (twists (N, m), actuator rates (N, n)).

    Under rate control the twists have no rows (``q_rate[:0]``): the evaluation writes no force columns then, and both
    controls share one compiled evaluation (``envs.kernels.evaluation._evaluate_rows``).
    """
    return paths._compiled_only()


@overload(motion_of, jit_options=_OVERLOAD_OPTIONS)
def _motion_of_control(dynamics, q_rate):
    if isinstance(dynamics, types.NoneType):
        return lambda dynamics, q_rate: (q_rate[:0], q_rate)
    return lambda dynamics, q_rate: (dynamics.o_twist, q_rate)


# -- the holding forces of N robots ---------------------------------------------------------------------------


def hold_rows(path, plant, dynamics, q, x, start, count):
    """The holding forces of robots start .. start + count − 1 at (q, x) into ``dynamics.hold`` (None: nothing).

    The step's ``HOLD`` mode (``envs.kernels.modes.holding_batch``).
    """
    return paths._compiled_only()


@overload(hold_rows, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _hold_rows_of(path, plant, dynamics, q, x, start, count):
    if isinstance(dynamics, types.NoneType):
        return lambda path, plant, dynamics, q, x, start, count: None

    def rows(path, plant, dynamics, q, x, start, count):
        wd, o_hold = dynamics.work, dynamics.hold
        for i in range(start, start + count):
            c, ci = _row(plant, i), _row(dynamics.inertia, i)
            hold = holding(path, c, ci, paths.vector(path, q[i]), paths.vector(path, x[i]), wd, wd[D_HOLD])
            for j in range(q.shape[1]):
                o_hold[i, j] = hold[j]

    return rows


# -- the action map in NumPy (controllers, the brake, a controller that knows another model) -------------------


def efforts_of_actions(hold: np.ndarray, action: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """The efforts of force-control actions (NumPy; the compiled step's map, ``envs.kernels.force``).

    τ = clip(h + a (τ_max + |h|), ±τ_max), h = clip(τ_h, ±τ_max): a zero action holds, ±1 reaches either limit.

    Args:
        hold: Holding forces τ_h at the period's start, shape (..., n) [N, N·m for cranks].
        action: Actions, shape (..., n), clipped to [−1, 1].
        limits: Drive limits τ_max > 0, shape (n,).

    Returns:
        τ, shape of the broadcast of ``hold`` and ``action``.
    """
    limits = np.asarray(limits, dtype=np.float64)
    h = np.clip(np.asarray(hold, dtype=np.float64), -limits, limits)
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    return np.clip(h + a * (limits + np.abs(h)), -limits, limits)


def actions_of_efforts(hold: np.ndarray, tau: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """The actions whose efforts are τ clipped to ±τ_max (same shapes).

    (clip(τ) − h) / (τ_max + |h|) within the limits, and ±1 at a limit, whose effort is the limit exactly (the
    quotient would land within rounding of it, and a drive at its limit would not count as saturated).
    """
    limits = np.asarray(limits, dtype=np.float64)
    h = np.clip(np.asarray(hold, dtype=np.float64), -limits, limits)
    tau = np.asarray(tau, dtype=np.float64)
    inside = np.clip((np.clip(tau, -limits, limits) - h) / (limits + np.abs(h)), -1.0, 1.0)
    return np.where(tau >= limits, 1.0, np.where(tau <= -limits, -1.0, inside))
