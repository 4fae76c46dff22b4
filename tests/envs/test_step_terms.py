"""A second check of each step's reward, observation and termination reason, read back from the env's own state.

``test_step_oracle.py`` predicts a whole step (its own transition) with ``tests/envs/oracle.py`` and compares.
These tests take the other direction and share nothing with that oracle: after each step of the env they read
its new state (q, x) and its info, and check the three outputs against the documents alone (the env docstring's
Rewards, Observation Space and Episode End sections, ``docs/environments.md``):

* the reward is recomputed from its documented formula, with the errors measured afresh (the orientation error
  as the angle of R* Rᵀ by ``scipy.spatial.transform.Rotation``) and k, k_I from ``kinematics``;
* the observation is read group by group in the documented layout (pose, target, error, strokes, stroke errors,
  k), each group compared with the code of the state and of ``kinematics``' values (quaternions by ``scipy``);
* the termination reason is derived from the state it ends at: sign(det J_x) against the episode's working mode,
  k against ``hard_threshold``, the pose against its bounds, k_I against ``actuator_hard_threshold``, in the
  documented order (``newton_failed`` and ``assembly_mode_change`` need the step's prediction, which only the
  oracle makes: a failed correction is checked to leave the robot where it was).
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

#: Weights unlike each other and unlike the defaults (and unlike ``test_step_oracle.WEIGHTS``).
WEIGHTS = {
    "position_weight": 1.4,
    "orientation_weight": 0.6,
    "singularity_weight": 2.9,
    "action_weight": 0.11,
    "termination_penalty": 23.0,
    "success_reward": 3.0,
    "actuator_singularity_weight": 1.9,
}
#: One robot of each kind: planar legs, translational cranks, planar cranks, spatial legs (the hexapod).
CASES = {
    "3-RPR": "Planar3RPRReach-v0",
    "Delta": "DeltaReach-v0",
    "3-RRR": "Planar3RRRReach-v0",
    "hexapod": "StewartGoughReach-v0",
}
#: Steps where a measure is this close (relatively) to its threshold are not used to check the reason.
MARGIN = 1e-7


def _wrap(angle: float) -> float:
    """The angle in [−π, π)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _rotation(r: np.ndarray) -> Rotation:
    return Rotation.from_rotvec(np.asarray(r, dtype=np.float64))


