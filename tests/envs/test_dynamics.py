"""Stroke limits, action clipping, the Euler/RK4 step onto Φ = 0, singularity terminations and Track targets."""

from __future__ import annotations

import numpy as np
import pytest

from envs import PLANAR_3RPR_IDS, physics
from envs.kernels import generic as fk
from kinematics.linalg import determinant
from tests.envs.helpers import SINGULAR_REASONS, best_node, pose_metric, straight_line_action

#: A direction of stroke rates with every leg moving, for the small-step tests.
DIRECTION = np.array([0.6, -0.4, 0.8])


def _start_near_stroke_limit(env, leg: int, sign: int) -> np.ndarray:
    """The best-conditioned safe node whose stroke ``leg`` is 2–3 cm from the limit it moves towards."""
    unwrapped = env.unwrapped
    params, workspace = unwrapped.params, unwrapped.workspace
    nodes = workspace.nodes.reshape(-1, 3)
    q = params.robot.inverse_kinematics(nodes)
    lo, hi = params.stroke_limits
    gap = hi - q[:, leg] if sign > 0 else q[:, leg] - lo
    kept = np.isin(workspace.labels.ravel(), workspace.component_ids)
    return best_node(workspace, kept & (gap >= 0.02) & (gap <= 0.03) & fk.safe_batch(params.packed, nodes))


@pytest.mark.parametrize("sign", [1, -1], ids=["extend", "retract"])
@pytest.mark.parametrize("leg", [0, 1, 2])
def test_strokes_stop_at_the_limits(leg, sign, make_env):
    """A leg driven at full rate stops exactly at its limit; the achieved (zero) rate then moves nothing."""
    env = make_env("Planar3RPRReach-v0")
    unwrapped = env.unwrapped
    params = unwrapped.params
    lo, hi = params.stroke_limits
    limit = hi if sign > 0 else lo
    env.reset(seed=0, options={"start": _start_near_stroke_limit(env, leg, sign)})
    action = np.zeros(3, dtype=np.float32)
    action[leg] = sign
    clamped_poses = []
    for step in range(12):
        q_before, x_before = unwrapped.state.q[0].copy(), unwrapped.state.x[0].copy()
        obs, _, terminated, _, info = env.step(action)
        q = unwrapped.state.q[0]
        assert not terminated, f"step {step}: {info['termination_reason']}"
        assert lo <= q[leg] <= hi, f"stroke {q[leg]} outside [{lo}, {hi}] at step {step}"
        np.testing.assert_array_equal(np.delete(q, leg), np.delete(q_before, leg))
        step_length = abs(q[leg] - q_before[leg])
        assert step_length <= params.max_rate * params.dt * (1 + 1e-12)
        if q_before[leg] == limit:
            assert q[leg] == limit
            np.testing.assert_array_equal(unwrapped.state.x[0], x_before)
            clamped_poses.append(unwrapped.state.x[0].copy())
            assert obs[11 + leg] == sign
    assert len(clamped_poses) >= 5, "the stroke never reached its limit"


def test_stroke_clamp_uses_the_achieved_rate(make_env):
    """On the step that hits a limit, the pose follows the achieved rate (q' − q)/dt, not the commanded one."""
    env = make_env("Planar3RPRReach-v0")
    unwrapped = env.unwrapped
    params = unwrapped.params
    env.reset(seed=0, options={"start": _start_near_stroke_limit(env, 0, 1)})
    action = np.array([1.0, 0.0, 0.0], dtype=np.float32)
    hi = params.stroke_limits[1]
    while True:
        q, x = unwrapped.state.q[0].copy(), unwrapped.state.x[0].copy()
        commanded = action * params.max_rate
        if q[0] + commanded[0] * params.dt > hi:
            break
        env.step(action)
    _, outcome = physics.transition(params, unwrapped.state, action[None].astype(np.float64))
    env.step(action)
    q_next, x_next = unwrapped.state.q[0], unwrapped.state.x[0]
    achieved = (q_next - q) / params.dt
    np.testing.assert_allclose(outcome.q_rate[0], achieved, rtol=1e-12, atol=1e-15)
    assert achieved[0] < commanded[0]
    J_f = params.robot.forward_jacobian(q, x)
    error_achieved = np.linalg.norm(x_next - (x + J_f @ achieved * params.dt))
    error_commanded = np.linalg.norm(x_next - (x + J_f @ commanded * params.dt))
    assert error_achieved < 0.1 * error_commanded


