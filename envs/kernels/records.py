"""The records the compiled step takes and returns: named tuples of arrays, one row (or one entry) per robot.

Numba compiles ``typing.NamedTuple`` classes, so the kernels read these fields by name (``state.q``,
``moved.reason``) instead of unpacking tuples by position. N robots, n actuators, m pose coordinates; strokes are
leg lengths [m], crank angles [rad] or slider positions [m]; poses are (x, y, φ) (planar), (p, rotation vector)
(spatial) or p (translational) of {P} in {B}.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.core import types
from numba.experimental import structref

__all__ = [
    "ASSEMBLE",
    "EVALUATE",
    "HOLD",
    "STEP",
    "STROKES",
    "TRANSITION",
    "Dynamics",
    "Measured",
    "Motion",
    "Moved",
    "Observation",
    "Outcome",
    "Reference",
    "StepArrays",
    "StepCall",
    "StepCallType",
]


class Motion(NamedTuple):
    """What the transition reads of N robots."""

    q: np.ndarray  #: strokes, (N, n)
    x: np.ndarray  #: poses, (N, m)
    t: np.ndarray  #: steps, (N,) int64 (not read by the transition)
    det_sign: np.ndarray  #: the working mode sign(det J_x) of each episode, (N,)
    residual: np.ndarray  #: the constraint residual max_i |Φ_i| at (q, x) [m²], (N,)


class Moved(NamedTuple):
    """What the transition writes for N robots."""

    q: np.ndarray  #: strokes after the period, (N, n)
    x: np.ndarray  #: poses after the period, (N, m)
    k: np.ndarray  #: inverse condition numbers (Type II measure), (N,)
    k1: np.ndarray  #: actuator condition numbers (Type I measure; 1 for legs), (N,)
    residual: np.ndarray  #: constraint residuals [m²], (N,)
    action: np.ndarray  #: applied actions (clipped to [−1, 1]), (N, n)
    q_rate: np.ndarray  #: achieved stroke rates [/s], (N, n)
    reason: np.ndarray  #: termination reason codes (0: none), (N,) int64
    jump: np.ndarray  #: largest Newton correction of the period [m], (N,)


class Observation(NamedTuple):
    """The observation's bounds and layout."""

    low: np.ndarray  #: lower bounds, (D,) float32
    high: np.ndarray  #: upper bounds, (D,) float32
    with_velocity: bool  #: whether the observation ends with the target velocity


class Measured(NamedTuple):
    """The state the evaluation reads of N robots (true or as the encoders measure it)."""

    q: np.ndarray  #: strokes, (N, n)
    x: np.ndarray  #: poses, (N, m)
    t: np.ndarray  #: step indices, (N,) int64
    k: np.ndarray  #: inverse condition numbers, (N,)
    k1: np.ndarray  #: actuator condition numbers, (N,)
    residual: np.ndarray  #: constraint residuals [m²], (N,)


class Reference(NamedTuple):
    """The targets of N robots (``envs.state.FamilyReference`` without its optional field)."""

    center: np.ndarray  #: centres c, (N, m)
    amplitude: np.ndarray  #: amplitudes a, (N, m)
    phase: np.ndarray  #: phases θ [rad], (N, m)
    strokes: np.ndarray  #: the actuator coordinates of the centres, (N, n)


class Outcome(NamedTuple):
    """What the evaluation reads of a transition's outcome."""

    action: np.ndarray  #: applied actions, (N, n)
    reason: np.ndarray  #: termination reason codes, (N,) int64


class StepArrays(NamedTuple):
    """The outputs of the fused step of N robots (``envs.kernels.step.allocate_step``)."""

    q: np.ndarray  #: strokes, (N, n)
    x: np.ndarray  #: poses, (N, m)
    t: np.ndarray  #: step indices, (N,) int64
    k: np.ndarray  #: inverse condition numbers, (N,)
    k1: np.ndarray  #: actuator condition numbers, (N,)
    residual: np.ndarray  #: constraint residuals [m²], (N,)
    action: np.ndarray  #: applied actions, (N, n)
    q_rate: np.ndarray  #: achieved stroke rates [/s], (N, n)
    reason: np.ndarray  #: termination reason codes, (N,) int64
    jump: np.ndarray  #: largest Newton corrections [m], (N,)
    evaluation: np.ndarray  #: evaluation rows (``packing.evaluation_rows``), (E_FIXED + 3m, N)
    observations: np.ndarray  #: observations, (N, D) float32


