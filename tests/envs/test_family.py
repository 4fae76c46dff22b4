"""The family core: compiled kernels against the NumPy kinematics, and the hexapod environments' contract."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import envs
from envs import physics, presets
from envs.kernels import generic as fk
from envs.kernels import step as step_kernels
from envs.wrappers.shield import SingularityShield
from kinematics import DistanceConstraintMechanism, Planar3RPR, StewartGough
from kinematics.stewart_gough import semi_regular_hexagon

HEXAPOD_IDS = ("StewartGoughReach-v0", "StewartGoughReachHard-v0", "StewartGoughTrack-v0")


def _random_poses(params, n, seed):
    rng = np.random.default_rng(seed)
    x = rng.uniform(params.sample_low, params.sample_high, size=(n, params.robot.n_pose))
    return x[fk.safe_batch(params.packed, x)]


@pytest.fixture(scope="module")
def hexapod():
    """Parameters of the default hexapod environment."""
    return presets.build_family_params()


def test_kernels_match_the_kinematics_library(hexapod):
    """Inverse kinematics, k and sign(det J_x) of the kernels equal the NumPy reference."""
    x = _random_poses(hexapod, 400, 0)
    q, k, k1, sign, residual = fk.initial_batch(hexapod.packed, x)
    np.testing.assert_array_equal(k1, 1.0)  # legs have no Type I singularity
    robot = hexapod.robot
    np.testing.assert_allclose(q, robot.inverse_kinematics(x), rtol=1e-13)
    k_ref, det = robot.singularity_measures(q, x)
    np.testing.assert_allclose(k, k_ref, rtol=1e-9)
    np.testing.assert_array_equal(sign, np.sign(det))
    assert residual.max() < 1e-14


def test_transition_is_the_twist_integrated_and_corrected(hexapod):
    """One step: the new pose satisfies Φ = 0 (≤ 1e-10), moved along J_f q̇ to first order, on the rotation group."""
    x = _random_poses(hexapod, 50, 1)
    ref = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(hexapod, x, ref)
    action = np.random.default_rng(2).uniform(-1, 1, size=(len(x), 6))
    new, outcome = physics.transition(hexapod, state, action)
    ok = outcome.reason == 0
    assert ok.mean() > 0.9
    robot = hexapod.robot
    assert np.abs(robot.constraints(new.q[ok], new.x[ok])).max() <= 1e-10
    np.testing.assert_allclose(new.q[ok], robot.inverse_kinematics(new.x[ok]), atol=1e-10)
    twist = np.einsum("nij,nj->ni", robot.forward_jacobian(state.q[ok], x[ok]), outcome.q_rate[ok]) * hexapod.dt
    moved = robot.pose_difference(new.x[ok], x[ok])
    assert np.abs(moved - twist).max() < 0.05 * np.abs(twist).max()


def test_newton_in_kernels_equals_library_forward_kinematics(hexapod):
    """The compiled correction lands on the pose the library's Newton finds from the same guess."""
    x = _random_poses(hexapod, 20, 3)
    ref = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(hexapod, x, ref)
    new, outcome = physics.transition(hexapod, state, np.full((len(x), 6), 0.3))
    result = hexapod.robot.forward_kinematics(new.q, x)
    ok = outcome.reason == 0
    np.testing.assert_allclose(result.x[ok], new.x[ok], atol=1e-9)


@pytest.mark.parametrize("env_id", HEXAPOD_IDS)
def test_checkers_pass_without_warnings(env_id):
    """Gymnasium's and SB3's environment checkers pass with zero warnings."""
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id).unwrapped
    with __import__("warnings").catch_warnings():
        __import__("warnings").simplefilter("error")
        check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=True)


@pytest.mark.parametrize("env_id", HEXAPOD_IDS)
def test_reward_is_the_sum_of_its_terms_and_rollouts_are_deterministic(env_id):
    """Same seed, same rollout; reward = Σ terms; residual ≤ 1e-10; spaces contain the observations."""

    def rollout(seed):
        env = gym.make(env_id)
        env.action_space.seed(seed)
        obs, info = env.reset(seed=seed)
        out = [obs]
        for _ in range(60):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs)
            terms = sum(info[name] for name in physics.REWARD_TERMS)
            assert reward == pytest.approx(terms, abs=1e-12)
            assert info["constraint_residual"] <= 1e-10 or terminated
            out.append(obs)
            if terminated or truncated:
                obs, info = env.reset()
        return np.array(out)

    np.testing.assert_array_equal(rollout(5), rollout(5))


