"""Compiled (Numba) kernels of the 3-RPR environments: their step, reward, observation and tasks.

Every function here works on one robot at a time, on scalars, so a batch is a loop that Numba compiles
to machine code (and, for large batches, spreads over the cores). ``envs.core`` wraps them in the pure,
batched functions that the single environment (N = 1), the native vector environment, the shield, the
controllers' harness and the tests call; nothing else computes the dynamics.

The dynamics are the family core's: the step (integration through J_f, the correction onto Φ = 0, the
singularity measure and the termination reasons) and the constraint math the tasks use (leg vectors, rows of
J_x, k) come from ``envs.family_planar``, the planar pose space of the distance-constraint family, which every
planar robot of the family steps through (``envs.family_kernels``). What is the 3-RPR environments' own is
here: the reward and the observation of their layout, the circle of Track, and the tasks drawn from the
certified grid (``envs.workspace``). ``kinematics.Planar3RPR`` (NumPy, checked against SymPy and finite
differences) is the reference these kernels are tested against.

The constants of an environment travel as one float64 vector (``pack_params``), indexed by the ``C_*``
offsets below; from ``C_FAMILY`` on it holds the family's packed constants of the same robot and settings
(``envs.family_layout``), which the family's functions read.
"""

from __future__ import annotations

import ctypes
import math
import os

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from envs import family_layout as fl
from envs import family_planar as fp
from envs import linalg_kernels
from envs.numba_cache import drop_stale_caches

drop_stale_caches(__file__, [fl.__file__, fp.__file__, linalg_kernels.__file__])


def _load_tbb() -> bool:
    """Make Intel TBB (the ``tbb`` wheel) loadable by Numba; True if Numba's TBB threading layer then imports.

    The wheel puts ``libtbb.so.12`` in the environment's ``lib`` folder, which is not on the dynamic
    loader's path of a virtual environment, so Numba's ``tbbpool`` extension cannot find it by itself.
    Loading the library first, by the path the wheel records, lets the loader resolve it by its soname.
    """
    import importlib.metadata

    names = ("libtbb.so.12", "libtbb.12.dylib", "tbb12.dll")
    try:
        files = importlib.metadata.files("tbb") or []
        paths = [f.locate() for f in files if f.name in names]
        for path in paths:
            ctypes.CDLL(os.fspath(path), mode=ctypes.RTLD_GLOBAL)
        from numba.np.ufunc import parallel

        check = getattr(parallel, "_check_tbb_version_compatible", None)  # private: absent in some versions
        if check is not None:
            check()  # TBB 2021.6 or newer, as Numba requires (raises ImportError otherwise)
        from numba.np.ufunc import tbbpool  # noqa: F401  (the import is the check)
    except (importlib.metadata.PackageNotFoundError, OSError, ImportError):
        return False
    return True


#: Numba's threading layer for the parallel step: Intel TBB where the ``tbb`` wheel is installed (a
#: dependency on x86-64), else the work-queue layer. The calling thread takes part in a TBB loop and idle
#: workers steal work, so a parallel step uses both cores however the OS placed the threads; the
#: work-queue layer hands each worker a fixed share, and on an idle machine the OS often wakes both
#: workers on one core (measured: the 16384-robot step took 7.0 ms after other work in the same process,
#: as long as on one thread, against 3.7 ms with TBB). OpenMP is not used: its barriers spin, and with
#: one core busy a step ran 14× slower. TBB is also what Numba calls its "safe" layer (thread- and
#: fork-safe; the work-queue layer aborts if two threads run parallel code at once). A user's
#: ``NUMBA_THREADING_LAYER`` still wins.
THREADING_LAYER = os.environ.get("NUMBA_THREADING_LAYER") or ("tbb" if _load_tbb() else "workqueue")
numba.config.THREADING_LAYER = THREADING_LAYER

__all__ = [
    "C_SIZE",
    "errors_batch",
    "evaluate_batch",
    "observation_batch",
    "pack_params",
    "random_streams",
    "reference_batch",
    "singularity_batch",
    "substep_batch",
    "success_batch",
    "terms_batch",
    "transition_batch",
    "uniform_batch",
]

# Offsets into the packed constants vector.
C_B = 0  # base anchors B_i (x, y) [m], 6 entries
C_P = 6  # platform points P_i (x, y) in {P} [m], 6 entries
C_LC = 12  # characteristic length ℓ_c [m]
C_LMIN = 13
C_LMAX = 14
C_DT = 15
C_RATE = 16
C_RK4 = 17  # 1.0 for RK4, 0.0 for Euler
C_LOW = 18  # pose_low, 3 entries
C_HIGH = 21  # pose_high, 3 entries
C_SAFE = 24
C_HARD = 25
C_WP = 26
C_WO = 27
C_WS = 28
C_WA = 29
C_PENALTY = 30
C_SUCC_P = 31
C_SUCC_O = 32
C_NEWTON_TOL = 33
C_NEWTON_IT = 34
C_JUMP = 35
C_MAX_SUBSTEP = 36
C_MAX_SUBSTEPS = 37
C_PERIOD = 38
C_SCALE = 39  # pose_scale of the homogeneous Jacobian, 3 entries
C_FAMILY = 42  # the family's packed constants of the same robot and settings (envs.family_layout), fl.C_SIZE entries
C_SIZE = C_FAMILY + fl.C_SIZE

# Termination reason codes (same order as ``core.TERMINATION_REASONS``).
_NEWTON_FAILED, _ASSEMBLY_MODE_CHANGE, _SINGULARITY_CROSSED, _SINGULAR, _OUT_OF_BOUNDS = 1, 2, 3, 4, 5

#: ``step_batch`` (the environments' hot path) runs batches at least this large on every core
#: (``numba.prange``); smaller ones stay on one thread, where waking the thread pool would cost more than
#: it saves. Measured on two cores (Reach, random actions): with TBB, N = 64 runs 1.26× faster on both
#: cores and N = 32 only 1.07×; the work-queue layer pays off later.
PARALLEL_MIN_BATCH = 64 if THREADING_LAYER == "tbb" else 512

