"""The RL Zoo trains our configs unchanged, and training.evaluate scores the run folders it writes."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from training import evaluate
from training.config import default_config_path

REPO_ROOT = Path(__file__).resolve().parents[2]

#: Env steps of every run: one PPO rollout (2 envs × 64 steps); 32 gradient steps of the off-policy algorithms.
TIMESTEPS = 128

#: One env id per config file (each file lists every id; the family ids and the 3-RPR ones both appear), with
#: budget overrides in the Zoo's own ``--hyperparams key:value`` syntax that keep the run to a few seconds.
CASES = {
    "ppo": ("Planar3RPRReach-v0", ["n_envs:2", "n_steps:64", "batch_size:64", "n_epochs:1"]),
    "sac": ("StewartGoughReach-v0", ["n_envs:1", "buffer_size:1000", "learning_starts:96", "batch_size:32"]),
    "td3": ("Planar3RPRReach-v0", ["n_envs:1", "buffer_size:1000", "learning_starts:96", "batch_size:32"]),
    "tqc": ("StewartGoughReach-v0", ["n_envs:1", "buffer_size:1000", "learning_starts:96", "batch_size:32"]),
}


@pytest.mark.slow
@pytest.mark.parametrize("algo", sorted(CASES))
def test_rl_zoo_trains_the_shipped_config_and_evaluate_scores_its_run(algo, tmp_path):
    """``python -m rl_zoo3.train -conf training/<algo>.yml`` runs; ``training.evaluate --run`` reads its folder."""
    # Found, not imported: importing rl_zoo3 patches gymnasium's TimeLimit for the whole worker (rl_zoo3.gym_patches
    # adds "TimeLimit.truncated" to every info), which would leak into the tests that run after this one
    # (tests/conftest.py fails any test that leaves the patch behind).
    assert importlib.util.find_spec("rl_zoo3") is not None, "rl_zoo3 is a test dependency: pip install -e '.[test]'"
    env_id, budget = CASES[algo]
    command = [
        sys.executable,
        "-m",
        "rl_zoo3.train",
        "--algo",
        algo,
        "--env",
        env_id,
        "--gym-packages",
        "envs",
        "-conf",
        str(default_config_path(algo)),
        "-n",
        str(TIMESTEPS),
        "--num-threads",  # one torch thread, as in the tests' own processes: more are ~4× slower on a shared core
        "1",
        "--eval-freq",
        "-1",
        "-f",
        str(tmp_path / "logs"),
        "--seed",
        "0",
        "--hyperparams",
        *budget,
    ]
    done = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    run = tmp_path / "logs" / algo / f"{env_id}_1"
    assert (run / f"{env_id}.zip").is_file(), sorted(p.name for p in run.iterdir())
    config = evaluate.read_run_config(run)
    assert (config["algo"], config["env_id"], config["source"]) == (algo, env_id, "rl_zoo3")
    out = tmp_path / "eval"
    # In a fresh interpreter, as a user runs it: loading the Zoo's model unpickles rl_zoo3's schedules, and importing
    # rl_zoo3 patches gymnasium's TimeLimit (rl_zoo3.gym_patches) for the rest of the process.
    scored = subprocess.run(
        [sys.executable, "-m", "training.evaluate", "--run", str(run), "--episodes", "1", "--seed", "10000"]
        + ["--out", str(out)],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert scored.returncode == 0, scored.stderr[-3000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["episodes"] == 1 and 0.0 <= metrics["success_rate"] <= 1.0
