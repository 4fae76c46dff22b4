"""Force control in the compiled step: the efforts of an action and the integration of the equations of motion.

The step's second integrator (``envs.kernels.step._advance_of`` chooses it when the step is given a ``Dynamics``
record): the action is an offset from the holding forces at the pose the period starts at, clipped to the drive
limits,

    τ = clip(τ_h(x) + clip(a, −1, 1) τ_max, −τ_max, τ_max),   J_iᵀ τ_h = G(x),

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

from numba.extending import overload

from envs.kernels import paths
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _row
from envs.kernels.dynamics import acceleration, dexp_inverse, holding
from envs.kernels.dynamics_layout import (
    D_APPLIED,
    D_HOLD,
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
    I_LIMIT,
    I_SUBSTEPS,
)
from envs.kernels.layout import C_DT, C_LMAX, C_LMIN, C_MAX_SUBSTEP, C_MAX_SUBSTEPS, W_KQ, W_KX
from envs.kernels.packing import _OVERLOAD_OPTIONS, WORK_ARRAYS, _literal_path
from envs.kernels.pose import _all_finite
from envs.kernels.setup import jit, jit_inline

__all__ = ["advance_force", "efforts"]

drop_stale_caches(__file__)


@jit
def _effort(ci, j, hold, action):
    """(τ_j, τ_j / τ_max,j) of actuator j: the holding force plus the clipped action times the limit, clipped."""
    limit = ci[I_LIMIT + j]
    tau = hold + min(max(action, -1.0), 1.0) * limit
    tau = min(max(tau, -limit), limit)
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
        t0, a0 = _effort(ci, 0, hold[0], action[0])
        t1, a1 = _effort(ci, 1, hold[1], action[1])
        t2, a2 = _effort(ci, 2, hold[2], action[2])
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
def _beyond_stops(c, q):
    """Whether a stroke of q (n,) is beyond the hard stops [q_min, q_max]."""
    for j in range(len(q)):
        if q[j] < c[C_LMIN] or q[j] > c[C_LMAX]:
            return True
    return False


@jit
def _substeps(c, ci, speed):
    """RKMK4 steps of a period that starts at ``speed`` ‖(v, ℓ_c ω)‖ [m/s].

    At least ``SUBSTEPS``, more so that each moves at most ``max_substep`` at that speed, at most ``max_substeps``.
    """
    count = math.ceil(speed * c[C_DT] / c[C_MAX_SUBSTEP]) if math.isfinite(speed) else c[C_MAX_SUBSTEPS]
    return int(min(max(count, ci[I_SUBSTEPS]), max(c[C_MAX_SUBSTEPS], ci[I_SUBSTEPS])))


@jit_inline
def _rkmk4(path, c, ci, q, x, v, tau, h, wd):
    """One RKMK4 step of h from (q, x, ẋ) under τ: (pose, twist) at its end, in rows D_NEXT of wd on the work path."""
    a0 = acceleration(path, c, ci, q, x, v, tau, wd, wd[D_STAGE])
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
        As ``step._advance``: (q, x, anchors, rows, τ / τ_max, mean actuator rates, residual, jump 0, failed). A
        robot whose state stops being finite (a leg that cannot reach its platform point, a singular M) stays
        where it was, at rest, and ``failed`` is set.
    """
    ci, wd = _row(dynamics.inertia, i), dynamics.work
    hold = holding(path, c, ci, q0, x0, wd, wd[D_HOLD])
    tau, applied = efforts(path, ci, hold, action, wd[D_TAU], wd[D_APPLIED])
    dt = c[C_DT]
    q = paths.keep(path, q0, w[W_KQ])
    x = paths.keep(path, x0, w[W_KX])
    v = paths.keep(path, paths.vector(path, dynamics.twist[i]), wd[D_XD])
    count = _substeps(c, ci, paths.metric(path, c, v))
    h = dt / count
    failed = False
    for _ in range(count):
        x1, v1 = _rkmk4(path, c, ci, q, x, v, tau, h, wd)
        x = paths.keep(path, x1, w[W_KX])
        v = paths.keep(path, v1, wd[D_XD])
        q = paths.inverse_kinematics(path, c, x, w[W_KQ])
        m = len(x)
        if not (_all_finite(x, m) and _all_finite(v, m) and _all_finite(q, m)):
            failed = True
            break
        if _beyond_stops(c, q):  # a drive hit its hard stop: the period (and the episode) ends here
            break
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