_TWO_PI = 2.0 * math.pi


def _jit(fn):
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


def _jit_inline(fn):
    # Inlined into its callers at Numba's IR level: per-robot helpers take many array arguments,
    # which an out-of-line call would pass field by field.
    return numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(fn)


def _jit_parallel(fn):
    return numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)(fn)


def pack_params(params) -> np.ndarray:
    """The constants of ``params`` (an ``envs.core.EnvParams``) as the kernels' float64 vector, shape (C_SIZE,).

    Args:
        params: Environment constants.

    Returns:
        Read-only float64 vector indexed by the ``C_*`` offsets.
    """
    robot = params.robot
    c = np.zeros(C_SIZE)
    c[C_B : C_B + 6] = np.asarray(robot.base, dtype=np.float64).ravel()
    c[C_P : C_P + 6] = np.asarray(robot.platform, dtype=np.float64).ravel()
    c[C_LC] = robot.characteristic_length
    c[C_LMIN], c[C_LMAX] = params.stroke_limits
    c[C_DT], c[C_RATE] = params.dt, params.max_rate
    c[C_RK4] = 1.0 if params.integrator == "rk4" else 0.0
    c[C_LOW : C_LOW + 3] = params.pose_low
    c[C_HIGH : C_HIGH + 3] = params.pose_high
    c[C_SAFE], c[C_HARD] = params.safe_threshold, params.hard_threshold
    c[C_WP], c[C_WO] = params.position_weight, params.orientation_weight
    c[C_WS], c[C_WA] = params.singularity_weight, params.action_weight
    c[C_PENALTY] = params.termination_penalty
    c[C_SUCC_P], c[C_SUCC_O] = params.success_position_tolerance, params.success_orientation_tolerance
    c[C_NEWTON_TOL], c[C_NEWTON_IT] = params.newton_tolerance, params.newton_max_iterations
    c[C_JUMP], c[C_MAX_SUBSTEP], c[C_MAX_SUBSTEPS] = params.jump_tolerance, params.max_substep, params.max_substeps
    c[C_PERIOD] = params.track_period
    c[C_SCALE : C_SCALE + 3] = robot.pose_scale
    _pack_family_copy(c, robot)
    c.setflags(write=False)
    return c


def _pack_family_copy(c: np.ndarray, robot) -> None:
    """Write the family's packed constants of the same robot and settings into c[C_FAMILY:] (the step reads them)."""
    f = c[C_FAMILY:]
    f[fl.C_N], f[fl.C_SPATIAL] = 3.0, 0.0
    f[fl.C_LEGS] = 1.0
    f[fl.C_LAM : fl.C_LAM + 3] = 1.0
    f[fl.C_B : fl.C_B + 9] = np.pad(np.asarray(robot.base, dtype=np.float64), ((0, 0), (0, 1))).ravel()
    f[fl.C_P : fl.C_P + 9] = np.pad(np.asarray(robot.platform, dtype=np.float64), ((0, 0), (0, 1))).ravel()
    f[fl.C_SCALE : fl.C_SCALE + 3] = c[C_SCALE : C_SCALE + 3]
    f[fl.C_LOW : fl.C_LOW + 3] = c[C_LOW : C_LOW + 3]
    f[fl.C_HIGH : fl.C_HIGH + 3] = c[C_HIGH : C_HIGH + 3]
    for mine, family in (
        (C_LC, fl.C_LC),
        (C_LMIN, fl.C_LMIN),
        (C_LMAX, fl.C_LMAX),
        (C_DT, fl.C_DT),
        (C_RATE, fl.C_RATE),
        (C_RK4, fl.C_RK4),
        (C_SAFE, fl.C_SAFE),
        (C_HARD, fl.C_HARD),
        (C_WP, fl.C_WP),
        (C_WO, fl.C_WO),
        (C_WS, fl.C_WS),
        (C_WA, fl.C_WA),
        (C_PENALTY, fl.C_PENALTY),
        (C_SUCC_P, fl.C_SUCC_P),
        (C_SUCC_O, fl.C_SUCC_O),
        (C_NEWTON_TOL, fl.C_NEWTON_TOL),
        (C_NEWTON_IT, fl.C_NEWTON_IT),
        (C_JUMP, fl.C_JUMP),
        (C_MAX_SUBSTEP, fl.C_MAX_SUBSTEP),
        (C_MAX_SUBSTEPS, fl.C_MAX_SUBSTEPS),
    ):
        f[family] = c[mine]
    f[fl.C_OMEGA] = 2.0 * math.pi / c[C_PERIOD]


# -- random streams: the generators' own bit generators, called from compiled code ----------------------


@intrinsic
def _next_double(typingctx, fn, state):
    """``fn(state)``: a bit generator's ``next_double`` at address fn on its state at address ``state``.

    This is what ``Generator.random()`` computes (a uniform double in [0, 1)), called through the
    bit generator's documented ctypes interface (NumPy's "extending with Numba" example), so a
    generator's stream is the same whether NumPy or a kernel draws from it.
    """
    sig = types.float64(fn, state)

    def codegen(context, builder, signature, args):
        pointer = ir.IntType(8).as_pointer()
        function = builder.inttoptr(args[0], ir.FunctionType(ir.DoubleType(), [pointer]).as_pointer())
        return builder.call(function, [builder.inttoptr(args[1], pointer)])

    return sig, codegen


