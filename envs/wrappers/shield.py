"""A one-step look-ahead safety filter ("shield") that keeps any agent out of Type II singularities.

A learned policy reaches its targets, but near a fold of the forward kinematics one saturated action can
cross a Type II singularity within a single control period (the inverse condition number drops from
about 0.1 to 1e-5 inside the step). No integrator setting prevents that: the commanded strokes have no
solution on the robot's branch. The shield (Alshiekh et al., *Safe reinforcement learning via shielding*,
AAAI 2018) tries the proposed action on a copy of the state with the environment's own pure
``envs.physics.transition`` before it is applied, and replaces it when the step would terminate or would
leave the robot below a guard level of the inverse condition number:

    a, a/2, a/4, a/8, 0 — the first candidate that does not terminate and ends with k' ≥ min(k_guard, k).

The zero action leaves strokes and pose unchanged, so a safe candidate always exists. Under force control
(``control="force"``) the candidates are tried with the equations of motion, and a candidate must also leave the
platform stoppable: braking after it for ``BRAKE_TIME`` (whole periods of ``brake_actions``: the computed-torque
effort that would stop the platform within one period, clipped to the drive limits) neither terminates nor takes k
below that level, and leaves the platform at rest (speeds ≤ ``REST_SPEED``) where the drives can hold it (holding
forces within their limits), from where holding keeps it there. Each accepted step thus keeps a way to stop in
reserve. The last resort is the braking effort, since a zero offset holds a platform at rest but does not stop a
moving one. That is not a guarantee: a platform already too fast to stop (a start, or a robot as built that
differs from the model the brake uses) cannot be saved.
The dynamics, rewards and termination rules are those of the environment; the cost is one to four extra
``core.transition`` calls per step (under force control 1 + ⌈``BRAKE_TIME`` / dt⌉ per candidate; the accepted
candidate is computed again by ``env.step``).
``shield_actions`` is the filter on a batch of robots; ``SingularityShield`` applies it to the single env and
``VectorSingularityShield`` to the native vector env (row i of the vector env is shielded exactly as the single env
of the same seed).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from envs.kernels.force import actions_of_efforts
from envs.physics import transition
from kinematics import SingularConfigurationError

__all__ = [
    "BRAKE_TIME",
    "REST_SPEED",
    "SHIELD_SCALES",
    "SingularityShield",
    "VectorSingularityShield",
    "brake_actions",
    "shield_actions",
]

#: Action scales tried in order; the last (zero) is always safe.
SHIELD_SCALES = (1.0, 0.5, 0.25, 0.125, 0.0)
#: Under force control, the time [s] within which braking after a candidate must stop the platform (whole periods).
BRAKE_TIME = 0.3
#: Under force control, the speed [m/s; ℓ_c rad/s about an angle] at or below which braking has stopped the platform.
REST_SPEED = 0.01


def shield_actions(params, state, actions: np.ndarray, k_guard: float) -> tuple[np.ndarray, np.ndarray]:
    """The shielded actions of N robots and the scale applied to each.

    Args:
        params: The environment's ``FamilyParams``.
        state: The robots' ``FamilyState`` (N rows).
        actions: Proposed normalised stroke rates, shape (N, n), finite; clipped to [-1, 1].
        k_guard: Guard level of the inverse condition number, in (0, 1).

    Returns:
        (actions (N, n) float32: row i is its proposal times the first scale of ``SHIELD_SCALES`` whose step does
        not terminate and ends with k' ≥ min(k_guard, k) (under force control, from which braking for
        ``BRAKE_TIME`` keeps it so), else zero (under force control the braking effort, ``brake_actions``); the
        scales (N,) float64).
    """
    proposed = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
    k_now = np.asarray(state.inverse_condition, dtype=np.float64)
    floor = np.minimum(k_guard, k_now)
    scales = np.zeros(len(proposed))
    open_rows = np.ones(len(proposed), dtype=bool)
    for i, scale in enumerate(SHIELD_SCALES[:-1]):
        new_state, outcome = transition(params, state, proposed * scale, validate=i == 0)  # one check of the state
        accept = open_rows & (outcome.reason == 0) & (new_state.inverse_condition >= floor)
        if params.control == "force" and accept.any():
            accept &= _stoppable(params, new_state, floor)
        scales[accept] = scale
        open_rows &= ~accept
        if not open_rows.any():
            break
    actions = proposed * scales[:, None]
    if params.control == "force" and open_rows.any():
        actions[open_rows] = brake_actions(params, state)[open_rows]
    return actions.astype(np.float32), scales


def _stoppable(params, state, floor: np.ndarray) -> np.ndarray:
    """Rows (N,) whose braking for ``BRAKE_TIME`` from ``state`` never ends, keeps k ≥ ``floor`` and stops where held.

    Stopped: every speed of the twist at most ``REST_SPEED`` (angular ones times ℓ_c); held: the holding forces
    there within the drive limits (|τ_h,i| < τ_max,i), so that a zero action keeps the platform at rest.
    """
    ok = np.ones(len(state.q), dtype=bool)
    for _ in range(max(1, math.ceil(BRAKE_TIME / params.dt - 1e-9))):
        with np.errstate(invalid="ignore"):
            state, outcome = transition(params, state, brake_actions(params, state), validate=False)  # made here
        ok &= (outcome.reason == 0) & (state.inverse_condition >= floor)
    at_rest = (np.abs(state.twist * params.pose_metric) <= REST_SPEED).all(axis=-1)
    _, hold = _brake_and_hold(params, state)
    with np.errstate(invalid="ignore"):
        held = (np.abs(hold) < params.force_limit_array).all(axis=-1)
    return ok & at_rest & held


def brake_actions(params, state) -> np.ndarray:
    """Force control: the actions whose efforts would stop each platform within one period, clipped.

    τ_b = J_fᵀ (M(x) (−ẋ / dt) + c(x, ẋ) + G(x)) (``kinematics.dynamics``, the nominal model), clipped to the drive
    limits, as the action of ``envs.kernels.force.actions_of_efforts`` (from the holding forces τ_h = J_fᵀ G); 0
    (hold) where J_x is singular.

    Args:
        params: The environment's ``FamilyParams`` (``control="force"``).
        state: The robots' ``FamilyState`` (N rows, with twists).

    Returns:
        Actions, shape (N, n) float64.
    """
    brake, hold = _brake_and_hold(params, state)
    return actions_of_efforts(np.nan_to_num(hold), np.nan_to_num(brake), params.force_limit_array)


def _brake_and_hold(params, state) -> tuple[np.ndarray, np.ndarray]:
    """The braking efforts τ_b and holding forces τ_h of ``brake_actions``, each (N, n); NaN where J_x is singular."""
    dynamics, robot = params.dynamics, params.robot
    q, x, twist = state.q, state.x, state.twist
    M = dynamics.mass_matrix(q, x)
    wrench = np.einsum("Nij,Nj->Ni", M, -twist / params.dt) + dynamics.bias_forces(q, x, twist)
    both = np.concatenate([wrench, dynamics.gravity_forces(q, x)])  # τ_b, then τ_h = J_fᵀ G
    q2, x2 = np.concatenate([q, q]), np.concatenate([x, x])
    try:
        brake, hold = np.split(robot.actuator_forces(q2, x2, both, validate=False), 2)
    except SingularConfigurationError:  # a row at a singularity (an ended episode): row by row, NaN there
        brake, hold = np.zeros_like(q), np.zeros_like(q)
        for i in range(len(q)):
            try:
                brake[i] = robot.actuator_forces(q[i], x[i], wrench[i], validate=False)
                hold[i] = robot.actuator_forces(q[i], x[i], both[len(q) + i], validate=False)
            except SingularConfigurationError:
                brake[i] = hold[i] = np.nan
    return brake, hold


def _guard(k_guard: Any) -> float:
    """``k_guard`` as a float, refused unless a number in (0, 1)."""
    if not (isinstance(k_guard, (int, float)) and 0.0 < float(k_guard) < 1.0):
        raise ValueError(f"k_guard must be a number in (0, 1), got {k_guard!r}")
    return float(k_guard)


class SingularityShield(gym.Wrapper):
    """Replace actions that would cross or approach a Type II singularity by scaled-down ones.

    Works on the single Reach and Track environments (anything whose ``unwrapped`` has ``params`` and
    a batched ``state`` of one robot). ``info["shield_scale"]`` is the scale applied to the proposed
    action at that step (1.0: unchanged; 0.0: held still).

    Args:
        env: A planar 3-RPR environment, possibly wrapped (``gym.make`` output).
        k_guard: Guard level of the inverse condition number in (0, 1): a step may end below it only if
            it does not lower k. Default 0.05 (above the hard threshold 0.03 of the default env).
    """

    def __init__(self, env: gym.Env, k_guard: float = 0.05) -> None:
        """Wrap ``env``; see the class docstring."""
        super().__init__(env)
        base = env.unwrapped
        if not (hasattr(base, "params") and hasattr(base, "state")):
            raise TypeError(f"SingularityShield needs a parallel-robot environment of envs, got {type(base).__name__}")
        self.k_guard = _guard(k_guard)

    def safe_action(self, action: Any) -> tuple[np.ndarray, float]:
        """The action to apply instead of ``action`` and its scale.

        Args:
            action: Proposed normalised stroke rates, shape (n,), finite.

        Returns:
            (the action, shape (n,) float32; the scale in ``SHIELD_SCALES`` applied to it).
        """
        base = self.env.unwrapped
        state = base.state
        if state is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        proposed = np.asarray(action, dtype=np.float64)
        n = base.action_space.shape[0]
        if proposed.shape != (n,) or not np.all(np.isfinite(proposed)):
            return np.asarray(action), 1.0  # let the environment reject it with its own message
        safe, scales = shield_actions(base.params, state, proposed[None], self.k_guard)
        return safe[0], float(scales[0])

    def step(self, action: Any):
        """Step with the shielded action; ``info["shield_scale"]`` records the scale used."""
        safe, scale = self.safe_action(action)
        obs, reward, terminated, truncated, info = self.env.step(safe)
        info["shield_scale"] = scale
        return obs, reward, terminated, truncated, info


class VectorSingularityShield(gym.vector.VectorWrapper):
    """``SingularityShield`` on the native vector env (``gym.make_vec(id, vectorization_mode="vector_entry_point")``).

    ``infos["shield_scale"]`` (N,) is the scale applied to each row's proposed action.

    Args:
        env: A native vector env of ``envs`` (its ``unwrapped`` has ``params`` and the batched ``state``).
        k_guard: Guard level of the inverse condition number in (0, 1) (default 0.05).
    """

    def __init__(self, env: gym.vector.VectorEnv, k_guard: float = 0.05) -> None:
        """Wrap ``env``; see the class docstring."""
        super().__init__(env)
        base = env.unwrapped
        if not (hasattr(base, "params") and hasattr(base, "state")):
            raise TypeError(f"VectorSingularityShield needs a native vector env of envs, got {type(base).__name__}")
        self.k_guard = _guard(k_guard)

    def step(self, actions: Any):
        """Step with the shielded actions; ``infos["shield_scale"]`` records the scales used."""
        base = self.env.unwrapped
        state = base.state
        if state is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        proposed = np.asarray(actions, dtype=np.float64)
        if proposed.shape != state.q.shape or not np.all(np.isfinite(proposed)):
            return self.env.step(actions)  # the environment rejects it with its own message
        safe, scales = shield_actions(base.params, state, proposed, self.k_guard)
        obs, rewards, terminations, truncations, infos = self.env.step(safe)
        infos["shield_scale"] = scales
        infos["_shield_scale"] = np.ones(len(scales), dtype=bool)
        return obs, rewards, terminations, truncations, infos
