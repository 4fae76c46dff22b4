"""The native vector env equals N single envs (SyncVectorEnv) step by step, in every autoreset mode."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from envs import ENV_IDS, FORCE_IDS, FamilyReachEnv, FamilyReachVectorEnv, FamilyTrackVectorEnv, FamilyVectorEnv
from tests.envs.helpers import INFO_KEYS, MAX_EPISODE_STEPS

#: Short episodes, so that a few dozen steps hold several autoresets.
SHORT = 20
#: Sub-environments of the lockstep comparisons (≥ 16: the batched kinematics take their closed-form path).
N = 16
#: Tolerances between the batched and the single code paths (they differ in rounding only).
OBS_ATOL, REWARD_RTOL, INFO_RTOL, INFO_ATOL = 1e-5, 1e-9, 1e-9, 1e-9
#: Ids whose robots (the hexapod's slow legs; the Delta's 8-step hard episodes) end fewer than 3 of the lockstep
#: comparison's episodes by termination: there only truncations (and autoresets) are required.
RARELY_TERMINATING = {
    "StewartGoughReach-v0",
    "StewartGoughReachHard-v0",
    "StewartGoughTrack-v0",
    "DeltaReachHard-v0",
    "ParallelRobotReach-v0",
    "ParallelRobotTrack-v0",
    *FORCE_IDS,  # small efforts (the platforms drift slowly)
}


def make_native(env_id: str, n: int = N, **kwargs: Any) -> FamilyVectorEnv:
    """The native vector env through ``gym.make_vec`` (the registered kwargs reach it)."""
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


def make_sync(env_id: str, n: int = N, autoreset_mode=AutoresetMode.NEXT_STEP, **kwargs: Any) -> SyncVectorEnv:
    """N single envs made with ``gym.make`` (default wrappers, TimeLimit) in Gymnasium's SyncVectorEnv."""
    return SyncVectorEnv([lambda: gym.make(env_id, **kwargs) for _ in range(n)], autoreset_mode=autoreset_mode)


