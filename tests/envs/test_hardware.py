"""The robot as built and as measured (``envs.hardware``): tolerances, encoders, drives, against the kinematics library.

Oracles: ``kinematics.DistanceConstraintMechanism`` (constraints, forward Jacobian, inverse kinematics of the
perturbed robot rebuilt from its data), and a drive model written out here step by step.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from envs import hardware, physics
from envs.kernels.setup import random_streams
from envs.presets import build_family_params

IDS = ("Planar3RPRReach-v0", "StewartGoughReach-v0", "DeltaReach-v0", "Planar3RRRReach-v0")


def _rollout(env: gym.Env, steps: int, seed: int) -> list:
    env.action_space.seed(seed)
    out = [env.reset(seed=seed)]
    for _ in range(steps):
        result = env.step(env.action_space.sample())
        out.append(result)
        if result[2] or result[3]:
            out.append(env.reset())
    return out


@pytest.mark.parametrize("env_id", IDS)
def test_the_robot_as_built_obeys_its_own_constraints_not_the_nominal_ones(env_id):
    """Every step of a perturbed robot satisfies the constraints of the mechanism rebuilt from its plant row.

    Oracle: ``kinematics`` on ``perturbed_robot`` (the nominal robot's constraints are violated by about the
    tolerance, so a transition that ignored the plant would fail the first assertion).
    """
    tolerance = 0.002
    env = gym.make(env_id, geometry_tolerance=tolerance).unwrapped
    env.reset(seed=3)
    state = env.state
    plant = state.plant[0]
    nominal = env.params.packed
    columns = hardware.plant_columns(env.params.robot)
    offsets = plant[columns] - nominal[columns]
    assert np.all(np.abs(offsets) <= tolerance) and np.max(np.abs(offsets)) > 0.5 * tolerance
    others = np.setdiff1d(np.arange(len(nominal)), columns)
    np.testing.assert_array_equal(plant[others], nominal[others])
    built = hardware.perturbed_robot(env.params, plant)
    scale = np.max(np.abs(state.q)) ** 2
    rng = np.random.default_rng(0)
    for _ in range(20):
        env.step(rng.uniform(-1, 1, env.action_space.shape))
        state = env.state
        q, x = state.q[0], state.x[0]
        assert np.max(np.abs(built.constraints(q, x))) <= 1e-9 * scale
        assert np.max(np.abs(env.params.robot.constraints(q, x))) > 1e-6 * scale


def test_the_start_pose_is_where_the_built_robot_assembles_at_the_nominal_strokes():
    """The robot starts at the strokes the nominal inverse kinematics gives for the task's start pose."""
    env = gym.make("StewartGoughReach-v0", geometry_tolerance=0.001).unwrapped
    nominal = gym.make("StewartGoughReach-v0").unwrapped
    _, info = env.reset(seed=11)
    _, info0 = nominal.reset(seed=11)
    np.testing.assert_array_equal(info["target"], info0["target"])  # the tasks are the nominal robot's
    q = env.state.q[0]
    np.testing.assert_allclose(q, nominal.params.robot.inverse_kinematics(nominal.state.x[0]), atol=1e-12)
    assert 0 < np.linalg.norm(env.state.x[0] - nominal.state.x[0]) < 0.02


@pytest.mark.parametrize("env_id", ("Planar3RPRReach-v0", "StewartGoughReach-v0", "Planar3RRRReach-v0"))
def test_encoder_noise_reaches_the_observation_quantised_with_its_spread(env_id):
    """Measured strokes are whole counts, off the true ones by noise of the given spread, and they are observed."""
    resolution, noise = 2e-5, 5e-5
    env = gym.make(env_id, observation_source="encoders", encoder_resolution=resolution, encoder_noise=noise)
    base = env.unwrapped
    params = base.params
    errors, pose_errors = [], []
    obs, info = env.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(300):
        obs, _, terminated, truncated, info = env.step(0.2 * rng.uniform(-1, 1, env.action_space.shape))
        q_true, q_meas = base.state.q[0], info["measured_strokes"]
        counts = q_meas / resolution
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
        errors.append(q_meas - q_true)
        pose_errors.append(np.linalg.norm(info["estimated_pose"] - info["pose"]))
        # the observation holds the measurement, not the truth
        n, m = params.robot.n_actuators, params.robot.n_pose
        layout_strokes = obs[-1 - 2 * n : -1 - n]
        lo, hi = params.stroke_limits
        np.testing.assert_allclose(layout_strokes, 2 * (q_meas - lo) / (hi - lo) - 1, atol=1e-6)
        assert obs[-1] == pytest.approx(info["estimate_inverse_condition_number"], abs=1e-6)
        assert m == len(info["estimated_pose"])
        if terminated or truncated:
            obs, info = env.reset()
    errors = np.concatenate(errors)
    expected = np.sqrt(noise**2 + resolution**2 / 12)  # Gaussian noise, then rounding to a count
    assert abs(np.mean(errors)) < 0.2 * expected
    assert 0.85 * expected < np.std(errors) < 1.15 * expected
    assert np.median(pose_errors) > 0


