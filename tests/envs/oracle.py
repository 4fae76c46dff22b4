"""An independent NumPy oracle of one environment step: dynamics, reward terms, observation and termination reason.

Written from the math of ``docs/environments.md`` and the env docstrings on the ``kinematics`` library alone
(constraints, ``forward_jacobian``, ``forward_kinematics``, ``singularity_measures``,
``actuator_condition_number``, ``retract``, ``pose_difference``, ``inverse_kinematics``) and plain NumPy:

1. a = clip(action, −1, 1); q' = clip(q + a · max_rate · dt, q_min, q_max); q̇ = (q' − q) / dt.
2. Substeps: ⌈‖J_f(q, x) q̇ · dt‖_metric / max_substep⌉ in [1, max_substeps] (max_substeps if not finite),
   with ‖(δp, δθ)‖_metric = ‖(δp, ℓ_c δθ)‖. Each predicts x ⊕ h ẋ (Euler) or the RK4 combination of twists,
   then corrects it onto Φ(q_s, x) = 0 by Newton's method; the step's jump is the largest ‖correction‖_metric.
3. A failed correction (non-finite prediction or no convergence) puts the robot back where it was.
4. k (Type II, σ_min/σ_max of the homogeneous Jacobian), sign(det J_x) and k_I (Type I; 1 for legs) at the new
   (q, x); the first reason that applies, in the documented order: newton_failed, assembly_mode_change,
   singularity_crossed, singular, out_of_bounds, actuator_singular.
5. r = −(w_p e_p + w_o ℓ_c e_o) − w_s ((k_safe − k)/k_safe)² [k < k_safe] − w_a ‖a‖² − P [terminated]
   − w_s1 ((k_I,safe − k_I)/k_I,safe)² [k_I < k_I,safe] + b [not terminated, e_p ≤ tol_p and e_o ≤ tol_o].

Everything this oracle reads from an environment goes through ``settings_of`` and ``state_of`` below (its
``unwrapped.params`` and ``unwrapped.state``): adapting the oracle to a new layout of ``envs`` is done here.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np

#: The termination reasons in the documented order of precedence ("" while the episode goes on).
REASONS = (
    "",
    "newton_failed",
    "assembly_mode_change",
    "singularity_crossed",
    "singular",
    "out_of_bounds",
    "actuator_singular",
)


@dataclasses.dataclass(frozen=True)
class Settings:
    """The constants of an environment the oracle needs (units as in the env docstrings).

    Attributes:
        robot: The ``kinematics`` mechanism.
        type_one: Whether the env reports the Type I terms (``reward_actuator_singularity`` and friends).
        fields: Every other constant, by its constructor name (``stroke_limits``, ``hard_threshold``, ...).
    """

    robot: Any
    type_one: bool
    fields: dict[str, Any]

    def __getattr__(self, name: str) -> Any:
        """A constant by name (``settings.hard_threshold``)."""
        try:
            return self.__dict__["fields"][name]
        except KeyError:
            raise AttributeError(name) from None


_FIELDS = (
    "stroke_limits",
    "dt",
    "max_rate",
    "integrator",
    "pose_low",
    "pose_high",
    "safe_threshold",
    "hard_threshold",
    "position_weight",
    "orientation_weight",
    "singularity_weight",
    "action_weight",
    "termination_penalty",
    "success_reward",
    "success_position_tolerance",
    "success_orientation_tolerance",
    "newton_tolerance",
    "newton_max_iterations",
    "jump_tolerance",
    "max_substep",
    "max_substeps",
)
_TYPE_ONE_FIELDS = ("actuator_safe_threshold", "actuator_hard_threshold", "actuator_singularity_weight")


def settings_of(env: gym.Env) -> Settings:
    """The oracle's constants of ``env`` (read from ``env.unwrapped.params``).

    Args:
        env: A registered environment (wrapped or not).

    Returns:
        The settings; without Type I fields the robot is driven by legs (k_I = 1, no Type I term).
    """
    params = env.unwrapped.params
    fields = {name: getattr(params, name) for name in _FIELDS}
    type_one = all(hasattr(params, name) for name in _TYPE_ONE_FIELDS)
    for name in _TYPE_ONE_FIELDS:
        fields[name] = getattr(params, name) if type_one else 0.0
    return Settings(robot=params.robot, type_one=type_one, fields=fields)


@dataclasses.dataclass(frozen=True)
class StartState:
    """One robot's state before a step.

    Attributes:
        q: Actuator coordinates, shape (n,).
        x: Pose, shape (m,).
        det_sign: The episode's working mode sign(det J_x).
        residual: Constraint residual at (q, x) [m²].
        target: The fixed target pose, shape (m,).
    """

    q: np.ndarray
    x: np.ndarray
    det_sign: float
    residual: float
    target: np.ndarray


def state_of(env: gym.Env) -> StartState:
    """The current state of a single Reach env (read from ``env.unwrapped.state``, batch of one)."""
    state = env.unwrapped.state
    return StartState(
        q=np.array(state.q[0], dtype=np.float64),
        x=np.array(state.x[0], dtype=np.float64),
        det_sign=float(state.det_sign[0]),
        residual=float(state.residual[0]),
        target=np.array(state.reference.center[0], dtype=np.float64),
    )


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What one step gives, by the oracle.

    Attributes:
        q: New actuator coordinates, shape (n,).
        x: New pose, shape (m,).
        k: Inverse condition number (Type II measure) at (q, x).
        k1: Actuator condition number (Type I measure, 1 for legs).
        det_sign: sign(det J_x) at (q, x).
        residual: Constraint residual after the correction [m²].
        jump: Largest prediction–correction gap [m].
        failed: Whether the correction failed.
        out: Whether the pose left its bounds.
        reason: Termination reason ("" if none).
        info: The env's numeric info entries (reward terms, errors, k, k_I, costs, success), by key.
        reward: The reward.
        observation: The observation (float32, clipped to the space's bounds).
    """

    q: np.ndarray
    x: np.ndarray
    k: float
    k1: float
    det_sign: float
    residual: float
    jump: float
    failed: bool
    out: bool
    reason: str
    info: dict[str, Any]
    reward: float
    observation: np.ndarray


