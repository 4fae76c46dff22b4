"""Pure, batched dynamics, reward, termination and observation of the planar 3-RPR environments.

The ``phys2d`` pattern of Gymnasium: parameters live in a frozen dataclass, the state in arrays with a
leading batch dimension N, and every function here is pure. The single environment calls them with
N = 1, the native vector environment with N robots; nothing is copied between the two.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from kinematics import Planar3RPR

__all__ = [
    "TERMINATION_REASONS",
    "EnvParams",
    "Reference",
    "State",
    "StepOutcome",
    "observation",
    "observation_bounds",
    "reference_pose",
    "reward_terms",
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
)
NEWTON_FAILED, ASSEMBLY_MODE_CHANGE, SINGULARITY_CROSSED, SINGULAR, OUT_OF_BOUNDS = range(1, 6)


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
    omega = 2.0 * np.pi / params.track_period
    wt = omega * t * params.dt
    angle = wt + reference.phase
    r, a = reference.radius, reference.amplitude
    pose = reference.center + np.stack([r * np.cos(angle), r * np.sin(angle), a * np.sin(wt)], axis=-1)
    velocity = omega * np.stack([-r * np.sin(angle), r * np.cos(angle), a * np.cos(wt)], axis=-1)
    return pose, velocity


def _pose_rate(robot: Planar3RPR, q: np.ndarray, x: np.ndarray, q_rate: np.ndarray) -> np.ndarray:
    """ẋ = J_f(q, x) q̇, shape (N, 3); NaN where J_x is exactly singular."""
    J_f = robot.forward_jacobian(q, x, validate=False)
    return np.einsum("nij,nj->ni", J_f, q_rate)


def _predict(
    params: EnvParams, q: np.ndarray, x: np.ndarray, q_rate: np.ndarray, h: np.ndarray, rate: np.ndarray | None = None
) -> np.ndarray:
    """Integrate ẋ = J_f(q(τ), x) q̇ over a time h with q(τ) = q + q̇ τ (Euler or classic RK4).

    Args:
        params: Environment constants (robot, integrator).
        q: Strokes at the start [m], shape (M, 3).
        x: Poses at the start, shape (M, 3).
        q_rate: Stroke rates [m/s], shape (M, 3).
        h: Time to integrate over [s], shape (M, 1).
        rate: ẋ = J_f(q, x) q̇ at the start if already known, shape (M, 3) (saves one J_f).

    Returns:
        Predicted poses, shape (M, 3); NaN where J_x is exactly singular.
    """
    robot = params.robot
    k1 = _pose_rate(robot, q, x, q_rate) if rate is None else rate
    if params.integrator == "euler":
        return x + h * k1
    k2 = _pose_rate(robot, q + 0.5 * h * q_rate, x + 0.5 * h * k1, q_rate)
    k3 = _pose_rate(robot, q + 0.5 * h * q_rate, x + 0.5 * h * k2, q_rate)
    k4 = _pose_rate(robot, q + h * q_rate, x + h * k3, q_rate)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


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
    if rate is None:
        rate = _pose_rate(params.robot, q, x, q_rate)
    with np.errstate(invalid="ignore", over="ignore"):
        motion = np.linalg.norm(rate * params.dt * params.pose_metric, axis=-1)
        count = np.ceil(motion / params.max_substep)
    return np.where(np.isfinite(count), np.clip(count, 1, params.max_substeps), params.max_substeps).astype(np.int64)


def conditioning(params: EnvParams, q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse condition number of the homogeneous Jacobian and sign(det J_x).

    Args:
        params: Environment constants (the robot).
        q: Strokes [m], shape (N, 3).
        x: Poses, shape (N, 3).

    Returns:
        (inverse condition number (N,) in [0, 1], sign of det J_x (N,) in {−1, 0, 1}).
    """
    inverse_condition, det = params.robot.singularity_measures(q, x, validate=False)
    return inverse_condition, np.sign(det)


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

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, 3), finite.

    Returns:
        (the new state, the step's outcome).
    """
    robot = params.robot
    a = np.clip(action, -1.0, 1.0)
    lo, hi = params.stroke_limits
    q_new = np.clip(state.q + a * (params.max_rate * params.dt), lo, hi)
    q_rate = (q_new - state.q) / params.dt
    rate = _pose_rate(robot, state.q, state.x, q_rate)  # ẋ at the start: sizes the substeps, starts the first
    count = substep_counts(params, state.q, state.x, q_rate, rate)
    q_k, x_k, residual = state.q.copy(), state.x.copy(), state.residual.copy()
    failed = np.zeros(len(count), dtype=bool)
    jump = np.zeros(len(count))
    for k in range(int(count.max())):
        idx = np.flatnonzero((k < count) & ~failed)
        if idx.size == 0:
            break
        n = count[idx][:, None]
        q_to = state.q[idx] + (k + 1) / n * (q_new[idx] - state.q[idx])
        x_pred = _predict(params, q_k[idx], x_k[idx], q_rate[idx], params.dt / n, rate[idx] if k == 0 else None)
        with np.errstate(invalid="ignore", over="ignore"):
            fk = robot.forward_kinematics(
                q_to,
                np.where(np.isfinite(x_pred), x_pred, x_k[idx]),
                tolerance=params.newton_tolerance,
                max_iterations=params.newton_max_iterations,
                validate=False,
            )
        ok = np.asarray(fk.converged) & np.isfinite(x_pred).all(axis=-1)
        gap = np.linalg.norm((fk.x - x_pred) * params.pose_metric, axis=-1)
        jump[idx] = np.maximum(jump[idx], np.where(ok, gap, 0.0))
        failed[idx] = ~ok
        q_k[idx[ok]], x_k[idx[ok]], residual[idx[ok]] = q_to[ok], fk.x[ok], fk.residual[ok]
    q_next = np.where(failed[:, None], state.q, q_k)
    x_next = np.where(failed[:, None], state.x, x_k)
    residual = np.where(failed, state.residual, residual)
    inverse_condition, det_sign = conditioning(params, q_next, x_next)
    out = np.any((x_next < params.pose_low) | (x_next > params.pose_high), axis=-1)
    reason = np.select(
        [
            failed,
            jump > params.jump_tolerance,
            det_sign != state.det_sign,
            inverse_condition < params.hard_threshold,
            out,
        ],
        [NEWTON_FAILED, ASSEMBLY_MODE_CHANGE, SINGULARITY_CROSSED, SINGULAR, OUT_OF_BOUNDS],
        default=0,
    )
    new_state = State(
        q=q_next,
        x=x_next,
        t=state.t + 1,
        det_sign=state.det_sign,
        inverse_condition=inverse_condition,
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
    delta = target - x
    return np.hypot(delta[..., 0], delta[..., 1]), np.abs(wrap_angle(delta[..., 2]))


def singularity_penalty(params: EnvParams, inverse_condition: np.ndarray) -> np.ndarray:
    """((k_safe − k) / k_safe)² below the safe threshold k_safe, 0 above (C¹ at k_safe).

    Args:
        params: Environment constants (safe_threshold).
        inverse_condition: k, any shape.

    Returns:
        Penalty in [0, 1], same shape.
    """
    gap = np.maximum(params.safe_threshold - inverse_condition, 0.0) / params.safe_threshold
    return gap * gap


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
             − w_s ((k_safe − k)/k_safe)² [k < k_safe]           singularity
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
    position_error, orientation_error = tracking_errors(params, x, target)
    l_c = params.robot.characteristic_length
    return {
        "reward_tracking": -(
            params.position_weight * position_error + params.orientation_weight * l_c * orientation_error
        ),
        "reward_singularity": -params.singularity_weight * singularity_penalty(params, inverse_condition),
        "reward_action": -params.action_weight * np.sum(action * action, axis=-1),
        "reward_termination": -params.termination_penalty * (reason != 0),
    }


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
    return (position_error <= params.success_position_tolerance) & (
        orientation_error <= params.success_orientation_tolerance
    )


@functools.lru_cache(maxsize=64)
def observation_bounds(params: EnvParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    """Finite bounds of the observation vector (see ``observation`` for the layout).

    Args:
        params: Environment constants (pose bounds, track period).
        with_velocity: Whether the target velocity is appended (Track).

    Returns:
        (low, high), each float32 of shape (18,) or (21,), read-only (cached per params).
    """
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
    x = state.x
    lo, hi = params.stroke_limits
    parts = [
        x[:, :2],
        np.cos(x[:, 2:3]),
        np.sin(x[:, 2:3]),
        target[:, :2],
        np.cos(target[:, 2:3]),
        np.sin(target[:, 2:3]),
        target[:, :2] - x[:, :2],
        wrap_angle(target[:, 2:3] - x[:, 2:3]),
        2.0 * (state.q - lo) / (hi - lo) - 1.0,
        (params.robot.inverse_kinematics(target, validate=False) - state.q) / (hi - lo),
        state.inverse_condition[:, None],
    ]
    if with_velocity:
        parts.append(velocity)
    low, high = observation_bounds(params, with_velocity)
    return np.clip(np.concatenate(parts, axis=-1), low, high).astype(np.float32)