def _pose_errors(space: str, x: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(‖p* − p‖ [m], angle of R* Rᵀ [rad]) by the documents (0 for a translational robot)."""
    if space == "planar":
        return math.hypot(target[0] - x[0], target[1] - x[1]), abs(_wrap(target[2] - x[2]))
    if space == "translational":
        return float(np.linalg.norm(target - x)), 0.0
    relative = _rotation(target[3:]) * _rotation(x[3:]).inv()
    return float(np.linalg.norm(target[:3] - x[:3])), float(relative.magnitude())


def _measures(robot, q: np.ndarray, x: np.ndarray) -> tuple[float, float, float]:
    """(k, sign(det J_x), k_I) at (q, x) from ``kinematics`` (k_I = 1 for legs, as documented)."""
    k = float(robot.inverse_condition_number(q, x))
    _, jacobian_x = robot.jacobians(q, x)
    sign = float(np.sign(np.linalg.det(jacobian_x)))
    legs = all(kind == "leg" for kind in robot.actuator_kinds)
    k1 = 1.0 if legs else float(robot.actuator_condition_number(q, x))
    return k, sign, k1


def _expected_reason(params, k: float, sign: float, mode: float, k1: float, x: np.ndarray) -> str | None:
    """The documented reason for a step that ends at a state with these measures (None: too close to call)."""
    legs = all(kind == "leg" for kind in params.robot.actuator_kinds)
    close = abs(k - params.hard_threshold) <= MARGIN * params.hard_threshold
    close |= not legs and abs(k1 - params.actuator_hard_threshold) <= MARGIN * params.actuator_hard_threshold
    low, high = np.asarray(params.pose_low), np.asarray(params.pose_high)
    close |= bool(np.any(np.minimum(np.abs(x - low), np.abs(x - high)) <= 1e-12))
    if sign != mode:
        return "singularity_crossed"
    if close:
        return None
    if k < params.hard_threshold:
        return "singular"
    if np.any(x < low) or np.any(x > high):
        return "out_of_bounds"
    if not legs and k1 < params.actuator_hard_threshold:
        return "actuator_singular"
    return ""


def _check_reward(params, info: dict, reward: float, x, target, k, k1, action, terminated) -> bool:
    """Assert the reward and its info terms equal the documented formula; True if the step was a success."""
    robot = params.robot
    e_p, e_o = _pose_errors(robot.pose_space.name, x, target)
    assert info["position_error"] == pytest.approx(e_p, abs=1e-9)
    assert info["orientation_error"] == pytest.approx(e_o, abs=1e-9)
    within = e_p <= params.success_position_tolerance and e_o <= params.success_orientation_tolerance
    success = bool(within and not terminated)
    assert info["is_success"] is success
    a = np.clip(action, -1.0, 1.0)
    safe, safe1 = params.safe_threshold, params.actuator_safe_threshold
    terms = {
        "reward_tracking": -(
            params.position_weight * e_p + params.orientation_weight * robot.characteristic_length * e_o
        ),
        "reward_singularity": -params.singularity_weight * ((safe - k) / safe) ** 2 if k < safe else 0.0,
        "reward_action": -params.action_weight * float(a @ a),
        "reward_termination": -params.termination_penalty if terminated else 0.0,
        "reward_actuator_singularity": (
            -params.actuator_singularity_weight * ((safe1 - k1) / safe1) ** 2 if k1 < safe1 else 0.0
        ),
        "reward_success": params.success_reward if success else 0.0,
    }
    for key, value in terms.items():
        assert info[key] == pytest.approx(value, abs=1e-9), key
    assert isinstance(reward, float)
    assert reward == pytest.approx(sum(terms.values()), abs=1e-9)
    assert info["cost"] == float(k < safe or k1 < safe1)
    assert info["cost_actuator_singularity"] == float(k1 < safe1)
    return success


def _pose_columns(space: str, x: np.ndarray) -> list[float]:
    """The documented code of a pose: (x, y, cos φ, sin φ), p, or (p, quaternion (w, x, y, z) with w ≥ 0)."""
    if space == "planar":
        return [x[0], x[1], math.cos(x[2]), math.sin(x[2])]
    if space == "translational":
        return list(x)
    xyzw = _rotation(x[3:]).as_quat()  # scipy orders the quaternion (x, y, z, w)
    wxyz = np.roll(xyzw, 1) * (1.0 if xyzw[3] >= 0 else -1.0)
    return [*x[:3], *wxyz]


def _check_observation(params, space_box: gym.spaces.Box, obs: np.ndarray, q, x, target, k) -> None:
    """Read ``obs`` in the documented layout and compare each group of columns with the code of the state."""
    robot = params.robot
    space = robot.pose_space.name
    n = robot.n_actuators
    lo, hi = params.stroke_limits
    span = hi - lo
    if space == "planar":
        error = [target[0] - x[0], target[1] - x[1], _wrap(target[2] - x[2])]
    elif space == "translational":
        error = list(target - x)
    else:
        error = [*(target[:3] - x[:3]), *(_rotation(target[3:]) * _rotation(x[3:]).inv()).as_rotvec()]
    groups = {
        "pose": _pose_columns(space, x),
        "target": _pose_columns(space, target),
        "error": error,
        "strokes": list(2.0 * (q - lo) / span - 1.0),
        "stroke errors": list((robot.inverse_kinematics(target) - q) / span),
        "k": [k],
    }
    assert obs.dtype == np.float32 and obs.shape == space_box.shape
    assert sum(len(v) for v in groups.values()) == len(obs)
    assert len(groups["strokes"]) == n
    start = 0
    for name, values in groups.items():
        stop = start + len(values)
        low, high = space_box.low[start:stop], space_box.high[start:stop]
        expected = np.clip(np.asarray(values, dtype=np.float64), low, high)
        np.testing.assert_allclose(obs[start:stop], expected, rtol=0, atol=2e-6, err_msg=name)
        start = stop


def _seeker(env: gym.Env, rng: np.random.Generator):
    """A policy that lowers k: actuator rates down its finite-difference gradient (through ``forward_kinematics``)."""
    robot = env.params.robot

    def act(env: gym.Env) -> np.ndarray:
        q, x = env.state.q[0], env.state.x[0]
        n, h = len(q), 1e-5
        strokes = np.concatenate([q + h * np.eye(n), q - h * np.eye(n)])
        with np.errstate(all="ignore"):
            poses = robot.forward_kinematics(strokes, np.broadcast_to(x, (2 * n, len(x))), validate=False).x
            k = robot.inverse_condition_number(strokes, poses, validate=False)
        gradient = (k[:n] - k[n:]) / (2 * h)
        peak = float(np.max(np.abs(gradient)))
        down = -gradient / peak if np.isfinite(peak) and peak > 0 else np.zeros(n)
        return 0.5 * down + rng.normal(0.0, 0.1, n)

    return act


def _heading(env: gym.Env, rng: np.random.Generator):
    """A policy that drives the platform along one random direction of its pose space (to its bounds, its limits)."""
    robot = env.params.robot
    direction = rng.normal(size=robot.n_pose) * robot.pose_scale

    def act(env: gym.Env) -> np.ndarray:
        q, x = env.state.q[0], env.state.x[0]
        with np.errstate(all="ignore"):
            rate = robot.inverse_jacobian(q, x, validate=False) @ direction
        peak = float(np.max(np.abs(rate)))
        ahead = rate / peak if np.isfinite(peak) and peak > 0 else np.zeros(len(q))
        return ahead + rng.normal(0.0, 0.2, len(q))

    return act


def _toward(env: gym.Env, rng: np.random.Generator):
    """A policy that closes half the pose error each step (q̇ = J_i e / 2 dt, saturated): it reaches the target."""
    robot, params = env.params.robot, env.params

    def act(env: gym.Env) -> np.ndarray:
        q, x = env.state.q[0], env.state.x[0]
        error = robot.pose_difference(env.state.reference.center[0], x, validate=False)
        with np.errstate(all="ignore"):
            rate = robot.inverse_jacobian(q, x, validate=False) @ error / (2.0 * params.dt * params.max_rate)
        return np.clip(np.nan_to_num(rate), -1.0, 1.0)

    return act


class Step(NamedTuple):
    """One step of a rollout, as the env gave it, and the state before and after it.

    Attributes:
        action: The action given, shape (n,).
        obs: The observation returned (after ``reset`` for the first record of an episode).
        reward: The reward returned (None after ``reset``).
        terminated: Whether the step terminated the episode.
        truncated: Whether it truncated it.
        info: The info returned.
        before: (q, x) before the step (None after ``reset``).
        after: (q, x) after it, from ``env.unwrapped.state``.
        mode: sign(det J_x) the env keeps for the episode (``state.det_sign``).
    """

    action: np.ndarray | None
    obs: np.ndarray
    reward: float | None
    terminated: bool
    truncated: bool
    info: dict
    before: tuple | None
    after: tuple
    mode: float


@functools.cache
def rollout(robot: str) -> tuple[Any, gym.spaces.Box, tuple[Step, ...]]:
    """A recorded run of ``CASES[robot]``: (params, observation space, every reset and step).

    15 episodes (custom weights, hard thresholds raised), ≤ 100 steps each, by the policies ``_seeker``,
    ``_heading`` and ``_toward`` in turn. Cached: the three tests below check the same run.
    """
    nominal = gym.make(CASES[robot]).unwrapped.params
    thresholds = {  # raised toward the safe ones, so that the policies end episodes by each reason
        "hard_threshold": 0.8 * nominal.safe_threshold,
        "actuator_hard_threshold": 0.8 * nominal.actuator_safe_threshold,
    }
    env = gym.make(CASES[robot], **WEIGHTS, **thresholds).unwrapped
    records = []

    def now() -> tuple[np.ndarray, np.ndarray]:
        return env.state.q[0].copy(), env.state.x[0].copy()

    for episode in range(15):
        obs, info = env.reset(seed=episode)
        mode = float(env.state.det_sign[0])
        records.append(Step(None, obs, None, False, False, info, None, now(), mode))
        act = (_seeker, _heading, _toward)[episode % 3](env, np.random.default_rng(episode))
        for _ in range(100):
            action = np.asarray(act(env), dtype=np.float64)
            before = now()
            obs, reward, terminated, truncated, info = env.step(action)
            records.append(Step(action, obs, reward, terminated, truncated, info, before, now(), mode))
            if terminated:
                break
    return env.params, env.observation_space, tuple(records)


@pytest.mark.parametrize("robot", list(CASES))
def test_the_reward_is_its_documented_formula_at_the_new_state(robot):
    """The reward and each reward term of info equal the documented formula at the state the step ends at.

    The errors are measured afresh from the pose and the target, k and k_I come from ``kinematics``, the action
    is clipped to [−1, 1] and the penalty follows ``terminated``; the success bonus is paid within the
    tolerances of an episode that goes on.
    """
    params, _, records = rollout(robot)
    penalised = successes = 0
    for step in records:
        q, x = step.after
        target = np.asarray(step.info["target"], dtype=np.float64)
        np.testing.assert_array_equal(step.info["pose"], x)
        if step.reward is None:
            continue
        k, _, k1 = _measures(params.robot, q, x)
        assert step.info["inverse_condition_number"] == pytest.approx(k, abs=1e-9)
        assert step.info["actuator_condition_number"] == pytest.approx(k1, abs=1e-9)
        successes += _check_reward(params, step.info, step.reward, x, target, k, k1, step.action, step.terminated)
        penalised += k < params.safe_threshold or k1 < params.actuator_safe_threshold
    assert penalised >= 5, "too few steps where a singularity penalty is active"
    assert successes >= 20, "too few steps that end within the success tolerances"


@pytest.mark.parametrize("robot", list(CASES))
def test_the_observation_decodes_to_the_state_by_its_documented_layout(robot):
    """Every observation, column group by group, is the documented code of the state it comes with.

    After reset and after each step: pose, target, error, normalised strokes, stroke errors (``kinematics``'
    inverse kinematics of the target), k.
    """
    params, space, records = rollout(robot)
    for step in records:
        q, x = step.after
        target = np.asarray(step.info["target"], dtype=np.float64)
        k, _, _ = _measures(params.robot, q, x)
        _check_observation(params, space, step.obs, q, x, target, k)


@pytest.mark.parametrize("robot", list(CASES))
def test_the_termination_reason_follows_from_the_state_the_step_ends_at(robot):
    """The reason is the first documented one that the new state shows (mode, k, bounds, k_I), "" if none.

    ``newton_failed`` is checked to leave the robot where it was; ``assembly_mode_change`` needs the step's
    prediction, which only ``tests/envs/oracle.py`` makes, and is not checked here.
    """
    params, _, records = rollout(robot)
    checked: dict[str, int] = {}
    for step in records:
        q, x = step.after
        k, sign, k1 = _measures(params.robot, q, x)
        if step.reward is None:
            assert step.mode == sign  # the episode's working mode is the start's
            continue
        reason = step.info["termination_reason"]
        assert step.terminated == bool(reason) and not step.truncated
        if reason == "newton_failed":  # a failed correction puts the robot back where it was
            np.testing.assert_array_equal(q, step.before[0])
            np.testing.assert_array_equal(x, step.before[1])
        elif reason != "assembly_mode_change":
            expected = _expected_reason(params, k, sign, step.mode, k1, x)
            if expected is not None:
                assert reason == expected
                checked[reason] = checked.get(reason, 0) + 1
    ended = {reason for reason in checked if reason}
    assert checked.get("", 0) >= 100 and "singular" in ended and len(ended) >= 2, checked
