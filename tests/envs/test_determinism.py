"""Same seed ⇒ same rollout, pickling keeps the state, and long random rollouts stay finite and on Φ = 0."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from envs import ENV_IDS, hardware
from envs.physics import TERMINATION_REASONS
from tests.envs.helpers import all_finite, assert_steps_equal, numeric_info_values

#: Random-action steps per id of the long rollout (10 000 per id, 30 000 for three 3-RPR ids).
LONG_ROLLOUT_STEPS = {env_id: 10_000 for env_id in ENV_IDS} | {
    "Planar3RPRReach-v0": 30_000,
    "Planar3RPRReachHard-v0": 30_000,
    "Planar3RPRTrack-v0": 30_000,
}


def _constraints(params, q: np.ndarray, x: np.ndarray, plants: list[bytes]) -> np.ndarray:
    """Φ(q, x) of every step by the kinematics library, each with its own robot (``plants``: one row per step)."""
    if not plants:
        return params.robot.constraints(q, x, validate=False)
    phi = np.empty_like(q)
    for plant in set(plants):
        rows = np.array([p == plant for p in plants])
        robot = hardware.perturbed_robot(params, np.frombuffer(plant))
        phi[rows] = robot.constraints(q[rows], x[rows], validate=False)
    return phi


def _lockstep(env_a, env_b, actions: np.ndarray, where: str) -> None:
    """Step two envs with the same actions (resetting both on episode end) and compare every result."""
    for step, action in enumerate(actions):
        result_a, result_b = env_a.step(action), env_b.step(action)
        assert_steps_equal(result_a, result_b, f"{where}, step {step}")
        if result_a[2] or result_a[3]:
            assert_steps_equal(env_a.reset(), env_b.reset(), f"{where}, reset after step {step}")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_same_rollout(env_id, make_env, rng):
    """Two envs reset with the same seed and fed the same actions give identical obs, rewards and infos."""
    env_a, env_b = make_env(env_id), make_env(env_id)
    assert_steps_equal(env_a.reset(seed=123), env_b.reset(seed=123), "reset")
    actions = rng.uniform(-1.0, 1.0, size=(500, *env_a.action_space.shape)).astype(np.float32)
    _lockstep(env_a, env_b, actions, env_id)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_different_seeds_give_different_tasks(env_id, make_env):
    """The seed drives the task: different seeds give different starting observations."""
    env = make_env(env_id)
    first = [env.reset(seed=seed)[0] for seed in range(5)]
    assert len({obs.tobytes() for obs in first}) == 5


def _writable(value: object, path: str = "params") -> dict[str, bool]:
    """Whether each array of an env's constants (cached ones and the certified grid's included) is writable."""
    if isinstance(value, np.ndarray):
        return {path: value.flags.writeable}
    if isinstance(value, (tuple, list)):
        items = enumerate(value)
    elif isinstance(value, dict):
        items = value.items()
    elif type(value).__module__.startswith(("envs.", "kinematics.")):
        items = vars(value).items()
    else:
        return {}
    return {p: w for key, item in items for p, w in _writable(item, f"{path}.{key}").items()}


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_pickle_round_trip(env_id, make_env, rng):
    """An env pickled mid-episode and loaded continues exactly like the original (state and RNG).

    Its constants come back read-only, as the kernels were compiled for them (a writable copy would compile
    every kernel it reaches a second time).
    """
    env = make_env(env_id)
    size = 0.1 if env.unwrapped.params.control == "force" else 0.5  # efforts: 0.5 of a drive's range flings it
    for seed in range(7, 17):  # mid-episode: the first seed whose 5 small random steps do not end it
        env.reset(seed=seed)
        ended = False
        for action in rng.uniform(-size, size, size=(5, *env.action_space.shape)).astype(np.float32):
            _, _, terminated, truncated, _ = env.step(action)
            ended |= terminated or truncated
            if ended:
                break
        if not ended:
            break
    assert not ended, "every seed ended its episode within 5 steps"
    clone = pickle.loads(pickle.dumps(env))
    assert clone is not env and clone.unwrapped is not env.unwrapped
    np.testing.assert_array_equal(clone.unwrapped.state.x, env.unwrapped.state.x)
    assert _writable(clone.unwrapped.params) == _writable(env.unwrapped.params)
    actions = rng.uniform(-1.0, 1.0, size=(300, *env.action_space.shape)).astype(np.float32)
    _lockstep(env, clone, actions, f"{env_id} pickled")


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_long_random_rollout_is_finite_and_on_the_manifold(env_id, make_env):
    """10 000 to 30 000 random steps per id: everything finite, |Φ| ≤ 1e-10, only documented reasons.

    Φ(q, x) is recomputed by the kinematics library from the env's state after every step; the reported
    ``info["constraint_residual"]`` must agree with it.
    """
    env = make_env(env_id)
    steps = LONG_ROLLOUT_STEPS[env_id]
    actions = np.random.default_rng(99).uniform(-1.0, 1.0, size=(steps, *env.action_space.shape)).astype(np.float32)
    obs, info = env.reset(seed=99)
    assert all_finite(obs, 0.0, info)
    numeric_keys = sorted(numeric_info_values(info))
    observations = np.empty((steps, *obs.shape), dtype=np.float32)
    rewards = np.empty(steps)
    infos = np.empty((steps, sum(np.size(info[k]) for k in numeric_keys)))
    robot = env.unwrapped.params.robot
    q, x = np.empty((steps, robot.n_actuators)), np.empty((steps, robot.n_pose))
    plants = []  # each step's robot, where it has its own geometry (a family of geometries)
    reasons: set[str] = set()
    for step, action in enumerate(actions):
        obs, reward, terminated, truncated, info = env.step(action)
        state = env.unwrapped.state
        q[step], x[step] = state.q[0], state.x[0]
        if state.plant is not None:
            plants.append(state.plant[0].tobytes())
        observations[step], rewards[step] = obs, reward
        infos[step] = np.concatenate([np.ravel(info[k]) for k in numeric_keys])
        if terminated:
            reasons.add(info["termination_reason"])
        if terminated or truncated:
            env.reset()
    finite = np.isfinite(observations).all(axis=1) & np.isfinite(rewards) & np.isfinite(infos).all(axis=1)
    bad = np.flatnonzero(~finite)
    assert bad.size == 0, (
        f"{bad.size} steps with a non-finite value, first at step {bad[0]}: obs={observations[bad[0]]}, "
        f"reward={rewards[bad[0]]}, info {numeric_keys} = {infos[bad[0]]}"
    )
    phi = _constraints(env.unwrapped.params, q, x, plants)
    residual = np.max(np.abs(phi), axis=1)
    worst = int(np.argmax(residual))
    assert residual[worst] <= 1e-10, f"|Φ(q, x)| = {residual[worst]} at step {worst}: q = {q[worst]}, x = {x[worst]}"
    sizes = [np.size(info[k]) for k in numeric_keys]
    reported = infos[:, sum(sizes[: numeric_keys.index("constraint_residual")])]
    np.testing.assert_allclose(reported, residual, rtol=0, atol=1e-12)
    assert reasons <= set(TERMINATION_REASONS) - {""}, reasons
