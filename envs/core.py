"""Pure, batched dynamics, reward, termination and observation of the planar 3-RPR environments.

The ``phys2d`` pattern of Gymnasium: parameters live in a frozen dataclass, the state in arrays with a
leading batch dimension N, and every function here is pure. The single environment calls them with
N = 1, the native vector environment with N robots, the shield, the evaluation harness and the tests
as well; nothing is copied between them.

The work is done robot by robot by the compiled kernels of ``envs.kernels`` (Numba; on every core for
large N); this module checks shapes, allocates the outputs and names the results. ``step`` fuses
``transition`` and ``evaluate`` (reward terms, errors, success, cost and observation) in one pass, which
is what the environments call on their hot path. The first call in a fresh checkout compiles the
kernels (about 10 s); Numba caches them next to the source afterwards.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from envs import kernels
from kinematics import Planar3RPR

__all__ = [
    "EVALUATION_ROWS",
    "REWARD_TERMS",
    "TERMINATION_REASONS",
    "EnvParams",
    "NonFiniteActionError",
    "Reference",
    "State",
    "StepBuffers",
    "StepOutcome",
    "batch3",
    "copy_state",
    "evaluate",
    "observation",
    "observation_bounds",
    "reference_pose",
    "reward_terms",
    "step",
    "substep_counts",
    "success",
    "transition",
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
#: Names of the reward terms, in the order they are summed.
REWARD_TERMS = ("reward_tracking", "reward_singularity", "reward_action", "reward_termination")


def batch3(a: np.ndarray) -> np.ndarray:
    """``a`` as a float64 array of shape (N, 3) (no copy when it already is one), or a ValueError.

    Args:
        a: Poses, strokes or actions, shape (N, 3).

    Returns:
        The float64 array.
    """
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"expected an array of shape (N, 3), got shape {a.shape}")
    return a


def _batch_size(**arrays: np.ndarray) -> int:
    """The common leading dimension N of ``arrays`` (the kernels index them without bounds checks)."""
    sizes = {name: np.shape(value)[0] if np.ndim(value) else None for name, value in arrays.items()}
    n = next(iter(sizes.values()))
    if n is None or any(size != n for size in sizes.values()):
        raise ValueError(f"arrays must share their leading batch dimension N, got {sizes}")
    return n


class NonFiniteActionError(ValueError):
    """An action given to ``step`` is NaN or infinite; ``rows`` are the robots (indices into N) concerned."""

    def __init__(self, message: str, rows: np.ndarray) -> None:
        """Keep the message and the offending rows (int array)."""
        super().__init__(message)
        self.rows = rows


@dataclass(frozen=True)
class EnvParams:
    """Every constant of an environment (see the env class docstrings for the meaning and units).

    Attributes:
        robot: The mechanism (geometry and characteristic length ℓ_c).
        stroke_limits: (L_min, L_max) hard stops of every actuator [m].
        dt: Control period [s].
        max_rate: Stroke rate commanded by an action of ±1 [m/s].
        integrator: "euler" (the lesson's ẋ = J_f q̇ step) or "rk4".
        pose_low: Lower workspace bounds (x [m], y [m], φ [rad]).
        pose_high: Upper workspace bounds (x [m], y [m], φ [rad]).
        safe_threshold: Inverse condition number below which the singularity penalty and cost start.
        hard_threshold: Inverse condition number below which the episode terminates.
        position_weight: Weight of the position error [1/m].
        orientation_weight: Weight of ℓ_c · |orientation error| [1/m].
        singularity_weight: Weight of the conditioning penalty.
        action_weight: Weight of ‖a‖².
        termination_penalty: Subtracted once when the episode terminates.
        success_position_tolerance: Position error counted as success [m].
        success_orientation_tolerance: Orientation error counted as success [rad].
        newton_tolerance: Constraint residual max_i |Φ_i| the correction reaches [m²].
        newton_max_iterations: Newton iterations allowed per step.
        jump_tolerance: Largest ‖(Δx, Δy, ℓ_c Δφ)‖ between prediction and correction [m] before the
            step counts as a change of assembly mode.
        max_substep: Largest platform motion ‖(Δx, Δy, ℓ_c Δφ)‖ [m] predicted in one substep.
        max_substeps: Largest number of substeps per control period.
        track_period: Period of the Track reference [s].
    """

    robot: Planar3RPR = field(default_factory=Planar3RPR)
    stroke_limits: tuple[float, float] = (0.3, 1.0)
    dt: float = 0.05
    max_rate: float = 0.25
    integrator: str = "euler"
    pose_low: tuple[float, float, float] = (-0.2, -0.3, -np.pi / 2)
    pose_high: tuple[float, float, float] = (1.2, 1.2, np.pi / 2)
    safe_threshold: float = 0.15
    hard_threshold: float = 0.03
    position_weight: float = 1.0
    orientation_weight: float = 1.0
    singularity_weight: float = 1.0
    action_weight: float = 0.01
    termination_penalty: float = 50.0
    success_position_tolerance: float = 0.02
    success_orientation_tolerance: float = 0.1
    newton_tolerance: float = 1e-12
    newton_max_iterations: int = 8
    jump_tolerance: float = 0.02
    max_substep: float = 0.01
    max_substeps: int = 16
    track_period: float = 10.0

    @functools.cached_property
    def packed(self) -> np.ndarray:
        """Every constant as the compiled kernels' float64 vector (``envs.kernels.pack_params``), read-only."""
        return kernels.pack_params(self)

    @functools.cached_property
    def observation_bounds(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``observation_bounds`` without (index 0) and with (index 1) the target velocity."""
        return _observation_bounds(self, False), _observation_bounds(self, True)

    @property
    def pose_metric(self) -> np.ndarray:
        """(1, 1, ℓ_c): multiplies a pose difference (Δx, Δy, Δφ) into metres (Δx, Δy, ℓ_c Δφ), shape (3,)."""
        return np.array([1.0, 1.0, self.robot.characteristic_length])


class Reference(NamedTuple):
    """Target trajectories of a batch: p*(t) = c + r (cos(ωt + θ), sin(ωt + θ)), φ*(t) = c_φ + a sin(ωt).

    A fixed target (Reach) has r = a = 0. ω = 2π / track_period.

    Attributes:
        center: c = (c_x [m], c_y [m], c_φ [rad]), shape (N, 3).
        radius: r [m], shape (N,).
        phase: θ [rad], shape (N,).
        amplitude: a [rad], shape (N,).
    """

    center: np.ndarray
    radius: np.ndarray
    phase: np.ndarray
    amplitude: np.ndarray


class State(NamedTuple):
    """State of N robots.

    Attributes:
        q: Strokes (L_1, L_2, L_3) [m], shape (N, 3).
        x: Platform pose (x [m], y [m], φ [rad]) of {P} in {B}, shape (N, 3).
        t: Steps taken in the episode, shape (N,) (int).
        det_sign: sign(det J_x) at the start of the episode (the working mode), shape (N,).
        inverse_condition: Homogeneous inverse condition number at (q, x), shape (N,).
        residual: Constraint residual max_i |Φ_i(q, x)| [m²], shape (N,).
        reference: The targets' trajectories.
    """

    q: np.ndarray
    x: np.ndarray
    t: np.ndarray
    det_sign: np.ndarray
    inverse_condition: np.ndarray
    residual: np.ndarray
    reference: Reference


class StepOutcome(NamedTuple):
    """What a transition reports besides the new state.

    Attributes:
        action: The action actually applied (clipped to [−1, 1]), shape (N, 3).
        q_rate: Achieved stroke rates after the hard stops [m/s], shape (N, 3).
        reason: Termination reason code (index into ``TERMINATION_REASONS``), shape (N,).
        jump: Largest ‖(Δx, Δy, ℓ_c Δφ)‖ between a substep's prediction and its Newton correction [m],
            shape (N,).
    """

    action: np.ndarray
    q_rate: np.ndarray
    reason: np.ndarray
    jump: np.ndarray


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap angles to [−π, π).

    Args:
        angle: Angles [rad], any shape.

    Returns:
        Wrapped angles [rad], same shape.
    """
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def reference_pose(params: EnvParams, reference: Reference, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Target pose and velocity at step t.

    Args:
        params: Environment constants (dt, track_period).
        reference: Target trajectories of the batch.
        t: Step index, shape (N,).

    Returns:
        (pose (N, 3) [m, m, rad], velocity (N, 3) [m/s, m/s, rad/s]).
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.int64))
    n = np.broadcast_shapes(t.shape, np.shape(reference.radius))
    if len(n) != 1:
        raise ValueError(f"t must have shape (N,) matching the reference's, got {t.shape}")
    (n,) = n
    center = batch3(reference.center)
    return kernels.reference_batch(
        params.packed,
        np.broadcast_to(t, (n,)),
        np.broadcast_to(center, (n, 3)),
        *(np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)) for v in reference[1:]),
    )


