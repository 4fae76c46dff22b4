"""Pure batched physics of N robots: state, transition, evaluation, reward terms and the step's info.

The ``phys2d`` pattern: constants in ``envs.params.FamilyParams``, the state of N robots in arrays with a
leading dimension N, pure functions (``initial_state``, ``transition``, ``evaluate``, ``step``,
``reward_terms``) over the compiled kernels of ``envs.kernels``. The single environments (N = 1), the native
vector environment, the shield, the HER goal view and the evaluation all call them.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from envs.kernels import generic as fk
from envs.params import FamilyParams

__all__ = [
    "INFO_KEYS",
    "REWARD_TERMS",
    "TERMINATION_REASONS",
    "FamilyOutcome",
    "FamilyReference",
    "FamilyState",
    "NonFiniteActionError",
    "StepBuffers",
    "check_state",
    "copy_state",
    "evaluate",
    "initial_state",
    "observation_bounds",
    "reward_terms",
    "step",
    "step_info",
    "transition",
    "with_strokes",
    "wrap_angle",
]

#: Termination reason codes (index) and names; 0 means the episode goes on.
TERMINATION_REASONS = (
    "",
    "newton_failed",
    "assembly_mode_change",
    "singularity_crossed",
    "singular",
    "out_of_bounds",
    "actuator_singular",
)
NEWTON_FAILED, ASSEMBLY_MODE_CHANGE, SINGULARITY_CROSSED, SINGULAR, OUT_OF_BOUNDS, ACTUATOR_SINGULAR = range(1, 7)
_REASON_NAMES = np.asarray(TERMINATION_REASONS, dtype=object)


class NonFiniteActionError(ValueError):
    """An action with a NaN or an infinity; ``rows`` holds the indices of the robots that got one."""

    def __init__(self, message: str, rows: np.ndarray) -> None:
        super().__init__(message)
        self.rows = rows


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap angles to [−π, π).

    Args:
        angle: Angles [rad], any shape.

    Returns:
        Wrapped angles [rad], same shape.
    """
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


REWARD_TERMS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "reward_actuator_singularity",
)
#: The scalar entries of a single env's ``info``, in order; "is_success" becomes a bool, then come
#: "termination_reason", "pose" and "target", then the Type I entries (``TYPE_I_INFO``).
INFO_KEYS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "position_error",
    "orientation_error",
    "inverse_condition_number",
    "constraint_residual",
    "is_success",
    "cost",
    "reward_actuator_singularity",
    "actuator_condition_number",
    "cost_actuator_singularity",
)
TYPE_I_INFO = ("reward_actuator_singularity", "actuator_condition_number", "cost_actuator_singularity")


class FamilyReference(NamedTuple):
    """Target trajectories of N robots: x*_j(t) = c_j + a_j sin(ω t + θ_j), ω = 2π / track_period.

    For spatial poses the coordinates are (p, rotation vector); a reference that moves one rotation
    coordinate alone (as Track's pitch) turns about a fixed axis, where ṙ is the angular velocity. A fixed
    target (Reach) has a = 0.

    Attributes:
        center: c, shape (N, m).
        amplitude: a, shape (N, m).
        phase: θ [rad], shape (N, m).
        strokes: The actuator coordinates of c (closed-form inverse kinematics, ``generic.strokes_batch``),
            shape (N, n), or None: ``initial_state`` fills it. The observation's stroke errors read it while a
            target is fixed, so that a crank's inverse kinematics is solved once per episode, not once per step.
    """

    center: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    strokes: np.ndarray | None = None


def with_strokes(params: FamilyParams, reference: FamilyReference) -> FamilyReference:
    """``reference`` with its ``strokes`` (computed from its centres if they are missing)."""
    if reference.strokes is not None:
        return reference
    return reference._replace(strokes=fk.strokes_batch(params.packed, np.ascontiguousarray(reference.center)))