class Dynamics(NamedTuple):
    """Force control (``envs.kernels.force``): what the transition reads and writes of N robots besides ``Motion``."""

    inertia: np.ndarray  #: packed inertia and drive limits (``pack_inertia``), (N or 1, C_INERTIA_SIZE)
    twist: np.ndarray  #: platform twists at the period's start, (N, m)
    o_twist: np.ndarray  #: platform twists at its end, (N, m)
    effort: np.ndarray  #: applied efforts τ [N, N·m for cranks], (N, n)
    hold: np.ndarray  #: holding forces τ_h at the period's start, (N, n)
    work: np.ndarray  #: the dynamics work array of one thread (``dynamics._dynamics_work``)


#: The fields of a ``StepCall``, in the order its constructor takes them.
STEP_CALL_FIELDS = (
    "model",  # packed constants the reward and the observation use, (N or 1, C_SIZE), read-only
    "plant",  # packed constants of the robots that move, (N or 1, C_SIZE), read-only
    "low",  # observation bounds, (D,) float32
    "high",
    "with_velocity",  # bool: the observation ends with the target velocity
    "q",  # the state the step starts from: strokes (N, n)
    "x",  # poses (N, m)
    "t",  # step indices (N,) int64
    "det_sign",  # sign(det J_x) of the working mode (N,)
    "residual",  # constraint residuals (N,)
    "center",  # the reference (``Reference``)
    "amplitude",
    "phase",
    "strokes",
    "outputs",  # the ``StepArrays`` written, then force control's (inertia, ẋ, ẋ', τ, τ_h) or nothing
    "mode",  # int: what the call does (``STEP``, ``EVALUATE``, ``TRANSITION``, ``ASSEMBLE``, ``STROKES``, ``HOLD``)
    "counter",  # int64 (1,): the next chunk of robots for the threads of a multi-core call; (0,): one thread does all
)

#: The modes of a ``StepCall``: the one compiled step in each role, so that an env compiles one kernel.
#: ``STEP``: transition (``plant``), then evaluation (``model``) of the new state, into the outputs.
#: ``EVALUATE``: the evaluation of the state the outputs hold, unmoved (episode starts, measurements).
#: ``TRANSITION``: the transition alone (the shield's look-ahead); the evaluation rows are not written.
#: ``ASSEMBLE``: at rest at the poses ``x``: strokes q (the closed-form inverse kinematics), k, k_I, residual, and
#: sign(det J_x) in ``jump`` (an episode's start).
#: ``STROKES``: the strokes q of the poses ``x`` only (a fixed target's).
#: ``HOLD``: under force control, the holding forces τ_h at (q, x) into force control's ``hold`` output.
STEP, EVALUATE, TRANSITION, ASSEMBLE, STROKES, HOLD = range(6)


@structref.register
class StepCallType(types.StructRef):
    """Numba's type of a ``StepCall``: one per combination of its fields' array types."""

    def preprocess_fields(self, fields):
        """The fields' types, literals widened (a ``with_velocity`` given as a constant types as a bool)."""
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepCall(structref.StructRefProxy):
    """Every array one call of the one-thread step reads and writes, but the action, held by reference.

    The single env and a small vector env step from the same arrays again and again (their state is the output of
    the step before, in one of two buffers used in turn): they build a ``StepCall`` once per pair of buffers and
    pass it with the action. Numba unboxes it as one pointer where it would type and unbox each of its thirty-odd
    arrays on every call (about 0.06 µs each). Built by ``envs.kernels.step.step_call``; its fields are
    ``STEP_CALL_FIELDS``.
    """


structref.define_proxy(StepCall, StepCallType, list(STEP_CALL_FIELDS))
