"""The step's compiled kernel in its other roles: evaluation at rest, transition, assembly, strokes.

Each function here builds a ``StepCall`` of the very Numba type an env's step call has (C-ordered writable arrays,
read-only constants; the arrays a mode does not read or write are empty stand-ins of the right type) and runs the
step's own kernel in one of the modes of ``envs.kernels.records``:

- ``evaluate_batch`` (``EVALUATE``): reward terms and observations of states as they are (episode starts,
  measurements, ``physics.reward_terms``);
- ``transition_batch`` (``TRANSITION``): one control period without the evaluation (the shield's look-ahead);
- ``initial_batch`` (``ASSEMBLE``): robots at rest at given poses (an episode's start);
- ``strokes_batch`` (``STROKES``): the strokes of given poses (a fixed target's);
- ``holding_batch`` (``HOLD``): the holding forces of robots under force control (an episode's start, a
  controller that knows another model than the plant).

An env that has compiled its step therefore compiles nothing more to start its episodes or to look ahead. Each
takes ``parallel``: run the multi-core step's kernel (on every core from ``PARALLEL_MIN_BATCH`` robots, on this
thread below), as a vector env of that many robots steps, rather than the one-thread step's.
"""

from __future__ import annotations

import numpy as np

from envs.kernels import packing
from envs.kernels.dynamics_layout import C_INERTIA_SIZE
from envs.kernels.layout import E_FIXED
from envs.kernels.records import ASSEMBLE, EVALUATE, HOLD, STROKES, TRANSITION, Moved, StepArrays
from envs.kernels.setup import PARALLEL_MIN_BATCH, uses_every_core
from envs.kernels.step import allocate_step, path_kernels, step_call, step_on_every_core

__all__ = [
    "evaluate_batch",
    "evaluation_call",
    "holding_batch",
    "initial_batch",
    "strokes_batch",
    "transition_batch",
    "writable",
]

_F8, _I8 = np.dtype(np.float64), np.dtype(np.int64)
#: Stand-ins for the arrays a mode neither reads nor writes: the observation bounds, a reference, (N, ·) rows,
#: (N,) columns, the evaluation rows, the observations, and under force control the inertia.
_NO_BOUNDS = packing.read_only(np.zeros(0, dtype=np.float32))
_NO_OBSERVATION = (_NO_BOUNDS, _NO_BOUNDS, False)
_NO_ROWS, _NO_COLUMN, _NO_STEPS = np.empty((0, 0)), np.empty(0), np.empty(0, dtype=np.int64)
_NO_OBSERVATIONS = np.empty((0, 0), dtype=np.float32)
_NO_INERTIA = packing.read_only(np.zeros((1, C_INERTIA_SIZE)))
#: The outputs of a call that writes none of them (``HOLD``).
_NO_OUTPUTS = StepArrays(
    _NO_ROWS, _NO_ROWS, _NO_STEPS, _NO_COLUMN, _NO_COLUMN, _NO_COLUMN, _NO_ROWS, _NO_ROWS, _NO_STEPS, _NO_COLUMN,
    _NO_ROWS, _NO_OBSERVATIONS,
)  # fmt: skip


def writable(a, dtype=_F8):
    """``a`` if it is a C-ordered writable array of ``dtype`` (0.1 µs, where ``np.require`` takes 0.7), else a copy.

    The step's calls take their arrays so (``step_call``): one compiled type for every caller.
    """
    if type(a) is np.ndarray and a.dtype == dtype and a.flags.carray:
        return a
    return np.require(a, dtype, ("C", "W"))


def _constants(cs):
    """Packed constants (or inertia) as the step takes them: a read-only C-ordered (N or 1, ·) float64 array."""
    if not (type(cs) is np.ndarray and cs.dtype == _F8 and cs.flags.c_contiguous and not cs.flags.writeable):
        cs = packing.read_only(np.require(cs, np.float64, "C"))
    return cs if cs.ndim == 2 else cs[None]


def _threads(parallel, n):
    """Whether the call of n robots runs on every core (``step_call``'s ``threads``)."""
    return bool(parallel) and n >= PARALLEL_MIN_BATCH


def _run(cs, call, action, parallel, force):
    """Run ``call`` on the step's kernel of the robots of ``cs``; True if an action is not finite.

    ``parallel``: on the multi-core step's kernel, on every core if the call was built for them (``_threads``).
    ``force``: whether the call has force control's arrays.
    """
    kernels = path_kernels(cs)
    if not parallel:
        return kernels.one_thread(force)(call, action)
    if _threads(parallel, action.shape[0]):
        return step_on_every_core(kernels, call, action)
    return kernels.step_chunks(call, action)


