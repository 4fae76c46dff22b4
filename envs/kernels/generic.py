"""Compiled (Numba) kernels of the distance-constraint family: one step, reward, observation and tasks for all.

A robot is data: its pose space (planar or spatial), its number of legs n (= m, the pose coordinates) and
its geometry travel in one float64 vector (``pack_family``); the code below reads them and never asks which
robot it runs. Points are handled in 3-D throughout (a planar robot's points have z = 0 and its pose
(x, y, φ) is p = (x, y, 0), R = R_z(φ)), so a planar and a spatial robot run through the same lines; the
only branch is on the pose space, where the twist has three coordinates (v_x, v_y, ω_z) or six (v, ω).

With d_i = p + R P_i − B_i (leg kind: A_i = B_i, ℓ_i = q_i), the kernels use

    Φ_i = d_iᵀ d_i − q_i²,   J_x = 2 A with row i of A = (d_iᵀ, ((R P_i) × d_i)ᵀ) restricted to the twist,
    J_q = −2 diag(q),        J_f = −J_x⁻¹ J_q = A⁻¹ diag(q),   J_i = diag(1/q) A,

as ``kinematics.DistanceConstraintMechanism`` (the NumPy reference they are tested against). Systems are
solved and conditioned by ``envs.kernels.linalg`` (closed forms for m = 3; pivoted elimination and a one-sided
Jacobi SVD for m = 6), accurate near singular matrices. A spatial
pose stores the rotation vector r; every update of it goes through unit quaternions (R ← exp([δθ]×) R), so
the integrator and Newton's method work on the rotation group, never on Euler angles.

The kernels take their arrays in a few records (tuples of arrays, built by ``envs.physics``): ``c``, the robot's
constants (``envs.kernels.layout``); ``state`` = (q, x, t, det_sign, residual); ``reference`` = (center,
amplitude, phase, strokes); ``observation`` = (low, high, with_velocity), the observation's bounds; ``measured``
= (q, x, t, k, k_I, residual) and ``outcome`` = (action, reason), what the evaluation reads; ``moved`` = (q, x, k,
k_I, residual, action, q_rate, reason, jump), what the transition writes. The step's row paths (``row_path``:
planar legs, three actuators, work arrays) share one order, predict, correct, measure, terminate.

Compile time: the row path and the pose space are compile-time constants of the entry kernels (closures over
them, ``path_kernels``), and overloads (``numba.extending.overload``) choose each path's and space's code by
them, so a robot compiles its own path and pose space only, not every robot's. The constants reach the kernels
read-only (``read_only``): a writable copy would be a second specialisation of every kernel.

Work arrays are allocated once per chunk of robots, not per robot; large batches run on every core. Inside a
chunk of the parallel step, spatial robots go in blocks of ``LANES``: each is moved alone, then the Jacobi SVD
behind their k runs on the whole block at once (vectorised across robots,
``envs.kernels.linalg.inverse_condition6_lanes``); the one-thread step moves them robot by robot.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core import errors, types
from numba.extending import overload

from envs.kernels import layout, linalg, planar, setup, three
from envs.kernels.cache import drop_stale_caches
from envs.kernels.linalg import (
    LANES,
    inverse_condition6,
    inverse_condition6_lanes,
    solve3,
    solve6,
)
from envs.kernels.setup import PARALLEL_MIN_BATCH, _next_double, jit, jit_inline, jit_parallel, random_streams

__all__ = [
    "C_SIZE",
    "E_COST1",
    "E_FIXED",
    "PATH_VERTICES",
    "allocate_step",
    "evaluate_batch",
    "evaluation_rows",
    "forward_batch",
    "initial_batch",
    "observation_layout",
    "pack_certificate",
    "pack_family",
    "path_kernels",
    "random_streams",
    "reference_batch",
    "row_path",
    "safe_batch",
    "safety_batch",
    "sample_reach_batch",
    "sample_track_batch",
    "segment_batch",
    "segment_min_safety_batch",
    "singularity_batch",
    "step_batch",
    "strokes_batch",
    "transition_batch",
]

from envs.kernels.layout import (
    C_A,
    C_B,
    C_BONUS,
    C_BRANCH,
    C_DT,
    C_E,
    C_ELL,
    C_HARD,
    C_HARD1,
    C_HARD_KIND,
    C_HIGH,
    C_JUMP,
    C_LAM,
    C_LC,
    C_LEGS,
    C_LMAX,
    C_LMIN,
    C_LOW,
    C_MARGIN,
    C_MAX_SUBSTEP,
    C_MAX_SUBSTEPS,
    C_N,
    C_NEWTON_IT,
    C_NEWTON_TOL,
    C_OMEGA,
    C_P,
    C_PATH,
    C_PATH_T,
    C_PATH_W,
    C_PENALTY,
    C_RATE,
    C_RK4,
    C_SAFE,
    C_SAFE1,
    C_SCALE,
    C_SHIGH,
    C_SIZE,
    C_SLOW,
    C_SPACING,
    C_SPATIAL,
    C_SUCC_O,
    C_SUCC_P,
    C_TRANSLATIONAL,
    C_U,
    C_V,
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
    E_SINGULARITY,
    E_SUCCESS,
    E_TERMINATION,
    E_TRACKING,
    EVALUATION,
    PATH_VERTICES,
)

drop_stale_caches(
    __file__,
    [
        layout.__file__,
        planar.__file__,
        three.__file__,
        setup.__file__,
        linalg.__file__,
    ],
)

# -- rows of the work array of one robot (each row holds up to 6 numbers) ------------------------------
W_A = 0  # A = J_x / 2, n × m (rows 0..5)
W_LU = 6  # elimination copy of A (rows 6..11)
W_H = 12  # homogeneous J_i, for the SVD (rows 12..17)
W_ELL = 18  # link lengths ℓ_i(q_i) [m] (for legs q_i; read only off the legs' fast path)
W_DQ = 19  # d_iᵀ A_i′ + ℓ_i ℓ_i′ = −(J_q)_ii / 2
W_SPEED = 20  # ‖(A_i′, ℓ_i′)‖
W_SQ = 21  # squared leg lengths d_iᵀ d_i
W_RHS = 22
W_SOL = 23
W_V = 24  # twist rate
W_K1, W_K2, W_K3 = 25, 26, 27  # RK4 stages
W_XM = 28  # an intermediate pose
W_KQ, W_KX = 29, 30  # strokes and pose of the current substep
W_NQ = 31  # strokes at the end of the step
W_QR = 32  # achieved stroke rates
W_PRED = 33  # predicted pose
W_Y = 34  # Newton's pose
W_T = 35  # strokes of a substep
W_QM = 36  # intermediate strokes
W_SPARE = 37  # (unused rows 37..42)
W_TGT = 43  # target pose
W_VEL = 44  # target velocity
W_DIFF = 45  # a pose difference
W_SEG = 46  # a point of a segment
W_SEG_D = 47  # a segment's direction
# The anchors of cranks and sliders depend on q alone: cached per leg for the q they were computed at (Newton's
# iterations and the substep's checks move x at fixed q). ``_work`` marks the cache empty (NaN).
W_CQ = 48  # the q_i the cached values belong to
W_CA = 49  # A_i(q_i), rows 49..51
W_CD = 52  # A_i′(q_i), rows 52..54
W_CELL = 55  # ℓ_i(q_i)
W_CSPEED = 56  # ‖(A_i′, ℓ_i′)‖
W_SIZE = 57

#: Robots per chunk of a batch: each chunk allocates its work arrays once (a multiple of ``LANES``).
CHUNK = 64
#: Candidates a sampler may reject before it reports failure.
SAMPLER_TRIES = 2000
#: Pairs from which the Reach sampler runs on every core (one generator per robot; each pair costs 10–70 µs).
PARALLEL_MIN_SAMPLES = 8
#: Waypoints tried per hard pair to certify a detour.
WAYPOINT_TRIES = 64
#: Most points checked along one segment.
SEGMENT_MAX_POINTS = 2000

_TWO_PI = 2.0 * math.pi


def pack_certificate(
    robot, stroke_limits, stroke_margin, safe_threshold, actuator_safe_threshold, hard_threshold=0.0
) -> np.ndarray:
    """The constants the certificate reads (``safety_batch``, ``segment_min_safety_batch``), shape (C_SIZE,).

    The robot's geometry, actuation and pose scale, its stroke limits and margin and the safe thresholds; every
    other entry is 0 (``pack_family`` fills them).

    Args:
        robot: A ``DistanceConstraintMechanism``.
        stroke_limits: (q_min, q_max) of every actuator [m, or rad for cranks].
        stroke_margin: Distance a safe pose keeps from both limits [m, rad].
        safe_threshold: k_safe.
        actuator_safe_threshold: k_I,safe (unused for legs).
        hard_threshold: k_hard.

    Returns:
        Read-only float64 vector indexed by the ``C_*`` offsets.
    """
    n, m = robot.n_actuators, robot.n_pose
    c = np.zeros(C_SIZE)
    c[C_N] = n
    c[C_SPATIAL] = 1.0 if robot.pose_space.name == "spatial" else 0.0
    c[C_TRANSLATIONAL] = 1.0 if robot.pose_space.name == "translational" else 0.0
    c[C_LC] = robot.characteristic_length
    c[C_LMIN], c[C_LMAX] = stroke_limits
    c[C_MARGIN] = stroke_margin
    c[C_SAFE], c[C_HARD], c[C_SAFE1] = safe_threshold, hard_threshold, actuator_safe_threshold
    c[C_SCALE : C_SCALE + m] = robot.pose_scale
    d = robot.base.shape[1]
    c[C_B : C_B + 3 * n] = np.pad(robot.base, ((0, 0), (0, 3 - d))).ravel()
    c[C_P : C_P + 3 * n] = np.pad(robot.platform, ((0, 0), (0, 3 - d))).ravel()
    c[C_LEGS] = 1.0 if all(kind == "leg" for kind in robot.actuator_kinds) else 0.0
    c[C_A : C_A + n] = robot.crank_radii
    axes = robot.crank_axes
    c[C_U : C_U + 3 * n] = np.pad(axes[:, 0], ((0, 0), (0, 3 - d))).ravel()
    c[C_V : C_V + 3 * n] = np.pad(axes[:, 1], ((0, 0), (0, 3 - d))).ravel()
    c[C_E : C_E + 3 * n] = np.pad(robot.rails, ((0, 0), (0, 3 - d))).ravel()
    c[C_LAM : C_LAM + n] = [1.0 if kind == "leg" else 0.0 for kind in robot.actuator_kinds]
    c[C_ELL : C_ELL + n] = robot.link_lengths
    c[C_BRANCH : C_BRANCH + n] = robot.branches
    c.setflags(write=False)
    return c


def pack_family(params) -> np.ndarray:
    """The constants of ``params`` (an ``envs.params.FamilyParams``) as the kernels' float64 vector, shape (C_SIZE,).

    Args:
        params: Environment constants with a ``DistanceConstraintMechanism`` as ``robot``.

    Returns:
        Read-only float64 vector indexed by the ``C_*`` offsets (the certificate's part is ``pack_certificate``).
    """
    m = params.robot.n_pose
    c = pack_certificate(
        params.robot,
        params.stroke_limits,
        params.stroke_margin,
        params.safe_threshold,
        params.actuator_safe_threshold,
        params.hard_threshold,
    ).copy()
    c[C_DT], c[C_RATE] = params.dt, params.max_rate
    c[C_RK4] = 1.0 if params.integrator == "rk4" else 0.0
    c[C_WP], c[C_WO] = params.position_weight, params.orientation_weight
    c[C_WS], c[C_WA] = params.singularity_weight, params.action_weight
    c[C_PENALTY], c[C_BONUS] = params.termination_penalty, params.success_reward
    c[C_SUCC_P], c[C_SUCC_O] = params.success_position_tolerance, params.success_orientation_tolerance
    c[C_NEWTON_TOL], c[C_NEWTON_IT] = params.newton_tolerance, params.newton_max_iterations
    c[C_JUMP], c[C_MAX_SUBSTEP], c[C_MAX_SUBSTEPS] = params.jump_tolerance, params.max_substep, params.max_substeps
    c[C_OMEGA] = _TWO_PI / params.track_period
    c[C_SPACING] = params.segment_spacing
    c[C_LOW : C_LOW + m] = params.pose_low
    c[C_HIGH : C_HIGH + m] = params.pose_high
    c[C_SLOW : C_SLOW + m] = params.sample_low
    c[C_SHIGH : C_SHIGH + m] = params.sample_high
    c[C_HARD_KIND] = 1.0 if params.hard_kind == "ill_conditioned" else 0.0
    c[C_HARD1] = params.actuator_hard_threshold
    c[C_WS1] = params.actuator_singularity_weight
    path = np.asarray(params.track_path, dtype=np.float64).reshape(-1, m)
    if len(path):
        c[C_PATH] = len(path)
        for k, vertex in enumerate(path):
            c[C_PATH_W + 6 * k : C_PATH_W + 6 * k + m] = vertex
        c[C_PATH_T : C_PATH_T + len(path)] = np.cumsum(params.track_path_times) / np.sum(params.track_path_times)
        c[C_PATH_T + len(path) - 1] = 1.0
    c.setflags(write=False)
    return c


def read_only(a: np.ndarray) -> np.ndarray:
    """``a``, or a read-only view of it: the kernels take their constants read-only, one compiled signature for all.

    A writable and a read-only array are two types to Numba, so a kernel given both would be compiled twice.
    """
    if not a.flags.writeable:
        return a
    view = a.view()
    view.setflags(write=False)
    return view


def evaluation_rows(m: int) -> dict[str, int | slice]:
    """Rows of the evaluation (``evaluate_batch``, ``step_batch``) for m pose coordinates; column i is robot i."""
    rows: dict[str, int | slice] = {info: row for row, (_, info) in enumerate(EVALUATION)}
    rows.update(
        target=slice(E_FIXED, E_FIXED + m),
        target_velocity=slice(E_FIXED + m, E_FIXED + 2 * m),
        pose=slice(E_FIXED + 2 * m, E_FIXED + 3 * m),
    )
    return rows


#: Width of the pose code and number of pose coordinates m of each pose space: (x, y, cos φ, sin φ) and
#: (x, y, φ); (p, quaternion) and (p, rotation vector); p and p.
POSE_CODES = {"planar": (4, 3), "spatial": (7, 6), "translational": (3, 3)}


def observation_layout(pose_space: str, n: int, with_velocity: bool) -> dict[str, slice]:
    """Slices of the observation vector (see ``envs.FamilyReachEnv``).

    Args:
        pose_space: "planar", "spatial" or "translational" (a ``PoseSpace.name``).
        n: Number of actuators.
        with_velocity: Whether the observation ends with the target velocity (Track).

    Returns:
        name → slice: pose, target, error, strokes, stroke_error, k (and target_velocity).
    """
    if pose_space not in POSE_CODES:
        raise ValueError(f"pose_space must be one of {sorted(POSE_CODES)}, got {pose_space!r}")
    pose, m = POSE_CODES[pose_space]
    names = [("pose", pose), ("target", pose), ("error", m), ("strokes", n), ("stroke_error", n), ("k", 1)]
    if with_velocity:
        names.append(("target_velocity", m))
    out, start = {}, 0
    for name, size in names:
        out[name] = slice(start, start + size)
        start += size
    return out


# -- rotations: quaternions (w, x, y, z) and rotation vectors ------------------------------------------


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
    """Wrap an angle to [−π, π)."""
    return (angle + math.pi) % _TWO_PI - math.pi


# -- pose-space operations -----------------------------------------------------------------------------


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


# -- the constraint-level math -------------------------------------------------------------------------


@jit
def _work():
    """A work array of the kernels (rows ``W_*``, 6 columns), its anchor cache marked empty."""
    w = np.empty((W_SIZE, 6))
    w[W_CQ, :] = np.nan
    return w


@jit_inline
def _rows_legs(c, q, x, w):
    """``_rows`` of a leg-actuated robot: the anchors are the B_i; ℓ_i = q_i and −(J_q)_ii / 2 = q_i."""
    n = int(c[C_N])
    p0, p1, p2, r00, r01, r02, r10, r11, r12, r20, r21, r22 = _frame(c, x)
    spatial = c[C_SPATIAL] != 0.0
    sq = w[W_SQ]
    for i in range(n):
        P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
        rp0 = r00 * P0 + r01 * P1 + r02 * P2
        rp1 = r10 * P0 + r11 * P1 + r12 * P2
        rp2 = r20 * P0 + r21 * P1 + r22 * P2
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
        P0, P1, P2 = c[C_P + 3 * i], c[C_P + 3 * i + 1], c[C_P + 3 * i + 2]
        rp0 = r00 * P0 + r01 * P1 + r02 * P2
        rp1 = r10 * P0 + r11 * P1 + r12 * P2
        rp2 = r20 * P0 + r21 * P1 + r22 * P2
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
def _ik_leg(c, i, w0, w1, w2):
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
        out[i] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) if legs else _ik_leg(c, i, d0, d1, d2)


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


@jit
def _singularity(c, q, w, src):
    """(inverse condition number of J_i diag(pose_scale), sign(det J_x)) from the rows ``src`` of A.

    The link Jacobian diag(1/ℓ) A diag(pose_scale) (legs: J_i diag(pose_scale), ℓ = q); its σ_min/σ_max in
    closed form (m = 3) or by a
    one-sided Jacobi SVD (m = 6; ``inverse_condition6``, bit for bit what the batched step's
    ``inverse_condition6_lanes`` gives). sign(det J_x) = sign(det A).
    """
    m = int(c[C_N])
    if m == 3:
        a, b, d = w[src], w[src + 1], w[src + 2]
        ell0, ell1, ell2 = _link_length(c, q, w, 0), _link_length(c, q, w, 1), _link_length(c, q, w, 2)
        return three.link_condition3(
            c, a[0], a[1], a[2], b[0], b[1], b[2], d[0], d[1], d[2], ell0, ell1, ell2
        )  # fmt: skip
    Ht = w[W_H : W_H + 6]  # column j of J_i diag(pose_scale) as row j
    for i in range(6):
        inv = 1.0 / _link_length(c, q, w, i)
        row = w[src + i]
        for j in range(6):
            Ht[j, i] = row[j] * inv * c[C_SCALE + j]
    k = inverse_condition6(Ht)
    det = _solve(w, m, src, w[W_RHS], w[W_SOL])
    return k, (1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0))


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


@jit
def _substeps(c, v):
    """Substeps so that each predicts at most ``max_substep`` of motion ‖(δp, ℓ_c δθ)‖ [m]."""
    count = np.ceil(_metric(c, v) * c[C_DT] / c[C_MAX_SUBSTEP])
    cap = c[C_MAX_SUBSTEPS]
    if not math.isfinite(count):
        return int(cap)
    return int(min(max(count, 1.0), cap))


@jit
def _rate_at(c, q, x, rate, w, out):
    """Out = J_f(q, x) q̇ at an arbitrary (q, x) (computes the rows of A there)."""
    _rows(c, q, x, w)
    _twist_rate(c, q, rate, w, W_A, out)


#: Rows of a block's lane work array (``allocate_lanes``): k, two rows for the SVD, sign(det J_x), flags, k_I.
L_K, L_WORST, L_ACTIVE, L_SIGN, L_FLAGS, L_K1 = 0, 1, 2, 3, 4, 5


@jit
def allocate_lanes():
    """Work arrays of one block of up to ``LANES`` spatial robots: (H (6, 6, LANES), lane rows (6, LANES))."""
    return np.empty((6, 6, LANES)), np.empty((6, LANES))


@jit
def _advance_spatial(c, state, action, i, w, moved):
    """Move robot i through one control period (predict, correct): its rows of ``moved`` but k, k_I, the reason.

    Returns (whether the correction failed, whether the pose left its bounds); the rows of A at the new pose
    are left in w.
    """
    q, x, _, _, residual = state
    o_q, o_x, _, _, o_res, o_a, o_qr, _, o_jump = moved
    m = int(c[C_N])
    dt = c[C_DT]
    lo, hi = c[C_LMIN], c[C_LMAX]
    stroke = c[C_RATE] * dt
    q0, x0 = q[i], x[i]
    nq, qr, kq, kx = w[W_NQ], w[W_QR], w[W_KQ], w[W_KX]
    v, pred, y, t = w[W_V], w[W_PRED], w[W_Y], w[W_T]
    for j in range(m):
        a = min(max(action[i, j], -1.0), 1.0)
        o_a[i, j] = a
        nq[j] = min(max(q0[j] + a * stroke, lo), hi)
        qr[j] = (nq[j] - q0[j]) / dt
        kq[j] = q0[j]
        kx[j] = x0[j]
    _rows(c, kq, kx, w)
    _twist_rate(c, kq, qr, w, W_A, v)
    count = _substeps(c, v)
    h = dt / count
    rk4 = c[C_RK4] != 0.0
    tolerance, iterations = c[C_NEWTON_TOL], int(c[C_NEWTON_IT])
    res = residual[i]
    jump = 0.0
    failed = False
    for s in range(count):
        frac = (s + 1) / count
        for j in range(m):
            t[j] = q0[j] + frac * (nq[j] - q0[j])
        if s > 0:  # at the pose Newton's method just returned, whose rows are in w
            _twist_rate(c, kq, qr, w, W_A, v)
        if rk4:
            k1, k2, k3, xm, qm = w[W_K1], w[W_K2], w[W_K3], w[W_XM], w[W_QM]
            for j in range(m):
                qm[j] = kq[j] + 0.5 * h * qr[j]
            _retract(c, kx, v, 0.5 * h, xm)
            _rate_at(c, qm, xm, qr, w, k1)
            _retract(c, kx, k1, 0.5 * h, xm)
            _rate_at(c, qm, xm, qr, w, k2)
            for j in range(m):
                qm[j] = kq[j] + h * qr[j]
            _retract(c, kx, k2, h, xm)
            _rate_at(c, qm, xm, qr, w, k3)
            for j in range(m):
                k3[j] = (v[j] + 2.0 * k1[j] + 2.0 * k2[j] + k3[j]) / 6.0
            _retract(c, kx, k3, h, pred)
        else:
            _retract(c, kx, v, h, pred)
        if not _all_finite(pred, m):
            failed = True
            break
        fres = _newton(c, t, pred, w, y, tolerance, iterations)
        if not fres <= tolerance:
            failed = True
            break
        _difference(c, y, pred, w[W_DIFF])
        jump = max(jump, _metric(c, w[W_DIFF]))
        for j in range(m):
            kq[j] = t[j]
            kx[j] = y[j]
        res = fres
    if failed:
        for j in range(m):
            kq[j] = q0[j]
            kx[j] = x0[j]
        res = residual[i]
        _rows(c, kq, kx, w)  # back at the start pose (rare: only when the correction failed)
    out = False
    for j in range(m):
        if kx[j] < c[C_LOW + j] or kx[j] > c[C_HIGH + j]:
            out = True
    for j in range(m):
        o_q[i, j] = kq[j]
        o_x[i, j] = kx[j]
        o_qr[i, j] = qr[j]
    o_res[i] = res
    o_jump[i] = jump
    return failed, out


#: Row paths of the step: planar legs in scalars (``envs.kernels.planar``), three actuators of any kind in
#: scalars (``envs.kernels.three``), any pose space over work arrays (here). The path is a compile-time constant
#: of the entry kernels (``_path_kernels``): a robot compiles its own path only.
PLANAR_LEGS, THREE, WORK_ARRAYS = 0, 1, 2
ROW_PATHS = (PLANAR_LEGS, THREE, WORK_ARRAYS)


def row_path(cs) -> int:
    """The row path (``PLANAR_LEGS``, ``THREE`` or ``WORK_ARRAYS``) that steps the robot of ``cs``.

    Args:
        cs: Packed constants, shape (C_SIZE,) or (N, C_SIZE) (the robots of one batch share their pose space and
            actuator kinds; the first row is read).
    """
    spatial = cs.item(C_SPATIAL)
    if spatial == 0.0 and cs.item(C_LEGS) != 0.0 and cs.item(C_TRANSLATIONAL) == 0.0:
        return PLANAR_LEGS
    if spatial == 0.0 and cs.item(C_N) == 3.0:  # cranks or sliders, planar or translational
        return THREE
    return WORK_ARRAYS


#: Pose spaces, the second compile-time constant of the entry kernels (the evaluation encodes and compares poses
#: of its own space only).
PLANAR_SPACE, SPATIAL_SPACE, TRANSLATIONAL_SPACE = 0, 1, 2


def pose_space_code(cs) -> int:
    """The pose space (``PLANAR_SPACE``, ``SPATIAL_SPACE`` or ``TRANSLATIONAL_SPACE``) of the robot of ``cs``."""
    if cs.item(C_SPATIAL) != 0.0:
        return SPATIAL_SPACE
    return TRANSLATIONAL_SPACE if cs.item(C_TRANSLATIONAL) != 0.0 else PLANAR_SPACE


def _literal_space(space) -> int:
    """The value of a pose space typed as a compile-time constant."""
    if not isinstance(space, types.IntegerLiteral) or space.literal_value not in (0, 1, 2):
        raise errors.TypingError(f"the pose space must be a compile-time constant in (0, 1, 2), got {space}")
    return space.literal_value


def _literal_path(path) -> int:
    """The value of a row path typed as a compile-time constant (the overloads below choose code by it)."""
    if not isinstance(path, types.IntegerLiteral) or path.literal_value not in ROW_PATHS:
        raise errors.TypingError(f"the row path must be a compile-time constant in {ROW_PATHS}, got {path}")
    return path.literal_value


#: What the overloads that choose a row path's code are compiled with (as ``setup.jit``).
_OVERLOAD_OPTIONS = {"nogil": True, "error_model": "numpy"}


@jit_inline
def _row(cs, i):
    """Robot i's constants: row i of per-robot constants (shape (N, C_SIZE)), or the one row all share ((1, C_SIZE))."""
    return cs[i] if cs.shape[0] > 1 else cs[0]


@jit_inline
def _planar_block(cs, state, action, start, count, w, lanes, moved):
    """``_transition_block`` of planar leg robots: each row in scalars (``planar.transition_row``)."""
    for i in range(start, start + count):
        planar.transition_row(_row(cs, i), state, action, i, moved)


@jit_inline
def _three_block(cs, state, action, start, count, w, lanes, moved):
    """``_transition_block`` of three cranks or sliders: each row in scalars (``three.transition_row``)."""
    for i in range(start, start + count):
        three.transition_row(_row(cs, i), state, action, i, moved)


@jit_inline
def _work_rows(cs, state, action, start, count, w, moved):
    """``_transition_block`` of any pose space over work arrays, robot by robot."""
    det_sign = state[3]
    o_q, _, o_k, o_k1, _, _, _, o_reason, o_jump = moved
    for i in range(start, start + count):
        c = _row(cs, i)
        failed, out = _advance_spatial(c, state, action, i, w, moved)
        k, sign = _singularity(c, o_q[i], w, W_A)
        k1 = _actuator_condition(c, w)
        o_k[i] = k
        o_k1[i] = k1
        o_reason[i] = planar.termination_reason(c, failed, o_jump[i], sign, det_sign[i], k, out, k1)


@jit_inline
def _work_block(cs, state, action, start, count, w, lanes, moved):
    """``_transition_block`` of any pose space over work arrays, spatial robots with m = 6 in SIMD lanes."""
    if count == 1 or cs[0][C_N] != 6.0:  # one robot (the plain Jacobi is cheaper) or m = 3
        _work_rows(cs, state, action, start, count, w, moved)
        return
    det_sign = state[3]
    o_q, _, o_k, o_k1, _, _, _, o_reason, o_jump = moved
    H, lane = lanes
    for r in range(count):
        i = start + r
        c = _row(cs, i)
        failed, out = _advance_spatial(c, state, action, i, w, moved)
        lane[L_SIGN, r] = _homogeneous_lane(c, o_q[i], w, W_A, H, r)
        lane[L_FLAGS, r] = (1.0 if failed else 0.0) + (2.0 if out else 0.0)
        lane[L_K1, r] = _actuator_condition(c, w)
    inverse_condition6_lanes(H, count, lane[L_K], lane[L_WORST], lane[L_ACTIVE])
    for r in range(count):
        i = start + r
        flags = lane[L_FLAGS, r]
        failed = flags == 1.0 or flags == 3.0
        out = flags >= 2.0
        k = lane[L_K, r]
        o_k[i] = k
        o_k1[i] = lane[L_K1, r]
        o_reason[i] = planar.termination_reason(
            _row(cs, i), failed, o_jump[i], lane[L_SIGN, r], det_sign[i], k, out, lane[L_K1, r]
        )


def _transition_block(path, cs, state, action, start, count, w, lanes, moved):
    """Advance robots start .. start + count − 1 (count ≤ ``LANES``) by one control period; writes their rows.

    Every path runs the algorithm of ``envs.physics.transition`` in its order: predict, correct (the row path),
    measure (k and k_I at the new pose), terminate (``planar.termination_reason``). ``path`` is the row path, a
    compile-time constant: the overload below compiles that path's block only. Args as ``transition_batch``;
    ``moved`` holds its outputs. With work arrays for SIMD lanes (``allocate_lanes``; None: robot by robot),
    spatial robots in blocks are moved one by one, then the k of all of them comes from one
    ``inverse_condition6_lanes`` call over the block (vectorised across robots, each robot's k bit for bit what
    it would be alone), then their termination reasons. ``cs`` holds one row of constants per robot or
    one row for all (the robots of one batch share their pose space and actuator kinds, not their geometry).
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_transition_block, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _transition_block_of_path(path, cs, state, action, start, count, w, lanes, moved):
    chosen = _literal_path(path)
    if chosen == WORK_ARRAYS and isinstance(lanes, types.NoneType):  # no lanes: robot by robot

        def rows(path, cs, state, action, start, count, w, lanes, moved):
            _work_rows(cs, state, action, start, count, w, moved)

        return rows
    block = (_planar_block, _three_block, _work_block)[chosen]

    def impl(path, cs, state, action, start, count, w, lanes, moved):
        block(cs, state, action, start, count, w, lanes, moved)

    return impl


@jit_inline
def _allocate_moved(n, m):
    """The outputs of ``transition_batch`` for n robots with m pose coordinates (see its Returns)."""
    q, x, action, q_rate = np.empty((n, m)), np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    k, k1, residual, jump = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    return q, x, k, k1, residual, action, q_rate, np.empty(n, dtype=np.int64), jump


def transition_batch(cs, state, action):
    """Advance N robots by one control period (the algorithm of ``envs.physics.transition``).

    Args:
        cs: Packed constants (``pack_family``) of the robots that move: shape (N, C_SIZE), one row per robot, or
            (1, C_SIZE), one geometry for all.
        state: (q, x, t, det_sign, residual): strokes [m] (N, n), poses (N, m), steps (N,) int (not read), the
            working mode sign(det J_x) of each episode (N,), the constraint residual at (q, x) [m²] (N,).
        action: Normalised stroke rates, shape (N, n), finite.

    Returns:
        (q', x', k', k_I', residual', applied action, achieved stroke rates [m/s], reason codes, jumps [m]).
    """
    return path_kernels(cs).transition(cs, state, action)


@jit
def strokes_batch(c, x):
    """Actuator coordinates of N poses x (N, m) by the closed-form inverse kinematics (NaN where out of reach).

    Leg lengths [m], crank angles [rad] or slider positions [m] on each actuator's chosen branch, shape (N, n): what
    the observation's stroke errors compare q with (``FamilyReference.strokes`` keeps those of a fixed target).
    """
    out = np.empty(x.shape)
    for i in range(x.shape[0]):
        _leg_lengths(c, x[i], out[i])
    return out


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
def initial_batch(c, x):
    """Strokes (inverse kinematics), k, k_I, sign(det J_x) and residual of N robots at rest at poses x (N, m)."""
    n, m = x.shape
    o_q, o_k, o_k1, o_sign, o_res = np.empty((n, m)), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    w = _work()
    for i in range(n):
        _inverse_kinematics(c, x[i], w, o_q[i])
        o_k[i], o_sign[i] = _singularity(c, o_q[i], w, W_A)
        o_k1[i] = _actuator_condition(c, w)
        o_res[i] = _residual(c, o_q[i], w)
    return o_q, o_k, o_k1, o_sign, o_res


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


# -- reference, errors, reward, observation -------------------------------------------------------------


@jit
def _reference_at(c, tau, center, amplitude, phase, i, o_pose, o_velocity):
    """Target pose and rate of robot i at the angle τ = ω t [rad] of its reference (``envs.physics.FamilyReference``).

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
def _evaluate_planar_row(c, observation, measured, reference, outcome, i, w, out):
    """``_evaluate_row`` of a planar leg robot: its terms and observation are ``envs.kernels.planar``'s."""
    q, x, t, k, k1, residual = measured
    center, amplitude, phase, _ = reference
    action, reason = outcome
    o_eval, o_obs = out
    g, vel = w[W_TGT], w[W_VEL]
    _reference(c, t[i], center, amplitude, phase, i, g, vel)
    xi = x[i]
    pose, target = (xi[0], xi[1], xi[2]), (g[0], g[1], g[2])
    applied = (action[i, 0], action[i, 1], action[i, 2])
    tr, si, ac, te, ep, eo = planar.reward_terms(c, pose, target, k[i], applied, reason[i])
    success = reason[i] == 0 and planar.is_success(c, ep, eo)
    bonus = c[C_BONUS] if success else 0.0
    o_eval[E_TRACKING, i], o_eval[E_SINGULARITY, i], o_eval[E_ACTION, i], o_eval[E_TERMINATION, i] = tr, si, ac, te
    o_eval[E_BONUS, i] = bonus
    o_eval[E_REWARD, i] = tr + si + ac + te + bonus
    o_eval[E_ACTUATOR, i] = 0.0  # legs: no Type I singularity
    o_eval[E_K1, i] = k1[i]
    o_eval[E_COST1, i] = 0.0
    o_eval[E_POSITION_ERROR, i], o_eval[E_ORIENTATION_ERROR, i] = ep, eo
    o_eval[E_SUCCESS, i] = 1.0 if success else 0.0
    o_eval[E_COST, i] = 1.0 if k[i] < c[C_SAFE] else 0.0
    o_eval[E_K, i] = k[i]
    o_eval[E_RESIDUAL, i] = residual[i]
    for j in range(3):
        o_eval[E_FIXED + j, i] = g[j]
        o_eval[E_FIXED + 3 + j, i] = vel[j]
        o_eval[E_FIXED + 6 + j, i] = xi[j]
    planar.observation_row(c, observation, q, x, k, target, (vel[0], vel[1], vel[2]), i, o_obs)


@jit_inline
def _evaluate_general_row(space, c, observation, measured, reference, outcome, i, w, out):
    """``_evaluate_row`` of any robot over work arrays (any pose space and actuator kind)."""
    low, high, with_velocity = observation
    q, x, t, k, k1, residual = measured
    center, amplitude, phase, center_strokes = reference
    action, reason = outcome
    o_eval, o_obs = out
    m = int(c[C_N])
    g, vel, diff = w[W_TGT], w[W_VEL], w[W_DIFF]
    _reference(c, t[i], center, amplitude, phase, i, g, vel)
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
    terminated = reason[i] != 0
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
    o_eval[E_K, i] = ki
    o_eval[E_RESIDUAL, i] = residual[i]
    for j in range(m):
        o_eval[E_FIXED + j, i] = g[j]
        o_eval[E_FIXED + m + j, i] = vel[j]
        o_eval[E_FIXED + 2 * m + j, i] = xi[j]
    col = _encode_pose(space, xi, o_obs, i, 0, low, high)
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
        target_q = center_strokes[i]
    else:
        target_q = w[W_SEG]
        _leg_lengths(c, g, target_q)
    for j in range(m):
        _clip32(o_obs, i, col + j, (target_q[j] - q[i, j]) / span, low, high)
    col += m
    _clip32(o_obs, i, col, ki, low, high)
    col += 1
    if with_velocity:
        for j in range(m):
            _clip32(o_obs, i, col + j, vel[j], low, high)


def _evaluate_row(path, space, c, observation, measured, reference, outcome, i, w, out):
    """Target, reward terms, errors, success, cost and observation of robot i (see ``envs.physics.evaluate``).

    Args as ``evaluate_batch``; ``out`` is (evaluation, observations); ``path`` is the row path, a compile-time
    constant, and so is ``space``, the pose space: a planar leg robot's terms and observation are
    ``envs.kernels.planar``'s, the others' those of their pose space.
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_evaluate_row, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _evaluate_row_of_path(path, space, c, observation, measured, reference, outcome, i, w, out):
    if _literal_path(path) == PLANAR_LEGS:

        def planar_row(path, space, c, observation, measured, reference, outcome, i, w, out):
            _evaluate_planar_row(c, observation, measured, reference, outcome, i, w, out)

        return planar_row
    _literal_space(space)

    def impl(path, space, c, observation, measured, reference, outcome, i, w, out):
        _evaluate_general_row(space, c, observation, measured, reference, outcome, i, w, out)

    return impl


def evaluate_batch(cs, observation, measured, reference, outcome):
    """Evaluation rows (``evaluation_rows``) and observations of N robots.

    Args:
        cs: Packed constants of the model the observation and the reward are computed with: shape (N, C_SIZE) or
            (1, C_SIZE), as ``transition_batch``.
        observation: (low, high, with_velocity): the observation's float32 bounds, shape (D,) each, and whether it
            ends with the target velocity.
        measured: (q, x, t, k, k_I, residual): strokes [m] (N, n), poses (N, m), step indices (N,) int, inverse
            condition numbers (N,), actuator condition numbers (Type I measure, 1 for legs) (N,), constraint
            residuals [m²] (N,).
        reference: (center, amplitude, phase, strokes) of the targets (``envs.physics.FamilyReference``), each
            (N, m); strokes, the actuator coordinates of the centres (``strokes_batch``, (N, n)), are read for the
            robots whose target is fixed (a = 0, C_PATH = 0) instead of solving the inverse kinematics again.
        outcome: (action, reason): applied actions (N, n) and termination reason codes (N,).

    Returns:
        (evaluation (E_FIXED + 3m, N) float64, observations (N, D) float32).
    """
    return path_kernels(cs).evaluate(cs, observation, measured, reference, outcome)


# -- the fused step: transition then evaluation, on every core for large batches ------------------------


@jit_inline
def _step_block(path, space, model, plant, observation, state, reference, action, start, count, w, lanes, out):
    """Transition (``plant``) then evaluation (``model``) of robots start .. start + count − 1 (count ≤ ``LANES``)."""
    o_q, o_x, o_t, o_k, o_k1, o_res, o_a, o_qr, o_reason, o_jump, o_eval, o_obs = out
    _transition_block(
        path, plant, state, action, start, count, w, lanes, (o_q, o_x, o_k, o_k1, o_res, o_a, o_qr, o_reason, o_jump)
    )
    t = state[2]
    measured, outcome = (o_q, o_x, o_t, o_k, o_k1, o_res), (o_a, o_reason)
    for i in range(start, start + count):
        o_t[i] = t[i] + 1
        _evaluate_row(path, space, _row(model, i), observation, measured, reference, outcome, i, w, (o_eval, o_obs))


@jit_inline
def _finite_actions(action):
    for i in range(action.shape[0]):
        for j in range(action.shape[1]):
            if not math.isfinite(action[i, j]):
                return False
    return True


@jit
def _step_range(path, space, model, plant, observation, state, reference, action, span, out):
    """Step robots span[0] .. span[1] − 1 in blocks of ``LANES``, over work arrays of their own.

    Compiled on its own (not inlined): the parallel loop calls it once per chunk, so Numba's parfor analysis
    never sees the tuples it unpacks.
    """
    w = _work()
    lanes = allocate_lanes()
    begin, end = span
    for start in range(begin, end, LANES):
        count = min(LANES, end - start)
        _step_block(path, space, model, plant, observation, state, reference, action, start, count, w, lanes, out)


class PathKernels(NamedTuple):
    """The entry kernels of one row path, each compiled for that path alone (see ``_path_kernels``)."""

    transition: Any
    evaluate: Any
    step_serial: Any
    step_parallel: Any


def _path_kernels(path: int, space: int) -> PathKernels:
    """The entry kernels of the row path ``path`` and the pose space ``space``, both compile-time constants.

    A closure over ints is cached by Numba under their values, so each path's kernels compile (and load from the
    on-disk cache) on their own, when a robot of that path first uses them: a robot compiles its own path only.
    The parallel step compiles at the first batch of at least ``PARALLEL_MIN_BATCH`` robots.
    """

    def transition(cs, state, action):
        n, m = action.shape
        moved = _allocate_moved(n, m)
        w = _work()
        lanes = allocate_lanes()
        for start in range(0, n, LANES):
            _transition_block(path, cs, state, action, start, min(LANES, n - start), w, lanes, moved)
        return moved

    def evaluate(cs, observation, measured, reference, outcome):
        n, m = measured[1].shape
        out = (np.empty((E_FIXED + 3 * m, n)), np.empty((n, observation[0].shape[0]), dtype=np.float32))
        w = _work()
        for i in range(n):
            _evaluate_row(path, space, _row(cs, i), observation, measured, reference, outcome, i, w, out)
        return out

    def step_serial(
        model,
        plant,
        low,
        high,
        with_velocity,
        q,
        x,
        t,
        det_sign,
        residual,
        center,
        amplitude,
        phase,
        strokes,
        action,
        out,
    ):
        # Flat, unlike the rest: the single env calls it at every step, and Numba types an array inside a tuple
        # argument slower than a bare one (about 0.2 µs per array per call).
        if not _finite_actions(action):
            return True
        observation = (low, high, with_velocity)
        state, reference = (q, x, t, det_sign, residual), (center, amplitude, phase, strokes)
        w = _work()
        lanes = None  # robot by robot: the SIMD lanes of the spatial SVD compile for the parallel step only
        n = q.shape[0]
        for start in range(0, n, LANES):
            count = min(LANES, n - start)
            _step_block(path, space, model, plant, observation, state, reference, action, start, count, w, lanes, out)
        return False

    def step_parallel(model, plant, observation, state, reference, action, out):
        if not _finite_actions(action):
            return True
        n = action.shape[0]
        chunks = (n + CHUNK - 1) // CHUNK
        for chunk in numba.prange(chunks):
            span = (chunk * CHUNK, min(n, (chunk + 1) * CHUNK))
            _step_range(path, space, model, plant, observation, state, reference, action, span, out)
        return False

    return PathKernels(jit(transition), jit(evaluate), jit(step_serial), jit_parallel(step_parallel))


#: The entry kernels of each row path and pose space, by (path, space).
_PATH_KERNELS = {(path, space): _path_kernels(path, space) for path in ROW_PATHS for space in range(3)}


def _step_serial(model, plant, *args):
    """The one-thread step of ``step_batch`` (flat arguments: observation, state and reference unpacked)."""
    return path_kernels(plant).step_serial(model, plant, *args)


def _step_parallel(model, plant, observation, state, reference, action, out):
    """The multi-core step of ``step_batch``."""
    return path_kernels(plant).step_parallel(model, plant, observation, state, reference, action, out)


def allocate_step(n, m, obs_dim):
    """Output arrays of ``step_batch`` for n robots with m pose coordinates and obs_dim observations.

    (q, x, t, k, k_I, residual, action, stroke rates, reasons, jumps, evaluation, observations).
    """
    q, x, action, q_rate = (np.empty((n, m)) for _ in range(4))
    k, k1, residual, jump = (np.empty(n) for _ in range(4))
    reason, t = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    evaluation, observations = np.empty((E_FIXED + 3 * m, n)), np.empty((n, obs_dim), dtype=np.float32)
    return q, x, t, k, k1, residual, action, q_rate, reason, jump, evaluation, observations


def path_kernels(cs) -> PathKernels:
    """The entry kernels of the robot of packed constants ``cs`` (its ``row_path``'s and pose space's)."""
    return _PATH_KERNELS[row_path(cs), pose_space_code(cs)]


def step_batch(model, plant, observation, state, reference, action, out, kernels=None):
    """Transition and evaluation of N robots into ``out`` (``allocate_step``); True if an action is not finite.

    Args:
        model: Packed constants of the model the reward and the observation are computed with, shape (N, C_SIZE)
            or (1, C_SIZE) (``transition_batch``'s ``cs``).
        plant: Packed constants of the robots that move (the integrated geometry), shape (N, C_SIZE) or
            (1, C_SIZE).
        observation: (low, high, with_velocity), as ``evaluate_batch``.
        state: (q, x, t, det_sign, residual), as ``transition_batch``.
        reference: (center, amplitude, phase, strokes), as ``evaluate_batch``.
        action: Normalised stroke rates, shape (N, n).
        out: The arrays of ``allocate_step``.
        kernels: ``path_kernels(plant)``, if the caller keeps them (the single env's step saves finding them).
    """
    if kernels is None:
        kernels = path_kernels(plant)
    if action.shape[0] >= PARALLEL_MIN_BATCH:
        return kernels.step_parallel(model, plant, observation, state, reference, action, out)
    return kernels.step_serial(model, plant, *observation, *state, *reference, action, out)


# -- the safe set and the task sampler ------------------------------------------------------------------


@jit
def _safety(c, strokes, w):
    """The measure tasks are certified on, on k's scale: k, or with cranks and sliders min(k, k_I · s / s_I).

    So a configuration has safety ≥ safe_threshold (s) exactly when k ≥ s and k_I ≥ actuator_safe_threshold
    (s_I): both kinds of singularity are kept at bay. Needs the rows of A at (strokes, x) in w.
    """
    k, _ = _singularity(c, strokes, w, W_A)
    if c[C_LEGS] != 0.0:
        return k
    return min(k, _actuator_condition(c, w) * c[C_SAFE] / c[C_SAFE1])


@jit
def _pose_safety(c, x, w, strokes):
    """The certificate of one pose: its ``_safety``, or −1 where an actuator leaves its limits less the margin.

    Every safety decision (the task samplers, the certified grid, the planner's edges) goes through here. The
    strokes of x (inverse kinematics) are left in ``strokes`` and the rows of A there in w. The sampling box is
    not checked.
    """
    _inverse_kinematics(c, x, w, strokes)
    lo, hi = c[C_LMIN] + c[C_MARGIN], c[C_LMAX] - c[C_MARGIN]
    for j in range(int(c[C_N])):
        if not (lo <= strokes[j] <= hi):
            return -1.0
    return _safety(c, strokes, w)


@jit
def _in_box(c, x):
    """Whether the pose x lies in the sampling box."""
    for j in range(int(c[C_N])):
        if not (c[C_SLOW + j] <= x[j] <= c[C_SHIGH + j]):
            return False
    return True


@jit
def _safe(c, x, w, strokes):
    """Whether x is in the sampling box and its ``_pose_safety`` (strokes with margin, safety) ≥ safe_threshold."""
    if not _in_box(c, x):
        return False
    return _pose_safety(c, x, w, strokes) >= c[C_SAFE]


@jit
def _segment_min_k(c, start, target, w, strokes, stop_below, spacing, box):
    """Smallest ``_pose_safety`` along the geodesic start → target (p linear, R along exp).

    Checked points are at most ``spacing`` apart in ‖(δp, ℓ_c δθ)‖ (ends included; at most
    ``SEGMENT_MAX_POINTS`` intervals). A point whose strokes leave the limits less the margin (or, with ``box``,
    that leaves the sampling box) makes the segment −1; a point where sign(det J_x) differs from the start's
    counts as safety 0 (the segment crossed a Type II singularity between checked points). Stops early once
    below ``stop_below``.
    """
    direction, point = w[W_SEG_D], w[W_SEG]
    _difference(c, target, start, direction)
    count = int(min(max(math.ceil(_metric(c, direction) / spacing), 1), SEGMENT_MAX_POINTS))
    worst = np.inf
    first_sign = 0.0
    for s in range(count + 1):
        _retract(c, start, direction, s / count, point)
        if box and not _in_box(c, point):
            return -1.0
        safety = _pose_safety(c, point, w, strokes)
        if safety < 0.0:
            return -1.0
        det = _solve(w, int(c[C_N]), W_A, w[W_RHS], w[W_SOL])
        sign = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)
        if s == 0:
            first_sign = sign
        elif sign != first_sign:
            safety = 0.0
        worst = min(worst, safety)
        if worst < stop_below:
            return worst
    return worst


@jit
def _draw_safe(c, fn, st, w, strokes, out):
    """A pose drawn uniformly in the sampling box until it is safe; False after ``SAMPLER_TRIES`` rejections."""
    m = int(c[C_N])
    for _ in range(SAMPLER_TRIES):
        for j in range(m):
            lo, hi = c[C_SLOW + j], c[C_SHIGH + j]
            out[j] = lo + (hi - lo) * _next_double(fn, st)
        if _safe(c, out, w, strokes):
            return True
    return False


@jit
def _draw_band(c, fn, st, w, strokes, low, high, out):
    """A pose of the sampling box with strokes within the margin and low ≤ k < high; False after the tries."""
    m = int(c[C_N])
    lo, hi = c[C_LMIN] + c[C_MARGIN], c[C_LMAX] - c[C_MARGIN]
    for _ in range(SAMPLER_TRIES):
        for j in range(m):
            out[j] = c[C_SLOW + j] + (c[C_SHIGH + j] - c[C_SLOW + j]) * _next_double(fn, st)
        _inverse_kinematics(c, out, w, strokes)
        inside = True
        for j in range(m):
            if not (lo <= strokes[j] <= hi):
                inside = False
        if inside:
            k, _ = _singularity(c, strokes, w, W_A)
            if low <= k < high:
                return True
    return False


@jit_inline
def _sample_reach_one(c, fn, st, hard, min_distance, w, strokes, start, target, waypoint, step):
    """One certified pair from the stream (fn, st) into start, target, waypoint (see ``_sample_reach``); success."""
    safe = c[C_SAFE]
    box = np.bool_(True)  # a bool, not the constant True: one compiled _segment_min_k for every caller
    band = hard and c[C_HARD_KIND] != 0.0
    floor = 2.0 * c[C_HARD]
    for _ in range(SAMPLER_TRIES):
        if not _draw_safe(c, fn, st, w, strokes, start):
            return False
        if band:
            if not _draw_band(c, fn, st, w, strokes, floor, safe, target):
                return False
        elif not _draw_safe(c, fn, st, w, strokes, target):
            return False
        _difference(c, target, start, step)
        if not _metric(c, step) >= min_distance:
            continue
        if not hard:
            if _segment_min_k(c, start, target, w, strokes, safe, c[C_SPACING], box) >= safe:
                return True
        elif band:
            if _segment_min_k(c, start, target, w, strokes, floor, c[C_SPACING], box) >= floor:
                return True
        elif 0.0 <= _segment_min_k(c, start, target, w, strokes, -np.inf, c[C_SPACING], box) < safe:
            for _ in range(WAYPOINT_TRIES):
                if not _draw_safe(c, fn, st, w, strokes, waypoint):
                    return False
                if (
                    _segment_min_k(c, start, waypoint, w, strokes, safe, c[C_SPACING], box) >= safe
                    and _segment_min_k(c, waypoint, target, w, strokes, safe, c[C_SPACING], box) >= safe
                ):
                    return True
    return False


@jit_inline
def _put_pair(c, hard, start, target, waypoint, i, o_start, o_target, o_waypoint):
    band = hard and c[C_HARD_KIND] != 0.0
    for j in range(int(c[C_N])):
        o_start[i, j] = start[j]
        o_target[i, j] = target[j]
        o_waypoint[i, j] = waypoint[j] if hard and not band else target[j]


@jit
def _sample_reach(c, streams, hard, min_distance, o_start, o_target, o_waypoint):
    """Fill o_start, o_target, o_waypoint (M, m) with certified pairs; −1 on success, else the failing pair.

    Standard pair: the geodesic start → target has k ≥ safe_threshold at every checked point. Hard pair
    (``hard_kind`` "detour"): that geodesic dips below safe_threshold (it stays inside the box and stroke
    limits), and the two geodesics start → waypoint → target are safe. Hard pair ("ill_conditioned"): a safe
    start and a target in the ill-conditioned band 2 hard_threshold ≤ k < safe_threshold, joined by a
    geodesic that keeps k ≥ 2 hard_threshold.
    """
    shared = streams.shape[0] == 1
    w = _work()
    strokes = np.empty(6)
    start, target, waypoint, step = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    for i in range(o_start.shape[0]):
        s = 0 if shared else i
        if not _sample_reach_one(
            c, streams[s, 0], streams[s, 1], hard, min_distance, w, strokes, start, target, waypoint, step
        ):
            return i
        _put_pair(c, hard, start, target, waypoint, i, o_start, o_target, o_waypoint)
    return -1


@jit_parallel
def _sample_reach_parallel(c, streams, hard, min_distance, o_start, o_target, o_waypoint):
    """``_sample_reach`` on every core, for one stream per robot (each robot's pair depends on its stream only).

    Every robot draws its pair (the serial kernel stops at the first failure); returns the first failing pair.
    """
    n = o_start.shape[0]
    ok = np.empty(n, dtype=np.bool_)
    for i in numba.prange(n):
        w = _work()
        strokes = np.empty(6)
        start, target, waypoint, step = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
        ok[i] = _sample_reach_one(
            c, streams[i, 0], streams[i, 1], hard, min_distance, w, strokes, start, target, waypoint, step
        )
        if ok[i]:
            _put_pair(c, hard, start, target, waypoint, i, o_start, o_target, o_waypoint)
    for i in range(n):
        if not ok[i]:
            return i
    return -1


def sample_reach_batch(c, streams, n, m, hard, min_distance):
    """Draw n certified start/target pairs (``FamilyReachEnv.sample_tasks``), or None if one could not be found.

    Args:
        c: Packed constants.
        streams: ``random_streams`` of one generator (shared) or of n generators, shape (1, 2) or (n, 2).
        n: Number of pairs.
        m: Pose coordinates.
        hard: Whether the straight path must dip below the safe threshold (with a certified detour).
        min_distance: Smallest ‖(δp, ℓ_c δθ)‖ between start and target [m].

    Returns:
        (starts (n, m), targets (n, m), waypoints (n, m): the detour's waypoint, or the target), or None.
    """
    c = read_only(c)
    o_start, o_target, o_waypoint = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    parallel = streams.shape[0] > 1 and n >= PARALLEL_MIN_SAMPLES
    kernel = _sample_reach_parallel if parallel else _sample_reach
    if kernel(c, streams, hard, min_distance, o_start, o_target, o_waypoint) >= 0:
        return None
    return o_start, o_target, o_waypoint


@jit
def _sample_track(c, streams, max_amplitude, n_check, o_center, o_amplitude, o_phase):
    """Fill references (centre, amplitude, phase) whose poses at ``n_check`` times of a period are all safe.

    Sinusoids: a_j uniform in [½, 1] of ``max_amplitude`` and θ_j uniform. A path: a = ``max_amplitude``, θ_0 = 0
    (the start at the first vertex) and the heading θ_1 = ψ uniform in [0, 2π) (see ``_reference_at``).
    """
    m = int(c[C_N])
    safe = c[C_SAFE]
    box = np.bool_(True)  # a bool, not the constant True (see ``_sample_reach_one``)
    path = c[C_PATH] != 0.0
    shared = streams.shape[0] == 1
    w = _work()
    strokes, point, previous, rate = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    for i in range(o_center.shape[0]):
        s = 0 if shared else i
        fn, st = streams[s, 0], streams[s, 1]
        done = False
        for _ in range(SAMPLER_TRIES):
            if not _draw_safe(c, fn, st, w, strokes, o_center[i]):
                return i
            for j in range(m):
                if path:
                    o_amplitude[i, j] = max_amplitude[j]
                    o_phase[i, j] = 0.0
                else:
                    o_amplitude[i, j] = max_amplitude[j] * (0.5 + 0.5 * _next_double(fn, st))
                    o_phase[i, j] = _TWO_PI * _next_double(fn, st)
            if path:
                o_phase[i, 1] = _TWO_PI * _next_double(fn, st)
            ok = True
            for step in range(n_check + 1):
                _reference_at(c, _TWO_PI * step / n_check, o_center, o_amplitude, o_phase, i, point, rate)
                if step > 0 and _segment_min_k(c, previous, point, w, strokes, safe, c[C_SPACING], box) < safe:
                    ok = False
                    break
                for j in range(m):
                    previous[j] = point[j]
            if ok:
                done = True
                break
        if not done:
            return i
    return -1


def sample_track_batch(c, streams, n, m, max_amplitude, n_check):
    """Draw n references whose whole period stays in the safe set (checked between ``n_check`` points), or None."""
    o_center, o_amplitude, o_phase = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    c = read_only(c)
    if (
        _sample_track(c, streams, np.asarray(max_amplitude, dtype=np.float64), n_check, o_center, o_amplitude, o_phase)
        >= 0
    ):
        return None
    return o_center, o_amplitude, o_phase


@jit
def safe_batch(c, x):
    """Whether each pose (N, m) is in the safe set (sampling box, strokes with margin, k ≥ safe_threshold)."""
    out = np.empty(x.shape[0], dtype=np.bool_)
    w = _work()
    strokes = np.empty(6)
    for i in range(x.shape[0]):
        out[i] = _safe(c, x[i], w, strokes)
    return out


@jit
def _segment_loop(c, start, target, spacing, box, out):
    w = _work()
    strokes = np.empty(6)
    for i in range(start.shape[0]):
        out[i] = _segment_min_k(c, start[i], target[i], w, strokes, -np.inf, spacing, box)
    return out


def segment_batch(c, start, target):
    """Smallest safety along each geodesic start → target as the samplers check it, shape (N,).

    Points ``segment_spacing`` apart; −1 if one leaves the sampling box or the stroke limits less the margin.
    """
    out = np.empty(start.shape[0])
    _segment_loop(c, start, target, c[C_SPACING], True, out)
    return out


@jit
def _safety_loop(c, x, o_safety, o_sign):
    w = _work()
    strokes = np.empty(6)
    m = int(c[C_N])
    for i in range(x.shape[0]):
        o_safety[i] = _pose_safety(c, x[i], w, strokes)
        det = _solve(w, m, W_A, w[W_RHS], w[W_SOL])
        o_sign[i] = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)


def safety_batch(c, x):
    """The certificate at N poses (N, m), ignoring the sampling box: (safety, sign(det J_x)), each shape (N,).

    Safety is ``_pose_safety``: k (with cranks and sliders min(k, k_I · k_safe / k_I,safe)), or −1 where an
    actuator leaves its limits less the margin; a pose is safe when it is ≥ safe_threshold. The sign is 0 where
    the inverse kinematics has no solution.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    o_safety, o_sign = np.empty(x.shape[0]), np.empty(x.shape[0])
    _safety_loop(c, x, o_safety, o_sign)
    return o_safety, o_sign


def segment_min_safety_batch(c, start, target, spacing):
    """Smallest safety (``safety_batch``) along each geodesic start → target, ignoring the sampling box, shape (M,).

    Args:
        c: Packed constants (``pack_family`` or ``pack_certificate``).
        start: Poses, shape (M, m).
        target: Poses, shape (M, m).
        spacing: Largest gap between checked points (ends included) in ‖(δp, ℓ_c δθ)‖ [m].

    Returns:
        The smallest safety at the checked points of each segment; −1 where one leaves the stroke limits less
        the margin.
    """
    start = np.ascontiguousarray(start, dtype=np.float64)
    target = np.ascontiguousarray(target, dtype=np.float64)
    out = np.empty(start.shape[0])
    _segment_loop(c, start, target, float(spacing), False, out)
    return out