def random_streams(generators) -> np.ndarray:
    """The kernels' handle on NumPy generators: (address of ``next_double``, address of the state) of each.

    Kernels given these draw exactly the numbers ``Generator.random()`` would, and advance the
    generators' states. The generators must stay alive while a kernel uses the addresses (the caller
    holds them); like Numba's own generator support, the kernels do not take the bit generators' locks.

    Args:
        generators: A sequence of ``np.random.Generator``.

    Returns:
        uint64 array of shape (len(generators), 2).

    Raises:
        TypeError: If an element is not a ``np.random.Generator``.
    """
    out = np.empty((len(generators), 2), dtype=np.uint64)
    for i, generator in enumerate(generators):
        if not isinstance(generator, np.random.Generator):
            raise TypeError(f"expected a numpy.random.Generator, got {type(generator).__name__} {generator!r}")
        bit_generator = generator.bit_generator
        interface = bit_generator.ctypes
        function = _NEXT_DOUBLE.get(type(bit_generator))
        if function is None:
            function = ctypes.cast(interface.next_double, ctypes.c_void_p).value
        out[i, 0] = function
        out[i, 1] = interface.state_address
    return out


#: ``next_double`` addresses of NumPy's bit generators: one C function per class, looked up once.
_NEXT_DOUBLE = {
    kind: ctypes.cast(kind().ctypes.next_double, ctypes.c_void_p).value
    for kind in (np.random.PCG64, np.random.PCG64DXSM, np.random.MT19937, np.random.Philox, np.random.SFC64)
}


@_jit
def _uniform_loop(streams, out):
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = _next_double(streams[i, 0], streams[i, 1])


def uniform_batch(streams, m):
    """Uniform draws in [0, 1), m from each stream, shape (S, m) (the kernels' ``Generator.random(m)``).

    Args:
        streams: ``random_streams(generators)``, shape (S, 2).
        m: Draws per stream.

    Returns:
        float64 array of shape (S, m).
    """
    out = np.empty((streams.shape[0], m))
    _uniform_loop(streams, out)
    return out


# -- the step: the family core's planar path (envs.family_planar), on the family's copy of the constants --


@_jit
def _transition_serial(c, q, x, det_sign, residual, action, o_q, o_x, o_k, o_res, o_a, o_qr, o_reason, o_jump):
    for i in range(q.shape[0]):
        fp.transition_row(
            c[C_FAMILY:], q, x, det_sign, residual, action, i, o_q, o_x, o_k, o_res, o_a, o_qr, o_reason, o_jump
        )


def transition_batch(c, q, x, det_sign, residual, action):
    """Advance N robots by one control period (the algorithm of ``core.transition``).

    Args:
        c: Packed constants (``pack_params``), shape (C_SIZE,).
        q: Strokes [m], shape (N, 3), float64.
        x: Poses (x [m], y [m], φ [rad]), shape (N, 3), float64.
        det_sign: Working mode sign(det J_x) of each episode, shape (N,).
        residual: Constraint residual at (q, x) [m²], shape (N,).
        action: Normalised stroke rates, shape (N, 3), finite.

    Returns:
        (q', x', k', residual', applied action, achieved stroke rates [m/s], reason codes, jumps [m]).
    """
    n = q.shape[0]
    o_q, o_x, o_a, o_qr = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    o_k, o_res, o_jump = np.empty(n), np.empty(n), np.empty(n)
    o_reason = np.empty(n, dtype=np.int64)
    _transition_serial(c, q, x, det_sign, residual, action, o_q, o_x, o_k, o_res, o_a, o_qr, o_reason, o_jump)
    return o_q, o_x, o_k, o_res, o_a, o_qr, o_reason, o_jump


@_jit
def _singularity_loop(c, q, x, o_k, o_sign):
    for i in range(q.shape[0]):
        o_k[i], o_sign[i] = fp.singularity(c[C_FAMILY:], q[i, 0], q[i, 1], q[i, 2], x[i, 0], x[i, 1], x[i, 2])


def singularity_batch(c, q, x):
    """Inverse condition number and sign(det J_x) of N configurations, each shape (N,).

    Args:
        c: Packed constants.
        q: Strokes [m], shape (N, 3), float64.
        x: Poses, shape (N, 3), float64.

    Returns:
        (k (N,) in [0, 1], sign (N,) in {−1, 0, 1}).
    """
    o_k, o_sign = np.empty(q.shape[0]), np.empty(q.shape[0])
    _singularity_loop(c, q, x, o_k, o_sign)
    return o_k, o_sign


@_jit
def _substep_loop(c, q, x, q_rate, o_count):
    for i in range(q.shape[0]):
        v0, v1, v2 = fp.pose_rate(
            c[C_FAMILY:], q[i, 0], q[i, 1], q[i, 2], x[i, 0], x[i, 1], x[i, 2], q_rate[i, 0], q_rate[i, 1], q_rate[i, 2]
        )
        o_count[i] = fp.substeps(c[C_FAMILY:], v0, v1, v2)


@_jit
def _substep_loop_rate(c, rate, o_count):
    for i in range(rate.shape[0]):
        o_count[i] = fp.substeps(c[C_FAMILY:], rate[i, 0], rate[i, 1], rate[i, 2])


def substep_batch(c, q, x, q_rate, rate=None):
    """Substeps per robot (see ``core.substep_counts``), int64 shape (N,).

    Args:
        c: Packed constants.
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).
        q_rate: Achieved stroke rates [m/s], shape (N, 3).
        rate: ẋ = J_f q̇ if already known, shape (N, 3).

    Returns:
        Counts in [1, max_substeps], shape (N,).
    """
    o_count = np.empty(q.shape[0], dtype=np.int64)
    if rate is None:
        _substep_loop(c, q, x, q_rate, o_count)
    else:
        _substep_loop_rate(c, rate, o_count)
    return o_count


# -- targets, reward, observation ---------------------------------------------------------------------


@_jit_inline
def _reference_row(c, t, center, radius, phase, amplitude, i):
    """Target pose and velocity of robot i at step t[i]: 6 scalars."""
    omega = _TWO_PI / c[C_PERIOD]
    wt = omega * t[i] * c[C_DT]
    r, a = radius[i], amplitude[i]
    p0, p1, p2 = center[i, 0], center[i, 1], center[i, 2]
    v0 = v1 = v2 = 0.0
    if r != 0.0:  # a fixed target (Reach) has r = a = 0: no trigonometry
        angle = wt + phase[i]
        ca, sa = math.cos(angle), math.sin(angle)
        p0, p1 = p0 + r * ca, p1 + r * sa
        v0, v1 = omega * (-r * sa), omega * (r * ca)
    if a != 0.0:
        p2 = p2 + a * math.sin(wt)
        v2 = omega * (a * math.cos(wt))
    return p0, p1, p2, v0, v1, v2


