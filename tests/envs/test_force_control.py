"""Force control (``control="force"``): the compiled step against the NumPy dynamics, and the env around it.

Statics, the observation, the info, the vector env and the refusals.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from envs import physics
from envs import state as family_state
from envs.kernels import generic as fk
from envs.presets import build_family_params
from kinematics.dynamics import RobotDynamics

#: The force ids and the robots of the family behind them (and two crank/slider robots by name).
FORCE_IDS = (
    "Planar3RPRForceReach-v0",
    "StewartGoughForceReach-v0",
    "DeltaForceReach-v0",
    "DeltaForceTrack-v0",
    "ParallelRobotForceReach-v0",
)
ROBOTS = ("planar_3rpr", "stewart_gough", "delta", "planar_3rrr", "planar_3prr")


def keep_rows(mask: np.ndarray) -> list[int]:
    """The indices where ``mask`` is set."""
    return np.flatnonzero(mask).tolist()


def _starts(params, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """N poses of the task box the robot reaches with k ≥ safe_threshold, strokes inside the stops, and the strokes."""
    rng = np.random.default_rng(seed)
    m = params.robot.n_pose
    poses = rng.uniform(params.sample_low, params.sample_high, size=(40 * n, m))
    q, k, _, _, _ = fk.initial_batch(params.packed, poses, force=params.control == "force")
    lo, hi = params.stroke_limits
    inside = ((q > lo + params.stroke_margin) & (q < hi - params.stroke_margin)).all(axis=1)
    kept = np.isfinite(q).all(axis=1) & (k >= params.safe_threshold) & inside
    assert kept.sum() >= n
    return poses[kept][:n], q[kept][:n]


def _interpolated_efforts(hold, action, limits):
    """The oracle of the action map, drive by drive: from h = clip(τ_h) by a (τ_max + |h|), stopped at ±τ_max."""
    out = np.empty(np.broadcast_shapes(hold.shape, action.shape))
    for index in np.ndindex(out.shape):
        limit = limits[index[-1]]
        h = min(max(hold[index], -limit), limit)
        a = min(max(action[index], -1.0), 1.0)
        out[index] = min(h + a * (limit + abs(h)), limit) if a >= 0 else max(h + a * (limit + abs(h)), -limit)
    return out


@pytest.mark.parametrize(
    ("robot", "damped"),
    [(robot, False) for robot in ROBOTS] + [(robot, True) for robot in ROBOTS],
)
def test_the_compiled_step_is_the_numpy_dynamics(robot, damped):
    """Against ``RobotDynamics.step`` (NumPy, its own RKMK4): efforts, poses, twists, strokes, residual ≤ 1e-10.

    Random starts of the task box with random twists and actions (some saturating), ten periods in a row, the
    efforts rebuilt from the NumPy holding forces: τ = clip(τ_h + a (τ_max + |τ_h|), ±τ_max). Damped: drives
    with viscous friction b_i = 0.1 s × τ_max,i per unit of q̇, and passive joints with 0.01 s × the largest τ_max.
    """
    params = build_family_params(robot, control="force", dynamics_substeps=3)
    if damped:
        limits = np.asarray(params.force_limits)
        inertia = params.dynamics.inertia.replace(actuator_damping=0.1 * limits, joint_damping=0.01 * limits.max())
        params = build_family_params(robot, control="force", dynamics_substeps=3, inertia=inertia)
    dynamics, limits = params.dynamics, np.asarray(params.force_limits)
    x, q = _starts(params, 6, seed=1)
    n, m = q.shape
    rng = np.random.default_rng(2)
    reference = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(params, x, reference)
    state = state._replace(twist=0.005 * rng.normal(size=(n, m)) / params.pose_metric)
    for period in range(10):
        action = rng.uniform(-0.05, 0.05, size=(len(state.q), m))
        if period == 0:
            action[0, 0] = 3.0  # clipped to 1, then τ to the limit
        live = state.twist.copy(), state.x.copy()
        new, outcome = physics.transition(params, state, action)
        hold = dynamics.holding_forces(state.q, state.x)
        tau = _interpolated_efforts(hold, action, limits)
        np.testing.assert_allclose(outcome.hold, hold, rtol=1e-9, atol=1e-9 * limits.max())
        np.testing.assert_allclose(outcome.effort, tau, rtol=1e-9, atol=1e-9 * limits.max())
        np.testing.assert_allclose(outcome.action, tau / limits, atol=1e-12)
        ok = outcome.reason == 0
        assert ok.sum() >= 3, [physics.TERMINATION_REASONS[r] for r in outcome.reason]
        # the documented substeps: at least 3, each moving at most max_substep at the period's starting speed
        speed = np.linalg.norm(live[0] * params.pose_metric, axis=1)
        count = np.clip(np.ceil(speed * params.dt / params.max_substep), 3, max(3, params.max_substeps)).astype(int)
        rows = [dynamics.step(live[1][i], live[0][i], tau[i], params.dt, substeps=int(count[i])) for i in keep_rows(ok)]
        want = type(rows[0])(*(np.array(field) for field in zip(*rows)))
        np.testing.assert_allclose(new.x[ok], want.x, atol=1e-10)
        np.testing.assert_allclose(new.twist[ok], want.xdot, atol=1e-7)
        np.testing.assert_allclose(new.q[ok], want.q, atol=1e-10)
        np.testing.assert_allclose(outcome.q_rate[ok], (want.q - state.q[ok]) / params.dt, atol=1e-8)
        assert (new.residual[ok] <= 1e-10).all()
        keep = np.flatnonzero(ok)
        state = physics.FamilyState(
            *(None if a is None else a[keep] for a in (new.q, new.x, new.t, new.det_sign)),
            new.inverse_condition[keep], new.actuator_condition[keep], new.residual[keep],
            physics.FamilyReference(*(a[keep] for a in reference[:3])), twist=new.twist[keep],
        )  # fmt: skip
        reference = state.reference


@pytest.mark.parametrize("env_id", ["StewartGoughForceReach-v0", "DeltaForceReach-v0"])
def test_a_zero_action_holds_the_platform_against_gravity(env_id):
    """Zero action = the holding forces: from rest the platform stays put (statics τ = J_fᵀ G, gravity on)."""
    env = gym.make(env_id)
    env.reset(seed=3)
    unwrapped = env.unwrapped
    x0 = unwrapped.state.x[0].copy()
    for _ in range(40):
        _, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert not terminated
    np.testing.assert_allclose(unwrapped.state.x[0], x0, atol=1e-9)
    np.testing.assert_allclose(unwrapped.state.twist[0], 0.0, atol=1e-8)
    assert np.abs(info["holding_forces"]).max() > 0.1  # gravity is on
    np.testing.assert_allclose(info["actuator_forces"], info["holding_forces"])


def test_without_gravity_and_efforts_the_kinetic_energy_is_kept():
    """τ = 0, g = 0 (a free mechanism): T = ½ ẋᵀ M ẋ (NumPy) drifts ≤ 1e-6 relative over 100 periods."""
    params = build_family_params("stewart_gough", control="force", gravity=(0.0, 0.0, 0.0), dynamics_substeps=4)
    x, _ = _starts(params, 1, seed=4)
    reference = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(params, x, reference)
    state = state._replace(twist=np.array([[0.01, -0.02, 0.005, 0.05, -0.03, 0.04]]))
    dynamics = params.dynamics
    energy = [float(dynamics.kinetic_energy(state.q, state.x, state.twist)[0])]
    for _ in range(100):
        state, outcome = physics.transition(params, state, np.zeros((1, 6)))
        assert outcome.reason[0] == 0 or physics.TERMINATION_REASONS[outcome.reason[0]] == "out_of_bounds"
        np.testing.assert_array_equal(outcome.effort, 0.0)
        energy.append(float(dynamics.kinetic_energy(state.q, state.x, state.twist)[0]))
    energy = np.array(energy)
    assert np.abs(energy / energy[0] - 1.0).max() <= 1e-6


def test_the_observation_holds_the_twist_and_the_actuator_rates(make_env):
    """The observation's ``twist`` and ``actuator_rates`` columns are ẋ and (q' − q) / dt, clipped to their bounds."""
    env = make_env("DeltaForceReach-v0")
    unwrapped = env.unwrapped
    params = unwrapped.params
    layout = fk.observation_layout("translational", 3, False, force=True)
    obs, _ = env.reset(seed=5)
    np.testing.assert_array_equal(obs[layout["twist"]], 0.0)
    low, high = env.observation_space.low, env.observation_space.high
    for action in ([0.3, -0.2, 0.1], [0.0, 0.0, 0.0], [-0.1, 0.2, 0.05]):
        q0 = unwrapped.state.q[0].copy()
        obs, _, terminated, _, _ = env.step(np.array(action, dtype=np.float32))
        assert not terminated
        twist, q1 = unwrapped.state.twist[0], unwrapped.state.q[0]
        want_twist = np.clip(twist, low[layout["twist"]], high[layout["twist"]]).astype(np.float32)
        want_rates = np.clip((q1 - q0) / params.dt, low[layout["actuator_rates"]], high[layout["actuator_rates"]])
        np.testing.assert_allclose(obs[layout["twist"]], want_twist, rtol=1e-6)
        np.testing.assert_allclose(obs[layout["actuator_rates"]], want_rates.astype(np.float32), rtol=1e-5, atol=1e-7)
    assert obs.shape == (layout["actuator_rates"].stop,)


def test_the_effort_penalty_and_the_saturation_info():
    """reward_action = −w_a ‖τ / τ_max‖²; ``saturated`` is set exactly when a drive sits at its limit."""
    env = gym.make("DeltaForceReach-v0")
    _, info = env.reset(seed=6)
    params = env.unwrapped.params
    push = 1.0 if info["holding_forces"][0] >= 0.0 else -1.0  # towards the limit the holding force is on the side of
    _, _, _, _, info = env.step(np.array([push, 0.0, 0.0], dtype=np.float32))
    limits = np.asarray(params.force_limits)
    np.testing.assert_allclose(
        info["reward_action"], -params.action_weight * np.sum((info["actuator_forces"] / limits) ** 2)
    )
    assert info["saturated"] and abs(info["actuator_forces"][0]) == limits[0]
    _, _, _, _, info = env.step(np.array([0.1, 0.0, 0.0], dtype=np.float32))
    assert not info["saturated"]


def test_rate_control_reports_no_saturation_and_no_force_columns():
    """Rate control: the ``saturated`` row stays 0 at full-scale actions; no force columns, no ``saturated`` info.

    Both controls share one compiled evaluation, which tells rate control by its motion without twists.
    """
    env = gym.make("Planar3RPRReach-v0")
    env.reset(seed=3)
    params = env.unwrapped.params
    _, _, evaluation, observations = physics.step(params, env.unwrapped.state, np.array([[1.0, -1.0, 1.0]]), False)
    np.testing.assert_array_equal(evaluation[params.evaluation_rows["saturated"]], 0.0)
    assert observations.shape == (1, *env.observation_space.shape)
    _, _, _, _, info = env.step(np.ones(3, dtype=np.float32))
    assert "saturated" not in info


def test_the_vector_env_is_the_single_env():
    """N single envs and the native vector env under force control: equal observations, rewards and infos."""
    env_id, n = "StewartGoughForceReach-v0", 3
    vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    singles = [gym.make(env_id) for _ in range(n)]
    obs, _ = vec.reset(seed=7)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(env.reset(seed=7 + i)[0], obs[i])
    rng = np.random.default_rng(8)
    for _ in range(6):
        actions = rng.uniform(-0.05, 0.05, size=(n, 6)).astype(np.float32)
        obs, rewards, terminations, _, info = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, term, _, single = env.step(actions[i])
            np.testing.assert_array_equal(o, obs[i])
            assert r == rewards[i] and term == terminations[i]
            np.testing.assert_array_equal(single["actuator_forces"], info["actuator_forces"][i])


@pytest.mark.slow
@pytest.mark.parametrize("env_id", FORCE_IDS)
def test_gymnasium_checks_every_force_id(env_id):
    """Gymnasium's own ``check_env`` passes; the action space is the normalised efforts (n,)."""
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.action_space.shape == (env.unwrapped.params.robot.n_actuators,)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"force_limits": (1.0, -2.0, 3.0)}, "force_limits must be 3 numbers > 0"),
        ({"gravity": (0.0, 0.0, -9.8)}, "gravity must be 2 finite numbers"),
        ({"dynamics_substeps": 0}, "dynamics_substeps"),
        ({"control": "torque"}, "control must be one of"),
        ({"max_acceleration": (1.0, 1.0, 1.0)}, "control='force' has no max_acceleration"),
        ({"inertia": {"platform_mass": -1.0}}, "inertial data needs"),
    ],
)
def test_bad_force_arguments_are_refused(kwargs, match):
    """Bad force-control arguments raise errors that name them (3-RPR: n = 3, planar points d = 2)."""
    with pytest.raises((ValueError, TypeError), match=match):
        build_family_params("planar_3rpr", **{"control": "force", **kwargs})