def assert_close(a: Any, b: Any, where: str) -> None:
    """Infos (vector layout, nested), observations and scalars agree: exactly for bools, strings and masks."""
    if isinstance(a, dict):
        assert isinstance(b, dict), f"{where}: dict vs {type(b).__name__}"
        assert a.keys() == b.keys(), f"{where}: keys differ: {sorted(set(a) ^ set(b))}"
        for key in a:
            assert_close(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert isinstance(b, np.ndarray) and b.dtype == object and a.shape == b.shape, f"{where}: {b!r}"
        for i, (u, v) in enumerate(zip(a, b)):
            if isinstance(u, np.ndarray):
                assert isinstance(v, np.ndarray), f"{where}[{i}]: {v!r}"
                np.testing.assert_allclose(u, v, rtol=0, atol=OBS_ATOL, err_msg=f"{where}[{i}]")
            else:
                assert u == v, f"{where}[{i}]: {u!r} != {v!r}"
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, f"{where}: {a!r} vs {b!r}"
        if a.dtype == np.bool_:
            np.testing.assert_array_equal(a, b, err_msg=where)
        else:
            np.testing.assert_allclose(a, b, rtol=INFO_RTOL, atol=INFO_ATOL, err_msg=where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def assert_step_close(native: tuple, sync: tuple, where: str) -> None:
    """Two vector ``step`` results agree (observations, rewards, flags exactly, infos)."""
    obs_a, rew_a, term_a, trunc_a, info_a = native
    obs_b, rew_b, term_b, trunc_b, info_b = sync
    assert obs_a.dtype == obs_b.dtype == np.float32 and obs_a.shape == obs_b.shape
    np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL, err_msg=f"{where}: observations")
    assert rew_a.dtype == rew_b.dtype and term_a.dtype == term_b.dtype == trunc_a.dtype == np.bool_
    np.testing.assert_allclose(rew_a, rew_b, rtol=REWARD_RTOL, atol=0, err_msg=f"{where}: rewards")
    np.testing.assert_array_equal(term_a, term_b, err_msg=f"{where}: terminations")
    np.testing.assert_array_equal(trunc_a, trunc_b, err_msg=f"{where}: truncations")
    assert_close(info_a, info_b, f"{where}: infos")


def large_actions(steps: int, n: int, seed: int = 0, hold: int = 5, width: int = 3) -> np.ndarray:
    """Random actions beyond [−1, 1] (clipped by the envs), each held ``hold`` steps: robots hit limits.

    ``width`` is the number of actuators (the action size).
    """
    blocks = np.random.default_rng(seed).uniform(-3.0, 3.0, size=(-(-steps // hold), n, width))
    return np.repeat(blocks, hold, axis=0)[:steps].astype(np.float32)


# -- registration ------------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_make_vec_returns_the_native_env(env_id):
    """make_vec(vector_entry_point) builds the native class with batched spaces and the registered length."""
    env = make_native(env_id, n=3)
    expected = FamilyTrackVectorEnv if "Track" in env_id else FamilyReachVectorEnv
    assert type(env) is expected and env.num_envs == 3
    assert env.max_episode_steps == MAX_EPISODE_STEPS[env_id] == expected.default_max_episode_steps
    assert env.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    single = gym.make(env_id)
    assert env.single_observation_space == single.observation_space
    assert env.single_action_space == single.action_space
    assert env.observation_space.shape == (3, *single.observation_space.shape)
    width = single.action_space.shape[0]
    assert env.action_space.shape == (3, width) and env.action_space.dtype == np.float32
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert set(INFO_KEYS) <= set(info) and all(info[f"_{key}"].all() for key in INFO_KEYS)
    assert gym.make_vec(env_id, num_envs=2).spec.kwargs["vectorization_mode"] == "vector_entry_point"


def test_registered_kwargs_reach_the_vector_env():
    """The hard id's targets="hard" is given to the vector env; a keyword argument overrides it."""
    assert make_native("Planar3RPRReachHard-v0", n=1).get_attr("targets") == ("hard",)
    assert make_native("Planar3RPRReachMixed-v0", n=1).get_attr("targets") == ("mixed",)
    assert make_native("Planar3RPRReach-v0", n=1).get_attr("targets") == ("standard",)
    assert make_native("Planar3RPRReach-v0", n=1).params == gym.make("Planar3RPRReach-v0").unwrapped.params
    assert make_native("DeltaTrack-v0", n=1).params.track_path == gym.make("DeltaTrack-v0").unwrapped.params.track_path
    env = make_native("Planar3RPRReach-v0", n=2, max_episode_steps=7, autoreset_mode="SameStep")
    assert env.max_episode_steps == 7 and env.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP


# -- lockstep equality with N single envs ------------------------------------------------------------


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP], ids=lambda m: m.value)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_equals_sync_vector_env_of_single_envs(env_id, mode):
    """Same seeds and actions ⇒ same observations, rewards, flags and infos, across many autoresets."""
    # Hard tasks are slow to sample (rejection of straight lines): shorter episodes, fewer steps.
    length, steps, hold = (8, 18, 1) if "Hard" in env_id else (SHORT, 3 * SHORT, 5)
    native = make_native(env_id, max_episode_steps=length, autoreset_mode=mode)
    sync = make_sync(env_id, autoreset_mode=mode, max_episode_steps=length)
    obs_a, info_a = native.reset(seed=11)
    obs_b, info_b = sync.reset(seed=11)
    np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL)
    assert_close(info_a, info_b, "reset")
    terminated = truncated = 0
    width = native.single_action_space.shape[0]
    scale = 0.005 if "Force" in env_id else 1.0  # efforts: small offsets, or the platform flies off at once
    for step, actions in enumerate(large_actions(steps, N, hold=hold, width=width)):
        actions = (actions * scale).astype(np.float32)
        result = native.step(actions)
        assert_step_close(result, sync.step(actions), f"{env_id} {mode.value}, step {step}")
        terminated += int(result[2].sum())
        truncated += int(result[3].sum())
    assert truncated >= 3, f"too few truncations: {truncated}"
    if env_id not in RARELY_TERMINATING:
        assert terminated >= 3, f"too few terminations: {terminated} terminated, {truncated} truncated"


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v0", "StewartGoughReach-v0"])
def test_a_vector_env_on_every_core_steps_as_on_one_thread(monkeypatch, env_id):
    """A vector env of more than ``PARALLEL_MIN_BATCH`` robots, over steps and restarts, equals itself on one thread.

    Its step's calls are kept from step to step (``physics.StepBuffers``): each multi-core step claims its chunks of
    robots afresh (``step_on_every_core``), to the last bit of every output.
    """
    from envs.kernels import setup

    n = setup.PARALLEL_MIN_BATCH + 7
    width = gym.make(env_id).action_space.shape[0]
    actions = large_actions(9, n, hold=2, width=width)

    def run() -> list:
        env = make_native(env_id, n=n, max_episode_steps=4)
        outputs = [env.reset(seed=3)[0]]
        for action in actions:
            outputs.extend(env.step(action)[:4])
        env.close()
        return outputs

    on_every_core = run()
    monkeypatch.setattr(setup, "PARALLEL_MIN_BATCH", 10**9)
    assert not setup.uses_every_core(n)
    for a, b in zip(on_every_core, run(), strict=True):
        np.testing.assert_array_equal(a, b)


def test_reset_with_seed_list_and_options_equals_sync():
    """A list of seeds and the single env's reset options act per sub-environment as in SyncVectorEnv."""
    native, sync = make_native("Planar3RPRReach-v0", n=4), make_sync("Planar3RPRReach-v0", n=4)
    seeds = [5, 3, 9, 1]
    for options in (None, {"targets": "hard"}):
        obs_a, info_a = native.reset(seed=seeds, options=options)
        obs_b, info_b = sync.reset(seed=seeds, options=options)
        np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL)
        assert_close(info_a, info_b, f"options {options}")
    start, target = np.asarray(info_a["pose"][0]), np.asarray(info_a["target"][0])
    _, info = native.reset(options={"start": start, "target": target})
    np.testing.assert_allclose(info["pose"], np.broadcast_to(start, (4, 3)))
    np.testing.assert_allclose(info["target"], np.broadcast_to(target, (4, 3)))
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) \['goal'\]"):
        native.reset(options={"goal": 1})
    with pytest.raises(TypeError, match="options must be a dict or None, got list"):
        native.reset(options=[1])
    with pytest.raises(ValueError, match="seed must be an int, None or a sequence of num_envs=4, got 2"):
        native.reset(seed=[1, 2])


