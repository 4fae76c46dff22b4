"""Layers import only downwards: envs loads no SB3 or torch, kinematics loads no Gymnasium."""

from __future__ import annotations

import pytest

from tests.envs.helpers import modules_after


@pytest.mark.parametrize(
    "statement",
    [
        "import envs",
        "import gymnasium as gym, envs\nenv = gym.make('Planar3RPRReach-v0')\nenv.reset(seed=0)\n"
        "env.step(env.action_space.sample())",
    ],
    ids=["import", "make-and-step"],
)
def test_envs_does_not_import_training_libraries(statement):
    """Using envs loads gymnasium but neither stable_baselines3, torch nor the training package."""
    modules = modules_after(statement)
    assert {"envs", "gymnasium", "kinematics"} <= modules
    assert "stable_baselines3" not in modules
    assert "torch" not in modules
    assert "training" not in modules


def test_kinematics_does_not_import_gymnasium():
    """Importing kinematics loads neither gymnasium nor anything above it."""
    modules = modules_after("import kinematics")
    assert "kinematics" in modules
    assert not modules & {"gymnasium", "envs", "stable_baselines3", "torch", "training"}


def test_robot_control_does_not_import_training_libraries():
    """The baselines load envs and Gymnasium but neither SB3, torch, training nor the experiments."""
    modules = modules_after("import robot_control")
    assert {"robot_control", "envs", "gymnasium"} <= modules
    assert not modules & {"stable_baselines3", "torch", "training", "experiments"}