def _metric(robot: Any, step: np.ndarray) -> float:
    """‖(δp, ℓ_c δθ)‖ of a twist step [m] (the rotation coordinates divided by the pose scale 1/ℓ_c)."""
    return float(np.linalg.norm(step / robot.pose_scale))


def _rate(robot: Any, q: np.ndarray, x: np.ndarray, q_rate: np.ndarray) -> np.ndarray:
    """The twist ẋ = J_f(q, x) q̇."""
    with np.errstate(all="ignore"):
        return robot.forward_jacobian(q, x, validate=False) @ q_rate


def _predict(settings: Settings, q: np.ndarray, x: np.ndarray, q_rate: np.ndarray, h: float, v: np.ndarray):
    """The pose predicted after h [s] from (q, x) with the twist v there (Euler, or RK4 on the group)."""
    robot = settings.robot
    with np.errstate(all="ignore"):
        if settings.integrator == "euler":
            return robot.retract(x, h * v, validate=False)
        k2 = _rate(robot, q + 0.5 * h * q_rate, robot.retract(x, 0.5 * h * v, validate=False), q_rate)
        k3 = _rate(robot, q + 0.5 * h * q_rate, robot.retract(x, 0.5 * h * k2, validate=False), q_rate)
        k4 = _rate(robot, q + h * q_rate, robot.retract(x, h * k3, validate=False), q_rate)
        return robot.retract(x, h * (v + 2.0 * k2 + 2.0 * k3 + k4) / 6.0, validate=False)