def test_vector_env_equals_single_envs():
    """Sub-environment i of the native vector env is the single env reset with seed s + i, step by step."""
    n = 4
    vec = gym.make_vec("StewartGoughReach-v0", num_envs=n, vectorization_mode="vector_entry_point")
    singles = [gym.make("StewartGoughReach-v0") for _ in range(n)]
    obs, _ = vec.reset(seed=7)
    for i, env in enumerate(singles):
        o, _ = env.reset(seed=7 + i)
        np.testing.assert_array_equal(obs[i], o)
    rng = np.random.default_rng(0)
    for _ in range(30):
        actions = rng.uniform(-1, 1, size=(n, 6)).astype(np.float32)
        obs, rewards, term, _trunc, _ = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, t, _, _ = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rewards[i] == r and term[i] == t


def test_pickling_and_headless_rendering():
    """A pickled env continues exactly as the original; rgb_array frames need no display."""
    env = gym.make("StewartGoughReach-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros(6, dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    action = np.full(6, 0.7, dtype=np.float32)
    np.testing.assert_array_equal(env.step(action)[0], clone.step(action)[0])
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    frames = gym.make_vec(
        "StewartGoughTrack-v0", num_envs=2, vectorization_mode="vector_entry_point", render_mode="rgb_array"
    )
    frames.reset(seed=0)
    assert all(f.shape == (480, 480, 3) for f in frames.render())


def test_parallel_step_equals_serial_step_bit_for_bit(hexapod):
    """The multi-core step (N ≥ PARALLEL_MIN_BATCH) gives exactly the one-thread results."""
    n = 2 * fk.PARALLEL_MIN_BATCH + 7
    generators = [np.random.default_rng(i) for i in range(n)]
    start, reference = envs.FamilyReachEnv().sample_tasks(generators, {})
    state = physics.initial_state(hexapod, start, reference)
    action = np.random.default_rng(1).uniform(-1, 1, size=(n, 6))
    low, high = physics.observation_bounds(hexapod, False)
    motion = (state.q, state.x, state.t, state.det_sign, state.residual)
    grouped = ((low, high, False), motion, tuple(state.reference), action)
    outs = [fk.allocate_step(n, 6, low.shape[0]) for _ in range(2)]
    assert not step_kernels._step_parallel(hexapod.packed_rows, hexapod.packed_rows, *grouped, outs[0])
    call = step_kernels.step_call(hexapod.packed_rows, hexapod.packed_rows, *grouped[:3], outs[1])
    assert not step_kernels.path_kernels(hexapod.packed_rows).step_serial(call, action)
    for a, b in zip(*outs):
        np.testing.assert_array_equal(a, b)


def test_hard_targets_are_certified():
    """Hard hexapod targets lie in the ill-conditioned band; the straight geodesic keeps k ≥ 2 k_hard."""
    env = gym.make("StewartGoughReachHard-v0")
    params = env.unwrapped.params
    for seed in range(5):
        _, info = env.reset(seed=seed)
        target = info["target"][None]
        q = params.robot.inverse_kinematics(target)
        k = params.robot.inverse_condition_number(q, target)
        assert 2 * params.hard_threshold <= k < params.safe_threshold
        k_min = fk.segment_batch(params.packed, info["pose"][None], target)
        assert k_min[0] >= 2 * params.hard_threshold


def test_standard_targets_have_a_safe_straight_path(hexapod):
    """A standard task's geodesic start → target keeps k ≥ k_safe (checked ≤ 1 cm apart)."""
    env = gym.make("StewartGoughReach-v0")
    for seed in range(5):
        _, info = env.reset(seed=seed)
        k_min = fk.segment_batch(hexapod.packed, info["pose"][None], info["target"][None])
        assert k_min[0] >= hexapod.safe_threshold


def test_shield_holds_the_hexapod_out_of_the_singular_zone():
    """Turning about the vertical toward Fichter's singularity ends in it unshielded; behind the shield, never."""

    def yaw_drive(env: gym.Env) -> list[str]:
        env.reset(seed=1)
        reasons = []
        for _ in range(120):
            state, robot = env.unwrapped.state, env.unwrapped.params.robot
            rate = robot.inverse_jacobian(state.q[0], state.x[0]) @ np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
            _, _, terminated, truncated, info = env.step((rate / np.abs(rate).max()).astype(np.float32))
            reasons.append(info["termination_reason"])
            if terminated or truncated:
                break
        return reasons

    singular = {"singular", "singularity_crossed", "newton_failed", "assembly_mode_change"}
    assert singular & set(yaw_drive(gym.make("StewartGoughReachHard-v0")))  # the negative control
    shielded = yaw_drive(SingularityShield(gym.make("StewartGoughReachHard-v0"), k_guard=0.05))
    assert not singular & set(shielded) and len(shielded) == 120


def test_goal_view_reward_equals_step_reward():
    """HER's compute_reward on the episode's own goal gives the reward step paid."""
    env = envs.GoalReachWrapper(gym.make("StewartGoughReach-v0"))
    obs, _ = env.reset(seed=1)
    for _ in range(10):
        obs, reward, _terminated, _, info = env.step(env.action_space.sample())
        assert env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == pytest.approx(reward, abs=1e-5)


def test_a_new_robot_is_data_a_6ups_and_a_3rpr_of_other_geometry():
    """A 6-UPS and a 3-RPR of other geometries, given only as points, step through gym.make."""
    base = semi_regular_hexagon(0.6, 20.0)
    platform = semi_regular_hexagon(0.25, 40.0)
    hexapod = DistanceConstraintMechanism(base, platform, pose_space="spatial")
    env = gym.make("StewartGoughReach-v0", robot=hexapod, stroke_limits=(0.45, 0.85))
    env.reset(seed=0)
    for _ in range(20):
        _, _, terminated, _, info = env.step(env.action_space.sample())
        assert info["constraint_residual"] <= 1e-10 or terminated
        assert info["pose"].shape == (6,)
        if terminated:
            env.reset()
    planar = Planar3RPR(base=[[0, 0], [1.2, 0.1], [0.5, 1.0]], platform=[[0, -0.15], [0.2, 0.05], [-0.2, 0.0]])
    env = gym.make("StewartGoughReach-v0", robot=planar)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (18,) and env.action_space.shape == (3,)
    for _ in range(20):
        _, _, terminated, _, info = env.step(env.action_space.sample())
        if terminated:
            env.reset()
    assert isinstance(StewartGough(), DistanceConstraintMechanism)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"robot": "hexapod"}, "DistanceConstraintMechanism"),
        ({"stroke_limits": (0.8, 0.4)}, "stroke_limits"),
        ({"sample_low": (-1.0, -0.1, 0.4, -0.2, -0.2, -0.5)}, "sampling box"),
        ({"pose_low": (-0.2, -0.2, 0.3)}, "pose_low must be 6"),
        ({"safe_threshold": 0.01}, "thresholds"),
        ({"integrator": "midpoint"}, "integrator"),
        ({"hard_kind": "any"}, "hard_kind"),
    ],
)
def test_bad_arguments_are_refused_with_the_expected_and_actual_value(kwargs, match):
    """Constructor arguments are validated at the boundary."""
    with pytest.raises((ValueError, TypeError), match=match):
        envs.FamilyReachEnv(**kwargs)


