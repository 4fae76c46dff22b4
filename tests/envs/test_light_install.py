"""A light install: without the extras, every id makes, steps, renders and vectorises; an extra's feature names it.

Each test runs a fresh interpreter in which the extras' modules cannot be imported (a meta-path finder refuses
them), as after ``pip install parallel-robot-gym`` with no extra.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]

#: What ``pip install parallel-robot-gym`` does not install (the planner, train and sweep extras).
EXTRA_MODULES = ("torch", "stable_baselines3", "sb3_contrib", "ray", "ompl", "matplotlib", "pandas", "rliable")

_BLOCK = """
import importlib.abc, json, sys

BLOCKED = set({blocked!r})


class _NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}} (not installed: a light install)", name=name)
        return None


sys.meta_path.insert(0, _NotInstalled())
"""

_EVERY_ID = """
import gymnasium as gym
import numpy as np

for module in BLOCKED:  # the blocking works
    try:
        __import__(module)
    except ModuleNotFoundError:
        pass
    else:
        raise AssertionError(f"{module} imported")

import envs

for env_id in envs.ENV_IDS:
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    env.action_space.seed(0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8, (env_id, type(frame))
    assert frame.ndim == 3 and frame.shape[2] == 3 and min(frame.shape[:2]) > 0, (env_id, frame.shape)
    env.close()
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    vec.action_space.seed(0)
    vec.step(vec.action_space.sample())
    vec.close()
print(json.dumps(sorted(m for m in sys.modules if m.partition(".")[0] in BLOCKED)))
"""


def _run(blocked: tuple[str, ...], code: str, timeout: float) -> subprocess.CompletedProcess:
    program = _BLOCK.format(blocked=sorted(blocked)) + code
    return subprocess.run(
        [sys.executable, "-c", program], cwd=REPO_ROOT, capture_output=True, text=True, timeout=timeout
    )


@pytest.mark.slow
def test_every_id_makes_steps_renders_and_vectorises_without_the_extras():
    """gym.make, reset, step, render("rgb_array") and make_vec of every id import no extra's module."""
    done = _run(EXTRA_MODULES, _EVERY_ID, timeout=900)
    assert done.returncode == 0, done.stderr[-4000:]
    assert json.loads(done.stdout.splitlines()[-1]) == []


@pytest.mark.parametrize(
    ("missing", "code", "extra"),
    [
        (
            "ompl",
            "import gymnasium as gym, envs\nfrom robot_control.planner import SafePlanner\n"
            "SafePlanner(gym.make('Planar3RPRReach-v0').unwrapped.params)",
            "planner",
        ),
        ("torch", "import training.train", "train"),
        # Before the sweep writes its plan: nothing to --resume after installing the extra.
        ("ray", "from training.sweep import main\nmain(['--name', 'light', '--root', '/nonexistent'])", "sweep"),
        (
            "matplotlib",
            "import gymnasium as gym, envs\nenv = gym.make('Planar3RPRReach-v0', render_mode='human')\n"
            "env.reset(seed=0)\nenv.render()",
            "train",
        ),
    ],
    ids=["planner", "training", "sweep", "human-render"],
)
def test_a_feature_of_a_missing_extra_names_the_extra(missing, code, extra):
    """The error of a feature whose extra is not installed says ``pip install 'parallel-robot-gym[<extra>]'``."""
    done = _run((missing,), code, timeout=300)
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("ModuleNotFoundError") and missing in last, done.stderr[-4000:]
    assert f"pip install 'parallel-robot-gym[{extra}]'" in last, done.stderr[-4000:]
