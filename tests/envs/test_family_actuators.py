"""The family's compiled transition for crank and slider actuators and the translational pose space.

The Delta (translational, cranks), the 3-RRR (planar, cranks) and the 3-PRR (planar, sliders) step through the
same kernels as the 3-RPR and the hexapod, with no robot-specific code; each step is checked against the NumPy
reference of ``kinematics`` (inverse kinematics, constraints, Newton's forward kinematics, both singularity
measures).
"""

from __future__ import annotations

import numpy as np
import pytest

from envs import physics, presets
from envs.info import step_info
from envs.kernels.modes import initial_batch
from envs.physics import TERMINATION_REASONS
from kinematics import Delta, Planar3PRR, Planar3RRR

ROBOTS = {"delta": Delta, "3rrr": Planar3RRR, "3prr": Planar3PRR}
SPREADS = {"delta": (0.3, 0.3, 0.15), "3rrr": (0.06, 0.06, 0.3), "3prr": (0.06, 0.06, 0.3)}


def _setup(name: str, count: int = 200, seed: int = 0):
    """(robot, params, x): wide pose bounds, and reachable poses with both measures above 0.05."""
    robot = ROBOTS[name]()
    home = robot.home_pose()
    spread = np.array(SPREADS[name])
    at_home = robot.inverse_kinematics(home)
    band = 1.5 if name != "3prr" else 0.3
    params = presets.build_family_params(
        robot,
        pose_low=tuple(home - 3 * spread),
        pose_high=tuple(home + 3 * spread),
        sample_low=tuple(home - spread),
        sample_high=tuple(home + spread),
        stroke_limits=(float(at_home.min()) - band, float(at_home.max()) + band),
        track_amplitude=tuple(0.5 * spread),
    )
    rng = np.random.default_rng(seed)
    x = home + rng.uniform(-1.0, 1.0, (8 * count, 3)) * spread
    q = robot.inverse_kinematics(x, validate=False)
    ok = np.isfinite(q).all(axis=-1)
    x, q = x[ok], q[ok]
    ok = (robot.inverse_condition_number(q, x) > 0.05) & (robot.actuator_condition_number(q, x) > 0.05)
    assert ok.sum() >= count
    return robot, params, x[ok][:count]


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_initial_state_matches_the_reference(name: str) -> None:
    """Strokes (closed-form IK on the chosen branches), k, sign(det J_x) and the residual at rest."""
    robot, params, x = _setup(name)
    q, k, k1, sign, residual = initial_batch(params.packed, x)
    np.testing.assert_allclose(k1, robot.actuator_condition_number(q, x), rtol=1e-12)
    np.testing.assert_allclose(q, robot.inverse_kinematics(x), atol=1e-13)
    k_ref, det = robot.singularity_measures(q, x)
    np.testing.assert_allclose(k, k_ref, rtol=1e-9)
    np.testing.assert_array_equal(sign, np.sign(det))
    assert residual.max() < 1e-13


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_transition_is_the_actuator_motion_integrated_and_corrected(name: str) -> None:
    """One step: q' = q + a · rate · dt; Φ(q', x') = 0; x' is Newton's pose from x; k' is the reference's."""
    robot, params, x = _setup(name)
    ref = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(params, x, ref)
    action = np.random.default_rng(1).uniform(-1.0, 1.0, (len(x), 3))
    new, outcome = physics.transition(params, state, action)
    ok = outcome.reason == 0
    assert ok.mean() > 0.95, np.bincount(outcome.reason)
    lo, hi = params.stroke_limits
    np.testing.assert_allclose(new.q, np.clip(state.q + action * params.max_rate * params.dt, lo, hi), atol=1e-15)
    assert np.abs(robot.constraints(new.q[ok], new.x[ok])).max() <= 1e-10
    fk = robot.forward_kinematics(new.q[ok], x[ok])
    np.testing.assert_allclose(new.x[ok], fk.x, atol=1e-9)
    np.testing.assert_allclose(
        new.inverse_condition[ok], robot.inverse_condition_number(new.q[ok], new.x[ok]), rtol=1e-9
    )
    twist = np.einsum("nij,nj->ni", robot.forward_jacobian(state.q[ok], x[ok]), outcome.q_rate[ok]) * params.dt
    moved = robot.pose_difference(new.x[ok], x[ok])
    assert np.abs(moved - twist).max() < 0.05 * np.abs(twist).max()
    # the kernels' own prediction J_f q̇ dt is right to first order: Newton corrects it by a small fraction
    scale = np.where(robot.pose_scale == 1.0, 1.0, robot.characteristic_length)
    assert np.max(outcome.jump[ok] / np.linalg.norm(moved * scale, axis=-1)) < 0.08


