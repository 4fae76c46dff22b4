"""The evaluation of N robots' states as they are (episode starts, measurements, rewards), by the step's kernel.

``evaluate_batch`` runs the step's own compiled kernel, told not to move (a ``StepCall`` with ``moving`` False):
a step's evaluation and a state's at rest are one compiled code, and an env that has compiled its step compiles
nothing more to start its episodes.
"""

from __future__ import annotations

import numpy as np

from envs.kernels import packing
from envs.kernels.dynamics_layout import C_INERTIA_SIZE
from envs.kernels.layout import E_FIXED
from envs.kernels.setup import PARALLEL_MIN_BATCH, on_every_core
from envs.kernels.step import path_kernels, step_call, writable

__all__ = ["evaluate_batch", "evaluation_call"]

#: The inertia of a force-control ``StepCall`` that only evaluates, which it does not read.
_NO_INERTIA = packing.read_only(np.zeros((1, C_INERTIA_SIZE)))
_F8, _I8 = np.dtype(np.float64), np.dtype(np.int64)


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
        parallel: Run the multi-core step's kernel (on every core from ``PARALLEL_MIN_BATCH`` robots), as a
            vector env of that many robots steps, rather than the one-thread step's.

    Returns:
        (evaluation (E_FIXED + 3m, N) float64, observations (N, D) float32).
    """
    call, action, evaluation, observations = evaluation_call(cs, observation, measured, reference, outcome)
    kernels = path_kernels(cs)
    n = action.shape[0]
    if not parallel:
        kernels.step_serial(call, action)
    elif n >= PARALLEL_MIN_BATCH:
        on_every_core(kernels.step_chunks, call, action)
    else:
        kernels.step_chunks(call, action, np.zeros(1, dtype=np.int64))
    return evaluation, observations


def evaluation_call(cs, observation, measured, reference, outcome):
    """``evaluate_batch``'s ``StepCall`` (not moving), actions, evaluation and observations (args: see there).

    Every array gets the type the step's own call has (C-ordered, writable but the read-only constants), so the
    evaluation runs the step's compiled kernel, not a second specialisation of it.
    """
    if not (type(cs) is np.ndarray and cs.dtype == _F8 and cs.flags.c_contiguous and not cs.flags.writeable):
        cs = packing.read_only(np.require(cs, np.float64, "C"))
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
    call = step_call(cs, cs, observation, (q, x, t, spare, residual), reference, out, force, moving=False)
    return call, action, evaluation, observations
