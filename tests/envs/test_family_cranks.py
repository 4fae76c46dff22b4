"""The crank- and slider-driven ids (Delta, 3-RRR, 3-PRR): the contract the hexapod's ids keep, and the adept cycle."""

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs
from envs import physics, presets
from envs.kernels import generic as fk
from envs.kernels import packing, records
from envs.kernels import step as step_kernels
from envs.tasks import samplers
from envs.wrappers.shield import SingularityShield
from robot_control.controllers import ResolvedRateController

CRANK_IDS = (
    "DeltaReach-v0",
    "DeltaReachHard-v0",
    "DeltaTrack-v0",
    "Planar3RRRReach-v0",
    "Planar3RRRReachHard-v0",
    "Planar3PRRReach-v0",
)
REACH_IDS = tuple(i for i in CRANK_IDS if "Track" not in i)


def test_the_ids_are_registered_family_ids():
    """Every new id is registered, on the family core, with its robot built by name."""
    assert set(CRANK_IDS) <= set(envs.ENV_IDS)
    kinds = {i: gym.make(i).unwrapped.params.robot.actuator_kinds for i in CRANK_IDS}
    assert kinds["DeltaReach-v0"] == ("crank",) * 3
    assert kinds["Planar3PRRReach-v0"] == ("slider",) * 3
    assert gym.make("DeltaReach-v0").unwrapped.params.robot.pose_space.name == "translational"


@pytest.mark.parametrize("env_id", CRANK_IDS)
def test_checkers_pass_without_warnings(env_id):
    """Gymnasium's and SB3's environment checkers pass with zero warnings."""
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id).unwrapped
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=True)


@pytest.mark.parametrize("env_id", CRANK_IDS)
def test_reward_is_the_sum_of_its_terms_and_rollouts_are_deterministic(env_id):
    """Same seed, same rollout; reward = Σ terms (Type I included); costs consistent; observations in the space."""

    def rollout(seed):
        env = gym.make(env_id)
        env.action_space.seed(seed)
        obs, info = env.reset(seed=seed)
        out = [obs]
        params = env.unwrapped.params
        for _ in range(60):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs)
            assert reward == pytest.approx(sum(info[name] for name in physics.REWARD_TERMS), abs=1e-12)
            assert info["constraint_residual"] <= 1e-10 or terminated
            type1 = info["actuator_condition_number"] < params.actuator_safe_threshold
            assert info["cost_actuator_singularity"] == float(type1)
            assert info["cost"] >= info["cost_actuator_singularity"]
            assert (info["reward_actuator_singularity"] < 0) == type1
            out.append(obs)
            if terminated or truncated:
                obs, info = env.reset()
        return np.array(out)

    np.testing.assert_array_equal(rollout(5), rollout(5))


@pytest.mark.parametrize("env_id", ["DeltaReach-v0", "Planar3RRRReach-v0", "DeltaTrack-v0"])
def test_vector_env_equals_single_envs(env_id):
    """Sub-environment i of the native vector env is the single env reset with seed s + i, step by step."""
    n = 3
    vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    singles = [gym.make(env_id) for _ in range(n)]
    obs, _ = vec.reset(seed=7)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=7 + i)[0])
    rng = np.random.default_rng(0)
    for _ in range(30):
        actions = rng.uniform(-1, 1, size=(n, 3)).astype(np.float32)
        obs, rewards, term, _trunc, _ = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, t, _, _ = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rewards[i] == r and term[i] == t
        if term.any():  # the vector env resets that robot next step; the single one would need reset()
            break