@_jit
def _reference_loop(c, t, center, radius, phase, amplitude, o_pose, o_velocity):
    for i in range(t.shape[0]):
        p0, p1, p2, v0, v1, v2 = _reference_row(c, t, center, radius, phase, amplitude, i)
        o_pose[i, 0], o_pose[i, 1], o_pose[i, 2] = p0, p1, p2
        o_velocity[i, 0], o_velocity[i, 1], o_velocity[i, 2] = v0, v1, v2


def reference_batch(c, t, center, radius, phase, amplitude):
    """Target poses and velocities at steps t, each shape (N, 3) (see ``core.reference_pose``).

    Args:
        c: Packed constants.
        t: Step index, shape (N,) (int).
        center: c = (c_x, c_y, c_φ), shape (N, 3).
        radius: r [m], shape (N,).
        phase: θ [rad], shape (N,).
        amplitude: a [rad], shape (N,).

    Returns:
        (pose (N, 3), velocity (N, 3)).
    """
    n = t.shape[0]
    o_pose, o_velocity = np.empty((n, 3)), np.empty((n, 3))
    _reference_loop(c, t, center, radius, phase, amplitude, o_pose, o_velocity)
    return o_pose, o_velocity


#: Rows of the evaluation written by ``evaluate_batch`` (one column per robot, so that each quantity
#: of the N robots is contiguous).
E_TRACKING, E_SINGULARITY, E_ACTION, E_TERMINATION = 0, 1, 2, 3
E_POSITION_ERROR, E_ORIENTATION_ERROR, E_SUCCESS, E_COST, E_REWARD = 4, 5, 6, 7, 8
E_TARGET = 9  # target pose, 3 rows
E_VELOCITY = 12  # target velocity, 3 rows
E_K, E_RESIDUAL = 15, 16  # inverse condition number, constraint residual [m²]
E_POSE = 17  # pose (x, y, φ), 3 rows
E_SIZE = 20


@_jit
def _errors_loop(x, target, o_position, o_orientation):
    for i in range(x.shape[0]):
        o_position[i], o_orientation[i] = fp.errors(x[i, 0], x[i, 1], x[i, 2], target[i, 0], target[i, 1], target[i, 2])


def errors_batch(x, target):
    """Position error ‖p* − p‖ [m] and orientation error |wrap(φ* − φ)| [rad] of N poses, each (N,).

    Args:
        x: Poses, shape (N, 3).
        target: Target poses, shape (N, 3).

    Returns:
        (position errors (N,), orientation errors (N,)).
    """
    o_position, o_orientation = np.empty(x.shape[0]), np.empty(x.shape[0])
    _errors_loop(x, target, o_position, o_orientation)
    return o_position, o_orientation


@_jit
def _success_loop(c, position_error, orientation_error, o_success):
    for i in range(position_error.shape[0]):
        o_success[i] = fp.is_success(c[C_FAMILY:], position_error[i], orientation_error[i])


def success_batch(c, position_error, orientation_error):
    """Whether each robot is within the success tolerances, bool shape (N,).

    Args:
        c: Packed constants.
        position_error: Position errors [m], shape (N,).
        orientation_error: Orientation errors [rad], shape (N,).

    Returns:
        Booleans, shape (N,).
    """
    o_success = np.empty(position_error.shape[0], dtype=np.bool_)
    _success_loop(c, position_error, orientation_error, o_success)
    return o_success


@_jit
def _terms_loop(c, x, target, k, action, reason, o_terms):
    for i in range(x.shape[0]):
        tr, si, ac, te, _, _ = fp.reward_terms(
            c[C_FAMILY:],
            x[i, 0],
            x[i, 1],
            x[i, 2],
            target[i, 0],
            target[i, 1],
            target[i, 2],
            k[i],
            action[i, 0],
            action[i, 1],
            action[i, 2],
            reason[i],
        )
        o_terms[i, 0], o_terms[i, 1], o_terms[i, 2], o_terms[i, 3] = tr, si, ac, te


def terms_batch(c, x, target, k, action, reason):
    """Reward terms (tracking, singularity, action, termination), shape (N, 4) (see ``core.reward_terms``).

    Args:
        c: Packed constants.
        x: Poses, shape (N, 3).
        target: Target poses, shape (N, 3).
        k: Inverse condition numbers, shape (N,).
        action: Applied actions, shape (N, 3).
        reason: Termination reason codes, shape (N,) (int).

    Returns:
        Terms, shape (N, 4).
    """
    o_terms = np.empty((x.shape[0], 4))
    _terms_loop(c, x, target, k, action, reason, o_terms)
    return o_terms


@_jit
def _observation_loop(c, low, high, with_velocity, q, x, k, target, velocity, o_obs):
    for i in range(x.shape[0]):
        fp.observation_row(
            c[C_FAMILY:],
            low,
            high,
            with_velocity,
            q,
            x,
            k,
            target[i, 0],
            target[i, 1],
            target[i, 2],
            velocity[i, 0],
            velocity[i, 1],
            velocity[i, 2],
            i,
            o_obs,
        )


def observation_batch(c, low, high, with_velocity, q, x, k, target, velocity):
    """Observations of N robots, float32 (see ``core.observation``).

    Args:
        c: Packed constants.
        low: Observation lower bounds, float32 (18,) or (21,).
        high: Observation upper bounds, same shape.
        with_velocity: Whether the target velocity is appended.
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).
        k: Inverse condition numbers, shape (N,).
        target: Target poses, shape (N, 3).
        velocity: Target velocities, shape (N, 3).

    Returns:
        Observations, shape (N, 18) or (N, 21), float32.
    """
    o_obs = np.empty((x.shape[0], low.shape[0]), dtype=np.float32)
    _observation_loop(c, low, high, with_velocity, q, x, k, target, velocity, o_obs)
    return o_obs