def test_pose_observation_ignores_the_encoder_settings_and_holds_the_truth():
    """The default source is the true pose: no estimate in info, observation = the exact pose."""
    env = gym.make("Planar3RPRReach-v0")
    obs, info = env.reset(seed=0)
    assert "estimated_pose" not in info
    np.testing.assert_allclose(obs[:2], info["pose"][:2], atol=1e-6)


def test_estimate_error_is_the_forward_jacobian_times_the_stroke_error_and_grows_as_k_falls():
    """x̂ − x ≈ J_f (q̃ − q) (``kinematics``' forward Jacobian), so its size grows like 1/k toward a singularity."""
    params = build_family_params("planar_3rpr", observation_source="encoders", encoder_noise=1e-5)
    robot = params.robot
    rng = np.random.default_rng(5)
    poses = rng.uniform(params.pose_low, params.pose_high, size=(4000, 3))
    q = robot.inverse_kinematics(poses)
    lo, hi = params.stroke_limits
    keep = np.all((q > lo) & (q < hi), axis=1)
    poses, q = poses[keep], q[keep]
    k = robot.inverse_condition_number(q, poses)
    keep = k > 0.005
    poses, q, k = poses[keep], q[keep], k[keep]
    streams = random_streams([np.random.default_rng([7, i]) for i in range(len(poses))])
    sensed = hardware.sense(params, q, poses, streams)
    ok = np.isfinite(sensed.residual)
    assert ok.mean() > 0.99
    error = robot.pose_difference(sensed.x[ok], poses[ok])
    linear = np.einsum("nij,nj->ni", robot.forward_jacobian(q[ok], poses[ok]), sensed.q[ok] - q[ok])
    size = np.linalg.norm(error * params.pose_metric, axis=1)
    well = k[ok] > 0.1
    gap = np.linalg.norm((error - linear)[well] * params.pose_metric, axis=1)
    assert np.all(gap <= 0.02 * size[well] + 1e-9), np.max(gap / size[well])  # second order in q̃ − q
    low, high = size[k[ok] < 0.03], size[k[ok] > 0.3]
    assert low.size > 20 and high.size > 20
    assert np.median(low) > 5 * np.median(high)


def test_estimator_warm_starts_from_its_previous_estimate():
    """The Newton iteration starts at the previous estimate: from a far guess it lands elsewhere or fails."""
    params = build_family_params("planar_3rpr", observation_source="encoders")
    x = np.array([[0.4, 0.4, 0.1]])
    q = params.robot.inverse_kinematics(x[0])[None]
    streams = random_streams([np.random.default_rng(0)])
    near = hardware.sense(params, q, x, streams)
    assert np.linalg.norm(near.x - x) < 1e-3
    mirror = hardware.sense(params, q, x + np.array([[0.0, 0.0, 2.5]]), streams)
    assert not np.isfinite(mirror.residual[0]) or np.linalg.norm(mirror.x - x) > 0.1


def _drive_oracle(actions: np.ndarray, delay: int, change: float) -> np.ndarray:
    """The applied actions of a drive written out: a delay line, then a rate-of-change limit."""
    applied, last = [], np.zeros(actions.shape[1])
    queue = [np.zeros(actions.shape[1])] * delay
    for a in np.clip(actions, -1, 1):
        queue.append(a)
        wanted = queue.pop(0)
        last = np.clip(wanted, last - change, last + change)
        applied.append(last)
    return np.array(applied)