def test_rate_control_is_unchanged_by_the_force_fields():
    """The default stays rate control: no twist in the state, the observation without the force columns."""
    env = gym.make("DeltaReach-v0")
    obs, info = env.reset(seed=0)
    assert env.unwrapped.state.twist is None and "actuator_forces" not in info
    assert obs.shape == (fk.observation_layout("translational", 3, False)["k"].stop,)


def _moving_delta(twist: tuple[float, float, float]):
    """A DeltaForceReach-v0 env after reset, its platform given the twist ``twist`` [m/s]."""
    env = gym.make("DeltaForceReach-v0")
    env.reset(seed=9)
    unwrapped = env.unwrapped
    unwrapped._state = unwrapped._state._replace(twist=np.array([twist], dtype=np.float64))
    return env, unwrapped


def test_the_brake_stops_a_moving_platform():
    """``brake_actions``: one period of its efforts takes ‖ẋ‖ down by ≥ 90 %; a zero offset keeps ≥ 90 % of it."""
    from envs.wrappers.shield import brake_actions

    speeds = []
    for use_brake in (True, False):
        env, unwrapped = _moving_delta((0.05, -0.03, 0.02))
        before = np.linalg.norm(unwrapped.state.twist[0])
        action = brake_actions(unwrapped.params, unwrapped.state)[0] if use_brake else np.zeros(3)
        _, _, terminated, _, info = env.step(action.astype(np.float32))
        assert not terminated and not info["saturated"]
        speeds.append(np.linalg.norm(unwrapped.state.twist[0]) / before)
    assert speeds[0] <= 0.1 and speeds[1] >= 0.9, speeds


