"""The environments follow the Gymnasium API to the letter: checkers, spaces, registry, rewards and infos."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from envs import ENV_IDS, PLANAR_3RPR_IDS, hardware, physics
from envs.kernels import generic as fk
from tests.envs.helpers import INFO_KEYS, MAX_EPISODE_STEPS, REWARD_TERMS, component_node

REPO_ROOT = Path(__file__).resolve().parents[2]


def _format(caught: list[warnings.WarningMessage]) -> str:
    return "\n".join(f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught)


def _rollout(env: gym.Env, steps: int, seed: int = 0) -> list[tuple]:
    """(obs, reward, terminated, truncated, info) of ``steps`` random steps, resetting when needed."""
    env.action_space.seed(seed)
    env.reset(seed=seed)
    out = []
    for _ in range(steps):
        result = env.step(env.action_space.sample())
        out.append(result)
        if result[2] or result[3]:
            env.reset()
    return out


@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_env_checker_passes_without_warnings(env_id, render_mode, make_env):
    """Gymnasium's own checker accepts the bare environment and emits no warning."""
    env = make_env(env_id, render_mode=render_mode)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gymnasium_check_env(env.unwrapped)
    assert not caught, f"gymnasium check_env warned:\n{_format(caught)}"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_env_checker_passes_without_warnings(env_id, make_env):
    """Stable-Baselines3's checker accepts the made (wrapped) environment and emits no warning."""
    env = make_env(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env, warn=True)
    assert not caught, f"SB3 check_env warned:\n{_format(caught)}"


def test_registry_matches_expected_ids():
    """ENV_IDS is exactly the documented set of ids, each registered; PLANAR_3RPR_IDS are its 3-RPR ones."""
    assert len(ENV_IDS) == len(set(ENV_IDS))
    assert set(ENV_IDS) == set(MAX_EPISODE_STEPS)
    assert set(PLANAR_3RPR_IDS) == {i for i in MAX_EPISODE_STEPS if i.startswith("Planar3RPR") and "Force" not in i}
    assert len(PLANAR_3RPR_IDS) == 5
    for env_id in ENV_IDS:
        assert env_id in gym.registry, env_id
        expected = "envs.env:FamilyTrackEnv" if "Track" in env_id else "envs.env:FamilyReachEnv"
        assert gym.spec(env_id).entry_point == expected


def test_reward_terms_are_the_family_ones():
    """The reward terms the tests sum are exactly those the environments report."""
    assert REWARD_TERMS == physics.REWARD_TERMS