def evaluate_batch(cs, observation, measured, reference, outcome, parallel=False):
    """Evaluation rows (``evaluation_rows``) and observations of N robots, by the step's own compiled kernel.

    The kernel runs told not to move (``evaluation_call``): a step's evaluation and a state's at rest are one
    compiled code, and an env that has compiled its step compiles nothing more to start its episodes.

    Args:
        cs: Packed constants of the model the observation and the reward are computed with: shape (N, C_SIZE) or
            (1, C_SIZE), as ``transition_batch``.
        observation: (low, high, with_velocity): the observation's float32 bounds, shape (D,) each, and whether it
            ends with the target velocity.
        measured: (q, x, t, k, k_I, residual): strokes [m] (N, n), poses (N, m), step indices (N,) int, inverse
            condition numbers (N,), actuator condition numbers (1 for legs) (N,), constraint residuals [m²] (N,).
        reference: (center, amplitude, phase, strokes) of the targets (``envs.state.FamilyReference``), each
            (N, m); the strokes of the centres (``strokes_batch``, (N, n)) are read where the target is fixed.
        outcome: (action, reason): applied actions (N, n) and termination reason codes (N,); with force control
            also (twists ẋ (N, m), actuator rates (N, n)), which the observation then holds after k.
        parallel: Run the multi-core step's kernel (see the module docstring).

    Returns:
        (evaluation (E_FIXED + 3m, N) float64, observations (N, D) float32).
    """
    cs = _constants(cs)
    call, action, evaluation, observations = evaluation_call(cs, observation, measured, reference, outcome, parallel)
    _run(cs, call, action, parallel, len(outcome) > 2)
    return evaluation, observations


def evaluation_call(cs, observation, measured, reference, outcome, parallel=False):
    """``evaluate_batch``'s ``StepCall`` (``EVALUATE``), actions, evaluation and observations (args: see there)."""
    cs = _constants(cs)
    q, x, k, k1, residual = (writable(measured[j]) for j in (0, 1, 3, 4, 5))
    t, action, reason = writable(measured[2], _I8), writable(outcome[0]), writable(outcome[1], _I8)
    reference = tuple(writable(a) for a in reference)
    n, m = x.shape
    low = observation[0]
    evaluation, observations = np.empty((E_FIXED + 3 * m, n)), np.empty((n, low.shape[0]), dtype=np.float32)
    spare, unread = np.empty(n), np.empty(q.shape)  # what only a moving step reads or writes
    if len(outcome) > 2:  # force control: the observation's twists and actuator rates
        twist, rates = writable(outcome[2]), writable(outcome[3])
        force = (_NO_INERTIA, twist, twist, unread, unread)
    else:
        rates, force = unread, ()
    out = (q, x, t, k, k1, residual, action, rates, reason, spare, evaluation, observations)
    state = (q, x, t, spare, residual)
    call = step_call(cs, cs, observation, state, reference, out, force, EVALUATE, _threads(parallel, n))
    return call, action, evaluation, observations


def transition_batch(cs, state, action, force=(), kernels=None, parallel=None):
    """Advance N robots by one control period (the algorithm of ``envs.physics.transition``).

    The step's own kernel runs in mode ``TRANSITION``, without the evaluation.

    Args:
        cs: Packed constants (``pack_family``) of the robots that move: shape (N, C_SIZE), one row per robot, or
            (1, C_SIZE), one geometry for all.
        state: (q, x, t, det_sign, residual): strokes [m] (N, n), poses (N, m), steps (N,) int (not read), the
            working mode sign(det J_x) of each episode (N,), the constraint residual at (q, x) [m²] (N,).
        action: Normalised stroke rates, shape (N, n), finite (force control: offsets from the holding forces in
            units of the drive limits).
        force: () for rate control, or (inertia, twist) for force control (``envs.kernels.force``): the packed
            inertia and drive limits (``pack_inertia``), (N or 1, C_INERTIA_SIZE), and the twists ẋ (N, m).
        kernels: The ``PathKernels`` to run (default ``path_kernels(cs)``, the robot's own row path's).
        parallel: Run the multi-core step's kernel (see the module docstring); None: as ``physics.step`` does for
            N robots (``uses_every_core``).

    Returns:
        A ``Moved`` (q', x', k', k_I', residual', applied action, achieved stroke rates [m/s], reason codes, jumps
        [m]); with force control, that and (ẋ' (N, m), efforts τ (N, n), holding forces τ_h (N, n)), the applied
        action being τ / τ_max and the rates the period's mean.

    Raises:
        ValueError: If an action is not finite.
    """
    cs = _constants(cs)
    q, x, t, det_sign, residual = state
    q, x, det_sign, residual = (writable(a) for a in (q, x, det_sign, residual))
    action, t = writable(action), writable(t, _I8)
    n, m = x.shape
    o = allocate_step(n, m, 0)._replace(evaluation=_NO_ROWS)  # the evaluation rows are not written
    moved = Moved(o.q, o.x, o.k, o.k1, o.residual, o.action, o.q_rate, o.reason, o.jump)
    if force:
        inertia, twist = force
        force = (_constants(inertia), writable(twist), np.empty((n, m)), np.empty((n, m)), np.empty((n, m)))
    parallel = uses_every_core(n) if parallel is None else parallel
    state, threads = (q, x, t, det_sign, residual), kernels is None and _threads(parallel, n)
    call = step_call(cs, cs, _NO_OBSERVATION, state, (_NO_ROWS,) * 4, o, force, TRANSITION, threads)
    if kernels is not None:
        failed = kernels.one_thread(bool(force))(call, action)
    else:
        failed = _run(cs, call, action, parallel, bool(force))
    if failed:
        raise ValueError(f"action must be finite, got {action[~np.isfinite(action).all(axis=1)][0].tolist()}")
    return (moved, force[2:]) if force else moved