def test_a_type_one_pose_terminates_as_actuator_singular() -> None:
    """The Delta next to an arm stretched straight ends its episode with "actuator_singular" (and not below)."""
    robot = Delta()
    R_b, r_p, a, ell = robot.dimensions
    z = -1.5
    stretched = np.array([R_b - r_p - np.sqrt((a + ell) ** 2 - z * z), 0.0, z])
    x = stretched + np.array([0.003, 0.0, 0.0])  # 3 mm back from the edge of arm 0's reach
    q = robot.inverse_kinematics(x)
    k1 = float(robot.actuator_condition_number(q, x))
    assert 1e-3 < k1 < 0.2
    for threshold, expected in ((2 * k1, "actuator_singular"), (0.2 * k1, "")):
        params = presets.build_family_params(
            robot,
            pose_low=(-1.5, -1.0, -2.0),
            pose_high=(1.0, 1.0, -0.5),
            sample_low=(-1.0, -0.5, -1.8),
            sample_high=(0.5, 0.5, -0.8),
            stroke_limits=(-1.0, 2.0),
            actuator_hard_threshold=threshold,
            actuator_safe_threshold=0.5,
            hard_threshold=1e-4,
            safe_threshold=1e-3,
        )
        ref = physics.FamilyReference(x[None].copy(), np.zeros((1, 3)), np.zeros((1, 3)))
        state = physics.initial_state(params, x[None], ref)
        _, outcome = physics.transition(params, state, np.zeros((1, 3)))
        assert TERMINATION_REASONS[outcome.reason[0]] == expected


def test_stroke_limits_of_cranks_may_be_negative_but_legs_not() -> None:
    """Crank angles take any limits q_min < q_max; leg lengths still need 0 < q_min."""
    presets.build_family_params(Delta(), stroke_limits=(-1.0, 1.0))
    with pytest.raises(ValueError, match="0 < q_min < q_max"):
        presets.build_family_params(stroke_limits=(-0.1, 0.7))
    with pytest.raises(ValueError, match="actuator_hard_threshold < actuator_safe_threshold < 1"):
        presets.build_family_params(Delta(), actuator_hard_threshold=0.2, actuator_safe_threshold=0.1)


def test_a_delta_given_as_data_gets_an_environment() -> None:
    """A translational robot's observation: p, p*, p* − p, strokes, stroke errors, k (no rotation code)."""
    import gymnasium as gym

    env = gym.make("StewartGoughReach-v0", robot=Delta(), max_rate=1.0)
    obs, info = env.reset(seed=0)
    assert obs.shape == (3 + 3 + 3 + 3 + 3 + 1,)
    np.testing.assert_allclose(obs[:3], info["pose"], atol=1e-6)
    np.testing.assert_allclose(obs[3:6], info["target"], atol=1e-6)
    np.testing.assert_allclose(obs[6:9], info["target"] - info["pose"], atol=1e-6)
    assert info["orientation_error"] == 0.0


@pytest.mark.parametrize("name", ["3rrr", "3prr"])
def test_planar_cranks_and_sliders_step_through_the_family_env(name: str) -> None:
    """A 3-RRR or 3-PRR given as data runs through gym.make with Gymnasium's checker silent."""
    import warnings

    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    robot, params, _ = _setup(name, count=10)
    env = gym.make("StewartGoughReach-v0", robot=robot, stroke_limits=params.stroke_limits).unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    for _ in range(20):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs) and np.isfinite(reward)
        assert info["termination_reason"] in ("", "out_of_bounds", "actuator_singular", "singular")
        if terminated or truncated:
            break


