"""Headless rgb_array rendering: frame format, motion, speed, render_fps and the no-render-mode warning."""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

from envs import ENV_IDS


@pytest.fixture
def headless(monkeypatch: pytest.MonkeyPatch) -> None:
    """No display: rendering must not need one."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_rgb_array_frames(env_id, headless, make_env):
    """render() gives uint8 (H, W, 3) frames with a drawing on them, identical while nothing moves."""
    env = make_env(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= 64 and frame.shape[1] >= 64
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 3, "the frame is (almost) blank"
    np.testing.assert_array_equal(env.render(), frame)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_frames_change_when_the_robot_moves(env_id, headless, make_env):
    """After a few steps that move the platform, the frame is different."""
    env = make_env(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    before = env.render()
    x_before = env.unwrapped.state.x.copy()
    action = np.resize(np.array([0.5, -0.3, 0.2], dtype=np.float32), env.action_space.shape)
    for _ in range(5):
        _, _, terminated, _, _ = env.step(action)
        if terminated:
            break
    assert not np.allclose(env.unwrapped.state.x, x_before)
    assert np.any(env.render() != before)


def test_render_is_fast(headless, make_env):
    """The median time of 20 renders is below dt (a sanity bound for real-time display, not a benchmark)."""
    env = make_env("Planar3RPRReach-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    times = []
    for _ in range(20):
        env.step(np.array([0.2, 0.1, -0.2], dtype=np.float32))
        start = time.perf_counter()
        env.render()
        times.append(time.perf_counter() - start)
    assert np.median(times) < env.unwrapped.params.dt, f"median render time {np.median(times):.4f} s"


@pytest.mark.parametrize("dt", [0.05, 0.1, 0.02])
def test_render_fps_is_one_over_dt(dt, make_env):
    """metadata["render_fps"] is 1/dt for the default and other control periods."""
    env = make_env("Planar3RPRReach-v0", render_mode="rgb_array", dt=dt)
    assert env.metadata["render_fps"] == pytest.approx(1.0 / dt, rel=1e-12)
    assert env.unwrapped.metadata["render_fps"] == pytest.approx(1.0 / dt, rel=1e-12)
    assert env.metadata["render_modes"] == ["human", "rgb_array"]


@pytest.mark.parametrize("wrapped", [False, True], ids=["unwrapped", "made"])
def test_render_without_render_mode_warns(wrapped, headless, make_env):
    """render() without a render_mode warns (naming render_mode) and returns None."""
    made = make_env("Planar3RPRReach-v0")
    env = made if wrapped else made.unwrapped
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


@pytest.mark.parametrize("wrapped", [False, True], ids=["unwrapped", "made"])
def test_render_before_reset_raises(wrapped, headless, make_env):
    """There is nothing to draw before the first reset: ResetNeeded, bare or through gym.make."""
    made = make_env("Planar3RPRReach-v0", render_mode="rgb_array")
    env = made if wrapped else made.unwrapped
    with pytest.raises(gym.error.ResetNeeded):
        env.render()
    env.close()
    env.close()