@pytest.mark.parametrize(("delay", "acceleration"), [(0, 0.4), (2, None), (3, 0.25)])
def test_drives_delay_and_limit_the_applied_actions(delay, acceleration):
    """The applied actions (``outcome.action``, what moves the strokes) follow the drive oracle exactly."""
    kwargs = {"action_delay": delay} | ({"max_acceleration": acceleration} if acceleration else {})
    env = gym.make("Planar3RPRReach-v0", **kwargs).unwrapped
    params = env.params
    change = np.inf if acceleration is None else acceleration * params.dt / params.max_rate
    rng = np.random.default_rng(2)
    actions = rng.uniform(-1.3, 1.3, size=(12, 3))
    env.reset(seed=4)
    q_before = env.state.q[0].copy()
    applied = []
    for a in actions:
        state = env.state
        _, outcome = physics.transition(params, state, a[None])  # what the step will apply
        applied.append(outcome.action[0])
        env.step(a)
    want = _drive_oracle(actions, delay, change)
    np.testing.assert_allclose(np.array(applied), want, atol=1e-12)
    if delay:
        assert np.linalg.norm(env.state.q[0] - q_before) > 0
    fresh = gym.make("Planar3RPRReach-v0", **kwargs).unwrapped
    fresh.reset(seed=4)
    for a in actions[:delay]:
        fresh.step(a)
    np.testing.assert_array_equal(fresh.state.q[0], q_before)  # nothing moves before the first action arrives


@pytest.mark.parametrize(
    "kwargs",
    [
        {"observation_source": "encoders", "geometry_tolerance": 0.001},
        {"observation_source": "encoders", "action_delay": 1, "max_acceleration": 0.5},
    ],
)
def test_vector_env_is_the_single_env_bit_for_bit_with_hardware(kwargs):
    """Sub-environment i of the vector env = the single env seeded s + i, across autoresets, noise included."""
    n, steps, seed = 3, 260, 40
    vec = gym.make_vec("Planar3RPRReach-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    singles = [gym.make("Planar3RPRReach-v0", **kwargs) for _ in range(n)]
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(steps, n, 3))
    obs, _ = vec.reset(seed=seed)
    single_obs = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    ended = np.zeros(n, dtype=bool)
    for t in range(steps):
        np.testing.assert_array_equal(obs, np.array(single_obs))
        obs, rewards, terminated, truncated, _ = vec.step(actions[t])
        for i, env in enumerate(singles):
            if ended[i]:
                single_obs[i] = env.reset()[0]
                assert rewards[i] == 0.0
            else:
                single_obs[i], reward, term, trunc, _ = env.step(actions[t, i])
                assert rewards[i] == reward and terminated[i] == term and truncated[i] == trunc
        ended = terminated | truncated


