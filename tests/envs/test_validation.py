"""The environments validate actions, call order and constructor arguments at the boundary, precisely."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

import kinematics
from envs import ENV_IDS, FamilyReachEnv, FamilyTrackEnv
from envs.arguments import Choice, Range, Vector
from envs.params import field_parameters

ENV_CLASSES = [FamilyReachEnv, FamilyTrackEnv]

#: (keyword arguments, exception, message pattern) refused by both environment classes.
BAD_ARGUMENTS = [
    ({"dt": 0}, ValueError, r"dt must be finite and > 0, got 0\.0"),
    ({"dt": -1}, ValueError, r"dt must be finite and > 0, got -1\.0"),
    ({"dt": float("nan")}, ValueError, r"dt must be finite and > 0, got nan"),
    ({"dt": "0.05"}, TypeError, r"dt must be a real number, got str '0\.05'"),
    ({"max_rate": 0}, ValueError, r"max_rate must be finite and > 0, got 0\.0"),
    (
        {"stroke_limits": (1.0, 0.5)},
        ValueError,
        r"stroke_limits must satisfy 0 < q_min < q_max \(leg lengths\), got \(1\.0, 0\.5\)",
    ),
    (
        {"stroke_limits": (0, 1)},
        ValueError,
        r"stroke_limits must satisfy 0 < q_min < q_max \(leg lengths\), got \(0\.0, 1\.0\)",
    ),
    ({"stroke_limits": (0.3,)}, ValueError, r"stroke_limits must be 2 finite numbers, got \(0\.3,\)"),
    ({"integrator": "rk5"}, ValueError, r"integrator must be one of \('euler', 'rk4'\), got 'rk5'"),
    ({"safe_threshold": 0.03}, ValueError, r"0 < hard_threshold < safe_threshold < 1, got 0\.03 and 0\.03"),
    ({"safe_threshold": 0.02}, ValueError, r"0 < hard_threshold < safe_threshold < 1, got 0\.03 and 0\.02"),
    ({"hard_threshold": 0}, ValueError, r"hard_threshold must be finite and in \(0, 1\), got 0\.0"),
    ({"safe_threshold": 1}, ValueError, r"safe_threshold must be finite and in \(0, 1\), got 1\.0"),
    ({"render_mode": "video"}, ValueError, r"render_mode must be one of \['human', 'rgb_array'\] or None, got 'video'"),
    ({"robot": "hexapod"}, ValueError, r"robot must be a DistanceConstraintMechanism or one of \[.*'planar_3rpr'"),
    ({"robot": 42}, TypeError, r"robot must be a kinematics\.DistanceConstraintMechanism, got int"),
    ({"colour": "red"}, TypeError, r"unknown argument\(s\) \['colour'\]"),
    ({"newton_max_iterations": 0}, ValueError, r"newton_max_iterations must be an int ≥ 1, got 0"),
    ({"newton_max_iterations": 2.0}, ValueError, r"newton_max_iterations must be an int ≥ 1, got 2\.0"),
    ({"position_weight": -1}, ValueError, r"position_weight must be finite and ≥ 0, got -1\.0"),
    ({"success_reward": -0.5}, ValueError, r"success_reward must be finite and ≥ 0, got -0\.5"),
    ({"success_reward": float("nan")}, ValueError, r"success_reward must be finite and ≥ 0, got nan"),
    ({"success_reward": float("inf")}, ValueError, r"success_reward must be finite and ≥ 0, got inf"),
    ({"success_reward": "1"}, TypeError, r"success_reward must be a real number, got str '1'"),
    ({"task_region": "disc"}, ValueError, r"task_region must be one of \('box', 'grid'\), got 'disc'"),
    ({"task_region": "grid"}, ValueError, r"task_region='grid' needs a robot with 3 pose coordinates, got 6"),
    ({"hard_kind": "crossing"}, ValueError, r"hard_kind='crossing' needs task_region='grid', got 'box'"),
    ({"track_shape": "circle"}, ValueError, r"track_shape='circle' needs task_region='grid' and no track_path"),
    ({"track_shape": "square"}, ValueError, r"track_shape must be one of \('sinusoid', 'circle'\), got 'square'"),
    ({"grid_cell": (0.1, 0.0, 0.1)}, ValueError, r"grid_cell must be 3 numbers > 0, got \[0\.1, 0\.0, 0\.1\]"),
    ({"track_radius_range": (0.2, 0.1)}, ValueError, r"track_radius_range must satisfy 0 ≤ low ≤ high"),
]


def _terminate(env, rng: np.random.Generator) -> dict:
    """Step with random actions until the episode terminates; returns the last info."""
    env.reset(seed=3, options={"targets": "hard"})
    for _ in range(5_000):
        _, _, terminated, truncated, info = env.step(rng.uniform(-1.0, 1.0, size=3).astype(np.float32))
        if terminated:
            return info
        if truncated:
            env.reset(options={"targets": "hard"})
    pytest.fail("random actions never terminated an episode")


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_non_finite_action_raises(env_id, value, make_env):
    """A NaN or infinite action is refused before it reaches the dynamics; the state is untouched."""
    env = make_env(env_id)
    env.reset(seed=0)
    x_before = env.unwrapped.state.x.copy()
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    action[1] = value
    with pytest.raises(ValueError, match="action must be finite"):
        env.step(action)
    np.testing.assert_array_equal(env.unwrapped.state.x, x_before)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))


@pytest.mark.parametrize("change", ["short", "column", "long", "scalar"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_wrong_action_shape_raises(env_id, change, make_env):
    """An action that is not of shape (n,) is refused, naming the shape it got."""
    env = make_env(env_id)
    env.reset(seed=0)
    n = env.action_space.shape[0]
    shape = {"short": (n - 1,), "column": (n, 1), "long": (n + 1,), "scalar": ()}[change]
    pattern = rf"action must have shape \({n},\), got shape {re.escape(str(shape))}"
    with pytest.raises(ValueError, match=pattern):
        env.unwrapped.step(np.zeros(shape, dtype=np.float32))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_step_before_reset_raises(env_id, make_env):
    """step() before reset() raises ResetNeeded, on the bare env and through gym.make's wrappers."""
    env = make_env(env_id)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(action)
    with pytest.raises(gym.error.ResetNeeded, match="before reset"):
        env.unwrapped.step(action)