@_jit_inline
def _evaluate_row(
    c,
    low,
    high,
    with_velocity,
    q,
    x,
    t,
    k,
    residual,
    center,
    radius,
    phase,
    amplitude,
    action,
    reason,
    i,
    o_eval,
    o_obs,
):
    p0, p1, p2, w0, w1, w2 = _reference_row(c, t, center, radius, phase, amplitude, i)
    tr, si, ac, te, ep, eo = fp.reward_terms(
        c[C_FAMILY:], x[i, 0], x[i, 1], x[i, 2], p0, p1, p2, k[i], action[i, 0], action[i, 1], action[i, 2], reason[i]
    )
    e = o_eval
    e[E_TRACKING, i], e[E_SINGULARITY, i], e[E_ACTION, i], e[E_TERMINATION, i] = tr, si, ac, te
    e[E_REWARD, i] = tr + si + ac + te
    e[E_POSITION_ERROR, i], e[E_ORIENTATION_ERROR, i] = ep, eo
    ok = reason[i] == 0 and fp.is_success(c[C_FAMILY:], ep, eo)
    e[E_SUCCESS, i] = 1.0 if ok else 0.0
    e[E_COST, i] = 1.0 if k[i] < c[C_SAFE] else 0.0
    e[E_TARGET, i], e[E_TARGET + 1, i], e[E_TARGET + 2, i] = p0, p1, p2
    e[E_VELOCITY, i], e[E_VELOCITY + 1, i], e[E_VELOCITY + 2, i] = w0, w1, w2
    e[E_K, i], e[E_RESIDUAL, i] = k[i], residual[i]
    e[E_POSE, i], e[E_POSE + 1, i], e[E_POSE + 2, i] = x[i, 0], x[i, 1], x[i, 2]
    fp.observation_row(c[C_FAMILY:], low, high, with_velocity, q, x, k, p0, p1, p2, w0, w1, w2, i, o_obs)


@_jit
def _evaluate_serial(
    c, low, high, with_velocity, q, x, t, k, residual, center, radius, phase, amplitude, action, reason, o_eval, o_obs
):
    for i in range(x.shape[0]):
        _evaluate_row(
            c,
            low,
            high,
            with_velocity,
            q,
            x,
            t,
            k,
            residual,
            center,
            radius,
            phase,
            amplitude,
            action,
            reason,
            i,
            o_eval,
            o_obs,
        )


def evaluate_batch(c, low, high, with_velocity, q, x, t, k, residual, center, radius, phase, amplitude, action, reason):
    """Everything an environment reports after a transition, for N robots, in one pass.

    Args:
        c: Packed constants.
        low: Observation lower bounds, float32 (D,).
        high: Observation upper bounds, float32 (D,).
        with_velocity: Whether the observation ends with the target velocity (D = 21, else 18).
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).
        t: Steps taken, shape (N,) (int).
        k: Inverse condition numbers, shape (N,).
        residual: Constraint residuals [m²], shape (N,).
        center: Reference centres, shape (N, 3).
        radius: Reference radii [m], shape (N,).
        phase: Reference phases [rad], shape (N,).
        amplitude: Reference orientation amplitudes [rad], shape (N,).
        action: Applied actions, shape (N, 3).
        reason: Termination reason codes, shape (N,) (int).

    Returns:
        (evaluation (E_SIZE, N) float64 with the ``E_*`` rows, observations (N, D) float32).
    """
    n = x.shape[0]
    o_eval = np.empty((E_SIZE, n))
    o_obs = np.empty((n, low.shape[0]), dtype=np.float32)
    _evaluate_serial(
        c,
        low,
        high,
        with_velocity,
        q,
        x,
        t,
        k,
        residual,
        center,
        radius,
        phase,
        amplitude,
        action,
        reason,
        o_eval,
        o_obs,
    )
    return o_eval, o_obs


# -- a whole environment step -------------------------------------------------------------------------


@_jit_inline
def _step_row(
    c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action, i,
    o_q, o_x, o_t, o_k, o_res, o_a, o_qr, o_reason, o_jump, o_eval, o_obs,
):  # fmt: skip
    fp.transition_row(
        c[C_FAMILY:], q, x, det_sign, residual, action, i, o_q, o_x, o_k, o_res, o_a, o_qr, o_reason, o_jump
    )
    o_t[i] = t[i] + 1
    _evaluate_row(
        c,
        low,
        high,
        with_velocity,
        o_q,
        o_x,
        o_t,
        o_k,
        o_res,
        center,
        radius,
        phase,
        amplitude,
        o_a,
        o_reason,
        i,
        o_eval,
        o_obs,
    )


@_jit
def _step_serial(
    c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action,
    o_q, o_x, o_t, o_k, o_res, o_a, o_qr, o_reason, o_jump, o_eval, o_obs,
):  # fmt: skip
    bad = 0
    for i in range(q.shape[0]):
        if not math.isfinite(action[i, 0] + action[i, 1] + action[i, 2]):  # ±inf and NaN alike
            bad += 1
        _step_row(
            c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action, i,
            o_q, o_x, o_t, o_k, o_res, o_a, o_qr, o_reason, o_jump, o_eval, o_obs,
        )  # fmt: skip
    return bad


@_jit_parallel
def _step_parallel(
    c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action,
    o_q, o_x, o_t, o_k, o_res, o_a, o_qr, o_reason, o_jump, o_eval, o_obs,
):  # fmt: skip
    bad = 0
    for i in numba.prange(q.shape[0]):
        if not math.isfinite(action[i, 0] + action[i, 1] + action[i, 2]):  # ±inf and NaN alike
            bad += 1
        _step_row(
            c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action, i,
            o_q, o_x, o_t, o_k, o_res, o_a, o_qr, o_reason, o_jump, o_eval, o_obs,
        )  # fmt: skip
    return bad