def test_disabled_autoreset_and_reset_mask_equal_sync():
    """DISABLED mode refuses to step ended envs; reset(options={"reset_mask": m}) resets them as Sync does."""
    mode = AutoresetMode.DISABLED
    native = make_native("Planar3RPRReach-v0", n=4, max_episode_steps=5, autoreset_mode=mode)
    sync = make_sync("Planar3RPRReach-v0", n=4, autoreset_mode=mode, max_episode_steps=5)
    native.reset(seed=2)
    sync.reset(seed=2)
    actions = np.zeros((4, 3), dtype=np.float32)
    for step in range(5):
        result = native.step(actions)
        assert_step_close(result, sync.step(actions), f"step {step}")
    assert result[3].all()
    with pytest.raises(gym.error.ResetNeeded, match="DISABLED"):
        native.step(actions)
    mask = np.array([True, False, True, False])
    obs_a, info_a = native.reset(options={"reset_mask": mask})
    obs_b, info_b = sync.reset(options={"reset_mask": mask.copy()})
    np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL)
    assert_close(info_a, info_b, "masked reset")
    np.testing.assert_array_equal(info_a["_is_success"], mask)
    with pytest.raises(TypeError, match="reset_mask"):
        native.reset(options={"reset_mask": [True] * 4})


# -- boundary checks ---------------------------------------------------------------------------------


def test_step_before_reset_raises():
    """Stepping or rendering a vector env that was never reset raises ResetNeeded."""
    env = make_native("Planar3RPRReach-v0", n=2, render_mode="rgb_array")
    with pytest.raises(gym.error.ResetNeeded, match=r"step\(\) before reset\(\)"):
        env.step(np.zeros((2, 3), dtype=np.float32))
    with pytest.raises(gym.error.ResetNeeded, match=r"render\(\) before reset\(\)"):
        env.render()


@pytest.mark.parametrize(
    ("actions", "error", "pattern"),
    [
        (np.full((3, 3), np.nan), ValueError, r"actions must be finite; sub-environment\(s\) \[0, 1, 2\]"),
        (np.array([[0.0, 0.0, 0.0], [0.0, np.inf, 0.0], [0.0, 0.0, 0.0]]), ValueError, r"sub-environment\(s\) \[1\]"),
        (np.zeros((3, 2)), ValueError, r"actions must have shape \(3, 3\), got shape \(3, 2\)"),
        (np.zeros(3), ValueError, r"actions must have shape \(3, 3\), got shape \(3,\)"),
        ([["a", "b", "c"]] * 3, TypeError, r"actions must be an array of shape \(3, 3\) of real numbers"),
    ],
    ids=["nan", "inf-row", "shape-n-2", "flat", "strings"],
)
def test_bad_actions_are_refused(actions, error, pattern):
    """Non-finite or mis-shaped actions raise before any robot moves."""
    env = make_native("Planar3RPRReach-v0", n=3)
    env.reset(seed=0)
    before = env.state.x.copy()
    with pytest.raises(error, match=pattern):
        env.step(actions)
    np.testing.assert_array_equal(env.state.x, before)