@pytest.mark.parametrize("env_id", ["DeltaReach-v0", "Planar3RRRReach-v0", "Planar3PRRReach-v0"])
def test_pickling_and_headless_rendering(env_id):
    """A pickled env continues exactly as the original; rgb_array frames (cranks drawn) need no display."""
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros(3, dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    action = np.full(3, 0.7, dtype=np.float32)
    np.testing.assert_array_equal(env.step(action)[0], clone.step(action)[0])
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10


def test_parallel_step_equals_serial_step_bit_for_bit():
    """The multi-core step gives exactly the one-thread results for the Delta."""
    params = gym.make("DeltaReach-v0").unwrapped.params
    n = 2 * fk.PARALLEL_MIN_BATCH + 7
    generators = [np.random.default_rng(i) for i in range(n)]
    start, reference = gym.make("DeltaReach-v0").unwrapped.sample_tasks(generators, {})
    state = physics.initial_state(params, start, reference)
    action = np.random.default_rng(1).uniform(-1, 1, size=(n, 3))
    low, high = physics.observation_bounds(params, False)
    motion = (state.q, state.x, state.t, state.det_sign, state.residual)
    grouped = ((low, high, False), motion, tuple(state.reference), action)
    outs = [fk.allocate_step(n, 3, low.shape[0]) for _ in range(2)]
    assert not step_kernels._step_parallel(params.packed_rows, params.packed_rows, *grouped, outs[0])
    call = step_kernels.step_call(params.packed_rows, params.packed_rows, *grouped[:3], outs[1])
    assert not step_kernels.path_kernels(params.packed_rows).step_serial(call, action)
    for a, b in zip(*outs):
        np.testing.assert_array_equal(a, b)


#: The robots of each pose space the register paths serve: each test compiles that space's work-array path once.
REGISTER_ROBOTS = {
    "planar": ("Planar3RRRReach-v0", "Planar3PRRReach-v0", "Planar3RPRReach-v0"),
    "translational": ("DeltaReach-v0",),
}


@pytest.mark.parametrize("space", sorted(REGISTER_ROBOTS))  # tests/numba_warmup.py compiles both paths
def test_register_path_equals_the_work_array_path_bit_for_bit(space):
    """The step's register path (3 × 3 in scalars) gives exactly what its work-array path gives.

    One step body (``envs.kernels.rate.advance_rate``) runs on both: the work-array path is what any pose space runs,
    the register path replaces it for three actuators (legs: the 3-RPR; cranks or sliders: the others); both
    integrators. Full-speed random actions, so some robots leave their bounds or meet a singularity and the
    failure branches are compared too.
    """
    for env_id in REGISTER_ROBOTS[space]:
        for integrator in ("euler", "rk4"):
            _compare_register_and_work_paths(env_id, integrator)


def _compare_register_and_work_paths(env_id, integrator):
    env = gym.make(env_id, integrator=integrator).unwrapped
    params = env.params
    n = 200
    start, reference = env.sample_tasks([np.random.default_rng(i) for i in range(n)], {})
    state = physics.initial_state(params, start, reference)
    cs = params.packed_rows
    assert packing.row_path(cs) in (packing.PLANAR_LEGS, packing.THREE)
    work = step_kernels._PATH_KERNELS[packing.WORK_ARRAYS, packing.pose_space_code(cs)]
    rng = np.random.default_rng(7)
    q, x, residual = state.q, state.x, state.residual
    reasons = []
    for _ in range(40):
        action = rng.uniform(-1.5, 1.5, size=(n, 3))
        motion = records.Motion(q, x, state.t, state.det_sign, residual)
        new = fk.transition_batch(cs, motion, action)
        for got, want in zip(new, fk.transition_batch(cs, motion, action, kernels=work)):
            np.testing.assert_array_equal(got, want, err_msg=f"{env_id} {integrator}")
        reasons.append(new[7])
        q, x, residual = new[0], new[1], new[4]
    assert np.any(np.concatenate(reasons) != 0), f"{env_id}: no termination, the failure branches went untested"


def _safety(params, x):
    """min(k, k_I k_safe / k_I,safe) of poses x (N, m): the measure tasks are certified on."""
    robot = params.robot
    q = robot.inverse_kinematics(x)
    k = robot.inverse_condition_number(q, x)
    k1 = robot.actuator_condition_number(q, x)
    return np.minimum(k, k1 * params.safe_threshold / params.actuator_safe_threshold)


@pytest.mark.parametrize("env_id", ["DeltaReach-v0", "Planar3RRRReach-v0", "Planar3PRRReach-v0"])
def test_standard_targets_have_a_safe_straight_path(env_id):
    """A standard task's straight path keeps both measures above k_safe (at points ``segment_spacing`` apart; ±5 %)."""
    env = gym.make(env_id)
    params = env.unwrapped.params
    for seed in range(5):
        _, info = env.reset(seed=seed)
        start, target = info["pose"][None], info["target"][None]
        assert fk.segment_batch(params.packed, start, target)[0] >= params.safe_threshold
        path = start + np.linspace(0.0, 1.0, 200)[:, None] * (target - start)
        assert _safety(params, path).min() >= 0.95 * params.safe_threshold


def test_delta_hard_targets_are_ill_conditioned():
    """DeltaReachHard-v0's targets lie where 2 k_hard ≤ safety < k_safe, reached by a path keeping ≥ 2 k_hard."""
    env = gym.make("DeltaReachHard-v0")
    params = env.unwrapped.params
    for seed in range(5):
        _, info = env.reset(seed=seed)
        target = info["target"][None]
        assert 2 * params.hard_threshold <= _safety(params, target)[0] < params.safe_threshold
        assert fk.segment_batch(params.packed, info["pose"][None], target)[0] >= 2 * params.hard_threshold


def test_3rrr_hard_targets_are_ill_conditioned_and_on_the_starts_side():
    """Planar3RRRReachHard-v0: targets where 2 k_hard ≤ safety < k_safe, reached by a path keeping ≥ 2 k_hard.

    Start and target have one sign of det J_x (the kinematics library's link Jacobian): a path joins them.
    """
    env = gym.make("Planar3RRRReachHard-v0")
    params = env.unwrapped.params
    robot = params.robot
    for seed in range(5):
        _, info = env.reset(seed=seed)
        start, target = info["pose"][None], info["target"][None]
        assert 2 * params.hard_threshold <= _safety(params, target)[0] < params.safe_threshold
        assert fk.segment_batch(params.packed, start, target)[0] >= 2 * params.hard_threshold
        ends = np.concatenate([start, target])
        signs = np.sign(np.linalg.det(robot.link_jacobian(robot.inverse_kinematics(ends), ends)))
        assert signs[0] == signs[1]


@pytest.mark.parametrize("env_id", ["DeltaReachHard-v0", "Planar3RRRReachHard-v0"])
def test_shield_keeps_random_actions_out_of_both_singularities(env_id):
    """Full-speed random actions end episodes at singularities unshielded; behind the shield, of neither type."""
    singular = {"singular", "singularity_crossed", "newton_failed", "assembly_mode_change", "actuator_singular"}

    def run(env: gym.Env) -> list[str]:
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        reasons = []
        for _ in range(100):
            _, _, terminated, truncated, info = env.step(rng.choice([-1.0, 1.0], size=3).astype(np.float32))
            reasons.append(info["termination_reason"])
            if terminated or truncated:
                env.reset()
        return reasons

    assert singular & set(run(gym.make(env_id)))  # the negative control: the scenario meets singularities
    assert not singular & set(run(SingularityShield(gym.make(env_id), k_guard=0.05)))


@pytest.mark.parametrize("env_id", ["DeltaReach-v0", "Planar3RRRReach-v0"])
def test_goal_view_reward_equals_step_reward(env_id):
    """HER's compute_reward on the episode's own goal gives the reward step paid (the Type I term included)."""
    env = envs.GoalReachWrapper(gym.make(env_id))
    obs, _ = env.reset(seed=1)
    for _ in range(10):
        obs, reward, _terminated, _, info = env.step(env.action_space.sample())
        assert env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == pytest.approx(reward, abs=1e-5)


@pytest.mark.parametrize("env_id", REACH_IDS)
def test_resolved_rate_reaches_standard_targets(env_id):
    """The resolved-rate baseline reads the observation (translational, planar) and reaches standard targets."""
    vec = gym.make_vec(env_id, num_envs=8, vectorization_mode="vector_entry_point")
    controller = ResolvedRateController(vec.unwrapped.params)
    obs, _ = vec.reset(seed=0, options={"targets": "standard"})
    reached = np.zeros(8, dtype=bool)
    for _ in range(200):
        obs, _, terminated, truncated, info = vec.step(controller(obs))
        reached |= info["is_success"] & ~terminated
        if (terminated | truncated).any():
            break
    assert reached.all()


# -- the adept cycle: a polyline path in the compiled reference ------------------------------------------------


@pytest.fixture(scope="module")
def delta_track():
    """The DeltaTrack-v0 environment (unwrapped)."""
    return gym.make("DeltaTrack-v0").unwrapped


def test_adept_cycle_reference_visits_its_corners_at_rest(delta_track):
    """25 mm up, 305 mm across, 25 mm down and back: the corners at the cumulative time shares, at rest there."""
    params = delta_track.params
    delta_track.reset(seed=3)
    ref = delta_track.state.reference
    c, a, heading = ref.center[0], ref.amplitude[0], ref.phase[0, 1]
    direction = np.array([np.cos(heading), np.sin(heading), 0.0])
    corners = [(0.0, 0.0), (0.0, 0.025), (0.305, 0.025), (0.305, 0.0), (0.305, 0.025), (0.0, 0.025)]
    steps_per_period = round(params.track_period / params.dt)
    shares = np.cumsum((0,) + params.track_path_times[:-1]) / np.sum(params.track_path_times)
    np.testing.assert_allclose(a, (0.305, 0.0, 0.025))
    for (across, up), share in zip(corners, shares):
        t = np.array([round(share * steps_per_period)])
        pose, rate = fk.reference_batch(params.packed, t, ref.center[:1], ref.amplitude[:1], ref.phase[:1])
        np.testing.assert_allclose(pose[0], c + across * direction + (0, 0, up), atol=1e-12)
        np.testing.assert_allclose(rate[0], 0.0, atol=1e-12)


def test_path_reference_rate_is_the_derivative_of_its_pose(delta_track):
    """ẋ* (fed to the observation) is dx*/dt: central differences over a whole period, within the space's bounds."""
    params = delta_track.params
    delta_track.reset(seed=4)
    ref = delta_track.state.reference
    steps = round(params.track_period / params.dt)
    fine = params.dt / 20.0
    # Sample the reference at fine times by scaling ω: a second packing with dt / 20 (same period).
    preset = {**presets.ROBOT_PRESETS["delta_track"], "dt": fine}
    fine_params = presets.build_family_params(preset.pop("robot"), **preset)
    t = np.arange(20 * steps + 1)
    one = [np.repeat(r[:1], len(t), 0) for r in ref[:3]]  # centre, amplitude, phase
    pose, rate = fk.reference_batch(fine_params.packed, t, *one)
    numeric = (pose[2:] - pose[:-2]) / (2 * fine)
    np.testing.assert_allclose(rate[1:-1], numeric, atol=2e-3 * np.abs(rate).max())
    _, high = physics.observation_bounds(params, True)
    assert np.all(np.abs(rate) <= high[-3:] + 1e-12)
    assert np.abs(rate[:, :2]).max() > 0.3  # the move across peaks at π/2 · 0.305 m / 1.2 s ≈ 0.40 m/s


def test_track_starts_on_the_cycle_and_the_whole_cycle_is_safe(delta_track):
    """Reset puts the plate at the pick point; every point of the cycle is safe (both singularity types)."""
    params = delta_track.params
    for seed in range(3):
        _, info = delta_track.reset(seed=seed)
        assert info["position_error"] == pytest.approx(0.0, abs=1e-12)
        ref = delta_track.state.reference
        t = np.arange(round(params.track_period / params.dt) + 1)
        one = [np.repeat(r[:1], len(t), 0) for r in ref[:3]]  # centre, amplitude, phase
        pose, _ = fk.reference_batch(params.packed, t, *one)
        assert _safety(params, pose).min() >= params.safe_threshold * (1 - 1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"track_path": ((0, 0, 0),), "track_path_times": (1,)}, "2 to 8 vertices of 3 values"),
        ({"track_path": ((0, 0), (1, 1)), "track_path_times": (1, 1)}, "2 to 8 vertices of 3 values"),
        ({"track_path": ((0, 0, 0), (1, 0, 0)), "track_path_times": (1,)}, "2 positive shares"),
        ({"track_path": ((0, 0, 0), (1, 0, 0)), "track_path_times": (1, -1)}, "2 positive shares"),
        ({"track_path": ((0, 0, 0), (np.nan, 0, 0)), "track_path_times": (1, 1)}, "finite"),
        ({"robot": "scara"}, "one of"),
    ],
)
def test_bad_paths_and_robot_names_are_refused(kwargs, match):
    """A malformed path or an unknown robot name is refused with the expected and the actual value."""
    base = {**presets.ROBOT_PRESETS["delta"]}
    base.update(kwargs)
    robot = base.pop("robot")
    with pytest.raises(ValueError, match=match):
        presets.build_family_params(robot, **base)


@pytest.mark.parametrize("hard", [False, True])
def test_parallel_reach_sampler_equals_the_serial_one(hard):
    """One generator per robot: the multi-core sampler draws exactly the serial sampler's pairs."""
    params = gym.make("Planar3RRRReach-v0").unwrapped.params
    n = 3 * fk.PARALLEL_MIN_SAMPLES + 1
    outs = []
    for parallel in (False, True):
        generators = [np.random.default_rng(100 + i) for i in range(n)]
        streams = fk.random_streams(generators)
        if parallel:  # every core: ``sample_reach_batch`` with one stream per robot
            arrays = list(samplers.sample_reach_batch(params.packed, streams, n, 3, hard, params.min_distance))
        else:
            arrays = [np.empty((n, 3)) for _ in range(3)]
            reach, ok = samplers.sampler_kernels(params.packed).reach, np.zeros(n, dtype=np.bool_)
            assert reach(params.packed, streams, hard, params.min_distance, *arrays, ok, fk.ONE_THREAD) == -1
            assert ok.all()
        outs.append(arrays + [np.array([g.random() for g in generators])])  # the generators advanced alike
    for a, b in zip(*outs):
        np.testing.assert_array_equal(a, b)