def allocate_step(n, obs_dim):
    """Output arrays of ``step_batch`` for n robots and observations of obs_dim entries.

    Args:
        n: Number of robots.
        obs_dim: Observation size (18 or 21).

    Returns:
        (q', x', t', k', residual', applied action, stroke rates, reasons, jumps, evaluation, observations).
    """
    return (
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty(n, dtype=np.int64),
        np.empty(n),
        np.empty(n),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty(n, dtype=np.int64),
        np.empty(n),
        np.empty((E_SIZE, n)),
        np.empty((n, obs_dim), dtype=np.float32),
    )


def step_batch(c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action, out):
    """Transition N robots, then evaluate them (``transition_batch`` followed by ``evaluate_batch``), in one pass.

    Args:
        c: Packed constants.
        low: Observation lower bounds, float32 (D,).
        high: Observation upper bounds, float32 (D,).
        with_velocity: Whether the observation ends with the target velocity.
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).
        t: Steps taken, shape (N,) (int).
        det_sign: Working mode sign(det J_x), shape (N,).
        residual: Constraint residuals [m²], shape (N,).
        center: Reference centres, shape (N, 3).
        radius: Reference radii [m], shape (N,).
        phase: Reference phases [rad], shape (N,).
        amplitude: Reference orientation amplitudes [rad], shape (N,).
        action: Normalised stroke rates, shape (N, 3).
        out: The output arrays (``allocate_step``), none of them an input.

    Returns:
        The number of robots whose action is not finite (their outputs are meaningless, never a crash).
    """
    kernel = _step_parallel if q.shape[0] >= PARALLEL_MIN_BATCH else _step_serial
    return kernel(
        c, low, high, with_velocity, q, x, t, det_sign, residual, center, radius, phase, amplitude, action, *out
    )


# -- task sampling ------------------------------------------------------------------------------------

# Offsets into the packed workspace constants (``pack_workspace``).
W_LMIN, W_LMAX, W_STROKE_MARGIN, W_SAFE = 0, 1, 2, 3
W_MARGIN = 4  # bounds margin (Δx, Δy, Δφ), 3 entries
W_LOW = 7  # pose bounds of the grid, 3 + 3 entries
W_HIGH = 10
W_CELL = 13  # grid spacing, 3 entries
W_SIZE = 16


def pack_workspace(workspace) -> tuple:
    """A certified ``envs.workspace.WorkspaceMap`` as the tuple of arrays the sampling kernels read.

    Args:
        workspace: The certified grid.

    Returns:
        (constants (W_SIZE,), labels (n_x, n_y, n_φ), sampled-label lookup (max label + 1,) bool,
        component ids (c,), cumulative sampling weights (c,), concatenated node indices of the sampled
        components, their offsets (c + 1,), axis x (n_x,), axis y (n_y,), axis φ (n_φ,)).
    """
    spec = workspace.spec
    w = np.zeros(W_SIZE)
    w[W_LMIN], w[W_LMAX] = spec.stroke_limits
    w[W_STROKE_MARGIN], w[W_SAFE] = spec.stroke_margin, spec.safe_threshold
    w[W_MARGIN : W_MARGIN + 3] = spec.bounds_margin
    w[W_LOW : W_LOW + 3] = spec.pose_low
    w[W_HIGH : W_HIGH + 3] = spec.pose_high
    w[W_CELL : W_CELL + 3] = spec.cell
    labels = np.ascontiguousarray(workspace.labels, dtype=np.int64)
    ids = np.asarray(workspace.component_ids, dtype=np.int64)
    sampled = np.zeros(int(labels.max()) + 1, dtype=np.bool_)
    sampled[ids] = True
    cumulative = np.cumsum(np.asarray(workspace.component_weights, dtype=np.float64))
    nodes = [np.asarray(workspace.component_nodes[int(i)], dtype=np.int64) for i in ids]
    offsets = np.concatenate([[0], np.cumsum([len(n) for n in nodes])]).astype(np.int64)
    axes = tuple(np.ascontiguousarray(a, dtype=np.float64) for a in workspace.axes)
    packed = (w, labels, sampled, ids, cumulative, np.concatenate(nodes), offsets, *axes)
    for array in packed:
        array.setflags(write=False)
    return packed


@_jit
def _node_index(values, v):
    """Index of the grid value nearest to v along one axis, clipped to the axis (as ``node_index``)."""
    i = np.rint((v - values[0]) / (values[1] - values[0]))
    if not i > 0.0:  # also NaN
        return 0
    last = values.shape[0] - 1
    if i > last:
        return last
    return int(i)


@_jit
def _label(ws, x0, x1, x2):
    """Component id of the grid node nearest to the pose (0: not in a safe region)."""
    return ws[1][_node_index(ws[7], x0), _node_index(ws[8], x1), _node_index(ws[9], x2)]


@_jit
def _safe(c, ws, x0, x1, x2):
    """``envs.tasks.is_safe`` for one pose: bounds and strokes with margins, k ≥ k_safe, in a sampled region."""
    w = ws[0]
    for j, v in enumerate((x0, x1, x2)):
        if not (w[W_LOW + j] + w[W_MARGIN + j] <= v <= w[W_HIGH + j] - w[W_MARGIN + j]):
            return False
    a = fp.rows(c[C_FAMILY:], x0, x1, x2)
    l0, l1, l2 = math.sqrt(a[9]), math.sqrt(a[10]), math.sqrt(a[11])
    if min(l0, min(l1, l2)) < w[W_LMIN] + w[W_STROKE_MARGIN] or max(l0, max(l1, l2)) > w[W_LMAX] - w[W_STROKE_MARGIN]:
        return False
    k, _ = fp.singularity_rows(c[C_FAMILY:], max(l0, 1e-9), max(l1, 1e-9), max(l2, 1e-9), a)
    if not k >= w[W_SAFE]:
        return False
    return ws[2][_label(ws, x0, x1, x2)]