def _at_rest(cs, x, mode, force, parallel, centers=None):
    """Run ``ASSEMBLE`` or ``STROKES`` at the poses x (N, m): (q, k, k_I, sign(det J_x), residual) arrays.

    With ``centers`` (N, m), the strokes of those poses (N, n) follow, from the same call.
    """
    cs = _constants(cs)
    x = writable(x)
    n, m = x.shape
    q, k, k1, sign, residual = np.empty((n, m)), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    no_rows, no_column = _NO_ROWS, _NO_COLUMN
    outputs = StepArrays(
        q, no_rows, _NO_STEPS, k, k1, residual, no_rows, no_rows, _NO_STEPS, sign, no_rows, _NO_OBSERVATIONS
    )
    extra = (_NO_INERTIA, no_rows, no_rows, no_rows, no_rows) if force else ()
    motion = (no_rows, x, _NO_STEPS, no_column, no_column)
    reference = (no_rows,) * 4 if centers is None else (writable(centers), no_rows, no_rows, np.empty((n, m)))
    call = step_call(cs, cs, _NO_OBSERVATION, motion, reference, outputs, extra, mode, _threads(parallel, n))
    _run(cs, call, np.empty((n, 0)), parallel, bool(force))
    return (q, k, k1, sign, residual) if centers is None else (q, k, k1, sign, residual, reference[3])


def initial_batch(c, x, force=False, parallel=False, centers=None):
    """Strokes (inverse kinematics), k, k_I, sign(det J_x) and residual of N robots at rest at poses x.

    Args:
        c: Packed constants: of one geometry, shape (C_SIZE,) or (1, C_SIZE), or one row per robot (N, C_SIZE).
        x: Poses, shape (N, m).
        force: Whether the env is under force control (its step's call then has force control's arrays).
        parallel: Run the multi-core step's kernel (see the module docstring).
        centers: Targets (N, m) whose strokes to solve in the same call (an episode's start: its reference's), or
            None.

    Returns:
        (strokes (N, n), k (N,), k_I (N,), sign(det J_x) (N,), residual max_i |Φ_i| [m²] (N,)), and with
        ``centers`` the strokes of the centres (N, n) (``strokes_batch``).
    """
    return _at_rest(c, x, ASSEMBLE, force, parallel, centers)


def strokes_batch(c, x, force=False, parallel=False):
    """Actuator coordinates of N poses x (N, m) by the closed-form inverse kinematics (NaN where out of reach).

    Leg lengths [m], crank angles [rad] or slider positions [m] on each actuator's chosen branch, shape (N, n): what
    the observation's stroke errors compare q with (``FamilyReference.strokes`` keeps those of a fixed target).
    ``c``, ``force`` and ``parallel`` as ``initial_batch``.
    """
    return _at_rest(c, x, STROKES, force, parallel)[0]


def holding_batch(cs, ci, q, x, parallel=False):
    """The holding forces τ_h (J_iᵀ τ_h = G) of N robots, shape (N, n); NaN where J_i is singular.

    Args:
        cs: Read-only packed constants, shape (1, C_SIZE) (one geometry) or (N, C_SIZE) (each robot's).
        ci: Packed inertia (``pack_inertia``), shape (1, C_INERTIA_SIZE).
        q: Actuator coordinates with Φ(q, x) = 0, shape (N, n).
        x: Platform poses, shape (N, m).
        parallel: Run the multi-core step's kernel (see the module docstring).
    """
    cs, ci = _constants(cs), _constants(ci)
    q, x = writable(q), writable(x)
    n, m = x.shape
    hold = np.empty((n, m))
    extra = (ci, _NO_ROWS, _NO_ROWS, _NO_ROWS, hold)
    motion = (q, x, _NO_STEPS, _NO_COLUMN, _NO_COLUMN)
    call = step_call(cs, cs, _NO_OBSERVATION, motion, (_NO_ROWS,) * 4, _NO_OUTPUTS, extra, HOLD, _threads(parallel, n))
    _run(cs, call, np.empty((n, 0)), parallel, True)
    return hold