def test_the_type_one_penalty_and_cost_are_reported_apart_from_type_two() -> None:
    """Below actuator_safe_threshold the reward loses w_s1 ((s1 − k_I)/s1)² and the cost is 1; info has both terms."""
    robot, params, x = _setup("3rrr", count=50)
    params = presets.build_family_params(
        robot,
        pose_low=params.pose_low,
        pose_high=params.pose_high,
        sample_low=params.sample_low,
        sample_high=params.sample_high,
        stroke_limits=params.stroke_limits,
        actuator_hard_threshold=0.01,
        actuator_safe_threshold=0.9,
        actuator_singularity_weight=2.0,
    )
    ref = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(params, x, ref)
    zeros = np.zeros((len(x), 3))
    evaluation, _ = physics.evaluate(params, state, zeros, np.zeros(len(x), dtype=np.int64), False)
    info = step_info(params, evaluation, np.zeros(len(x), dtype=np.int64))
    k1 = robot.actuator_condition_number(state.q, x)
    np.testing.assert_allclose(info["actuator_condition_number"], k1, rtol=1e-12)
    expected = np.where(k1 < 0.9, -2.0 * ((0.9 - k1) / 0.9) ** 2, 0.0)
    np.testing.assert_allclose(info["reward_actuator_singularity"], expected, rtol=1e-12, atol=1e-15)
    assert (k1 < 0.9).any() and (k1 >= 0.9).any()
    total = sum(info[name] for name in physics.REWARD_TERMS)
    np.testing.assert_allclose(evaluation[params.evaluation_rows["reward"]], total, rtol=1e-12, atol=1e-12)
    k2 = info["inverse_condition_number"]
    np.testing.assert_array_equal(info["cost"], ((k2 < params.safe_threshold) | (k1 < 0.9)).astype(float))


def test_tasks_are_certified_against_both_kinds_of_singularity() -> None:
    """Reach tasks of a 3-RRR: start, target and the straight path between keep k ≥ k_safe and k_I ≥ k_I,safe."""
    import gymnasium as gym

    robot, params, _ = _setup("3rrr", count=10)
    env = gym.make(
        "StewartGoughReach-v0", robot=robot, stroke_limits=params.stroke_limits, actuator_safe_threshold=0.5
    ).unwrapped
    safe, safe1 = env.params.safe_threshold, env.params.actuator_safe_threshold
    worst_k1 = np.inf
    for seed in range(20):
        _, info = env.reset(seed=seed)
        start, target = info["pose"], info["target"]
        path = start + np.linspace(0.0, 1.0, 60)[:, None] * (target - start)
        q = robot.inverse_kinematics(path)
        assert (robot.inverse_condition_number(q, path) >= safe - 1e-9).all()
        k1 = robot.actuator_condition_number(q, path)
        assert (k1 >= safe1 - 1e-9).all()
        worst_k1 = min(worst_k1, k1.min())
    assert worst_k1 < 0.8  # the Type I bound was active somewhere near, not trivially far


def test_planar_cranks_are_drawn_from_their_angles() -> None:
    """The headless frame of a 3-RRR draws each crank from its angle: the env's frame is the one of its state's q."""
    import gymnasium as gym

    from envs.rendering import render_family_frame

    robot, params, _ = _setup("3rrr", count=10)
    env = gym.make("StewartGoughReach-v0", robot=robot, stroke_limits=params.stroke_limits, render_mode="rgb_array")
    env.reset(seed=3)
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    state = env.unwrapped._state
    p = env.unwrapped.params
    target = env.unwrapped._info(
        physics.evaluate(p, state, np.zeros((1, 3)), np.zeros(1, dtype=np.int64), False)[0][:, 0], 0, None
    )[0]["target"]
    common = {
        "safe_threshold": p.safe_threshold,
        "hard_threshold": p.hard_threshold,
        "view_low": p.pose_low,
        "view_high": p.pose_high,
        "trail": [state.x[0][:2]],
        "step": 0,
    }
    k = float(state.inverse_condition[0])
    same = render_family_frame(robot, state.x[0], target, k, q=state.q[0], **common)
    np.testing.assert_array_equal(frame, same)
    turned = render_family_frame(robot, state.x[0], target, k, q=state.q[0] + 0.3, **common)
    assert np.abs(turned.astype(int) - frame.astype(int)).sum() > 0