@pytest.mark.parametrize(
    "kwargs",
    [
        {"observation_source": "encoders"},
        {"geometry_tolerance": 0.002},
        {"action_delay": 2, "max_acceleration": 0.3},
        {"observation_source": "encoders", "geometry_tolerance": 0.001, "action_delay": 1},
    ],
)
@pytest.mark.parametrize("env_id", ("Planar3RPRReach-v0", "StewartGoughReach-v0", "DeltaTrack-v0"))
def test_checkers_are_silent_and_runs_reproducible_in_every_mode(env_id, kwargs):
    """Gymnasium's and SB3's checkers warn of nothing, and one seed gives one run (geometry and noise included)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(env_id, **kwargs).unwrapped, skip_render_check=True)
        sb3_check_env(gym.make(env_id, **kwargs), warn=True)
    assert not caught, [str(w.message) for w in caught]
    runs = [_rollout(gym.make(env_id, **kwargs), 30, seed=9) for _ in range(2)]
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a[0], b[0])
    assert any(not np.array_equal(a[0], b[0]) for a, b in zip(runs[0], _rollout(gym.make(env_id, **kwargs), 30, 10)))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"encoder_noise": -1e-5}, "encoder_noise must be 3 numbers ≥ 0"),
        ({"encoder_resolution": 0.0}, "encoder_resolution must be 3 numbers > 0"),
        ({"encoder_resolution": (1e-5, 1e-5)}, "encoder_resolution must be 3 finite numbers"),
        ({"geometry_tolerance": -0.001}, "geometry_tolerance must be finite and ≥ 0"),
        ({"geometry_tolerance": 0.3}, "geometry_tolerance=0.3 m makes the robot unassemblable"),
        ({"observation_source": "camera"}, "observation_source must be one of ('pose', 'encoders')"),
        ({"action_delay": -1}, "action_delay must be an int ≥ 0"),
        ({"action_delay": 1.5}, "action_delay must be an int ≥ 0"),
        ({"max_acceleration": 0.0}, "max_acceleration must be 3 numbers > 0"),
        ({"estimator_iterations": 0}, "estimator_iterations must be an int ≥ 1"),
    ],
)
def test_bad_hardware_parameters_are_refused_with_the_expected_and_the_actual_value(kwargs, message):
    """Negative noise, a zero count, an unassemblable tolerance, … : a ValueError that names the value."""
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        gym.make("Planar3RPRReach-v0", **kwargs)


def test_a_family_robot_is_its_own_known_geometry_and_its_codes_are_observed():
    """Each episode's robot is the known geometry its codes say, and is observed so.

    Oracle: the draw written out with NumPy and the kinematics library: base and platform scaled and sheared as the
    codes say, its steps obey its own constraints, its task is safe on its own geometry, its codes end the observation.
    """
    env = gym.make("Planar3RPRReachFamily-v0").unwrapped
    params = env.params
    robot = params.robot
    nu = params.geometry_variation
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        state = env.state
        codes = state.geometry[0]
        np.testing.assert_array_equal(obs[-8:], codes.astype(np.float32))
        s_base, s_platform = np.eye(2) + nu * codes[:4].reshape(2, 2), np.eye(2) + nu * codes[4:].reshape(2, 2)
        centre = robot.base.mean(axis=0)
        built = hardware.perturbed_robot(params, state.plant[0])
        np.testing.assert_allclose(built.base, centre + (robot.base - centre) @ s_base.T, atol=1e-15)
        np.testing.assert_allclose(built.platform, robot.platform @ s_platform.T, atol=1e-15)
        q0 = state.q[0]
        np.testing.assert_allclose(q0, built.inverse_kinematics(state.x[0]), atol=1e-12)
        assert built.inverse_condition_number(q0, state.x[0]) >= params.safe_threshold
        k_target = built.inverse_condition_number(built.inverse_kinematics(info["target"]), info["target"])
        assert k_target >= params.safe_threshold
        rng = np.random.default_rng(seed)
        for _ in range(10):
            obs, *_ = env.step(rng.uniform(-1, 1, 3))
            assert np.max(np.abs(built.constraints(env.state.q[0], env.state.x[0]))) < 1e-9
        np.testing.assert_array_equal(obs[-8:], codes.astype(np.float32))
        # the observed stroke error is against the robot's own inverse kinematics of the target
        span = params.stroke_limits[1] - params.stroke_limits[0]
        own = (built.inverse_kinematics(info["target"]) - env.state.q[0]) / span
        np.testing.assert_allclose(obs[-8 - 1 - 3 : -8 - 1], own, atol=1e-6)


def test_family_vector_env_is_the_single_env_bit_for_bit():
    """Sub-environment i of the family's vector env = the single env seeded s + i (geometry drawn first)."""
    n, seed = 3, 7
    vec = gym.make_vec("Planar3RPRReachFamily-v0", num_envs=n, vectorization_mode="vector_entry_point")
    obs, _ = vec.reset(seed=seed)
    actions = np.random.default_rng(0).uniform(-1, 1, size=(30, n, 3))
    singles = [gym.make("Planar3RPRReachFamily-v0") for _ in range(n)]
    single = np.array([env.reset(seed=seed + i)[0] for i, env in enumerate(singles)])
    np.testing.assert_array_equal(obs, single)
    for a in 0.3 * actions:
        obs, rewards, terminated, *_ = vec.step(a)
        steps = [env.step(a[i]) for i, env in enumerate(singles)]
        np.testing.assert_array_equal(obs, np.array([s[0] for s in steps]))
        np.testing.assert_array_equal(rewards, np.array([s[1] for s in steps]))
        if terminated.any():  # autoresets are the hardware test's (above); the geometry draw is compared here
            break


def test_geometry_variation_is_refused_where_it_cannot_hold():
    """Grid tasks certify one geometry; a tolerance on top is not combined; ν must stay below 0.5."""
    with pytest.raises(ValueError, match="geometry_variation needs task_region='box'"):
        gym.make("Planar3RPRReach-v0", geometry_variation=0.1)
    with pytest.raises(ValueError, match=r"geometry_variation must be finite and in \[0, 0\.5\), got 0\.6"):
        gym.make("Planar3RPRReachFamily-v0", geometry_variation=0.6)