@pytest.mark.parametrize("wrapped", [False, True], ids=["unwrapped", "made"])
def test_step_after_termination_raises(wrapped, make_env, rng):
    """After a terminal step, step() raises ResetNeeded until the next reset."""
    made = make_env("Planar3RPRReach-v0")
    env = made if wrapped else made.unwrapped
    info = _terminate(env, rng)
    assert info["termination_reason"] != ""
    with pytest.raises(gym.error.ResetNeeded, match="terminated"):
        env.step(np.zeros(3, dtype=np.float32))
    env.reset(seed=1)
    env.step(np.zeros(3, dtype=np.float32))


@pytest.mark.parametrize(("kwargs", "error", "match"), BAD_ARGUMENTS)
@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_invalid_constructor_arguments(cls, kwargs, error, match):
    """Each invalid argument is refused with the right exception and a message naming it."""
    with pytest.raises(error, match=match):
        cls(**kwargs)


def _outside(check: Range | Choice | Vector) -> tuple[object, str]:
    """A value the check refuses, and the pattern of the refusal (the expected and the actual value)."""
    if isinstance(check, Choice):
        return "nonsense", re.escape(f"must be one of {check.values}, got 'nonsense'")
    if isinstance(check, Vector):
        size = {"m": 6, "n": 6, "d": 3}.get(check.size, check.size)  # the hexapod's
        if check.element is None:
            return (0.0,) * (size + 1), re.escape(f"must be {size} finite numbers, got {(0.0,) * (size + 1)}")
        bad = check.element.low - (0.0 if check.element.low_open else 1.0)
        return (bad,) * size, re.escape(f"must be {size} numbers {check.element.text}, got {[bad] * size}")
    bad = check.low - (0 if check.low_open else 1)
    if check.integer:
        return bad, re.escape(f"must be an int {check.text}, got {bad!r}")
    return float(bad), re.escape(f"must be finite and {check.text}, got {float(bad)!r}")