def test_make_with_module_prefix_in_fresh_interpreter():
    """gym.make("envs:Planar3RPRReach-v0") imports the package itself and gives a working env."""
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('envs:Planar3RPRReach-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "obs, reward, terminated, truncated, info = env.step(env.action_space.sample())\n"
        "print(type(env.unwrapped).__name__, env.spec.max_episode_steps, env.observation_space.contains(obs))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["FamilyReachEnv", "200", "True"]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_max_episode_steps_truncates(env_id, make_env):
    """The spec sets max_episode_steps and the TimeLimit truncates exactly there (robot at rest)."""
    expected = MAX_EPISODE_STEPS[env_id]
    assert gym.spec(env_id).max_episode_steps == expected
    env = make_env(env_id)
    assert env.spec.max_episode_steps == expected
    env.reset(seed=0)
    still = np.zeros(env.action_space.shape, dtype=np.float32)
    for step in range(1, expected + 1):
        _, _, terminated, truncated, _ = env.step(still)
        assert not terminated, f"terminated at rest at step {step}"
        assert truncated == (step == expected), f"truncated={truncated} at step {step}"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_spaces(env_id, make_env):
    """Normalised Box(-1, 1, (n,), float32) actions; finite float32 observation bounds of the documented size."""
    env = make_env(env_id)
    robot = env.unwrapped.params.robot
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, shape=(robot.n_actuators,), dtype=np.float32)
    space = env.observation_space
    assert isinstance(space, gym.spaces.Box)
    assert space.dtype == np.float32
    reach_size = {"spatial": 33, "planar": 18, "translational": 16}[robot.pose_space.name]  # Observation Space
    reach_size += 2 * robot.n_pose if "Force" in env_id else 0  # the twist and the actuator rates
    codes = 2 * robot.base.shape[1] ** 2 if env.unwrapped.params.geometry_variation else 0  # a known geometry's
    assert space.shape == ((reach_size + robot.n_pose,) if "Track" in env_id else (reach_size + codes,))
    assert np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))
    assert np.all(space.low < space.high)
    assert space.is_bounded("both")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_observations_rewards_and_infos(env_id, make_env):
    """Observations are float32 members of the space; rewards are Python floats; infos carry every key."""
    env = make_env(env_id)
    obs, info = env.reset(seed=1)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    missing = set(INFO_KEYS) - set(info)
    assert not missing, f"reset info lacks {sorted(missing)}"
    for obs, reward, terminated, truncated, info in _rollout(env, 400, seed=1):
        assert obs.dtype == np.float32
        assert env.observation_space.contains(obs), obs
        assert type(reward) is float
        assert type(terminated) is bool and type(truncated) is bool
        missing = set(INFO_KEYS) - set(info)
        assert not missing, f"step info lacks {sorted(missing)}"
        assert all(type(info[k]) is float for k in REWARD_TERMS)
        assert type(info["is_success"]) is bool
        assert isinstance(info["termination_reason"], str)
        assert (info["termination_reason"] != "") == terminated


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reward_is_sum_of_terms(env_id, make_env):
    """The reward is reward_tracking + reward_singularity + reward_action + reward_termination, every step."""
    env = make_env(env_id)
    terminated_seen = False
    for step, (_, reward, terminated, _, info) in enumerate(_rollout(env, 600, seed=2)):
        total = sum(info[k] for k in REWARD_TERMS)
        assert reward == pytest.approx(total, rel=1e-12, abs=1e-12), (step, reward, info)
        terminated_seen |= terminated
        if terminated:
            assert info["reward_termination"] == -env.unwrapped.params.termination_penalty
        else:
            assert info["reward_termination"] == 0.0
    if env_id == "Planar3RPRReachHard-v0":
        assert terminated_seen, "600 random steps of the hard task never terminated"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_cost_flags_low_conditioning(env_id, make_env):
    """info["cost"] is 1.0 exactly when k < safe_threshold or k_I < actuator_safe_threshold, else 0.0."""
    env = make_env(env_id)
    params = env.unwrapped.params
    costs = []
    for _, _, _, _, info in _rollout(env, 600, seed=3):
        type_i = info["actuator_condition_number"] < params.actuator_safe_threshold
        assert info["cost_actuator_singularity"] == (1.0 if type_i else 0.0), info
        expected = 1.0 if info["inverse_condition_number"] < params.safe_threshold or type_i else 0.0
        assert info["cost"] == expected, info
        costs.append(info["cost"])
    assert 0.0 in costs
    if env_id == "Planar3RPRReachHard-v0":
        assert 1.0 in costs, "600 random steps of the hard task never went below safe_threshold"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_returned_arrays_are_fresh(env_id, make_env, rng):
    """Mutating a returned observation or info array changes neither the env nor the next results."""
    mutated, clean = make_env(env_id), make_env(env_id)
    obs_a, info_a = mutated.reset(seed=4)
    obs_b, info_b = clean.reset(seed=4)
    previous = None
    for step in range(30):
        for value in (obs_a, *info_a.values()):
            if isinstance(value, np.ndarray):
                value[...] = 123.0
        action = rng.uniform(-1.0, 1.0, size=mutated.action_space.shape).astype(np.float32)
        obs_a, _, terminated, truncated, info_a = mutated.step(action)
        obs_b, _, _, _, info_b = clean.step(action)
        np.testing.assert_array_equal(obs_a, obs_b, err_msg=f"step {step}")
        for key, value in info_b.items():
            np.testing.assert_array_equal(info_a[key], value, err_msg=f"step {step}, info[{key!r}]")
        if previous is not None:
            assert obs_a is not previous[0] and not np.shares_memory(obs_a, previous[0])
            assert info_a is not previous[1]
        previous = (obs_a, info_a)
        if terminated or truncated:
            obs_a, info_a = mutated.reset(seed=step)
            obs_b, info_b = clean.reset(seed=step)
            previous = None


