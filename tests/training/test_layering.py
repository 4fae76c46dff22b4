"""Layering: the training layer sits on top of the baselines and envs, and loads none of the experiments.

That envs loads no SB3, torch or training is ``tests/envs/test_layering.py``'s.
"""

from __future__ import annotations

from tests.envs.helpers import REPO_ROOT, modules_after


def test_training_builds_on_the_baselines_and_envs_and_not_the_experiments():
    """The training library (train, evaluate, distill, export) stands on robot_control, envs and kinematics.

    training.evaluate finds the classical controllers in robot_control; no module of the experiments is loaded.
    """
    modules = modules_after("import training.train, training.evaluate, training.distill, training.export")
    assert {"training", "robot_control", "envs", "kinematics"} <= modules
    assert "experiments" not in modules


def test_training_config_loads_sb3():
    """training.config is where SB3 enters: it maps algorithm names to SB3 classes."""
    assert "stable_baselines3" in modules_after("import training.config")


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