class FamilyState(NamedTuple):
    """State of N robots.

    Attributes:
        q: Leg lengths [m], shape (N, n).
        x: Platform poses of {P} in {B}, shape (N, m).
        t: Steps taken in the episode, shape (N,) (int).
        det_sign: sign(det J_x) at the start of the episode (the working mode), shape (N,).
        inverse_condition: Homogeneous inverse condition number k at (q, x) (Type II measure), shape (N,).
        actuator_condition: Actuator condition number at (q, x) (Type I measure; 1 for legs), shape (N,).
        residual: Constraint residual max_i |Φ_i| [m²], shape (N,).
        reference: The targets' trajectories.
    """

    q: np.ndarray
    x: np.ndarray
    t: np.ndarray
    det_sign: np.ndarray
    inverse_condition: np.ndarray
    actuator_condition: np.ndarray
    residual: np.ndarray
    reference: FamilyReference


class FamilyOutcome(NamedTuple):
    """What a transition reports besides the new state.

    Attributes:
        action: The applied (clipped) action, shape (N, n).
        q_rate: Achieved stroke rates [m/s], shape (N, n).
        reason: Termination reason codes (``TERMINATION_REASONS``), shape (N,).
        jump: Largest prediction–correction gap ‖(δp, ℓ_c δθ)‖ [m], shape (N,).
    """

    action: np.ndarray
    q_rate: np.ndarray
    reason: np.ndarray
    jump: np.ndarray