def substep_counts(
    params: EnvParams, q: np.ndarray, x: np.ndarray, q_rate: np.ndarray, rate: np.ndarray | None = None
) -> np.ndarray:
    """Substeps per robot so that each predicts at most ``max_substep`` of platform motion.

    The motion is estimated from ẋ = J_f q̇ at the start of the step, in (x, y, ℓ_c φ) [m]; the count is
    capped at ``max_substeps`` (near a singularity J_f is huge and the step fails anyway).

    Args:
        params: Environment constants.
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).
        q_rate: Achieved stroke rates [m/s], shape (N, 3).
        rate: ẋ = J_f(q, x) q̇ if already known, shape (N, 3).

    Returns:
        Integer counts in [1, max_substeps], shape (N,).
    """
    q, x, q_rate = batch3(q), batch3(x), batch3(q_rate)
    rate = None if rate is None else batch3(rate)
    _batch_size(q=q, x=x, q_rate=q_rate, **({} if rate is None else {"rate": rate}))
    return kernels.substep_batch(params.packed, q, x, q_rate, rate)


def conditioning(params: EnvParams, q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse condition number of the homogeneous Jacobian and sign(det J_x).

    k = σ_min/σ_max of J_i diag(1, 1, 1/ℓ_c) (the robot's ``inverse_condition_number``).

    Args:
        params: Environment constants (the robot).
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).

    Returns:
        (inverse condition number (N,) in [0, 1], sign of det J_x (N,) in {−1, 0, 1}).
    """
    q, x = batch3(q), batch3(x)
    _batch_size(q=q, x=x)
    return kernels.singularity_batch(params.packed, q, x)


def transition(params: EnvParams, state: State, action: np.ndarray) -> tuple[State, StepOutcome]:
    """Advance N robots by one control period.

    1. a is clipped to [−1, 1]; strokes advance by a · max_rate · dt and are clamped to the stroke
       limits (hard stops), so the rate used is the achieved one, q̇ = (q' − q) / dt.
    2. The step is split into substeps so that each moves the platform by at most ``max_substep``
       (``substep_counts``; one substep in most of the workspace). In each, the pose is predicted with
       ẋ = J_f(q, x) q̇ (the lesson's Euler step, or RK4), then corrected onto Φ(q_k, x) = 0 by
       Newton's method warm-started at the prediction: a path-following (continuation) scheme that
       stays on the robot's branch of solutions.
    3. A robot whose correction fails is put back where it was at the start of the step (and
       terminates); the others are checked, in this order, for a jump between a prediction and its
       correction larger than ``jump_tolerance`` (a change of assembly mode), a flip of sign(det J_x)
       (a crossed Type II singularity), an inverse condition number below ``hard_threshold``, and a
       pose outside the bounds.

    The work is done per robot by the compiled kernel ``envs.kernels.transition_batch`` (on every core
    for large N).

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, 3), finite.

    Returns:
        (the new state, the step's outcome).
    """
    action = batch3(action)
    _batch_size(q=state.q, x=state.x, det_sign=state.det_sign, residual=state.residual, action=action)
    q, x, k, residual, a, q_rate, reason, jump = kernels.transition_batch(
        params.packed, state.q, state.x, state.det_sign, state.residual, action
    )
    new_state = State(
        q=q,
        x=x,
        t=state.t + 1,
        det_sign=state.det_sign,
        inverse_condition=k,
        residual=residual,
        reference=state.reference,
    )
    return new_state, StepOutcome(action=a, q_rate=q_rate, reason=reason, jump=jump)


def tracking_errors(params: EnvParams, x: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error ‖p* − p‖ [m] and orientation error |wrap(φ* − φ)| [rad], each shape (N,).

    Args:
        params: Environment constants (unused; kept for a uniform signature).
        x: Poses, shape (N, 3).
        target: Target poses, shape (N, 3).

    Returns:
        (position error (N,) [m], orientation error (N,) [rad]).
    """
    x, target = batch3(x), batch3(target)
    _batch_size(x=x, target=target)
    return kernels.errors_batch(x, target)


def reward_terms(
    params: EnvParams,
    x: np.ndarray,
    target: np.ndarray,
    inverse_condition: np.ndarray,
    action: np.ndarray,
    reason: np.ndarray,
) -> dict[str, np.ndarray]:
    """Every term of the reward; the reward is their sum.

    reward = −(w_p ‖p* − p‖ + w_φ ℓ_c |wrap(φ* − φ)|)         tracking
             − w_s ((k_safe − k)/k_safe)² [k < k_safe]           singularity (C¹ at k_safe)
             − w_a ‖a‖²                                          action
             − P [terminated]                                    termination

    Args:
        params: Environment constants (weights, thresholds).
        x: Poses, shape (N, 3).
        target: Target poses, shape (N, 3).
        inverse_condition: k, shape (N,).
        action: Applied (clipped) actions, shape (N, 3).
        reason: Termination reason codes, shape (N,).

    Returns:
        {"reward_tracking", "reward_singularity", "reward_action", "reward_termination"}, each (N,).
    """
    x, target, action = batch3(x), batch3(target), batch3(action)
    inverse_condition = np.asarray(inverse_condition, dtype=np.float64)
    reason = np.asarray(reason, dtype=np.int64)
    _batch_size(x=x, target=target, inverse_condition=inverse_condition, action=action, reason=reason)
    terms = kernels.terms_batch(params.packed, x, target, inverse_condition, action, reason)
    return dict(zip(REWARD_TERMS, terms.T.copy()))


def success(params: EnvParams, x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Whether each pose is within the success tolerances of its target, shape (N,) (bool).

    Args:
        params: Environment constants (success tolerances).
        x: Poses, shape (N, 3).
        target: Target poses, shape (N, 3).

    Returns:
        Boolean array, shape (N,).
    """
    position_error, orientation_error = tracking_errors(params, x, target)
    return kernels.success_batch(params.packed, position_error, orientation_error)


def observation_bounds(params: EnvParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    """Finite bounds of the observation vector (see ``observation`` for the layout).

    Args:
        params: Environment constants (pose bounds, track period).
        with_velocity: Whether the target velocity is appended (Track).

    Returns:
        (low, high), each float32 of shape (18,) or (21,), read-only (computed once per params).
    """
    return params.observation_bounds[bool(with_velocity)]


def _observation_bounds(params: EnvParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    low_p, high_p = np.array(params.pose_low), np.array(params.pose_high)
    span = high_p[:2] - low_p[:2]
    pose_lo = [low_p[0], low_p[1], -1.0, -1.0]
    pose_hi = [high_p[0], high_p[1], 1.0, 1.0]
    low = [*pose_lo, *pose_lo, -span[0], -span[1], -np.pi, *[-1.0] * 6, 0.0]
    high = [*pose_hi, *pose_hi, span[0], span[1], np.pi, *[1.0] * 6, 1.0]
    if with_velocity:
        # |ṗ*| ≤ ω · max(span)/2 and |φ̇*| ≤ ω · (φ_max − φ_min)/2 for every admissible reference.
        omega = 2.0 * np.pi / params.track_period
        v_max = omega * float(np.max(span)) / 2.0
        w_max = omega * float(high_p[2] - low_p[2]) / 2.0
        low += [-v_max, -v_max, -w_max]
        high += [v_max, v_max, w_max]
    low_arr, high_arr = np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)
    low_arr.setflags(write=False)
    high_arr.setflags(write=False)
    return low_arr, high_arr


def observation(
    params: EnvParams, state: State, target: np.ndarray, velocity: np.ndarray, with_velocity: bool
) -> np.ndarray:
    """The observation vector of N robots, float32, clipped to ``observation_bounds``.

    Layout: [0:4] pose (x, y, cos φ, sin φ); [4:8] target (x*, y*, cos φ*, sin φ*);
    [8:11] error (x* − x, y* − y, wrap(φ* − φ)); [11:14] strokes normalised to [−1, 1];
    [14:17] stroke error (q(x*) − q) / (L_max − L_min), with q(x*) the target's inverse kinematics;
    [17] inverse condition number; [18:21] (Track only) target velocity (ẋ*, ẏ*, φ̇*).

    Args:
        params: Environment constants.
        state: The robots' state.
        target: Target poses at the state's step (``reference_pose``), shape (N, 3).
        velocity: Target velocities at the state's step, shape (N, 3).
        with_velocity: Whether to append the target velocity.

    Returns:
        Observations, shape (N, 18) or (N, 21), float32.
    """
    low, high = observation_bounds(params, with_velocity)
    target, velocity = batch3(target), batch3(velocity)
    _batch_size(q=state.q, x=state.x, k=state.inverse_condition, target=target, velocity=velocity)
    return kernels.observation_batch(
        params.packed, low, high, with_velocity, state.q, state.x, state.inverse_condition, target, velocity
    )


#: Rows of the evaluation returned by ``evaluate`` and ``step`` (``envs.kernels.E_*``; column i is robot i):
#: the four reward terms, their sum, the errors, success, cost, the target pose and velocity, the
#: inverse condition number, the constraint residual and the pose.
EVALUATION_ROWS = {
    "reward_tracking": kernels.E_TRACKING,
    "reward_singularity": kernels.E_SINGULARITY,
    "reward_action": kernels.E_ACTION,
    "reward_termination": kernels.E_TERMINATION,
    "reward": kernels.E_REWARD,
    "position_error": kernels.E_POSITION_ERROR,
    "orientation_error": kernels.E_ORIENTATION_ERROR,
    "is_success": kernels.E_SUCCESS,
    "cost": kernels.E_COST,
    "target": slice(kernels.E_TARGET, kernels.E_TARGET + 3),
    "target_velocity": slice(kernels.E_VELOCITY, kernels.E_VELOCITY + 3),
    "inverse_condition_number": kernels.E_K,
    "constraint_residual": kernels.E_RESIDUAL,
    "pose": slice(kernels.E_POSE, kernels.E_POSE + 3),
}


class _BufferState(State):
    """A State over the arrays of a ``StepBuffers``, consistent by construction.

    Its own arrays are allocated for N robots; det_sign and reference come from a state that passed
    ``_check_state``. ``_replace`` (and ``_make``) give a plain State, which is checked again.
    """

    __slots__ = ()

    @classmethod
    def _make(cls, iterable: Any) -> State:
        return State._make(iterable)


def copy_state(state: State) -> State:
    """A deep copy of ``state`` (every array copied), for handing out a state the env will overwrite.

    Args:
        state: The robots' state.

    Returns:
        A plain State with fresh arrays.
    """
    reference = Reference(*(field.copy() for field in state.reference))
    return State(*(field.copy() for field in state[:-1]), reference)


def _check_state(state: State, action: np.ndarray | None = None) -> int:
    """N, after checking that every array of ``state`` (and ``action``) has the shape the kernels index."""
    n = state.q.shape[0]
    if type(state) is _BufferState and (action is None or action.shape == (n, 3)):
        return n
    rows, flat = (n, 3), (n,)
    ref = state.reference
    if (
        (state.q.shape, state.x.shape, ref.center.shape) != (rows, rows, rows)
        or (
            state.t.shape,
            state.det_sign.shape,
            state.inverse_condition.shape,
            state.residual.shape,
            ref.radius.shape,
            ref.phase.shape,
            ref.amplitude.shape,
        )
        != (flat, flat, flat, flat, flat, flat, flat)
        or (action is not None and action.shape != rows)
    ):
        shapes = {name: np.shape(value) for name, value in zip(State._fields, state) if name != "reference"}
        shapes.update({f"reference.{name}": np.shape(value) for name, value in zip(Reference._fields, ref)})
        if action is not None:
            shapes["action"] = action.shape
        raise ValueError(f"state arrays must have shapes (N, 3) or (N,) with one N, got {shapes}")
    return n


def evaluate(
    params: EnvParams, state: State, action: np.ndarray, reason: np.ndarray, with_velocity: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Everything the environments report about a state, in one compiled pass.

    Equivalent to ``reference_pose``, ``reward_terms``, ``tracking_errors``, ``success`` (and reason == 0),
    cost (k < safe_threshold) and ``observation``, which share its kernels.

    Args:
        params: Environment constants.
        state: The robots' state.
        action: The applied actions, shape (N, 3).
        reason: Termination reason codes, shape (N,).
        with_velocity: Whether the observation ends with the target velocity.

    Returns:
        (evaluation, shape (len(E), N) float64 with the rows of ``EVALUATION_ROWS``;
        observations, shape (N, 18) or (N, 21) float32).
    """
    action = batch3(action)
    reason = np.asarray(reason, dtype=np.int64)
    n = _check_state(state, action)
    if reason.shape != (n,):
        raise ValueError(f"reason must have shape ({n},), got {reason.shape}")
    low, high = params.observation_bounds[bool(with_velocity)]
    ref = state.reference
    return kernels.evaluate_batch(
        params.packed,
        low,
        high,
        bool(with_velocity),
        state.q,
        state.x,
        state.t,
        state.inverse_condition,
        state.residual,
        ref.center,
        ref.radius,
        ref.phase,
        ref.amplitude,
        action,
        reason,
    )


class StepBuffers:
    """Output arrays of ``step`` for N robots, allocated once and overwritten by every ``step(..., out=self)``.

    An environment that owns two of them and alternates (``step`` must not write over its input
    state) steps without allocating; what it hands out (observations, infos, ``state``) it copies.

    Args:
        n: Number of robots.
        with_velocity: Whether the observations end with the target velocity.
    """

    def __init__(self, n: int, with_velocity: bool) -> None:
        """Allocate the arrays; see the class docstring."""
        self.arrays = kernels.allocate_step(n, 21 if with_velocity else 18)
        q, x, t, k, residual, a, q_rate, reason, jump, evaluation, observations = self.arrays
        self.outcome = StepOutcome(a, q_rate, reason, jump)
        self.evaluation, self.observations = evaluation, observations
        self._fields = (q, x, t, k, residual)
        self._state: State | None = None

    def state(self, det_sign: np.ndarray, reference: Reference) -> State:
        """The State over these arrays with the episode's ``det_sign`` and ``reference`` (built once per episode)."""
        state = self._state
        if state is None or state.det_sign is not det_sign or state.reference is not reference:
            q, x, t, k, residual = self._fields
            state = self._state = _BufferState(q, x, t, det_sign, k, residual, reference)
        return state


def step(
    params: EnvParams, state: State, action: np.ndarray, with_velocity: bool, out: StepBuffers | None = None
) -> tuple[State, StepOutcome, np.ndarray, np.ndarray]:
    """``transition`` then ``evaluate`` of the new state, fused in one compiled pass (what the envs call).

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, 3), float64, finite.
        with_velocity: Whether the observation ends with the target velocity.
        out: Arrays to write the results into (overwritten; none of them may belong to ``state``), or
            None for fresh ones.

    Returns:
        (new state, outcome, evaluation (len(E), N) float64, observations float32), as ``transition``
        and ``evaluate``.

    Raises:
        NonFiniteActionError: (a ValueError) If an action is not finite (``state`` is untouched; ``out``
            holds garbage). The check is part of the compiled pass, so finite actions cost nothing extra.
    """
    n = _check_state(state, action)
    if out is None:
        out = StepBuffers(n, with_velocity)
    elif out.evaluation.shape[1] != n or out.observations.shape[1] != (21 if with_velocity else 18):
        raise ValueError(f"out holds {out.evaluation.shape[1]} robots of {out.observations.shape[1]} observations")
    ref = state.reference
    bad = kernels.step_batch(
        params.packed,
        *params.observation_bounds[with_velocity],
        with_velocity,
        state.q,
        state.x,
        state.t,
        state.det_sign,
        state.residual,
        ref.center,
        ref.radius,
        ref.phase,
        ref.amplitude,
        action,
        out.arrays,
    )
    if bad:
        rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
        where = f" (row(s) {rows[:10].tolist()} of {n})" if n > 1 else ""
        raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}{where}", rows)
    return out.state(state.det_sign, ref), out.outcome, out.evaluation, out.observations