def test_the_shield_falls_back_on_the_brake_under_force_control():
    """When every scaled candidate ends the episode, the shield applies the braking effort, not a zero offset."""
    from envs.wrappers.shield import brake_actions, shield_actions

    _, unwrapped = _moving_delta((0.0, 0.0, 0.0))
    params = unwrapped.params
    gap = unwrapped.state.x[0, 2] - params.pose_low[2]
    _, unwrapped = _moving_delta((0.0, 0.0, -1.5 * gap / params.dt))  # falling: past the lower bound in a period
    state = unwrapped.state
    proposed = np.array([[-1.0, -1.0, -1.0]])
    _, outcome = physics.transition(params, state, proposed)
    assert outcome.reason[0] != 0  # the proposal ends the episode
    actions, scales = shield_actions(params, state, proposed, 0.05)
    if scales[0] == 0.0:
        np.testing.assert_allclose(actions[0], brake_actions(params, state)[0].astype(np.float32))
        assert np.abs(actions[0]).max() > 0.1
    else:  # a smaller push was safe after all: it must then be one of the scaled proposals
        assert scales[0] in (0.5, 0.25, 0.125)


def test_the_compiled_holding_forces_are_the_numpy_ones():
    """``holding_batch`` (the reset's info) equals ``RobotDynamics.holding_forces`` on every path, gravity on."""
    for robot in ("planar_3rpr", "stewart_gough", "delta"):
        params = build_family_params(robot, control="force", gravity=(0.0, -9.8) if robot == "planar_3rpr" else ())
        x, q = _starts(params, 5, seed=10)
        got = fk.holding_batch(params.packed_rows, params.packed_inertia, q, x)
        want = params.dynamics.holding_forces(q, x)
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())
        assert np.abs(want).max() > 0.1