def test_a_robot_given_as_a_json_file_is_that_robot(tmp_path):
    """``robot="file.json"`` builds the mechanism of the file (``to_dict`` round trip), bad files name themselves."""
    from kinematics import Delta, DistanceConstraintMechanism, Planar3RRR

    for robot in (Delta(), Planar3RRR()):
        path = tmp_path / "robot.json"
        path.write_text(__import__("json").dumps(robot.to_dict()))
        rebuilt = gym.make("ParallelRobotReach-v0", robot=str(path)).unwrapped.params.robot
        assert isinstance(rebuilt, DistanceConstraintMechanism)
        np.testing.assert_array_equal(rebuilt.base, robot.base)
        np.testing.assert_array_equal(rebuilt.platform, robot.platform)
        for name in ("link_lengths", "crank_radii", "crank_axes", "rails", "branches"):
            np.testing.assert_array_equal(getattr(rebuilt, name), getattr(robot, name))
        assert rebuilt.actuator_kinds == robot.actuator_kinds
    example = gym.make("ParallelRobotReach-v0", robot="docs/examples/my_3rpr.json").unwrapped
    assert example.params.robot.base[1, 0] == 1.05
    bad = tmp_path / "bad.json"
    bad.write_text('{"base": [[0, 0], [1, 0], [0.5, 0.8]], "platform": [[0, 0], [0.1, 0], [0, 0.1]], "legs": 3}')
    with pytest.raises(ValueError, match=r"bad.json: unknown key\(s\) \['legs'\]"):
        gym.make("ParallelRobotReach-v0", robot=str(bad))


def test_a_robot_as_built_that_cannot_assemble_at_its_start_draws_again_in_both_envs():
    """A robot as built that does not assemble at its task's start draws both again, the same in every env.

    Near the 3-RRR's band a millimetre moves the pose by a tenth of a radian or out of reach: such a robot and its
    task are drawn again from the same generator, so every start assembles and the vector env still equals the
    single envs seed by seed.
    """
    kwargs = {"geometry_tolerance": 0.001}
    n = 40
    vec = gym.make_vec("Planar3RRRReach-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    obs, _ = vec.reset(seed=0)
    state = vec.unwrapped.state
    assert np.all(state.residual <= vec.unwrapped.params.newton_tolerance)
    for i in range(n):
        single = gym.make("Planar3RRRReach-v0", **kwargs)
        np.testing.assert_array_equal(single.reset(seed=i)[0], obs[i])
    # the redraw happened: some of these robots did not assemble at their first task
    params = vec.unwrapped.params
    first = []
    for i in range(n):
        env = gym.make("Planar3RRRReach-v0").unwrapped
        generator = np.random.default_rng(i)
        start, reference = env.sample_tasks([generator], {})
        streams = random_streams([generator])
        first.append(physics.initial_state(params, start, reference, streams, strict=False).residual[0])
    assert not np.all(np.isfinite(first))


@pytest.mark.parametrize(("env_id", "dims"), [("Planar3RPRReach-v0", 2), ("StewartGoughReach-v0", 3)])
def test_the_encoder_estimate_is_solved_on_the_nominal_model_not_on_the_robot_as_built(env_id, dims):
    """With a geometry tolerance, x̂ is the *nominal* forward kinematics of the encoder reading, not the plant's.

    Oracle: the encoder model written out (q̃ whole counts within res/2 + 8σ of the true q) and Newton's method of
    ``kinematics`` on the nominal mechanism from the previous estimate. The same reading solved on the robot as
    built (rebuilt from its plant row) lands millimetres away, so an estimator that used the plant fails here.
    """
    resolution, noise = 1e-5, 2e-6
    kwargs = {"encoder_resolution": resolution, "encoder_noise": noise}
    env = gym.make(env_id, observation_source="encoders", geometry_tolerance=0.002, **kwargs).unwrapped
    obs, info = env.reset(seed=3)
    nominal = env.params.robot
    built = hardware.perturbed_robot(env.params, env.state.plant[0])
    guess = env.state.x[0]  # the reset's estimate starts from the pose the controller believes: the task's start
    rng = np.random.default_rng(0)
    gaps = []
    for _ in range(12):
        q_true, q_read = env.state.q[0], info["measured_strokes"]
        counts = q_read / resolution
        np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-6)
        assert np.all(np.abs(q_read - q_true) <= resolution / 2 + 8 * noise)
        solved = nominal.forward_kinematics(q_read, guess, tolerance=1e-13, max_iterations=50)
        assert solved.converged
        np.testing.assert_allclose(info["estimated_pose"], solved.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(obs[:dims], solved.x[:dims], rtol=0, atol=2e-6)  # the observed pose is x̂
        on_plant = built.forward_kinematics(q_read, solved.x, tolerance=1e-13, max_iterations=50)
        assert on_plant.converged
        gaps.append(np.linalg.norm(on_plant.x[:dims] - solved.x[:dims]))
        guess = info["estimated_pose"]
        obs, _, terminated, truncated, info = env.step(0.3 * rng.uniform(-1, 1, env.action_space.shape))
        assert not (terminated or truncated)
    assert min(gaps) > 1e-4  # the plant's answer is far outside the tolerances above (0.5 mm and more)