@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
def test_out_of_range_actions_are_clipped(env_id, make_env):
    """[5, −5, 0.5] acts exactly like [1, −1, 0.5] (state, observation, reward)."""
    big, unit = make_env(env_id), make_env(env_id)
    big.reset(seed=11)
    unit.reset(seed=11)
    result_big = big.step(np.array([5.0, -5.0, 0.5], dtype=np.float32))
    result_unit = unit.step(np.array([1.0, -1.0, 0.5], dtype=np.float32))
    np.testing.assert_array_equal(big.unwrapped.state.q, unit.unwrapped.state.q)
    np.testing.assert_array_equal(big.unwrapped.state.x, unit.unwrapped.state.x)
    np.testing.assert_array_equal(result_big[0], result_unit[0])
    assert result_big[1] == result_unit[1]
    weight = big.unwrapped.params.action_weight
    assert result_big[4]["reward_action"] == pytest.approx(-weight * 2.25, rel=1e-12)


def _substep_count(params, q: np.ndarray, x: np.ndarray, q_rate: np.ndarray) -> int:
    """Substeps of a step: ⌈‖J_f q̇ dt (1, 1, ℓ_c)‖ / max_substep⌉ within [1, max_substeps] (library J_f)."""
    motion = np.linalg.norm(params.robot.forward_jacobian(q, x) @ q_rate * params.dt * pose_metric(params))
    return int(np.clip(np.ceil(motion / params.max_substep), 1, params.max_substeps))


def _euler_error(env, seed: int, scale: float) -> tuple[float, float, float]:
    """(‖x' − (x + J_f q̇ dt)‖, ‖x' − x‖, max |Φ(q', x')|) of one step with action scale · DIRECTION."""
    unwrapped = env.unwrapped
    params = unwrapped.params
    env.reset(seed=seed)
    q, x = unwrapped.state.q[0].copy(), unwrapped.state.x[0].copy()
    _, _, terminated, _, _ = env.step((scale * DIRECTION).astype(np.float32))
    assert not terminated
    q_next, x_next = unwrapped.state.q[0], unwrapped.state.x[0]
    q_rate = (q_next - q) / params.dt
    euler = x + params.robot.forward_jacobian(q, x) @ q_rate * params.dt
    residual = float(np.max(np.abs(params.robot.constraints(q_next, x_next))))
    scale_vec = pose_metric(params)
    return (
        float(np.linalg.norm((x_next - euler) * scale_vec)),
        float(np.linalg.norm((x_next - x) * scale_vec)),
        residual,
    )


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_small_step_matches_euler_to_first_order(seed, make_env):
    """One step gives x' = x + J_f q̇ dt + O(dt²), and x' lies on the constraint manifold (|Φ| ≤ 1e-10)."""
    env = make_env("Planar3RPRReach-v0")
    error_big, _, residual_big = _euler_error(env, seed, 0.1)
    error_small, motion_small, residual_small = _euler_error(env, seed, 0.05)
    assert residual_big <= 1e-10 and residual_small <= 1e-10
    assert motion_small > 0
    assert error_small <= 2e-2 * motion_small, (error_small, motion_small)
    # A second-order remainder: halving the step divides the error by about four.
    assert 3.0 < error_big / error_small < 5.0, (error_big, error_small)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rk4_prediction_is_closer_than_euler(seed, make_env, rng):
    """With integrator="rk4" the prediction lands much closer to the Newton-corrected pose than Euler's."""
    euler_env = make_env("Planar3RPRReach-v0")
    rk4_env = make_env("Planar3RPRReach-v0", integrator="rk4")
    euler_params, rk4_params = euler_env.unwrapped.params, rk4_env.unwrapped.params
    assert (euler_params.integrator, rk4_params.integrator) == ("euler", "rk4")
    euler_env.reset(seed=seed)
    rk4_env.reset(seed=seed)
    first = rng.uniform(-1.0, 1.0, size=3).astype(np.float32)
    euler_env.step(first)
    rk4_env.step(first)
    # Both integrators are corrected onto the same solution of Φ = 0.
    np.testing.assert_allclose(rk4_env.unwrapped.state.x, euler_env.unwrapped.state.x, rtol=0, atol=1e-9)
    for _ in range(5):
        action = rng.uniform(-1.0, 1.0, size=3).astype(np.float32)
        state = euler_env.unwrapped.state
        after_euler, euler = physics.transition(euler_params, state, action[None].astype(np.float64))
        after_rk4, rk4 = physics.transition(rk4_params, state, action[None].astype(np.float64))
        assert euler.reason[0] == 0 and rk4.reason[0] == 0
        assert rk4.jump[0] < 0.1 * euler.jump[0], (rk4.jump, euler.jump)
        np.testing.assert_allclose(after_rk4.x, after_euler.x, rtol=0, atol=1e-9)
        # The reported Euler gap is the one of the lesson's prediction x + J_f q̇ dt.
        q, x = state.q[0], state.x[0]
        predicted = x + euler_params.robot.forward_jacobian(q, x) @ euler.q_rate[0] * euler_params.dt
        euler_env.step(action)
        corrected = euler_env.unwrapped.state.x[0]
        np.testing.assert_array_equal(corrected, after_euler.x[0])
        gap = np.linalg.norm((corrected - predicted) * pose_metric(euler_params))
        if _substep_count(euler_params, state.q[0], state.x[0], euler.q_rate[0]) == 1:
            assert gap == pytest.approx(euler.jump[0], rel=1e-6)
        else:  # substeps follow the path more closely than one Euler step
            assert euler.jump[0] < gap