@pytest.mark.parametrize("parameter", [p for p in field_parameters() if p.check is not None], ids=lambda p: p.name)
def test_every_checked_field_refuses_a_value_outside_its_metadata(parameter):
    """Each field's Parameter.check validates it: a value outside gives a message naming it, the range, the value."""
    value, pattern = _outside(parameter.check)
    with pytest.raises(ValueError, match=rf"^{parameter.name} {pattern}$"):
        FamilyReachEnv(**{parameter.name: value})
    if isinstance(parameter.check, Range) and parameter.check.high < np.inf:
        high = parameter.check.high + (0.0 if parameter.check.high_open else 1.0)
        with pytest.raises(
            ValueError, match=rf"^{parameter.name} must be finite and {re.escape(parameter.check.text)}"
        ):
            FamilyReachEnv(**{parameter.name: high})


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v0", "Planar3RPRTrack-v0", "ParallelRobotReach-v0"])
def test_invalid_arguments_through_gym_make(env_id):
    """gym.make forwards the refusals, for a preset's own ids as for the generic ones."""
    with pytest.raises(ValueError, match=r"dt must be finite and > 0, got -1\.0"):
        gym.make(env_id, dt=-1)
    with pytest.raises(TypeError, match=r"unknown argument\(s\) \['base'\]"):
        gym.make(env_id, base=[[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]])


def test_invalid_targets_argument():
    """Reach refuses an unknown targets mode, naming the valid ones; gym.make forwards the refusal."""
    with pytest.raises(ValueError, match=r"targets must be one of \('standard', 'hard', 'mixed'\), got 'impossible'"):
        FamilyReachEnv(targets="impossible")
    with pytest.raises(ValueError, match="targets must be one of"):
        gym.make("Planar3RPRReach-v0", targets="impossible")
    env = gym.make("Planar3RPRReach-v0")
    with pytest.raises(ValueError, match=r"options\['targets'\] must be one of \('standard', 'hard', 'mixed'\)"):
        env.reset(seed=0, options={"targets": "impossible"})


def test_track_period_is_validated():
    """Track's own argument is validated like the shared ones."""
    with pytest.raises(ValueError, match=r"track_period must be finite and > 0, got 0\.0"):
        FamilyTrackEnv(track_period=0)


def test_robot_argument_replaces_the_geometry_arguments():
    """A user geometry is given as robot=kinematics.Planar3RPR(base, platform); a collinear base is refused there."""
    default = kinematics.Planar3RPR()
    base = np.asarray(default.base) * 1.1
    env = gym.make("Planar3RPRReach-v0", robot=kinematics.Planar3RPR(base, default.platform))
    np.testing.assert_array_equal(env.unwrapped.params.robot.base, base)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    with pytest.raises(ValueError, match="collinear"):
        kinematics.Planar3RPR([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]], default.platform)


@pytest.mark.parametrize(
    ("options", "error", "pattern"),
    [
        ({"goal": 1}, ValueError, r"unknown reset option\(s\) \['goal'\]"),
        ({"start": [0.5, 0.5]}, ValueError, r"options\['start'\] must be 3 finite numbers"),
        ({"target": [np.nan, 0.5, 0.0]}, ValueError, r"options\['target'\] must be 3 finite numbers"),
        ({"start": [5.0, 5.0, 0.0]}, ValueError, r"options\['start'\] = \[5\.0, 5\.0, 0\.0\] is not in the certified"),
    ],
    ids=["unknown", "short-start", "nan-target", "unsafe-start"],
)
def test_invalid_reset_options(options, error, pattern, make_env):
    """Reset options are checked and named; a start or target must be a safe pose."""
    env = make_env("Planar3RPRReach-v0")
    with pytest.raises(error, match=pattern):
        env.reset(seed=0, options=options)


def test_start_or_target_alone_needs_the_grid(make_env):
    """Reset options "start" or "target" alone need task_region="grid" (the 3-RPR's); a box robot needs both."""
    env = make_env("Planar3RPRReach-v0")
    _, info = env.reset(seed=0)
    _, alone = env.reset(seed=1, options={"start": info["pose"]})
    np.testing.assert_array_equal(alone["pose"], info["pose"])
    box = make_env("StewartGoughReach-v0")
    _, info = box.reset(seed=0)
    with pytest.raises(ValueError, match=r"'start' and 'target' alone need task_region='grid'; give both"):
        box.reset(seed=1, options={"start": info["pose"]})
