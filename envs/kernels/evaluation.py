"""The evaluation of a step in compiled code: the reference, the errors, the reward terms and the observation.

The evaluation reads the records of ``envs.kernels.records``: ``Observation`` (the observation's bounds),
``Measured`` (the state it evaluates), ``Reference`` (the targets) and ``Outcome`` (the applied actions and the
termination reasons). Every robot's terms and observation are computed by
one row function; where they depend on the pose space (the pose error, the pose's code in the observation), a
compile-time constant selects the code through overloads (``numba.extending.overload``), so a robot compiles its
own pose space only.
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import overload

from envs.kernels import paths
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _row
from envs.kernels.layout import (
    C_BONUS,
    C_DT,
    C_LC,
    C_LMAX,
    C_LMIN,
    C_N,
    C_OMEGA,
    C_PATH,
    C_PATH_T,
    C_PATH_W,
    C_PENALTY,
    C_SAFE,
    C_SAFE1,
    C_SUCC_O,
    C_SUCC_P,
    C_WA,
    C_WO,
    C_WP,
    C_WS,
    C_WS1,
    E_ACTION,
    E_ACTUATOR,
    E_BONUS,
    E_COST,
    E_COST1,
    E_FIXED,
    E_K,
    E_K1,
    E_ORIENTATION_ERROR,
    E_POSITION_ERROR,
    E_RESIDUAL,
    E_REWARD,
    E_SATURATED,
    E_SINGULARITY,
    E_SUCCESS,
    E_TERMINATION,
    E_TRACKING,
    W_DIFF,
    W_SEG,
    W_TGT,
    W_VEL,
)
from envs.kernels.packing import _OVERLOAD_OPTIONS, _literal_path, _literal_space
from envs.kernels.pose import _TWO_PI, _quat_from_rotvec, _relative_rotvec, _wrap
from envs.kernels.setup import jit, jit_inline

__all__ = ["reference_batch"]

drop_stale_caches(__file__)


@jit
def _reference_at(c, tau, center, amplitude, phase, i, o_pose, o_velocity):
    """Target pose and rate of robot i at the angle τ = ω t [rad] of its reference (``envs.state.FamilyReference``).

    Sinusoids (C_PATH = 0): x*_j = c_j + a_j sin(τ + θ_j). A polyline path of K vertices W_k: the period is cut
    into K segments (W_k → W_k+1 mod K, ending at the fractions C_PATH_T of the period, shifted by θ_0 / 2π);
    on a segment the point moves with the cosine profile s = (1 − cos πu) / 2 of its time fraction u (at rest at
    every vertex, the rate continuous) through the offsets d_j = a_j (W_kj + s (W_k+1,j − W_kj)), and
    x* = c + d with (d_0, d_1) turned by the heading ψ = θ_1 in their plane.
    """
    m = int(c[C_N])
    count = int(c[C_PATH])
    if count == 0:
        omega = c[C_OMEGA]
        for j in range(m):
            a = amplitude[i, j]
            if a == 0.0:
                o_pose[j] = center[i, j]
                o_velocity[j] = 0.0
            else:
                u = tau + phase[i, j]
                o_pose[j] = center[i, j] + a * math.sin(u)
                o_velocity[j] = a * omega * math.cos(u)
        return
    f = (tau + phase[i, 0]) / _TWO_PI
    f -= math.floor(f)
    k = 0
    while k < count - 1 and f >= c[C_PATH_T + k]:
        k += 1
    begin = 0.0 if k == 0 else c[C_PATH_T + k - 1]
    duration = (c[C_PATH_T + k] - begin) * _TWO_PI / c[C_OMEGA]  # [s]
    u = min(max((f - begin) * _TWO_PI / c[C_OMEGA] / duration, 0.0), 1.0)
    s = 0.5 - 0.5 * math.cos(math.pi * u)
    rate = 0.5 * math.pi * math.sin(math.pi * u) / duration
    nxt = 0 if k == count - 1 else k + 1
    for j in range(m):
        w0, w1 = c[C_PATH_W + 6 * k + j], c[C_PATH_W + 6 * nxt + j]
        a = amplitude[i, j]
        o_pose[j] = a * (w0 + s * (w1 - w0))
        o_velocity[j] = a * (w1 - w0) * rate
    cs, sn = math.cos(phase[i, 1]), math.sin(phase[i, 1])
    d0, d1 = o_pose[0], o_pose[1]
    o_pose[0], o_pose[1] = cs * d0 - sn * d1, sn * d0 + cs * d1
    v0, v1 = o_velocity[0], o_velocity[1]
    o_velocity[0], o_velocity[1] = cs * v0 - sn * v1, sn * v0 + cs * v1
    for j in range(m):
        o_pose[j] += center[i, j]


@jit
def _reference(c, t, center, amplitude, phase, i, o_pose, o_velocity):
    """Target pose and its rate of robot i at step t (``_reference_at`` at τ = ω t dt)."""
    _reference_at(c, c[C_OMEGA] * t * c[C_DT], center, amplitude, phase, i, o_pose, o_velocity)


@jit
def _reference_loop(c, t, center, amplitude, phase, o_pose, o_velocity):
    for i in range(center.shape[0]):
        _reference(c, t[i], center, amplitude, phase, i, o_pose[i], o_velocity[i])


def reference_batch(c, t, center, amplitude, phase):
    """Target poses and rates of N references at steps t (shape (N,), int), each (N, m) (``_reference_at``)."""
    o_pose, o_velocity = np.empty(center.shape), np.empty(center.shape)
    _reference_loop(c, np.asarray(t, dtype=np.int64), center, amplitude, phase, o_pose, o_velocity)
    return o_pose, o_velocity


@jit_inline
def _errors_spatial(x, g, diff):
    diff[0], diff[1], diff[2] = g[0] - x[0], g[1] - x[1], g[2] - x[2]
    diff[3], diff[4], diff[5] = _relative_rotvec(g[3], g[4], g[5], x[3], x[4], x[5])
    position = math.sqrt(diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2])
    orientation = math.sqrt(diff[3] * diff[3] + diff[4] * diff[4] + diff[5] * diff[5])
    return position, orientation


@jit_inline
def _errors_translational(x, g, diff):
    diff[0], diff[1], diff[2] = g[0] - x[0], g[1] - x[1], g[2] - x[2]
    return math.sqrt(diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2]), 0.0


@jit_inline
def _errors_planar(x, g, diff):
    diff[0], diff[1] = g[0] - x[0], g[1] - x[1]
    diff[2] = _wrap(g[2] - x[2])
    return math.sqrt(diff[0] * diff[0] + diff[1] * diff[1]), abs(diff[2])


def _errors(space, x, g, diff):
    """(‖p* − p‖ [m], orientation error [rad]) of pose x against target g; diff gets the error vector.

    ``space`` is the pose space, a compile-time constant: the overload below compiles its comparison only.
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_errors, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _errors_of_space(space, x, g, diff):
    errors_in = (_errors_planar, _errors_spatial, _errors_translational)[_literal_space(space)]

    def impl(space, x, g, diff):
        return errors_in(x, g, diff)

    return impl


