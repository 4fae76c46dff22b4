"""The SB3 adapter of the native vector env behaves like DummyVecEnv of single envs and trains PPO."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor

from envs import PLANAR_3RPR_IDS
from training.train import VEC_KINDS, build_parser, make_training_env, read_monitor
from training.vec_adapter import NativeVecEnvAdapter

N = 4
SHORT = 20
OBS_ATOL = 1e-5


def make_dummy(env_id: str, n: int = N, **kwargs: Any) -> DummyVecEnv:
    """DummyVecEnv of ``gym.make`` envs (default wrappers, no Monitor)."""
    return DummyVecEnv([lambda: gym.make(env_id, **kwargs) for _ in range(n)])


def assert_info_close(a: dict[str, Any], b: dict[str, Any], where: str) -> None:
    """Per-env info dicts agree: same keys and types, floats to rounding, the rest exactly."""
    assert a.keys() == b.keys(), f"{where}: keys differ: {sorted(set(a) ^ set(b))}"
    for key in a:
        u, v = a[key], b[key]
        assert type(u) is type(v), f"{where}[{key!r}]: {type(u).__name__} vs {type(v).__name__}"
        if isinstance(u, np.ndarray):
            np.testing.assert_allclose(u, v, rtol=1e-9, atol=OBS_ATOL, err_msg=f"{where}[{key!r}]")
        elif isinstance(u, float):
            assert u == pytest.approx(v, rel=1e-9, abs=1e-9), f"{where}[{key!r}]: {u!r} != {v!r}"
        else:
            assert u == v, f"{where}[{key!r}]: {u!r} != {v!r}"


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v0", "Planar3RPRTrack-v0"])
def test_adapter_equals_dummy_vec_env(env_id):
    """Same seeds and actions ⇒ same obs, rewards, dones, terminal observations, TimeLimit flags, infos."""
    adapter = NativeVecEnvAdapter.from_id(env_id, N, max_episode_steps=SHORT)
    dummy = make_dummy(env_id, max_episode_steps=SHORT)
    assert adapter.seed(21) == dummy.seed(21)
    obs_a, obs_b = adapter.reset(), dummy.reset()
    np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL)
    for i in range(N):
        assert_info_close(adapter.reset_infos[i], dummy.reset_infos[i], f"reset info {i}")
    rng = np.random.default_rng(21)
    actions = np.repeat(rng.uniform(-3.0, 3.0, size=(20, N, 3)), 8, axis=0).astype(np.float32)
    ends = {"terminated": 0, "truncated": 0}
    for step, action in enumerate(actions):
        obs_a, rew_a, done_a, infos_a = adapter.step(action)
        obs_b, rew_b, done_b, infos_b = dummy.step(action)
        where = f"{env_id}, step {step}"
        assert obs_a.dtype == obs_b.dtype and rew_a.dtype == rew_b.dtype and done_a.dtype == done_b.dtype
        np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL, err_msg=where)
        np.testing.assert_allclose(rew_a, rew_b, rtol=1e-6, err_msg=where)
        np.testing.assert_array_equal(done_a, done_b, err_msg=where)
        assert isinstance(infos_a, list) and len(infos_a) == N
        for i in range(N):
            assert_info_close(infos_a[i], infos_b[i], f"{where}, info {i}")
            if done_a[i]:
                assert infos_a[i]["terminal_observation"].shape == obs_a[i].shape
                assert_info_close(adapter.reset_infos[i], dummy.reset_infos[i], f"{where}, reset info {i}")
                ends["truncated" if infos_a[i]["TimeLimit.truncated"] else "terminated"] += 1
    assert ends["terminated"] >= 2 and ends["truncated"] >= 2, ends


def test_vec_env_contract_by_hand():
    """Spaces, reset/step shapes and dtypes, attributes, env_is_wrapped, set_attr, render and close."""
    adapter = NativeVecEnvAdapter.from_id("Planar3RPRReach-v0", 3, render_mode="rgb_array")
    assert isinstance(adapter, VecEnv) and adapter.num_envs == 3
    single = gym.make("Planar3RPRReach-v0")
    assert adapter.observation_space == single.observation_space
    assert adapter.action_space == single.action_space
    adapter.seed(0)
    obs = adapter.reset()
    assert obs.shape == (3, *single.observation_space.shape) and obs.dtype == np.float32
    assert all(adapter.observation_space.contains(o) for o in obs)
    assert len(adapter.reset_infos) == 3 and all("is_success" in info for info in adapter.reset_infos)
    obs, rewards, dones, infos = adapter.step(np.zeros((3, 3), dtype=np.float32))
    assert rewards.shape == (3,) and rewards.dtype == np.float32 and dones.dtype == np.bool_
    assert all(isinstance(info["is_success"], bool) and isinstance(info["cost"], float) for info in infos)
    assert all(info["TimeLimit.truncated"] is False for info in infos)
    assert adapter.get_attr("render_mode") == ["rgb_array"] * 3
    assert adapter.get_attr("targets", indices=[1]) == ["standard"]
    assert adapter.get_attr("observation_space", indices=0) == [single.observation_space]
    assert adapter.has_attr("params") and not adapter.has_attr("no_such_attribute")
    assert adapter.env_is_wrapped(Monitor) == [False, False, False]
    adapter.set_attr("targets", "hard")
    assert adapter.get_attr("targets") == ["hard"] * 3
    with pytest.raises(ValueError, match="share 'targets'"):
        adapter.set_attr("targets", "standard", indices=[0])
    frames = adapter.get_images()
    assert len(frames) == 3 and frames[0].shape == (480, 480, 3)
    assert adapter.env_method("render", indices=[2])[0].shape == (480, 480, 3)
    with pytest.raises(NotImplementedError, match="rows of one batch"):
        adapter.env_method("reset")
    adapter.close()
    with pytest.raises(ValueError, match="SAME_STEP"):
        NativeVecEnvAdapter(gym.make_vec("Planar3RPRReach-v0", num_envs=2, vectorization_mode="vector_entry_point"))


def test_seed_none_and_options():
    """seed(None) draws a seed; set_options reaches every env at the next reset (then is forgotten)."""
    adapter = NativeVecEnvAdapter.from_id("Planar3RPRReach-v0", 2)
    seeds = adapter.seed()
    assert seeds[1] == seeds[0] + 1
    adapter.reset()
    start, target = np.asarray(adapter.reset_infos[0]["pose"]), np.asarray(adapter.reset_infos[0]["target"])
    adapter.set_options({"start": start, "target": target})
    adapter.reset()
    for info in adapter.reset_infos:
        np.testing.assert_allclose(info["pose"], start)
        np.testing.assert_allclose(info["target"], target)
    adapter.set_options([{"targets": "hard"}, {}])
    adapter.reset()
    assert adapter._options == [{}, {}]


def test_ppo_learns_a_few_hundred_steps_through_the_adapter(tmp_path: Path):
    """PPO collects and trains through make_training_env(vec="native"); VecMonitor logs is_success and cost."""
    venv = make_training_env(
        "Planar3RPRReach-v0", 4, seed=0, vec="native", monitor_dir=tmp_path, env_kwargs={"max_episode_steps": 16}
    )
    assert isinstance(venv, VecMonitor) and isinstance(venv.venv, NativeVecEnvAdapter)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.set_logger(configure(str(tmp_path), []))  # no SB3 temp folder
    model.learn(total_timesteps=384)
    assert model.num_timesteps == 384
    assert model.ep_info_buffer and {"is_success", "cost"} <= set(model.ep_info_buffer[0])
    venv.close()
    episodes = read_monitor(tmp_path)
    assert len(episodes["r"]) >= 384 // 16 - 4 and set(np.unique(episodes["is_success"])) <= {0.0, 1.0}


def test_native_is_the_default_vectorisation():
    """--vec defaults to native, which every registered id supports."""
    assert VEC_KINDS[0] == "native"
    args = build_parser().parse_args(["--algo", "ppo", "--env", PLANAR_3RPR_IDS[0]])
    assert args.vec == "native"
    for env_id in PLANAR_3RPR_IDS:
        assert gym.spec(env_id).vector_entry_point is not None
    native = gym.make_vec(
        PLANAR_3RPR_IDS[0], num_envs=2, vectorization_mode="vector_entry_point", autoreset_mode=AutoresetMode.SAME_STEP
    )
    assert isinstance(NativeVecEnvAdapter(native), VecEnv)


def test_a_wrapper_with_a_vector_form_trains_on_the_native_env_like_dummy_envs():
    """make_training_env(vec="native", wrapper_class=W) wraps the native env in W's vector form (not DummyVecEnv).

    Its observations equal a DummyVecEnv of single envs wrapped in W, with the same seeds, step for step.
    """
    import robot_control

    env_id, kwargs = "Planar3RPRForceReach-v0", {"max_episode_steps": 8}
    wrapper = robot_control.ComputedTorqueResidualWrapper
    native = make_training_env(env_id, 2, seed=5, vec="native", env_kwargs=kwargs, wrapper_class=wrapper)
    dummy = make_training_env(env_id, 2, seed=5, vec="dummy", env_kwargs=kwargs, wrapper_class=wrapper)
    assert isinstance(native.venv, NativeVecEnvAdapter)
    assert isinstance(native.venv.venv, robot_control.VectorComputedTorqueResidualWrapper)
    assert native.observation_space == dummy.observation_space
    np.testing.assert_allclose(native.reset(), dummy.reset(), rtol=1e-6, atol=1e-6)
    rng = np.random.default_rng(0)
    for _ in range(12):  # past an autoreset
        actions = rng.uniform(-1.0, 1.0, (2, 3)).astype(np.float32)
        obs_n, rew_n, done_n, infos_n = native.step(actions)
        obs_d, rew_d, done_d, infos_d = dummy.step(actions)
        np.testing.assert_allclose(obs_n, obs_d, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(rew_n, rew_d, rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(done_n, done_d)
        for i in np.flatnonzero(done_n):
            np.testing.assert_allclose(
                infos_n[i]["terminal_observation"], infos_d[i]["terminal_observation"], rtol=1e-6, atol=1e-6
            )
    assert native.get_attr("params")[0] is not None