@_jit
def _safe_loop(c, ws, x, out):
    for i in range(x.shape[0]):
        out[i] = _safe(c, ws, x[i, 0], x[i, 1], x[i, 2])


def safe_batch(c, ws, x):
    """Whether each pose is in a sampled safe region (see ``envs.tasks.is_safe``), bool (M,).

    Args:
        c: Packed constants.
        ws: Packed workspace (``pack_workspace``).
        x: Poses, shape (M, 3), finite.

    Returns:
        Booleans, shape (M,).
    """
    out = np.empty(x.shape[0], dtype=np.bool_)
    _safe_loop(c, ws, x, out)
    return out


@_jit
def _segment_min_k(c, s0, s1, s2, t0, t1, t2, n):
    """Smallest inverse condition number at n points of the straight line s → t in pose space (ends included)."""
    k_min = np.inf
    for j in range(n):
        f = j / (n - 1)
        p0, p1, p2 = s0 + f * (t0 - s0), s1 + f * (t1 - s1), s2 + f * (t2 - s2)
        a = fp.rows(c[C_FAMILY:], p0, p1, p2)
        l0, l1, l2 = max(math.sqrt(a[9]), 1e-9), max(math.sqrt(a[10]), 1e-9), max(math.sqrt(a[11]), 1e-9)
        k, _ = fp.singularity_rows(c[C_FAMILY:], l0, l1, l2, a)
        if k < k_min or k != k:
            k_min = k
    return k_min


@_jit
def _segment_loop(c, start, target, n, out):
    for i in range(start.shape[0]):
        out[i] = _segment_min_k(c, start[i, 0], start[i, 1], start[i, 2], target[i, 0], target[i, 1], target[i, 2], n)


def segment_batch(c, start, target, n):
    """Smallest inverse condition number along each straight segment (see ``envs.tasks.segment_min_condition``).

    Args:
        c: Packed constants.
        start: Poses, shape (M, 3).
        target: Poses, shape (M, 3).
        n: Points per segment (≥ 2), ends included.

    Returns:
        min k along each segment, shape (M,).
    """
    out = np.empty(start.shape[0])
    _segment_loop(c, start, target, n, out)
    return out


@_jit
def _pose_in_component(c, ws, fn, st, j, tries):
    """A safe pose in sampled component j: a random node of it jittered within its cell.

    Returns:
        (found, x0, x1, x2); found is False after ``tries`` rejected candidates.
    """
    w, labels, comp = ws[0], ws[1], ws[3][j]
    nodes, offsets = ws[5], ws[6]
    size = offsets[j + 1] - offsets[j]
    ny, nphi = labels.shape[1], labels.shape[2]
    for _ in range(tries):
        flat = nodes[offsets[j] + min(int(_next_double(fn, st) * size), size - 1)]
        ix, rest = divmod(flat, ny * nphi)
        iy, iphi = divmod(rest, nphi)
        x0 = ws[7][ix] + (_next_double(fn, st) - 0.5) * w[W_CELL]
        x1 = ws[8][iy] + (_next_double(fn, st) - 0.5) * w[W_CELL + 1]
        x2 = ws[9][iphi] + (_next_double(fn, st) - 0.5) * w[W_CELL + 2]
        if _safe(c, ws, x0, x1, x2) and _label(ws, x0, x1, x2) == comp:
            return True, x0, x1, x2
    return False, 0.0, 0.0, 0.0


@_jit
def _choose_component(ws, fn, st):
    """Index of a sampled component, drawn with probability proportional to its size."""
    cumulative = ws[4]
    u = _next_double(fn, st) * cumulative[-1]
    for j in range(cumulative.shape[0] - 1):
        if u < cumulative[j]:
            return j
    return cumulative.shape[0] - 1


@_jit
def _component_index(ws, x0, x1, x2):
    """Index (into the sampled components) of the region of a pose, −1 if it is in none."""
    label = _label(ws, x0, x1, x2)
    ids = ws[3]
    for j in range(ids.shape[0]):
        if ids[j] == label:
            return j
    return -1


#: Candidates a sampler may reject (per pose or pair) before it reports failure.
SAMPLER_TRIES = 6400


@_jit
def _sample_reach(c, ws, streams, hard, min_distance, fixed_kind, f0, f1, f2, segment_points, o_start, o_target):
    """Fill o_start / o_target (M, 3) with pairs in one region; fixed_kind 1 (2) keeps the start (target) f.

    Pair i draws from ``streams[i]`` (or from ``streams[0]`` for every pair when there is one stream).

    Returns:
        −1 on success, else the index of the first pair for which ``SAMPLER_TRIES`` candidates were rejected.
    """
    lc = c[C_LC]
    fixed_j = -1
    if fixed_kind != 0:
        fixed_j = _component_index(ws, f0, f1, f2)
        if fixed_j < 0:
            return 0
    shared = streams.shape[0] == 1
    for i in range(o_start.shape[0]):
        s = 0 if shared else i
        fn, st = streams[s, 0], streams[s, 1]
        done = False
        for _ in range(SAMPLER_TRIES):
            if fixed_kind == 0:
                j = _choose_component(ws, fn, st)
                ok, s0, s1, s2 = _pose_in_component(c, ws, fn, st, j, SAMPLER_TRIES)
                ok2, t0, t1, t2 = _pose_in_component(c, ws, fn, st, j, SAMPLER_TRIES)
                if not (ok and ok2):
                    return i
            else:
                ok, o0, o1, o2 = _pose_in_component(c, ws, fn, st, fixed_j, SAMPLER_TRIES)
                if not ok:
                    return i
                if fixed_kind == 1:
                    s0, s1, s2, t0, t1, t2 = f0, f1, f2, o0, o1, o2
                else:
                    s0, s1, s2, t0, t1, t2 = o0, o1, o2, f0, f1, f2
            d0, d1, d2 = t0 - s0, t1 - s1, lc * (t2 - s2)
            if not math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) >= min_distance:
                continue
            if hard and not _segment_min_k(c, s0, s1, s2, t0, t1, t2, segment_points) < c[C_HARD]:
                continue
            o_start[i, 0], o_start[i, 1], o_start[i, 2] = s0, s1, s2
            o_target[i, 0], o_target[i, 1], o_target[i, 2] = t0, t1, t2
            done = True
            break
        if not done:
            return i
    return -1