def test_bad_actions_are_refused():
    """Wrong shape and non-finite actions raise clear errors."""
    env = gym.make("StewartGoughReach-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(6, np.nan))


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_vector_env_autoreset_modes_and_sb3_adapter(mode):
    """The family vector env runs both autoreset modes; in SAME_STEP it serves SB3 through the native adapter."""
    from gymnasium.vector import AutoresetMode

    from training.vec_adapter import NativeVecEnvAdapter

    vec = gym.make_vec(
        "StewartGoughReach-v0",
        num_envs=3,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode(mode),
        max_episode_steps=5,
    )
    vec.reset(seed=0)
    ended_seen = False
    for _ in range(12):
        _, _, term, trunc, infos = vec.step(vec.action_space.sample())
        ended_seen |= bool((term | trunc).any())
        if mode == "SameStep" and (term | trunc).any():
            assert infos["_final_obs"].any()
    assert ended_seen
    if mode == "SameStep":
        adapter = NativeVecEnvAdapter.from_id("StewartGoughReach-v0", 2, max_episode_steps=4)
        adapter.seed(1)
        obs = adapter.reset()
        assert obs.shape == (2, 33)
        finals = 0
        for _ in range(5):
            adapter.step_async(np.zeros((2, 6), dtype=np.float32))
            obs, _rewards, dones, infos = adapter.step_wait()
            finals += sum("terminal_observation" in info for info in infos)
            assert finals == 0 or dones.any() or finals == 2
        assert finals == 2  # both robots truncated at step 4, with their last observation


def test_6x6_inverse_condition_against_lapack():
    """The compiled one-sided Jacobi gives LAPACK's σ_min/σ_max: 1e-12 when well conditioned, 1e-7 down to k = 1e-4."""
    from envs.kernels.linalg import inverse_condition6

    rng = np.random.default_rng(0)
    U, _ = np.linalg.qr(rng.normal(size=(400, 6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(400, 6, 6)))
    k_true = np.logspace(0, -4, 400)
    sigma = np.stack([np.ones(400), *rng.uniform(0.3, 1.0, size=(4, 400)), k_true], axis=-1)
    M = U @ (sigma[..., None] * np.swapaxes(V, -1, -2))
    k = np.array([inverse_condition6(np.ascontiguousarray(m.T)) for m in M])
    ref = np.linalg.svd(M, compute_uv=False)
    ref = ref[:, -1] / ref[:, 0]
    rel = np.abs(k - ref) / ref
    assert rel[k_true > 1e-2].max() < 1e-12
    assert rel.max() < 1e-7
    assert inverse_condition6(np.zeros((6, 6))) == 0.0
    assert np.isnan(inverse_condition6(np.full((6, 6), np.nan)))


@pytest.mark.parametrize("count", [1, 7, 16])
def test_6x6_inverse_condition_lanes_equal_one_at_a_time(count):
    """Side by side, each matrix's k is bit for bit its k alone, whatever its neighbours (converged, zero, NaN)."""
    from envs.kernels.linalg import LANES, inverse_condition6, inverse_condition6_lanes

    rng = np.random.default_rng(count)
    U, _ = np.linalg.qr(rng.normal(size=(count, 6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(count, 6, 6)))
    sigma = np.sort(rng.uniform(1e-5, 1.0, size=(count, 6)), axis=-1)
    M = U @ (sigma[..., None] * np.swapaxes(V, -1, -2))  # sweeps needed differ from matrix to matrix
    M[0] = np.diag(np.arange(1.0, 7.0))  # orthogonal columns: converged before the first rotation
    if count > 2:
        M[1] = 0.0
        M[2, 3, 4] = np.nan
    alone = np.array([inverse_condition6(np.ascontiguousarray(m.T)) for m in M])
    H = np.full((6, 6, LANES), 7.0)  # unused lanes hold junk that must not matter
    H[:, :, :count] = np.transpose(M, (2, 1, 0))  # column c of matrix l at H[c, :, l]
    out, worst, active = np.full(LANES, -1.0), np.empty(LANES), np.empty(LANES)
    inverse_condition6_lanes(H, count, out, worst, active)
    np.testing.assert_array_equal(out[:count], alone)
    assert (out[count:] == -1.0).all()
    assert alone[0] == pytest.approx(1 / 6, rel=1e-15)
    if count > 2:
        assert alone[1] == 0.0 and np.isnan(alone[2])


def _matrices_of_condition(rng, size: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Random size × size matrices with k = σ_min/σ_max spread over [t / 3, 3 t], and NumPy's SVD's k of them.

    One per entry of t; the other singular values lie between k and σ_max = 1.
    """
    n = len(t)
    U, _ = np.linalg.qr(rng.normal(size=(n, size, size)))
    V, _ = np.linalg.qr(rng.normal(size=(n, size, size)))
    k = t * np.exp(rng.uniform(np.log(1 / 3), np.log(3), size=n))
    sigma = np.exp(rng.uniform(np.log(k)[:, None], 0.0, size=(n, size)))
    sigma[:, 0], sigma[:, 1] = k, 1.0  # σ_min/σ_max = k exactly
    M = U @ (sigma[..., None] * np.swapaxes(V, -1, -2))
    ref = np.linalg.svd(M, compute_uv=False)
    return M, ref[:, -1] / ref[:, 0]


def test_3x3_condition_proof_is_sound_and_proves_every_well_conditioned_matrix():
    """condition_at_least3 proves k ≥ t only where NumPy's SVD agrees, and proves it wherever k ≥ 1.35 t.

    min(‖MᵀM‖_∞, tr MᵀM) ≤ √3 σ_max², so every k > 3^(1/4) t ≈ 1.32 t is provable. The matrices are built with
    k spread over [t / 3, 3 t], the middle singular value between, some of them with a scale of 1e±6.
    """
    from envs.kernels.linalg import condition_at_least3

    rng = np.random.default_rng(43)
    t = rng.choice([0.03, 0.1, 0.15, 0.3], size=4000)
    M, ref = _matrices_of_condition(rng, 3, t)
    M *= rng.choice([1e-6, 1.0, 1e6], size=4000)[:, None, None]
    proven = np.array([condition_at_least3(*m.ravel(), ti) for m, ti in zip(M, t)])
    assert (ref[proven] >= t[proven]).all(), "a proof of k >= t where k < t"
    assert proven[ref >= 1.35 * t].all(), "k >= 1.35 t not proven"
    assert 0.2 < proven.mean() < 0.8  # both outcomes are exercised
    assert not condition_at_least3(*np.zeros(9), 0.1)
    assert not condition_at_least3(*np.full(9, np.nan), 0.1)
    assert condition_at_least3(*np.eye(3).ravel(), 0.999)


def test_6x6_condition_proof_is_sound_and_proves_every_well_conditioned_matrix():
    """condition_at_least6 proves k ≥ t only where NumPy's SVD agrees, and proves it wherever k ≥ 1.6 t.

    ‖HᵀH‖_∞ ≤ √6 σ_max², so every k > 6^(1/4) t ≈ 1.57 t is provable. The matrices are built with k spread over
    [t / 3, 3 t], the other singular values between.
    """
    from envs.kernels.linalg import condition_at_least6

    rng = np.random.default_rng(41)
    t = rng.choice([0.03, 0.1, 0.3], size=3000)
    M, ref = _matrices_of_condition(rng, 6, t)
    G = np.empty((6, 6))
    proven = np.array([condition_at_least6(np.ascontiguousarray(m.T), G, ti) for m, ti in zip(M, t)])
    assert (ref[proven] >= t[proven]).all(), "a proof of k >= t where k < t"
    assert proven[ref >= 1.6 * t].all(), "k >= 1.6 t not proven"
    assert 0.2 < proven.mean() < 0.8  # both outcomes are exercised
    assert not condition_at_least6(np.zeros((6, 6)), G, 0.1)
    assert not condition_at_least6(np.full((6, 6), np.nan), G, 0.1)
    H = np.ascontiguousarray(M[0].T)
    kept = H.copy()
    condition_at_least6(H, G, 0.1)
    np.testing.assert_array_equal(H, kept)  # H is read, not overwritten


def test_hexapod_transition_in_blocks_equals_one_robot_at_a_time(hexapod):
    """A batch on every core conditions LANES robots at a time; each robot's outcome is bit for bit its N = 1 one."""
    x = _random_poses(hexapod, 1000, 5)[: fk.PARALLEL_MIN_BATCH + 37]  # the multi-core kernel, a partial last block
    assert len(x) == fk.PARALLEL_MIN_BATCH + 37 and (fk.PARALLEL_MIN_BATCH + 37) % 16 != 0
    ref = physics.FamilyReference(x.copy(), np.zeros_like(x), np.zeros_like(x))
    state = physics.initial_state(hexapod, x, ref)
    action = np.random.default_rng(6).uniform(-1, 1, size=(len(x), 6))
    batch, outcome = physics.transition(hexapod, state, action)
    for i in (0, 15, 16, 31, 32, 36, len(x) - 6, len(x) - 1):
        one_ref = physics.FamilyReference(x[i : i + 1].copy(), np.zeros((1, 6)), np.zeros((1, 6)))
        one = physics.initial_state(hexapod, x[i : i + 1], one_ref)
        single, single_outcome = physics.transition(hexapod, one, action[i : i + 1])
        for name in ("q", "x", "inverse_condition", "residual"):
            np.testing.assert_array_equal(getattr(batch, name)[i], getattr(single, name)[0])
        assert outcome.reason[i] == single_outcome.reason[0]