def _documented_observation(env: gym.Env, previous_q: np.ndarray | None = None) -> np.ndarray:
    """The observation the Observation Space table describes for a planar robot, rebuilt from the state.

    Under force control it holds ẋ and the actuator rates (q − ``previous_q``) / dt (0 without ``previous_q``).
    """
    unwrapped = env.unwrapped
    params, state = unwrapped.params, unwrapped.state
    q, x = state.q[0], state.x[0]
    reference = state.reference
    target, velocity = fk.reference_batch(
        params.packed, state.t, reference.center, reference.amplitude, reference.phase
    )
    target, velocity = target[0], velocity[0]
    lo, hi = params.stroke_limits
    # a robot of a known family of geometries is observed with its own model, and its codes end the observation
    robot = params.robot if state.geometry is None else hardware.perturbed_robot(params, state.plant[0])
    parts = [
        x[:2],
        [np.cos(x[2]), np.sin(x[2])],
        target[:2],
        [np.cos(target[2]), np.sin(target[2])],
        target[:2] - x[:2],
        [np.angle(np.exp(1j * (target[2] - x[2])))],
        2.0 * (q - lo) / (hi - lo) - 1.0,
        (robot.inverse_kinematics(target) - q) / (hi - lo),
        [robot.inverse_condition_number(q, x)],
    ]
    force = params.control == "force"
    if force:
        parts += [state.twist[0], np.zeros(3) if previous_q is None else (q - previous_q) / params.dt]
    if unwrapped.with_velocity:
        parts.append(velocity)
    codes = [] if state.geometry is None else list(state.geometry[0])
    parts.append(codes)
    assert env.observation_space.shape[0] == (21 if unwrapped.with_velocity else 18) + 6 * force + len(codes)
    expected = np.concatenate([np.asarray(p, dtype=np.float64) for p in parts])
    return np.clip(expected, env.observation_space.low, env.observation_space.high)


#: The ids of planar robots, whose observation layout the planar rows of the Observation Space section give.
PLANAR_IDS = tuple(i for i in ENV_IDS if i.startswith(("Planar3", "ParallelRobotReachHard")))


def test_planar_ids_are_the_planar_robots():
    """PLANAR_IDS holds exactly the ids whose robot is planar."""
    planar = {i for i in ENV_IDS if gym.make(i).unwrapped.params.robot.pose_space.name == "planar"}
    assert planar == set(PLANAR_IDS)


@pytest.mark.parametrize("env_id", PLANAR_IDS)
def test_observation_matches_documented_layout(env_id, make_env, rng):
    """Every entry is what the Observation Space table says, in that order (pose, target, errors, k, …)."""
    env = make_env(env_id)
    obs, _ = env.reset(seed=6)
    np.testing.assert_allclose(obs, _documented_observation(env), rtol=0, atol=2e-6)
    scale = 0.05 if env.unwrapped.params.control == "force" else 1.0  # efforts: small offsets keep episodes going
    for step in range(100):
        previous_q = env.unwrapped.state.q[0].copy()
        obs, _, terminated, truncated, _ = env.step(rng.uniform(-scale, scale, size=3).astype(np.float32))
        expected = _documented_observation(env, previous_q)
        np.testing.assert_allclose(obs, expected, rtol=1e-6, atol=2e-6, err_msg=f"step {step}")
        if terminated or truncated:
            obs, _ = env.reset()


def test_success_at_the_target(make_env):
    """Holding still on the target is a success with zero tracking reward; elsewhere it is not."""
    env = make_env("Planar3RPRReach-v0")
    workspace = env.unwrapped.workspace
    component = workspace.component_ids[np.argmax(workspace.component_weights)]
    params = env.unwrapped.params
    pose = component_node(workspace, component, box=(params.sample_low, params.sample_high))
    np.testing.assert_allclose(component_node(workspace, component), pose, rtol=0, atol=0)  # the default box
    _, info = env.reset(seed=0, options={"start": pose, "target": pose})
    assert info["is_success"] and info["position_error"] == 0.0 and info["orientation_error"] == 0.0
    _, reward, terminated, _, info = env.step(np.zeros(3, dtype=np.float32))
    assert not terminated and info["is_success"]
    assert info["reward_tracking"] == 0.0 and reward == pytest.approx(info["reward_singularity"], abs=1e-15)
    outcomes = set()
    for _ in range(10):
        _, _, terminated, _, info = env.step(np.array([0.5, 1.0, 0.5], dtype=np.float32))
        within = (
            info["position_error"] <= params.success_position_tolerance
            and info["orientation_error"] <= params.success_orientation_tolerance
        )
        assert info["is_success"] == (within and not terminated), info
        assert info["reward_tracking"] < 0.0
        outcomes.add(info["is_success"])
        if terminated:
            break
    assert outcomes == {True, False}, "the platform never left (or never was within) the success tolerance"