def transition(settings: Settings, start: StartState, action: np.ndarray) -> tuple:
    """One control period from ``start``: (q, x, residual, applied action, jump, failed).

    Args:
        settings: The env's constants.
        start: The state before the step.
        action: The action given to ``step``, shape (n,).

    Returns:
        (q', x', residual', clipped action, jump [m], whether the correction failed).
    """
    robot = settings.robot
    dt = settings.dt
    lo, hi = settings.stroke_limits
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    q0, x0 = start.q, start.x
    q_end = np.clip(q0 + a * (settings.max_rate * dt), lo, hi)
    q_rate = (q_end - q0) / dt
    v = _rate(robot, q0, x0, q_rate)
    with np.errstate(all="ignore"):
        count = math.ceil(_metric(robot, v) * dt / settings.max_substep) if np.all(np.isfinite(v)) else None
    count = settings.max_substeps if count is None else int(min(max(count, 1), settings.max_substeps))
    h = dt / count
    q, x, residual, jump, failed = q0, x0, start.residual, 0.0, False
    for s in range(count):
        q_to = q0 + (s + 1) / count * (q_end - q0)
        if s > 0:
            v = _rate(robot, q, x, q_rate)
        prediction = _predict(settings, q, x, q_rate, h, v)
        if not np.all(np.isfinite(prediction)):
            failed = True
            break
        with np.errstate(all="ignore"):
            fk = robot.forward_kinematics(
                q_to,
                prediction,
                tolerance=settings.newton_tolerance,
                max_iterations=settings.newton_max_iterations,
                validate=False,
            )
        if not bool(fk.converged):
            failed = True
            break
        jump = max(jump, _metric(robot, robot.pose_difference(fk.x, prediction, validate=False)))
        q, x, residual = q_to, np.asarray(fk.x, dtype=np.float64), float(fk.residual)
    if failed:
        q, x, residual = q0, x0, start.residual
    return q, x, residual, a, jump, failed


def measures(settings: Settings, q: np.ndarray, x: np.ndarray) -> tuple[float, float, float]:
    """(k, sign(det J_x), k_I) at (q, x); k_I = 1 for a robot driven by legs."""
    robot = settings.robot
    k, det = robot.singularity_measures(q, x, validate=False)
    legs = all(kind == "leg" for kind in robot.actuator_kinds)
    k1 = 1.0 if legs else float(robot.actuator_condition_number(q, x, validate=False))
    return float(k), float(np.sign(det)), k1