def observation_bounds(params: FamilyParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    """Finite float32 bounds of the observation (layout in ``FamilyReachEnv``'s docstring).

    Args:
        params: Environment constants.
        with_velocity: Whether the target velocity is appended (Track).

    Returns:
        (low, high), read-only float32 arrays.
    """
    return params.observation_bounds[bool(with_velocity)]


def _rows(a: Any, width: int, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (N, {width}), got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def check_state(params: FamilyParams, state: FamilyState) -> int:
    """N, after checking that every array of ``state`` has the shape the kernels index (they do not check).

    Raises:
        ValueError: Naming every array's shape, if one of them does not fit one N and the robot's n and m.
    """
    n_rows = state.q.shape[0]
    n, m = params.robot.n_actuators, params.robot.n_pose
    ref = state.reference
    rows, pose, flat = (n_rows, n), (n_rows, m), (n_rows,)
    strokes = rows if ref.strokes is None else ref.strokes.shape
    got = (*(field.shape for field in state[:-1]), ref.center.shape, ref.amplitude.shape, ref.phase.shape, strokes)
    if got != (rows, pose, flat, flat, flat, flat, flat, pose, pose, pose, rows):
        shapes = {name: np.shape(v) for name, v in zip(FamilyState._fields, state) if name != "reference"}
        shapes.update({f"reference.{name}": np.shape(v) for name, v in zip(FamilyReference._fields, ref)})
        raise ValueError(f"state arrays must have shapes (N, {n}), (N, {m}) or (N,) with one N, got {shapes}")
    return n_rows


def _motion(state: FamilyState) -> tuple[np.ndarray, ...]:
    """The state arrays the transition kernels take: (q, x, t, det_sign, residual)."""
    return state.q, state.x, state.t, state.det_sign, state.residual


def initial_state(params: FamilyParams, start: np.ndarray, reference: FamilyReference) -> FamilyState:
    """State of N robots at rest at ``start`` (shape (N, m)), strokes from the inverse kinematics."""
    start = _rows(start, params.robot.n_pose, "start")
    q, k, k1, det_sign, residual = fk.initial_batch(params.packed, start)
    reference = with_strokes(params, reference)
    return FamilyState(q, start.copy(), np.zeros(len(start), dtype=np.int64), det_sign, k, k1, residual, reference)


def transition(params: FamilyParams, state: FamilyState, action: np.ndarray) -> tuple[FamilyState, FamilyOutcome]:
    """Advance N robots by one control period: predict, correct, measure, terminate.

    Strokes advance by the clipped action · max_rate · dt, clamped to the hard stops; the step is split into
    substeps of at most ``max_substep`` of predicted motion; each predicts the pose with the twist
    J_f(q, x) q̇ (Euler or RK4, on the rotation group) and corrects it onto Φ = 0 by Newton's method. A robot
    whose correction fails stays where it was; the others are checked for an assembly-mode jump, a flip of
    sign(det J_x), k < hard_threshold and leaving the pose bounds, in that order.

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, n), finite.

    Returns:
        (the new state, the outcome).
    """
    action = _rows(action, params.robot.n_actuators, "action")
    if action.shape[0] != check_state(params, state):
        raise ValueError(f"action must have shape {state.q.shape}, got {action.shape}")
    if not np.isfinite(action).all():
        rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
        raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}", rows)
    q, x, k, k1, residual, a, q_rate, reason, jump = fk.transition_batch(params.packed, _motion(state), action)
    new = FamilyState(q, x, state.t + 1, state.det_sign, k, k1, residual, state.reference)
    return new, FamilyOutcome(a, q_rate, reason, jump)


def evaluate(
    params: FamilyParams, state: FamilyState, action: np.ndarray, reason: np.ndarray, with_velocity: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Reward terms, errors, success, cost, targets and observations of a state, in one compiled pass.

    Args:
        params: Environment constants.
        state: The robots' state.
        action: The applied actions, shape (N, n).
        reason: Termination reason codes, shape (N,).
        with_velocity: Whether the observation ends with the target velocity.

    Returns:
        (evaluation (rows of ``params.evaluation_rows``, N) float64, observations (N, D) float32).
    """
    action = _rows(action, params.robot.n_actuators, "action")
    reason = np.asarray(reason, dtype=np.int64)
    n = check_state(params, state)
    if action.shape[0] != n or reason.shape != (n,):
        raise ValueError(f"action and reason must have {n} rows, got shapes {action.shape} and {reason.shape}")
    low, high = observation_bounds(params, with_velocity)
    ref = with_strokes(params, state.reference)
    measured = (state.q, state.x, state.t, state.inverse_condition, state.actuator_condition, state.residual)
    outcome = (action, reason)
    return fk.evaluate_batch(params.packed, (low, high, bool(with_velocity)), measured, tuple(ref), outcome)


def reward_terms(
    params: FamilyParams,
    x: np.ndarray,
    target: np.ndarray,
    inverse_condition: np.ndarray,
    action: np.ndarray,
    reason: np.ndarray,
    actuator_condition: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Every term of the reward of N poses against fixed targets (what HER's ``compute_reward`` calls).

    Args:
        params: Environment constants.
        x: Poses, shape (N, m).
        target: Target poses, shape (N, m).
        inverse_condition: k, shape (N,).
        action: Applied actions, shape (N, n).
        reason: Termination reason codes, shape (N,).
        actuator_condition: k_I, shape (N,) (default 1: no Type I penalty, as for legs).

    Returns:
        The ``REWARD_TERMS``, each shape (N,).
    """
    m = params.robot.n_pose
    x, target = _rows(x, m, "x"), _rows(target, m, "target")
    n = len(x)
    k = np.asarray(inverse_condition, dtype=np.float64).reshape(n)
    k1 = np.ones(n) if actuator_condition is None else np.asarray(actuator_condition, dtype=np.float64).reshape(n)
    ref = FamilyReference(target, np.zeros((n, m)), np.zeros((n, m)))
    strokes = np.full((n, m), np.mean(params.stroke_limits))
    state = FamilyState(strokes, x, np.zeros(n, dtype=np.int64), np.ones(n), k, k1, np.zeros(n), ref)
    evaluation, _ = evaluate(params, state, action, reason, False)
    rows = params.evaluation_rows
    return {name: evaluation[rows[name]].copy() for name in REWARD_TERMS}


class StepBuffers:
    """Output arrays of ``step`` for N robots, reused by every step (an env alternates two of them)."""

    def __init__(self, params: FamilyParams, n: int, with_velocity: bool) -> None:
        obs_dim = observation_bounds(params, with_velocity)[0].shape[0]
        self.arrays = fk.allocate_step(n, params.robot.n_pose, obs_dim)
        q, x, t, k, k1, residual, a, q_rate, reason, jump, evaluation, observations = self.arrays
        self.outcome = FamilyOutcome(a, q_rate, reason, jump)
        self.evaluation, self.observations = evaluation, observations
        self.fields = (q, x, t, k, k1, residual)
        self.shape = (n, params.robot.n_pose, obs_dim)


def step(
    params: FamilyParams,
    state: FamilyState,
    action: np.ndarray,
    with_velocity: bool,
    out: StepBuffers | None = None,
    *,
    validate: bool = True,
) -> tuple[FamilyState, FamilyOutcome, np.ndarray, np.ndarray]:
    """``transition`` then ``evaluate``, fused in one compiled pass (on every core for large N).

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, n), float64.
        with_velocity: Whether the observation ends with the target velocity.
        out: Buffers to write into (none of them may hold ``state``), or None.
        validate: Check the state's and the buffers' shapes (``check_state``). The envs pass False for the
            state they hold, which ``initial_state`` and ``step`` made with the right shapes.

    Returns:
        (new state, outcome, evaluation, observations).

    Raises:
        NonFiniteActionError: If an action is not finite (``state`` is untouched).
    """
    n = check_state(params, state) if validate else state.q.shape[0]
    if action.shape != state.q.shape or action.dtype != np.float64:
        action = _rows(action, params.robot.n_actuators, "action")
        if action.shape[0] != n:
            raise ValueError(f"action must have shape {state.q.shape}, got {action.shape}")
    if out is None:
        out = StepBuffers(params, n, with_velocity)
    elif validate and out.shape != (n, params.robot.n_pose, observation_bounds(params, with_velocity)[0].shape[0]):
        raise ValueError(f"out holds buffers of shape (N, m, D) = {out.shape}, the step needs N = {n}")
    ref = with_strokes(params, state.reference)
    low, high = observation_bounds(params, with_velocity)
    observation = (low, high, bool(with_velocity))
    bad = fk.step_batch(params.packed, observation, _motion(state), tuple(ref), action, out.arrays)
    if bad:
        rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
        where = f" (row(s) {rows[:10].tolist()} of {n})" if n > 1 else ""
        raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}{where}", rows)
    q, x, t, k, k1, residual = out.fields
    return FamilyState(q, x, t, state.det_sign, k, k1, residual, ref), out.outcome, out.evaluation, out.observations


def copy_state(state: FamilyState) -> FamilyState:
    """A deep copy of ``state`` (every array copied)."""
    ref = FamilyReference(*(None if a is None else a.copy() for a in state.reference))
    return FamilyState(*(a.copy() for a in state[:-1]), ref)


def step_info(params: FamilyParams, evaluation: np.ndarray, reason: np.ndarray) -> dict[str, np.ndarray]:
    """Per-robot info arrays (leading dimension N) from an evaluation, in the single env's key order.

    ``INFO_KEYS`` in order (``is_success`` as bools, the reasons as names, pose and target as (N, m)), the Type I
    entries last.
    """
    rows = params.evaluation_rows
    info = {name: evaluation[rows[name]].copy() for name in INFO_KEYS if name not in TYPE_I_INFO}
    info["is_success"] = info["is_success"] != 0.0
    info["termination_reason"] = _REASON_NAMES[reason]
    info["pose"] = evaluation[rows["pose"]].T.copy()
    info["target"] = evaluation[rows["target"]].T.copy()
    for name in TYPE_I_INFO:
        info[name] = evaluation[rows[name]].copy()
    return info