def sample_reach_batch(c, ws, streams, n, hard, min_distance, fixed_kind, fixed, segment_points):
    """Draw n start/target pairs (see ``envs.tasks.sample_reach``) from random streams.

    Args:
        c: Packed constants.
        ws: Packed workspace.
        streams: ``random_streams`` of one generator (every pair drawn from it, in turn) or of n
            generators (pair i drawn from generator i), shape (1, 2) or (n, 2).
        n: Number of pairs.
        hard: Whether the straight line must dip below the hard threshold.
        min_distance: Smallest ‖(Δx, Δy, ℓ_c Δφ)‖ between start and target [m].
        fixed_kind: 0 (none), 1 (``fixed`` is the start) or 2 (``fixed`` is the target).
        fixed: The fixed pose, shape (3,) (ignored when fixed_kind is 0).
        segment_points: Points checked along a hard pair's segment.

    Returns:
        (starts (n, 3), targets (n, 3)), or None if no pair was found for one of them.
    """
    o_start, o_target = np.empty((n, 3)), np.empty((n, 3))
    f0, f1, f2 = (float(v) for v in fixed)
    failed = _sample_reach(
        c, ws, streams, hard, min_distance, fixed_kind, f0, f1, f2, segment_points, o_start, o_target
    )
    if failed >= 0:
        return None
    return o_start, o_target


@_jit
def _sample_track(c, ws, streams, r_lo, r_hi, a_lo, a_hi, n_check, o_center, o_radius, o_phase, o_amplitude):
    """Fill the M references (centre, radius, phase, amplitude) whose every step pose is safe in one region.

    Reference i draws from ``streams[i]`` (or from ``streams[0]`` when there is one stream).

    Returns:
        −1 on success, else the index of the first reference that could not be drawn.
    """
    omega_dt = _TWO_PI / c[C_PERIOD] * c[C_DT]
    shared = streams.shape[0] == 1
    for i in range(o_radius.shape[0]):
        s = 0 if shared else i
        fn, st = streams[s, 0], streams[s, 1]
        done = False
        for _ in range(SAMPLER_TRIES):
            j = _choose_component(ws, fn, st)
            ok, c0, c1, c2 = _pose_in_component(c, ws, fn, st, j, SAMPLER_TRIES)
            if not ok:
                return i
            r = r_lo + _next_double(fn, st) * (r_hi - r_lo)
            th = -math.pi + _next_double(fn, st) * _TWO_PI
            a = a_lo + _next_double(fn, st) * (a_hi - a_lo)
            comp = ws[3][j]
            good = True
            for step in range(n_check):
                wt = omega_dt * step
                p0 = c0 + r * math.cos(wt + th)
                p1 = c1 + r * math.sin(wt + th)
                p2 = c2 + a * math.sin(wt)
                if not (_safe(c, ws, p0, p1, p2) and _label(ws, p0, p1, p2) == comp):
                    good = False
                    break
            if good:
                o_center[i, 0], o_center[i, 1], o_center[i, 2] = c0, c1, c2
                o_radius[i], o_phase[i], o_amplitude[i] = r, th, a
                done = True
                break
        if not done:
            return i
    return -1


def sample_track_batch(c, ws, streams, n, radius_range, amplitude_range, n_check):
    """Draw n reference trajectories (see ``envs.tasks.sample_track``) from random streams.

    Args:
        c: Packed constants.
        ws: Packed workspace.
        streams: ``random_streams`` of one generator (shape (1, 2)) or of n generators (shape (n, 2)).
        n: Number of references.
        radius_range: (r_min, r_max) [m].
        amplitude_range: (a_min, a_max) [rad].
        n_check: Steps of one period checked for safety.

    Returns:
        (centres (n, 3), radii (n,), phases (n,), amplitudes (n,)), or None if one was not found.
    """
    center, radius, phase, amplitude = np.empty((n, 3)), np.empty(n), np.empty(n), np.empty(n)
    r_lo, r_hi = (float(v) for v in radius_range)
    a_lo, a_hi = (float(v) for v in amplitude_range)
    failed = _sample_track(c, ws, streams, r_lo, r_hi, a_lo, a_hi, n_check, center, radius, phase, amplitude)
    if failed >= 0:
        return None
    return center, radius, phase, amplitude


# -- the state at the start of an episode -------------------------------------------------------------


@_jit
def _initial_loop(c, x, o_q, o_k, o_sign, o_res):
    for i in range(x.shape[0]):
        a = fp.rows(c[C_FAMILY:], x[i, 0], x[i, 1], x[i, 2])
        q0, q1, q2 = math.sqrt(a[9]), math.sqrt(a[10]), math.sqrt(a[11])
        o_q[i, 0], o_q[i, 1], o_q[i, 2] = q0, q1, q2
        o_k[i], o_sign[i] = fp.singularity_rows(c[C_FAMILY:], q0, q1, q2, a)
        o_res[i] = fp.max_abs3(a[9] - q0 * q0, a[10] - q1 * q1, a[11] - q2 * q2)


def initial_batch(c, x):
    """Strokes (inverse kinematics), k, sign(det J_x) and constraint residual of N robots at rest at x.

    Args:
        c: Packed constants.
        x: Poses, shape (N, 3).

    Returns:
        (q (N, 3) [m], k (N,), sign (N,), residual (N,) [m²]).
    """
    n = x.shape[0]
    o_q, o_k, o_sign, o_res = np.empty((n, 3)), np.empty(n), np.empty(n), np.empty(n)
    _initial_loop(c, x, o_q, o_k, o_sign, o_res)
    return o_q, o_k, o_sign, o_res