def test_driving_into_a_singularity_terminates(make_env):
    """A straight-line controller on hard targets meets the ill-conditioned zone and is stopped there."""
    env = make_env("Planar3RPRReachHard-v0")
    penalty = env.unwrapped.params.termination_penalty
    endings = []
    for seed in range(10):
        _, info = env.reset(seed=seed)
        target = info["target"]
        for _ in range(200):
            _, reward, terminated, truncated, info = env.step(straight_line_action(env, target))
            if terminated or truncated:
                break
        if terminated:
            endings.append(info["termination_reason"])
            assert info["termination_reason"] in SINGULAR_REASONS, (seed, info["termination_reason"])
            assert info["reward_termination"] == -penalty
            assert reward <= -penalty
    assert len(endings) >= 3, f"only {len(endings)} of 10 hard episodes met the singular zone: {endings}"


@pytest.mark.parametrize("env_id", PLANAR_3RPR_IDS)
def test_working_mode_never_changes_silently(env_id, make_env, rng):
    """sign(det J_x) at every non-terminal step equals its value at reset."""
    env = make_env(env_id)
    robot = env.unwrapped.params.robot
    unwrapped = env.unwrapped

    def det_sign() -> float:
        _, J_x = robot.jacobians(unwrapped.state.q, unwrapped.state.x)
        return float(np.sign(determinant(J_x))[0])

    checked = 0
    for episode in range(15):
        env.reset(seed=episode)
        initial = det_sign()
        assert initial != 0
        for step in range(200):
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, size=3).astype(np.float32))
            if terminated:
                break
            assert det_sign() == initial, f"episode {episode}, step {step}: det J_x changed sign"
            checked += 1
            if truncated:
                break
    assert checked > 500


def test_track_target_follows_its_reference(make_env):
    """Track: info["target"] is the reference at the current step, moves, and obs[-3:] is its velocity.

    The target velocity (ẋ*, ẏ*, φ̇*) is the last block of the Track observation (Observation Space table).
    """
    env = make_env("Planar3RPRTrack-v0")
    unwrapped = env.unwrapped
    params = unwrapped.params
    obs, info = env.reset(seed=5)
    np.testing.assert_array_equal(info["pose"], info["target"])  # starts at rest on the reference
    targets, velocities = [info["target"]], [obs[-3:].astype(np.float64)]
    for _ in range(60):
        obs, _, terminated, _, info = env.step(np.zeros(3, dtype=np.float32))
        assert not terminated
        reference, t = unwrapped.state.reference, unwrapped.state.t
        expected, _ = fk.reference_batch(params.packed, t, reference.center, reference.amplitude, reference.phase)
        np.testing.assert_array_equal(info["target"], expected[0])
        phase = 2.0 * np.pi / params.track_period * t[0] * params.dt + reference.phase[0]
        formula = reference.center[0] + reference.amplitude[0] * np.sin(phase)
        np.testing.assert_allclose(info["target"], formula, rtol=0, atol=1e-14)
        assert not np.array_equal(info["target"], targets[-1]), "the target did not move"
        np.testing.assert_allclose(obs[4:6], info["target"][:2], atol=1e-6)
        targets.append(info["target"])
        velocities.append(obs[-3:].astype(np.float64))
    targets, velocities = np.array(targets), np.array(velocities)
    central = (targets[2:] - targets[:-2]) / (2.0 * params.dt)
    np.testing.assert_allclose(velocities[1:-1], central, atol=1e-4)
    assert np.max(np.abs(velocities)) > 1e-3


def test_newton_failure_keeps_the_robot_in_place(make_env):
    """When the correction does not converge the episode ends (newton_failed) and (q, x) stay as they were."""
    env = make_env("Planar3RPRReach-v0", newton_max_iterations=1)
    unwrapped = env.unwrapped
    env.reset(seed=0)
    q, x = unwrapped.state.q.copy(), unwrapped.state.x.copy()
    _, _, terminated, _, info = env.step(np.array([1.0, -1.0, 1.0], dtype=np.float32))
    assert terminated and info["termination_reason"] == "newton_failed"
    np.testing.assert_array_equal(unwrapped.state.q, q)
    np.testing.assert_array_equal(unwrapped.state.x, x)
    assert info["constraint_residual"] <= 1e-10
    assert info["reward_termination"] == -unwrapped.params.termination_penalty
