"""A user's robot without hand-tuned boxes: the generic ids derive every default from the robot's size."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs.kernels import generic as fk
from envs.params import FamilyParams
from envs.presets import REFERENCE_REACH, build_family_params, reach
from kinematics import DistanceConstraintMechanism, Planar3RPR, StewartGough

# MuJoCo Menagerie's Stewart platform, google-deepmind/mujoco_menagerie stewart_platform/stewart_platform.xml
# (commit 096ff10a33c76d2baa99757db10c59eced520851): each universal joint's centre is the midpoint of its two
# hinges' positions, found by composing the body chain (pos, quat) of each leg at qpos = 0 (the chain's end
# then meets the platform's weld site exactly). Base joints [m] in the world frame; platform joints [m] in the
# frame of the body "upper", which starts at (0.0002058, 0.0051264, 1.1) m; legs 0.926-0.929 m long there.
MENAGERIE_BASE = np.array(
    [
        [0.4921, -0.1032, 0.1240],
        [0.1563, 0.4774, 0.1239],
        [-0.1321, 0.4984, 0.1302],
        [-0.4915, -0.1033, 0.1239],
        [-0.3656, -0.3636, 0.1304],
        [0.3353, -0.3741, 0.1241],
    ]
)
MENAGERIE_PLATFORM = np.array(
    [
        [0.3279, 0.0978, -0.0867],
        [0.2262, 0.2564, -0.0786],
        [-0.2689, 0.2570, -0.0814],
        [-0.3289, 0.0981, -0.0866],
        [-0.0792, -0.3329, -0.0867],
        [0.1071, -0.3229, -0.0799],
    ]
)
MENAGERIE_HOME = np.array([0.0002058, 0.0051264, 1.1, 0.0, 0.0, 0.0])


def menagerie(scale: float = 1.0) -> DistanceConstraintMechanism:
    """The Menagerie Stewart platform, every length times ``scale``."""
    return DistanceConstraintMechanism(
        scale * MENAGERIE_BASE,
        scale * MENAGERIE_PLATFORM,
        pose_space="spatial",
        home=MENAGERIE_HOME * np.array([scale] * 3 + [1.0] * 3),
    )


def menagerie_low() -> DistanceConstraintMechanism:
    """The Menagerie Stewart platform lowered to z = 0.4 m, its legs leaning far out: much of the box is unsafe."""
    return DistanceConstraintMechanism(
        MENAGERIE_BASE, MENAGERIE_PLATFORM, pose_space="spatial", home=(0, 0, 0.4, 0, 0, 0)
    )


def _hexapod() -> DistanceConstraintMechanism:
    default = StewartGough()
    return DistanceConstraintMechanism(default.base, default.platform, pose_space="spatial")


def _planar(scale: float) -> DistanceConstraintMechanism:
    default = Planar3RPR()
    return DistanceConstraintMechanism(scale * default.base, scale * default.platform, pose_space="planar")


ROBOTS = {
    "menagerie": lambda: menagerie(1.0),
    "menagerie_x0.1": lambda: menagerie(0.1),
    "menagerie_x3": lambda: menagerie(3.0),
    "menagerie_low": menagerie_low,
    "hexapod": _hexapod,
    "planar_3rpr_x2": lambda: _planar(2.0),
    "planar_3rpr_x0.2": lambda: _planar(0.2),
}


def test_menagerie_geometry():
    """The anchors are those the model states: base radius ≈ 0.5 m, legs ≈ 0.93 m at home."""
    robot = menagerie()
    np.testing.assert_allclose(np.linalg.norm(MENAGERIE_BASE[:, :2], axis=1).mean(), 0.506, atol=0.005)
    np.testing.assert_allclose(robot.inverse_kinematics(robot.home_pose()), 0.9275, atol=0.003)


@pytest.mark.parametrize("name", sorted(ROBOTS))
@pytest.mark.parametrize("env_id", ["ParallelRobotReach-v0", "ParallelRobotTrack-v0"])
def test_user_robot_resets_and_steps(name, env_id):
    """Without boxes, the robot's certified tasks are found and a few random steps run from each."""
    env = gym.make(env_id, robot=ROBOTS[name]())
    params = env.unwrapped.params
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        assert env.observation_space.contains(obs)
        assert fk.safe_batch(params.packed, info["pose"][None])[0]
        env.action_space.seed(seed)
        for _ in range(5):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert np.isfinite(reward)
            if terminated or truncated:
                break
    env.close()


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_derived_box_is_mostly_safe(name):
    """At least half of the derived task box is certified safe (the box shrinks around home until it is)."""
    params = build_family_params(ROBOTS[name]())
    low, high = np.array(params.sample_low), np.array(params.sample_high)
    x = low + np.random.default_rng(1).uniform(size=(2000, len(low))) * (high - low)
    assert fk.safe_batch(params.packed, x).mean() >= 0.45


@pytest.mark.parametrize("scale", [0.1, 3.0])
def test_lengths_scale_with_the_robot(scale):
    """A robot ``scale`` times the Menagerie one gets ``scale`` times its lengths and rates."""
    small, large = build_family_params(menagerie(1.0)), build_family_params(menagerie(scale))
    for name in ("stroke_margin", "segment_spacing", "min_distance", "success_position_tolerance", "max_rate"):
        assert getattr(large, name) == pytest.approx(scale * getattr(small, name), rel=1e-9), name
    np.testing.assert_allclose(large.stroke_limits, scale * np.array(small.stroke_limits), rtol=1e-9)


def test_the_default_hexapod_keeps_the_documented_lengths():
    """At the reference reach the derived lengths are ``FamilyParams``' defaults; a named robot keeps them.

    The 3-PRR's certificate spacing is the exception: capped at (k_safe − k_hard) / L₉₉ (about 1 mm, its safety
    changing fast with the platform's rotation), which the hexapod's 1 cm is not.
    """
    robot = _hexapod()
    assert reach(robot) == pytest.approx(REFERENCE_REACH)
    derived = build_family_params(robot)
    prr = build_family_params("planar_3prr")
    for name in ("stroke_margin", "segment_spacing", "min_distance", "success_position_tolerance", "max_rate"):
        default = FamilyParams.__dataclass_fields__[name].default
        assert getattr(derived, name) == pytest.approx(default, rel=1e-12), name
        if name == "segment_spacing":
            assert 0.0005 < prr.segment_spacing < 0.2 * default
        else:
            assert getattr(prr, name) == default, name


def test_explicit_box_stays():
    """A caller's own task box is kept as given (no shrinking)."""
    low, high = (-0.05, -0.05, 1.05, -0.1, -0.1, -0.2), (0.05, 0.05, 1.15, 0.1, 0.1, 0.2)
    params = build_family_params(menagerie(), sample_low=low, sample_high=high)
    assert params.sample_low == low and params.sample_high == high
