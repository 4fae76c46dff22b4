"""The compiled step of the family: transition (predict, correct, measure, terminate), then evaluation.

The entry kernels take their arrays flat and gather them in the records of ``envs.kernels.records``: the
transition reads a ``Motion`` and writes a ``Moved``; the evaluation reads an ``Observation``, a ``Measured``, a
``Reference`` and an ``Outcome``; the fused step writes a ``StepArrays``. One body steps every robot:
``force.advance`` (predict, correct: ``rate.advance_rate`` under rate control, ``force.advance_force`` under force
control, chosen at compile time by whether the step has a ``Dynamics`` record), then ``_transition_rows``
(measure, terminate), on the vectors of its row path (``envs.kernels.paths``). The row path and the pose space
are compile-time constants of the entry kernels (``path_kernels``), so a robot compiles its own path and pose
space only.

Work arrays are allocated once per chunk of robots, not per robot; large batches run on every core. Inside a
chunk of the parallel step under rate control, spatial robots go in blocks of ``LANES``: each is moved alone, then
the Jacobi SVD behind their k runs on the whole block at once (vectorised across robots,
``envs.kernels.linalg.inverse_condition6_lanes``); the one-thread step, and the parallel step under force control
(``lane_work``), move them robot by robot, with one compiled block.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba.core import types
from numba.extending import overload

from envs.kernels import paths
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _actuator_condition, _homogeneous_lane, _row, _work
from envs.kernels.evaluation import _evaluate_rows
from envs.kernels.force import advance, beyond_stops, from_extra, hold_rows, motion_of
from envs.kernels.layout import (
    _ACTUATOR_SINGULAR,
    _ASSEMBLY_MODE_CHANGE,
    _NEWTON_FAILED,
    _OUT_OF_BOUNDS,
    _SINGULAR,
    _SINGULARITY_CROSSED,
    C_HARD,
    C_HARD1,
    C_HIGH,
    C_JUMP,
    C_LEGS,
    C_LOW,
    C_N,
    C_SPATIAL,
    C_TRANSLATIONAL,
    E_FIXED,
    L_ACTIVE,
    L_FLAGS,
    L_K,
    L_K1,
    L_SIGN,
    L_WORST,
    LANES_ROWS,
    W_A,
    W_KQ,
)
from envs.kernels.linalg import LANES, inverse_condition6_lanes
from envs.kernels.packing import (
    _OVERLOAD_OPTIONS,
    ROW_PATHS,
    WORK_ARRAYS,
    _literal_path,
    pose_space_code,
    row_path,
)
from envs.kernels.records import (
    ASSEMBLE,
    EVALUATE,
    HOLD,
    STEP,
    TRANSITION,
    Measured,
    Motion,
    Moved,
    Observation,
    Outcome,
    Reference,
    StepArrays,
    StepCall,
)
from envs.kernels.setup import (
    ONE_THREAD,
    PARALLEL_MIN_BATCH,
    borrow,
    claim,
    jit,
    jit_inline,
    keep_alive,
    on_every_thread,
)

__all__ = [
    "allocate_step",
    "path_kernels",
    "step_batch",
    "step_call",
    "step_on_every_core",
]

drop_stale_caches(__file__)


N_LANE_ROWS = len(LANES_ROWS)
#: Arrays of ``StepArrays``: the fused step's outputs; force control's arrays follow them (``step_batch``).
N_STEP_ARRAYS = len(StepArrays._fields)

#: Robots per chunk of a batch: each chunk allocates its work arrays once (a multiple of ``LANES``).
CHUNK = 64


@jit
def allocate_lanes():
    """Work arrays of one block of up to ``LANES`` spatial robots: (H (6, 6, LANES), lane rows (``LANES_ROWS``))."""
    return np.empty((6, 6, LANES)), np.empty((N_LANE_ROWS, LANES))


def lane_work(path, call):
    """The parallel step's SIMD lane work arrays (``allocate_lanes``): on the work-array path under rate control.

    ``path`` (the row path) and the type of ``call`` (a ``StepCall``, whose outputs under force control have force
    control's arrays after the ``StepArrays``) are compile-time choices; the call's fields are not read; elsewhere
    None, and the parallel step moves its robots one at a time with the one-thread step's compiled block. The
    register paths have no 6 × 6 SVD to put in lanes. Under force control the period's dynamics outweigh the SVD:
    its blocks in lanes ran about 4 % faster (the hexapod's vector env at N = 16384) for a second compile of the
    block, about 12 s of CPU.
    """
    return paths._compiled_only()


@overload(lane_work, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _lane_work_of(path, call):
    if _literal_path(path) == WORK_ARRAYS and len(call.field_dict["outputs"]) == N_STEP_ARRAYS:
        return lambda path, call: allocate_lanes()
    return lambda path, call: None


@jit_inline
def termination_reason(c, failed, jump, sign, mode, k, out, k1):
    """The step's termination reason code (0: none), first match in the order of ``TERMINATION_REASONS``.

    Args:
        c: Packed constants of the robot.
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
def _outside(c, q, x):
    """Whether the pose x (m,) left its bounds or a stroke of q (n,) its hard stops (force control: a crash)."""
    for j in range(len(x)):
        if x[j] < c[C_LOW + j] or x[j] > c[C_HIGH + j]:
            return True
    return beyond_stops(c, q)


@jit_inline
def _store(i, kq, kx, a, qr, res, jump, moved):
    """Write robot i's strokes, pose, applied action, stroke rates, residual and jump into ``moved`` (``Moved``)."""
    o_q, o_x, o_a, o_qr = moved.q, moved.x, moved.action, moved.q_rate
    for j in range(len(kx)):
        o_q[i, j] = kq[j]
        o_x[i, j] = kx[j]
        o_a[i, j] = a[j]
        o_qr[i, j] = qr[j]
    moved.residual[i] = res
    moved.jump[i] = jump


@jit_inline
def _transition_rows(path, cs, state, action, start, count, w, moved, dynamics):
    """Transition of robots start .. start + count − 1, one at a time: advance, measure, terminate."""
    # The fields in locals, read once: a field read inside the loop costs a little on every robot.
    q, x, residual, det_sign = state.q, state.x, state.residual, state.det_sign
    o_k, o_k1, o_reason = moved.k, moved.k1, moved.reason
    for i in range(start, start + count):
        c = _row(cs, i)
        q0, x0 = paths.vector(path, q[i]), paths.vector(path, x[i])
        kq, kx, anchors, rows, a, qr, res, jump, failed = advance(
            path, c, dynamics, i, q0, x0, action[i], residual[i], w
        )
        k, sign, k1 = paths.measure(path, c, kq, anchors, rows, w)
        _store(i, kq, kx, a, qr, res, jump, moved)
        o_k[i], o_k1[i] = k, k1
        o_reason[i] = termination_reason(c, failed, jump, sign, det_sign[i], k, _outside(c, kq, kx), k1)


@jit_inline
def _transition_lanes(cs, state, action, start, count, w, lanes, moved, dynamics):
    """``_transition_rows`` of spatial robots (m = 6) in SIMD lanes: each robot advanced, then their k at once.

    The k of all of them comes from one ``inverse_condition6_lanes`` call over the block (vectorised across
    robots, each robot's k bit for bit what it would be alone).
    """
    H, lane = lanes
    for r in range(count):
        i = start + r
        c = _row(cs, i)
        q0, x0, residual = state.q[i], state.x[i], state.residual[i]
        kq, kx, _, _, a, qr, res, jump, failed = advance(WORK_ARRAYS, c, dynamics, i, q0, x0, action[i], residual, w)
        _store(i, kq, kx, a, qr, res, jump, moved)
        lane[L_SIGN, r] = _homogeneous_lane(c, kq, w, W_A, H, r)
        lane[L_FLAGS, r] = (1.0 if failed else 0.0) + (2.0 if _outside(c, kq, kx) else 0.0)
        lane[L_K1, r] = _actuator_condition(c, w)
    inverse_condition6_lanes(H, count, lane[L_K], lane[L_WORST], lane[L_ACTIVE])
    for r in range(count):
        i = start + r
        flags = lane[L_FLAGS, r]
        k = lane[L_K, r]
        moved.k[i], moved.k1[i] = k, lane[L_K1, r]
        failed, out = flags == 1.0 or flags == 3.0, flags >= 2.0
        moved.reason[i] = termination_reason(
            _row(cs, i), failed, moved.jump[i], lane[L_SIGN, r], state.det_sign[i], k, out, lane[L_K1, r]
        )


def _transition_block(path, cs, state, action, start, count, w, lanes, moved, dynamics):
    """Advance robots start .. start + count − 1 (count ≤ ``LANES``) by one control period; writes their rows.

    The algorithm of ``envs.physics.transition``: predict and correct (``force.advance``), measure (k and k_I at the
    new pose), terminate (``termination_reason``). ``path`` is the row path, a compile-time constant: the
    overload below compiles that path's block only. Args as ``transition_batch``; ``moved`` holds its outputs.
    With work arrays for SIMD lanes (``allocate_lanes``; None: robot by robot), spatial robots (m = 6) in blocks
    of more than one are measured together (``_transition_lanes``). ``cs`` holds one row of constants per robot
    or one row for all (the robots of one batch share their pose space and actuator kinds, not their geometry).
    ``dynamics``: None (rate control) or the batch's ``Dynamics`` (force control, ``envs.kernels.force``).
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_transition_block, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _transition_block_of_path(path, cs, state, action, start, count, w, lanes, moved, dynamics):
    if _literal_path(path) != WORK_ARRAYS or isinstance(lanes, types.NoneType):

        def rows(path, cs, state, action, start, count, w, lanes, moved, dynamics):
            _transition_rows(path, cs, state, action, start, count, w, moved, dynamics)

        return rows

    def block(path, cs, state, action, start, count, w, lanes, moved, dynamics):
        if count == 1 or cs[0][C_N] != 6.0:  # one robot (the plain Jacobi is cheaper) or m = 3
            _transition_rows(path, cs, state, action, start, count, w, moved, dynamics)
        else:
            _transition_lanes(cs, state, action, start, count, w, lanes, moved, dynamics)

    return block


@jit_inline
def _step_block(
    path, space, model, plant, observation, state, reference, action, start, count, w, lanes, out, dynamics, mode
):
    """Transition (``plant``) then evaluation (``model``) of robots start .. start + count − 1 (count ≤ ``LANES``).

    Or one part of it, by ``mode`` (``envs.kernels.records``): ``EVALUATE`` the state ``out`` holds
    (``evaluate_batch``), ``TRANSITION`` only (``transition_batch``), ``ASSEMBLE`` or ``STROKES`` at the poses of
    ``state`` (``initial_batch``, ``strokes_batch``), ``HOLD`` the holding forces there (``holding_batch``).
    """
    if mode == HOLD:
        hold_rows(path, plant, dynamics, state.q, state.x, start, count)
        return
    if mode >= ASSEMBLE:
        _assemble_rows(path, plant, state.x, reference, start, count, w, out, mode == ASSEMBLE)
        return
    if mode != EVALUATE:
        moved = Moved(out.q, out.x, out.k, out.k1, out.residual, out.action, out.q_rate, out.reason, out.jump)
        _transition_block(path, plant, state, action, start, count, w, lanes, moved, dynamics)
        t, o_t = state.t, out.t
        for i in range(start, start + count):
            o_t[i] = t[i] + 1
    if mode == TRANSITION:
        return
    measured = Measured(out.q, out.x, out.t, out.k, out.k1, out.residual)
    outcome, written = Outcome(out.action, out.reason), (out.evaluation, out.observations)
    motion = motion_of(dynamics, out.q_rate)
    _evaluate_rows(
        path, space, model, observation, measured, reference, outcome, motion, start, start + count, w, written
    )


def _assemble_rows(path, plant, x, reference, start, count, w, out, measuring):
    """Robots start .. start + count − 1 at rest at their poses x: q (and if ``measuring`` k, k_I, residual, sign).

    The strokes come from the closed-form inverse kinematics of each robot's own branches; sign(det J_x) goes to
    ``out.jump``. Where ``reference.strokes`` has rows, the strokes of the reference's centres go there too. A
    function of its own (the overload below), not inlined: the one-thread and the multi-core step link one copy.
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_assemble_rows, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _assemble_rows_of_path(path, plant, x, reference, start, count, w, out, measuring):
    _literal_path(path)
    return _assemble


def _assemble(path, plant, x, reference, start, count, w, out, measuring):
    o_q, o_k, o_k1, o_residual, o_sign = out.q, out.k, out.k1, out.residual, out.jump
    center, o_strokes = reference.center, reference.strokes
    targets = o_strokes.shape[0] > 0
    for i in range(start, start + count):
        c = _row(plant, i)
        x0 = paths.vector(path, x[i])
        q = paths.inverse_kinematics(path, c, x0, w[W_KQ])
        if measuring:
            anchors = paths.anchors_at(path, c, q)
            rows = paths.rows_at(path, c, q, anchors, x0, w)
            o_k[i], o_sign[i], o_k1[i] = paths.measure(path, c, q, anchors, rows, w)
            o_residual[i] = paths.residual(path, c, q, anchors, rows, w)
        for j in range(len(x0)):
            o_q[i, j] = q[j]
        if targets:
            strokes = paths.inverse_kinematics(path, c, paths.vector(path, center[i]), w[W_KQ])
            for j in range(len(x0)):
                o_strokes[i, j] = strokes[j]


@jit_inline
def _finite_actions(action):
    for i in range(action.shape[0]):
        for j in range(action.shape[1]):
            if not math.isfinite(action[i, j]):
                return False
    return True


@jit_inline
def _unpack(call):
    """The records of a ``StepCall``: (model, plant, observation, state, reference, out, dynamics).

    ``dynamics`` is None under rate control, else a ``Dynamics`` with a work array allocated here.
    """
    outputs = call.outputs
    return (
        call.model,
        call.plant,
        Observation(call.low, call.high, call.with_velocity),
        Motion(call.q, call.x, call.t, call.det_sign, call.residual),
        Reference(call.center, call.amplitude, call.phase, call.strokes),
        StepArrays(*outputs[:N_STEP_ARRAYS]),
        from_extra(outputs[N_STEP_ARRAYS:]),
    )


@jit_inline
def _step_chunks(
    path, space, model, plant, observation, state, reference, action, w, lanes, out, dynamics, mode, counter
):
    """The step of robots in chunks of ``CHUNK``: every chunk in turn (``counter`` empty), or one thread's share.

    With a one-element ``counter`` the threads of ``on_every_core`` claim the chunks from it (``claim``). On the
    work-array path under rate control spatial robots go in blocks of ``LANES`` (their k in SIMD lanes,
    ``lane_work``); ``lanes`` None moves them robot by robot.
    """
    n = action.shape[0]
    chunks = (n + CHUNK - 1) // CHUNK
    one_thread = counter.shape[0] == 0
    chunk = 0 if one_thread else claim(counter)
    while chunk < chunks:
        end = min(n, (chunk + 1) * CHUNK)
        for start in range(chunk * CHUNK, end, LANES):
            count = min(LANES, end - start)
            _step_block(
                path, space, model, plant, observation, state, reference, action, start, count, w, lanes, out,
                dynamics, mode,
            )  # fmt: skip
        chunk = chunk + 1 if one_thread else claim(counter)


@jit_inline
def _run_call(path, space, call, action, counter, lanes_owned):
    """An entry kernel's body: ``call`` with ``action`` on the chunks ``counter`` gives (``_step_chunks``).

    On one thread (``counter`` empty) it first checks the actions: True, without stepping, if one is not finite.
    ``lanes_owned``: the SIMD lane work arrays (``lane_work``) or None. Each thread's call has work arrays of its own
    (``_unpack`` allocates force control's). The arrays are borrowed (``borrow``): the caller holds the call's, and
    those allocated here are kept to the end.
    """
    mode = call.mode
    if counter.shape[0] == 0 and (mode == STEP or mode == TRANSITION) and not _finite_actions(action):
        return True
    owned, work = _unpack(call), _work()
    (model, plant, observation, state, reference, out, dynamics), w, lanes, action, counter = borrow(
        (owned, work, lanes_owned, action, counter)
    )
    _step_chunks(
        path, space, model, plant, observation, state, reference, action, w, lanes, out, dynamics, mode, counter
    )  # fmt: skip
    keep_alive(work)
    keep_alive(lanes_owned)
    keep_alive(owned)
    return False


class PathKernels(NamedTuple):
    """The entry kernels of one row path and pose space (see ``_path_kernels``), each ``kernel(call, action)``.

    ``step_serial`` steps every robot on the calling thread; ``step_chunks`` steps the chunks of robots the call's
    counter gives it (``step_call``): all of them with a one-thread call, one thread's share of them in a call on
    every core (``step_on_every_core``). On one thread both return True, without stepping, if an action is not
    finite; the multi-core step leaves that check to its caller.
    """

    step_serial: Any
    step_chunks: Any

    def one_thread(self, force: bool):
        """The kernel of a one-thread call: ``step_serial`` under rate control, else ``step_chunks``.

        Under force control the multi-core step moves robots one at a time too (``lane_work``): its kernel on one
        thread is the one-thread step, and a process with both compiles it once.
        """
        return self.step_chunks if force else self.step_serial


def _path_kernels(path: int, space: int) -> PathKernels:
    """The entry kernels of the row path ``path`` and the pose space ``space``, both compile-time constants.

    A closure over ints is cached by Numba under their values, so each path's kernels compile (and load from the
    on-disk cache) on their own, when a robot of that path first uses them: a robot compiles its own path only.
    Each entry kernel compiles the whole step, so the register paths have one, ``step_chunks``, which is also their
    ``step_serial``. The work-array path has two: its multi-core step moves spatial robots in SIMD lanes under rate
    control (``lane_work``), which its one-thread step, robot by robot, does not compile.
    """

    # The entry kernels take one ``StepCall`` record rather than flat arrays: the single env calls them at every
    # step, and Numba types and unboxes each array argument (about 0.06 µs each) where it unboxes a record as one
    # pointer; a multi-core step's threads each unbox their arguments holding the GIL.
    def step_serial(call, action):
        return _run_call(path, space, call, action, ONE_THREAD, None)  # robot by robot: no SIMD lanes to compile

    def step_chunks(call, action):
        return _run_call(path, space, call, action, call.counter, lane_work(path, call))

    closures = locals()
    compiled = {}
    for name in PathKernels._fields if path == WORK_ARRAYS else ("step_chunks",):
        kernel = closures[name]
        # Numba's on-disk cache keeps one index file per qualified name, shared by every closure of that name; two
        # processes compiling two paths at once would then overwrite each other's entries, and a later process could
        # load one path's machine code for another's. A name per (path, space) gives each its own index.
        kernel.__qualname__ = kernel.__name__ = f"{name}_path{path}_space{space}"
        compiled[name] = jit(kernel)
    compiled.setdefault("step_serial", compiled["step_chunks"])
    return PathKernels(**compiled)


#: The entry kernels of each row path and pose space, by (path, space).
_PATH_KERNELS = {(path, space): _path_kernels(path, space) for path in ROW_PATHS for space in range(3)}


@jit
def _new_step_call(
    model, plant, low, high, with_velocity, q, x, t, det_sign, residual, center, amplitude, phase, strokes, outputs,
    mode, counter,
):  # fmt: skip
    return StepCall(
        model, plant, low, high, with_velocity, q, x, t, det_sign, residual, center, amplitude, phase, strokes, outputs,
        mode, counter,
    )  # fmt: skip


def step_call(model, plant, observation, state, reference, out, force=(), mode=STEP, threads=False) -> StepCall:
    """The ``StepCall`` of ``step_batch``'s arguments but the action (see there), for ``kernel(call, action)``.

    It holds the arrays by reference: a call steps from whatever they hold when it runs. ``mode`` (``STEP``, or
    one of the others of ``envs.kernels.records``: ``envs.kernels.modes``) says what it does. ``threads``: a call
    for ``step_on_every_core``, whose threads claim its chunks of robots from a counter of its own; else a call for
    one thread (``ONE_THREAD``), of either entry kernel.
    """
    counter = np.zeros(1, dtype=np.int64) if threads else ONE_THREAD
    call = _new_step_call(model, plant, *observation, *state, *reference, (*out, *force), mode, counter)
    call.counter = counter  # for ``step_on_every_core`` (a proxy does not show its record's fields to Python)
    return call


def step_on_every_core(kernels, call, action):
    """``kernels.step_chunks(call, action)`` on every core (``on_every_thread``); True if an action is not finite.

    ``kernels``: the ``path_kernels`` of the call's plant; ``call``: built with ``threads=True``.

    Raises:
        ValueError: If ``call`` was built for one thread.
    """
    if not np.isfinite(action).all():
        return True
    counter = call.counter
    if counter.shape != (1,):
        raise ValueError(
            f"a call on every core needs a counter of shape (1,) (step_call(threads=True)), got {counter.shape}"
        )
    counter[0] = 0  # no chunk claimed yet
    on_every_thread(kernels.step_chunks, call, action)
    return False


def _step_parallel(model, plant, observation, state, reference, action, out, force=()):
    """The multi-core step of ``step_batch``."""
    call = step_call(model, plant, observation, state, reference, out, force, threads=True)
    return step_on_every_core(path_kernels(plant), call, action)


def allocate_step(n, m, obs_dim):
    """Output arrays of ``step_batch`` for n robots with m pose coordinates and obs_dim observations.

    (q, x, t, k, k_I, residual, action, stroke rates, reasons, jumps, evaluation, observations).
    """
    q, x, action, q_rate = (np.empty((n, m)) for _ in range(4))
    k, k1, residual, jump = (np.empty(n) for _ in range(4))
    reason, t = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    evaluation, observations = np.empty((E_FIXED + 3 * m, n)), np.empty((n, obs_dim), dtype=np.float32)
    return StepArrays(q, x, t, k, k1, residual, action, q_rate, reason, jump, evaluation, observations)


def path_kernels(cs) -> PathKernels:
    """The entry kernels of the robot of packed constants ``cs`` (its ``row_path``'s and pose space's)."""
    kind = (cs.item(C_SPATIAL), cs.item(C_LEGS), cs.item(C_TRANSLATIONAL), cs.item(C_N))
    key = _KEYS.get(kind)
    if key is None:
        key = _KEYS[kind] = (row_path(cs), pose_space_code(cs))
    return _PATH_KERNELS[key]


#: (row path, pose space) by the constants that decide them (``path_kernels``: one lookup at every reset).
_KEYS: dict[tuple[float, ...], tuple[int, int]] = {}


def step_batch(model, plant, observation, state, reference, action, out, kernels=None, force=()):
    """Transition and evaluation of N robots into ``out`` (``allocate_step``); True if an action is not finite.

    Args:
        model: Packed constants of the model the reward and the observation are computed with, shape (N, C_SIZE)
            or (1, C_SIZE) (``transition_batch``'s ``cs``).
        plant: Packed constants of the robots that move (the integrated geometry), shape (N, C_SIZE) or
            (1, C_SIZE).
        observation: (low, high, with_velocity), as ``evaluate_batch``.
        state: (q, x, t, det_sign, residual), as ``transition_batch``.
        reference: (center, amplitude, phase, strokes), as ``evaluate_batch``.
        action: Normalised stroke rates, shape (N, n) (force control: offsets from the holding forces in units
            of the drive limits).
        out: The arrays of ``allocate_step`` (a ``StepArrays``).
        kernels: ``path_kernels(plant)``, if the caller keeps them (the single env's step saves finding them).
        force: () for rate control, or for force control (inertia (N or 1, C_INERTIA_SIZE), twists ẋ (N, m) and
            the arrays the step writes: ẋ' (N, m), efforts τ (N, n), holding forces τ_h (N, n)); the observation
            then holds ẋ' and the period's mean actuator rates after k, and ``out.action`` is τ / τ_max.
    """
    if kernels is None:
        kernels = path_kernels(plant)
    if action.shape[0] >= PARALLEL_MIN_BATCH:
        return _step_parallel(model, plant, observation, state, reference, action, out, force)
    return kernels.one_thread(bool(force))(step_call(model, plant, observation, state, reference, out, force), action)
