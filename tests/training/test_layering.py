"""Layering: envs imports nothing from SB3 or torch, and the training layer sits on top of envs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


def _modules_after(statement: str) -> set[str]:
    """Top-level names of the modules a fresh interpreter holds after running ``statement``."""
    code = f"import json, sys\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    return {name.split(".")[0] for name in json.loads(done.stdout.splitlines()[-1])}


@pytest.mark.parametrize(
    "statement",
    [
        "import envs",
        "import envs, gymnasium as gym; env = gym.make('Planar3RPRReach-v0'); env.reset(seed=0); env.step([0, 0, 0])",
    ],
)
def test_envs_does_not_import_training_libraries(statement):
    """Using envs loads gymnasium but neither stable_baselines3, torch nor the training package."""
    modules = _modules_after(statement)
    assert {"envs", "gymnasium"} <= modules
    assert not modules & {"stable_baselines3", "torch", "training"}, sorted(modules & {"stable_baselines3", "torch"})


def test_training_builds_on_the_baselines_and_envs():
    """training.evaluate finds the classical controllers in robot_control, which stands on envs and kinematics."""
    modules = _modules_after("import training.evaluate")
    assert {"training", "robot_control", "envs", "kinematics"} <= modules


def test_training_config_loads_sb3():
    """training.config is where SB3 enters: it maps algorithm names to SB3 classes."""
    assert "stable_baselines3" in _modules_after("import training.config")


#: The most lines a source file of the environment, the kinematics or the training library may have.
MAX_SOURCE_LINES = 600


def test_no_source_file_is_over_600_lines():
    """Every module of envs/, kinematics/ and training/ stays a file one can read (issue 40's limit)."""
    long = {}
    for folder in ("envs", "kinematics", "training"):
        for path in sorted((REPO_ROOT / folder).rglob("*.py")):
            lines = len(path.read_text(encoding="utf-8").splitlines())
            if lines > MAX_SOURCE_LINES:
                long[str(path.relative_to(REPO_ROOT))] = lines
    assert not long, f"over {MAX_SOURCE_LINES} lines: {long}"