@jit_inline
def _clip32(o_obs, i, j, value, low, high):
    o_obs[i, j] = min(max(value, low[j]), high[j])


@jit_inline
def _encode_spatial(x, o_obs, i, start, low, high):
    qw, qx, qy, qz = _quat_from_rotvec(x[3], x[4], x[5])
    if qw < 0.0:
        qw, qx, qy, qz = -qw, -qx, -qy, -qz
    values = (x[0], x[1], x[2], qw, qx, qy, qz)
    for j in range(7):
        _clip32(o_obs, i, start + j, values[j], low, high)
    return start + 7


@jit_inline
def _encode_translational(x, o_obs, i, start, low, high):
    for j in range(3):
        _clip32(o_obs, i, start + j, x[j], low, high)
    return start + 3


@jit_inline
def _encode_planar(x, o_obs, i, start, low, high):
    _clip32(o_obs, i, start, x[0], low, high)
    _clip32(o_obs, i, start + 1, x[1], low, high)
    _clip32(o_obs, i, start + 2, math.cos(x[2]), low, high)
    _clip32(o_obs, i, start + 3, math.sin(x[2]), low, high)
    return start + 4


def _encode_pose(space, x, o_obs, i, start, low, high):
    """Position and a continuous rotation code, (x, y, cos φ, sin φ), (p, quaternion, w ≥ 0) or p; next column.

    ``space`` is the pose space, a compile-time constant: the overload below compiles its code only.
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_encode_pose, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _encode_pose_of_space(space, x, o_obs, i, start, low, high):
    encode = (_encode_planar, _encode_spatial, _encode_translational)[_literal_space(space)]

    def impl(space, x, o_obs, i, start, low, high):
        return encode(x, o_obs, i, start, low, high)

    return impl


@jit_inline
def _stroke_errors(target_q, q, m, span, o_obs, i, col, low, high):
    """Observation columns col .. col + m − 1 of row i: (q*_j − q_j) / stroke span, clipped."""
    for j in range(m):
        _clip32(o_obs, i, col + j, (target_q[j] - q[j]) / span, low, high)


@jit_inline
def _saturation(motion, action, i):
    """Row i's ``saturated`` entry: 1.0 while a drive of force control is at its limit, else 0.0.

    Under force control (twists in ``motion``) the applied actions are τ_j / τ_max,j, exactly ±1 at a limit (the
    step clips the efforts to ±τ_max); under rate control (no twists) the entry is 0.0.
    """
    if motion[0].shape[0] == 0:
        return 0.0
    for j in range(action.shape[1]):
        if abs(action[i, j]) >= 1.0:
            return 1.0
    return 0.0


@jit_inline
def _encode_motion(motion, o_obs, i, col, low, high):
    """Observation columns of force control from col: row i's twist ẋ (m) and actuator rates (n); the next column.

    Nothing under rate control, whose ``motion`` has no twists (``envs.kernels.force.motion_of``).
    """
    twist, rate = motion
    if twist.shape[0] == 0:
        return col
    m = twist.shape[1]
    for j in range(m):
        _clip32(o_obs, i, col + j, twist[i, j], low, high)
    for j in range(m):
        _clip32(o_obs, i, col + m + j, rate[i, j], low, high)
    return col + 2 * m


@jit_inline
def _evaluate_row(path, space, c, observation, measured, reference, outcome, motion, i, w, out):
    """``_evaluate_rows``' row i: the target, the reward terms, the errors, success, the cost and the observation."""
    low, high = observation.low, observation.high
    q, x, k, k1 = measured.q, measured.x, measured.k, measured.k1
    amplitude, action = reference.amplitude, outcome.action
    o_eval, o_obs = out
    m = int(c[C_N])
    g, vel, diff = w[W_TGT], w[W_VEL], w[W_DIFF]
    _reference(c, measured.t[i], reference.center, amplitude, reference.phase, i, g, vel)
    xi = x[i]
    position_error, orientation_error = _errors(space, xi, g, diff)
    ki = k[i]
    tracking = -(c[C_WP] * position_error + c[C_WO] * c[C_LC] * orientation_error)
    safe = c[C_SAFE]
    singularity = 0.0
    if ki < safe:
        gap = (safe - ki) / safe
        singularity = -c[C_WS] * gap * gap
    a2 = 0.0
    for j in range(m):
        a2 += action[i, j] * action[i, j]
    terminated = outcome.reason[i] != 0
    termination = -c[C_PENALTY] if terminated else 0.0
    k1i = k1[i]
    safe1 = c[C_SAFE1]
    actuator = 0.0
    if k1i < safe1:
        gap1 = (safe1 - k1i) / safe1
        actuator = -c[C_WS1] * gap1 * gap1
    success = (not terminated) and position_error <= c[C_SUCC_P] and orientation_error <= c[C_SUCC_O]
    bonus = c[C_BONUS] if success else 0.0
    o_eval[E_TRACKING, i] = tracking
    o_eval[E_SINGULARITY, i] = singularity
    o_eval[E_ACTION, i] = -c[C_WA] * a2
    o_eval[E_TERMINATION, i] = termination
    o_eval[E_BONUS, i] = bonus
    o_eval[E_REWARD, i] = tracking + singularity - c[C_WA] * a2 + termination + actuator + bonus
    o_eval[E_ACTUATOR, i] = actuator
    o_eval[E_K1, i] = k1i
    o_eval[E_POSITION_ERROR, i] = position_error
    o_eval[E_ORIENTATION_ERROR, i] = orientation_error
    o_eval[E_SUCCESS, i] = 1.0 if success else 0.0
    o_eval[E_COST, i] = 1.0 if ki < safe or k1i < safe1 else 0.0
    o_eval[E_COST1, i] = 1.0 if k1i < safe1 else 0.0
    o_eval[E_SATURATED, i] = _saturation(motion, action, i)
    o_eval[E_K, i] = ki
    o_eval[E_RESIDUAL, i] = measured.residual[i]
    for j in range(m):
        o_eval[E_FIXED + j, i] = g[j]
        o_eval[E_FIXED + m + j, i] = vel[j]
        o_eval[E_FIXED + 2 * m + j, i] = xi[j]
    col = _encode_pose(space, xi, o_obs, i, np.int64(0), low, high)  # int64, not a constant: one compiled call
    col = _encode_pose(space, g, o_obs, i, col, low, high)
    for j in range(m):
        _clip32(o_obs, i, col + j, diff[j], low, high)
    col += m
    lo, hi = c[C_LMIN], c[C_LMAX]
    span = hi - lo
    for j in range(m):
        _clip32(o_obs, i, col + j, 2.0 * (q[i, j] - lo) / span - 1.0, low, high)
    col += m
    fixed = c[C_PATH] == 0.0
    for j in range(m):
        if amplitude[i, j] != 0.0:
            fixed = False
    if fixed:  # the target is the reference's centre, whose actuator coordinates are kept with it
        _stroke_errors(reference.strokes[i], q[i], m, span, o_obs, i, col, low, high)
    else:
        target_q = paths.inverse_kinematics(path, c, paths.vector(path, g), w[W_SEG])
        _stroke_errors(target_q, q[i], m, span, o_obs, i, col, low, high)
    col += m
    _clip32(o_obs, i, col, ki, low, high)
    col = _encode_motion(motion, o_obs, i, col + 1, low, high)
    if observation.with_velocity:
        for j in range(m):
            _clip32(o_obs, i, col + j, vel[j], low, high)


def _evaluate_rows(path, space, cs, observation, measured, reference, outcome, motion, start, stop, w, out):
    """Target, reward terms, errors, success, cost and observation of robots start .. stop − 1.

    See ``envs.physics.evaluate``. Robot i has the row of constants ``_row(cs, i)``; the other args as
    ``evaluate_batch``; ``motion`` is force control's (twists ẋ (N, m), actuator rates (N, n)), which the
    observation holds after k, or under rate control no twists and no columns (``envs.kernels.force.motion_of``:
    one compiled evaluation for both controls); ``out`` is (evaluation, observations). ``path`` is the row path and
    ``space`` the pose space, compile-time constants: the overloads of the target's inverse kinematics, the pose
    comparison and the pose code compile that path's and that space's code only. One compiled call per block of
    robots, the row's code inlined in it.
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_evaluate_rows, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _evaluate_rows_of_space(path, space, cs, observation, measured, reference, outcome, motion, start, stop, w, out):
    _literal_path(path), _literal_space(space)

    def rows(path, space, cs, observation, measured, reference, outcome, motion, start, stop, w, out):
        for i in range(start, stop):
            _evaluate_row(path, space, _row(cs, i), observation, measured, reference, outcome, motion, i, w, out)

    return rows