@pytest.mark.parametrize("robot", ["stewart_gough", "delta"])
def test_the_multi_core_step_is_the_one_thread_step(robot, monkeypatch):
    """Under force control the multi-core step (the hexapod's in SIMD lanes) equals the one-thread step bit for bit."""
    from envs.kernels import step as step_kernels

    params = build_family_params(robot, control="force")
    n = fk.PARALLEL_MIN_BATCH + 7
    x, _ = _starts(params, n, seed=12)
    rng = np.random.default_rng(13)
    reference = physics.FamilyReference(x[::-1].copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(params, x, reference)
    state = state._replace(twist=0.01 * rng.normal(size=x.shape) / params.pose_metric)
    action = rng.uniform(-0.2, 0.2, size=state.q.shape)

    def arrays(result):
        new, outcome, evaluation, obs = result
        return [
            a.copy() for a in (*family_state.state_arrays(new), *(o for o in outcome if o is not None), evaluation, obs)
        ]

    parallel = arrays(physics.step(params, state, action, False))
    monkeypatch.setattr(step_kernels, "PARALLEL_MIN_BATCH", 10**9)
    serial = arrays(physics.step(params, state, action, False))
    for a, b in zip(parallel, serial, strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_action_map_reaches_every_effort_and_inverts():
    """``efforts_of_actions`` against the oracle; ±1 gives ±τ_max whatever τ_h; ``actions_of_efforts`` inverts it."""
    from envs.kernels.force import actions_of_efforts, efforts_of_actions

    rng = np.random.default_rng(5)
    limits = np.array([12.0, 13.0, 0.5])
    hold = rng.uniform(-1.5, 1.5, size=(200, 3)) * limits  # some beyond the limits (near a singularity)
    action = rng.uniform(-1.2, 1.2, size=(200, 3))
    tau = efforts_of_actions(hold, action, limits)
    np.testing.assert_allclose(tau, _interpolated_efforts(hold, action, limits), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(efforts_of_actions(hold, np.ones(3), limits), np.broadcast_to(limits, hold.shape))
    np.testing.assert_allclose(efforts_of_actions(hold, -np.ones(3), limits), -np.broadcast_to(limits, hold.shape))
    np.testing.assert_allclose(efforts_of_actions(hold, np.zeros(3), limits), np.clip(hold, -limits, limits))
    unclipped = (np.abs(tau) < limits * (1.0 - 1e-12)) & (np.abs(action) <= 1.0)
    back = actions_of_efforts(hold, tau, limits)
    np.testing.assert_allclose(back[unclipped], action[unclipped], atol=1e-12)
    wanted = rng.uniform(-2.0, 2.0, size=(200, 3)) * limits
    np.testing.assert_allclose(efforts_of_actions(hold, actions_of_efforts(hold, wanted, limits), limits),
                               np.clip(wanted, -limits, limits), atol=1e-12)  # fmt: skip


def _applied_efforts_oracle(params, known_q, known_x, action):
    """Efforts of ``action`` offset from the nominal NumPy model's holding forces at (known_q, known_x)."""
    dynamics = RobotDynamics(params.robot, params.dynamics.inertia)
    return _interpolated_efforts(dynamics.holding_forces(known_q, known_x), action, params.force_limit_array)


def test_encoders_under_force_control_observe_differences_and_hold_from_the_estimate():
    """Encoders: the efforts are offsets from the nominal τ_h at the *estimated* pose.

    The observed twist and rates are the period's differences of the estimates and of the readings.
    """
    env = gym.make("DeltaForceReach-v0", observation_source="encoders", encoder_resolution=(1e-3, 1e-3, 1e-3))
    params = env.unwrapped.params
    layout = fk.observation_layout("translational", 3, True, force=True)
    obs, info = env.reset(seed=3)
    rng = np.random.default_rng(4)
    for _ in range(8):
        before_x, before_q = info["estimated_pose"].copy(), info["measured_strokes"].copy()
        action = rng.uniform(-0.1, 0.1, 3).astype(np.float32)
        obs, _, terminated, _, info = env.step(action)
        assert not terminated
        want = _applied_efforts_oracle(params, before_q[None], before_x[None], action[None].astype(float))[0]
        np.testing.assert_allclose(info["actuator_forces"], want, rtol=1e-9, atol=1e-9)
        twist = (info["estimated_pose"] - before_x) / params.dt
        rates = (info["measured_strokes"] - before_q) / params.dt
        np.testing.assert_allclose(obs[layout["twist"]], twist, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(obs[layout["actuator_rates"]], rates, rtol=1e-5, atol=1e-5)
    assert not np.allclose(info["estimated_pose"], info["pose"], atol=1e-9)  # a 1 mrad count: the estimate is off


def test_a_robot_as_built_is_driven_by_the_nominal_holding_forces():
    """A geometry tolerance: the efforts are offsets from the *nominal* model's τ_h at the true pose.

    So a zero action does not hold the robot as built exactly.
    """
    env = gym.make("StewartGoughForceReach-v0", geometry_tolerance=2e-3)
    params = env.unwrapped.params
    _, info = env.reset(seed=1)
    rng = np.random.default_rng(5)
    for step in range(5):
        pose = info["pose"].copy()
        action = np.zeros(6, np.float32) if step < 2 else rng.uniform(-0.1, 0.1, 6).astype(np.float32)
        _, _, terminated, _, info = env.step(action)
        assert not terminated
        q_nominal = params.robot.inverse_kinematics(pose)
        want = _applied_efforts_oracle(params, q_nominal[None], pose[None], action[None].astype(float))[0]
        np.testing.assert_allclose(info["actuator_forces"], want, rtol=1e-9, atol=1e-7)
        if step < 2:
            assert not np.allclose(info["actuator_forces"], info["holding_forces"], rtol=1e-6)


def test_the_shield_keeps_random_full_efforts_from_ending_force_episodes():
    """3-RPR under force control, random full-scale efforts: episodes end without the shield, never behind it."""
    from envs.wrappers.shield import SingularityShield

    def ended(env, seed):
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        for _ in range(60):
            _, _, terminated, _, info = env.step(rng.uniform(-1.0, 1.0, 3).astype(np.float32))
            if terminated:
                return info["termination_reason"]
        return None

    plain = [ended(gym.make("Planar3RPRForceReach-v0"), seed) for seed in range(6)]
    shielded = [ended(SingularityShield(gym.make("Planar3RPRForceReach-v0"), 0.05), seed) for seed in range(6)]
    assert sum(reason is not None for reason in plain) >= 3, plain
    assert shielded == [None] * 6, shielded


def test_an_effort_at_a_limit_is_the_limit_exactly():
    """``actions_of_efforts`` gives ±1 for efforts at or beyond a limit, whose efforts are the limit to the bit."""
    from envs.kernels.force import actions_of_efforts, efforts_of_actions

    limits = np.array([12.0, 13.0, 13.0])
    hold = np.array([[-3.54434053, 5.22143976, -5.22143976]])
    wanted = np.array([[12.0, 13.0 + 1e-3, -13.0]])
    action = actions_of_efforts(hold, wanted, limits)
    np.testing.assert_array_equal(action, [[1.0, 1.0, -1.0]])
    np.testing.assert_array_equal(efforts_of_actions(hold, action, limits), [[12.0, 13.0, -13.0]])


@pytest.mark.parametrize("robot", ["delta", "planar_3rpr"])
def test_a_state_the_shield_calls_stoppable_survives_braking_for_ever(robot):
    """From every state ``_stoppable`` accepts, braking (the shield's last resort) keeps it safe for 2 s, not 0.3.

    The oracle is the closed loop itself: ``brake_actions`` applied period after period with the environment's own
    transition. Random fast states (speeds up to 3 m/s, poses of the task box) give both kinds; a check that only
    looked ``BRAKE_TIME`` ahead accepts states that are still moving then, or stopped where the drives cannot hold
    them, and that end later.
    """
    from envs.wrappers.shield import _stoppable, brake_actions

    params = build_family_params(robot, control="force")
    n = 256
    x, _ = _starts(params, n, seed=21)
    rng = np.random.default_rng(22)
    reference = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(params, x, reference)
    twist = rng.normal(size=x.shape) * rng.uniform(0.0, 3.0, size=(n, 1)) / np.sqrt(x.shape[1])
    state = state._replace(twist=twist / params.pose_metric)
    floor = np.full(n, 0.05)
    accepted = _stoppable(params, state, floor)
    assert 0 < accepted.sum() < n, accepted.sum()
    ok = np.ones(n, dtype=bool)
    for _ in range(int(np.ceil(2.0 / params.dt))):
        with np.errstate(invalid="ignore"):
            state, outcome = physics.transition(params, state, brake_actions(params, state))
        ok &= (outcome.reason == 0) & (state.inverse_condition >= floor)
    assert ok[accepted].all(), np.flatnonzero(accepted & ~ok)