@pytest.mark.parametrize(
    ("kwargs", "error", "pattern"),
    [
        ({"dt": -1}, ValueError, r"dt must be finite and > 0, got -1\.0"),
        ({"integrator": "rk5"}, ValueError, r"integrator must be one of \('euler', 'rk4'\), got 'rk5'"),
        ({"targets": "easy"}, ValueError, r"targets must be one of \('standard', 'hard', 'mixed'\), got 'easy'"),
        ({"colour": "red"}, TypeError, r"unknown argument\(s\) \['colour'\]"),
        ({"robot": "hexapod"}, ValueError, r"robot must be a DistanceConstraintMechanism or one of \["),
        ({"robot": 42}, TypeError, r"robot must be a kinematics\.DistanceConstraintMechanism, got int"),
        ({"num_envs": 0}, ValueError, r"num_envs must be ≥ 1, got 0"),
        ({"num_envs": 2.0}, TypeError, r"num_envs must be an int, got float 2\.0"),
        ({"max_episode_steps": 0}, ValueError, r"max_episode_steps must be ≥ 1, got 0"),
        ({"autoreset_mode": "Sometimes"}, ValueError, r"autoreset_mode must be an AutoresetMode or one of"),
        ({"render_mode": "human"}, ValueError, r"render_mode must be one of \['rgb_array'\] or None, got 'human'"),
    ],
)
def test_constructor_errors_match_the_single_env(kwargs, error, pattern):
    """Every keyword argument is validated by the single env's build_family_params (same messages) or named."""
    if set(kwargs) <= {"dt", "integrator", "targets", "colour", "robot"}:
        with pytest.raises(error, match=pattern):
            FamilyReachEnv(**kwargs)
    with pytest.raises(error, match=pattern):
        FamilyReachVectorEnv(**{"num_envs": 2, **kwargs})


def test_base_class_is_abstract():
    """FamilyVectorEnv itself names the concrete classes to use."""
    with pytest.raises(
        TypeError, match="FamilyVectorEnv is abstract; use FamilyReachVectorEnv or FamilyTrackVectorEnv"
    ):
        FamilyVectorEnv(num_envs=2)


# -- rendering, memory -------------------------------------------------------------------------------


def test_render_returns_the_frames_of_the_sub_envs(monkeypatch):
    """rgb_array: one (480, 480, 3) uint8 frame per sub-env, equal to the single envs' frames (trails included)."""
    monkeypatch.delenv("DISPLAY", raising=False)
    native = make_native("Planar3RPRTrack-v0", n=3, render_mode="rgb_array", max_episode_steps=4)
    sync = make_sync("Planar3RPRTrack-v0", n=3, render_mode="rgb_array", max_episode_steps=4)
    native.reset(seed=4)
    sync.reset(seed=4)
    for actions in large_actions(6, 3, seed=4):
        native.step(actions)
        sync.step(actions)
    frames, expected = native.render(), sync.render()
    assert isinstance(frames, tuple) and len(frames) == 3
    for frame, reference in zip(frames, expected):
        assert frame.dtype == np.uint8 and frame.shape == (480, 480, 3)
        differing = np.mean(np.any(frame != reference, axis=-1))
        assert differing < 1e-3, f"{differing:.2%} of the pixels differ from the single env's frame"
    silent = make_native("Planar3RPRTrack-v0", n=2)
    silent.reset(seed=0)
    with pytest.warns(UserWarning, match="without a render_mode"):
        assert silent.render() is None


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v0", "StewartGoughTrack-v0"])
def test_memory_grows_linearly_with_n(env_id):
    """The state arrays hold the same number of bytes per robot at N = 10, 100 and 1000: those of the fields."""
    per_robot = []
    for n in (10, 100, 1000):
        env = make_native(env_id, n=n)
        env.reset(seed=0)
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        per_robot.append(env.state_nbytes() / n)
    robot = env.params.robot
    a, m = robot.n_actuators, robot.n_pose
    # q, x, t, det sign, k, k_I, residual; the reference's centre, amplitude, phase and target strokes: float64/int64.
    expected = 8 * (a + m + 5 + 3 * m + a)
    assert per_robot[0] == per_robot[1] == per_robot[2] == expected, per_robot
    assert "Memory grows linearly with N" in " ".join((FamilyVectorEnv.__doc__ or "").split())