def termination_reason(
    settings: Settings, failed: bool, jump: float, sign: float, mode: float, k: float, out: bool, k1: float
) -> str:
    """The first documented termination reason that applies ("" if none)."""
    if failed:
        return "newton_failed"
    if jump > settings.jump_tolerance:
        return "assembly_mode_change"
    if sign != mode:
        return "singularity_crossed"
    if k < settings.hard_threshold:
        return "singular"
    if out:
        return "out_of_bounds"
    if settings.type_one and k1 < settings.actuator_hard_threshold:
        return "actuator_singular"
    return ""


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def errors(settings: Settings, x: np.ndarray, target: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(position error [m], orientation error [rad], the error vector of the observation)."""
    space = settings.robot.pose_space.name
    if space == "planar":
        error = np.array([target[0] - x[0], target[1] - x[1], _wrap(target[2] - x[2])])
        return math.hypot(error[0], error[1]), abs(error[2]), error
    if space == "translational":
        error = target - x
        return float(np.linalg.norm(error)), 0.0, error
    error = settings.robot.pose_difference(target, x, validate=False)  # (p* − p, rotation vector of R* Rᵀ)
    return float(np.linalg.norm(error[:3])), float(np.linalg.norm(error[3:])), error


def reward_terms(
    settings: Settings, x: np.ndarray, target: np.ndarray, k: float, k1: float, action: np.ndarray, reason: str
) -> dict[str, float]:
    """The reward terms by their info keys (the Type I term only where the env reports it)."""
    position_error, orientation_error, _ = errors(settings, x, target)
    lc = settings.robot.characteristic_length
    terms = {
        "reward_tracking": -(
            settings.position_weight * position_error + settings.orientation_weight * lc * orientation_error
        ),
        "reward_singularity": 0.0,
        "reward_action": -settings.action_weight * float(np.sum(action * action)),
        "reward_termination": -settings.termination_penalty if reason else 0.0,
    }
    success = (
        not reason
        and position_error <= settings.success_position_tolerance
        and orientation_error <= settings.success_orientation_tolerance
    )
    if k < settings.safe_threshold:
        terms["reward_singularity"] = (
            -settings.singularity_weight * ((settings.safe_threshold - k) / settings.safe_threshold) ** 2
        )
    if settings.type_one:
        safe1 = settings.actuator_safe_threshold
        terms["reward_actuator_singularity"] = (
            -settings.actuator_singularity_weight * ((safe1 - k1) / safe1) ** 2 if k1 < safe1 else 0.0
        )
    terms["reward_success"] = settings.success_reward if success else 0.0
    return terms


def _pose_code(space: str, x: np.ndarray) -> list[float]:
    """The observation's pose code: (x, y, cos φ, sin φ), p, or (p, quaternion (w, x, y, z) with w ≥ 0)."""
    if space == "planar":
        return [x[0], x[1], math.cos(x[2]), math.sin(x[2])]
    if space == "translational":
        return list(x)
    angle = float(np.linalg.norm(x[3:]))
    axis = x[3:] / angle if angle > 0 else np.zeros(3)
    quaternion = [math.cos(0.5 * angle), *(math.sin(0.5 * angle) * axis)]
    if quaternion[0] < 0:
        quaternion = [-v for v in quaternion]
    return [*x[:3], *quaternion]


def observation(
    settings: Settings, q: np.ndarray, x: np.ndarray, target: np.ndarray, k: float, space: gym.spaces.Box
) -> np.ndarray:
    """Pose code, target code, error, normalised strokes, stroke errors (q(x*) − q)/span and k, clipped, float32."""
    robot = settings.robot
    lo, hi = settings.stroke_limits
    span = hi - lo
    _, _, error = errors(settings, x, target)
    target_q = robot.inverse_kinematics(target, validate=False)
    name = robot.pose_space.name
    values = np.array(
        [
            *_pose_code(name, x),
            *_pose_code(name, target),
            *error,
            *(2.0 * (q - lo) / span - 1.0),
            *((target_q - q) / span),
            k,
        ]
    )
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    return np.clip(values, low, high).astype(np.float32)


def step(settings: Settings, start: StartState, action: Any, observation_space: gym.spaces.Box) -> Outcome:
    """Everything ``env.step(action)`` returns for a Reach env in state ``start``, by the oracle.

    Args:
        settings: The env's constants (``settings_of``).
        start: The state before the step (``state_of``).
        action: The action, shape (n,).
        observation_space: The env's observation space (its bounds clip the observation).

    Returns:
        The oracle's outcome.
    """
    q, x, residual, a, jump, failed = transition(settings, start, action)
    k, sign, k1 = measures(settings, q, x)
    out = bool(np.any(x < np.asarray(settings.pose_low)) or np.any(x > np.asarray(settings.pose_high)))
    reason = termination_reason(settings, failed, jump, sign, start.det_sign, k, out, k1)
    terms = reward_terms(settings, x, start.target, k, k1, a, reason)
    position_error, orientation_error, _ = errors(settings, x, start.target)
    type_one_cost = settings.type_one and k1 < settings.actuator_safe_threshold
    info = {
        **terms,
        "position_error": position_error,
        "orientation_error": orientation_error,
        "inverse_condition_number": k,
        "is_success": not reason
        and position_error <= settings.success_position_tolerance
        and orientation_error <= settings.success_orientation_tolerance,
        "cost": float(k < settings.safe_threshold or type_one_cost),
    }
    if settings.type_one:
        info["actuator_condition_number"] = k1
        info["cost_actuator_singularity"] = float(type_one_cost)
    return Outcome(
        q=q,
        x=x,
        k=k,
        k1=k1,
        det_sign=sign,
        residual=residual,
        jump=jump,
        failed=failed,
        out=out,
        reason=reason,
        info=info,
        reward=float(sum(terms.values())),
        observation=observation(settings, q, x, start.target, k, observation_space),
    )


def near_threshold(settings: Settings, outcome: Outcome, relative: float = 1e-9) -> bool:
    """Whether a quantity that decides the reason lies within ``relative`` of its threshold.

    There two correct implementations may round to different sides; the tests skip such steps and count them.
    """

    def near(value: float, threshold: float) -> bool:
        return abs(value - threshold) <= relative * max(abs(threshold), 1e-300)

    bounds = np.concatenate([np.asarray(settings.pose_low), np.asarray(settings.pose_high)])
    position = np.concatenate([outcome.x, outcome.x])
    return (
        near(outcome.k, settings.hard_threshold)
        or (settings.type_one and near(outcome.k1, settings.actuator_hard_threshold))
        or near(outcome.jump, settings.jump_tolerance)
        or bool(np.any(np.abs(position - bounds) <= relative * np.maximum(np.abs(bounds), 1.0)))
    )
