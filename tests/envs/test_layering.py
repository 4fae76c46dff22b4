"""Layers import only downwards: envs loads no SB3 or torch, kinematics loads no Gymnasium."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


def _modules_after(statement: str) -> set[str]:
    """Top-level module names loaded by a fresh interpreter after running ``statement``."""
    code = f"import json, sys\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return {name.split(".")[0] for name in json.loads(done.stdout.splitlines()[-1])}


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
    """Using envs loads gymnasium but neither stable_baselines3 nor torch."""
    modules = _modules_after(statement)
    assert {"envs", "gymnasium", "kinematics"} <= modules
    assert "stable_baselines3" not in modules
    assert "torch" not in modules
    assert "training" not in modules


def test_kinematics_does_not_import_gymnasium():
    """Importing kinematics loads neither gymnasium nor anything above it."""
    modules = _modules_after("import kinematics")
    assert "kinematics" in modules
    assert not modules & {"gymnasium", "envs", "stable_baselines3", "torch", "training"}


def test_robot_control_does_not_import_training_libraries():
    """The baselines load envs and Gymnasium but neither SB3, torch, training nor the experiments."""
    modules = _modules_after("import robot_control")
    assert {"robot_control", "envs", "gymnasium"} <= modules
    assert not modules & {"stable_baselines3", "torch", "training", "experiments"}


def test_training_does_not_import_the_experiments():
    """The training library (train, evaluate, distill, export) loads no module of the experiments."""
    modules = _modules_after("import training.train, training.evaluate, training.distill, training.export")
    assert "training" in modules
    assert "experiments" not in modules
