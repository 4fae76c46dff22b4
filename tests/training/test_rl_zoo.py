"""The RL Zoo trains our configs unchanged, and training.evaluate scores the run folders it writes."""

from __future__ import annotations

import importlib.util
import json
import os
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


#: The Zoo's own entry point (``python -m rl_zoo3.train`` and ``rl_zoo3 train`` call it), once per argv, in one
#: fresh interpreter: the four runs then pay for importing torch, SB3 and the Zoo once.
_TRAIN_EACH = "import sys\nfrom rl_zoo3.train import train\nfor argv in {argvs!r}:\n    sys.argv = argv\n    train()\n"

#: ``training.evaluate``'s command line (``main``), once per argv, in another fresh interpreter, as a user runs it:
#: loading the Zoo's model unpickles rl_zoo3's schedules, and importing rl_zoo3 patches gymnasium's TimeLimit
#: (rl_zoo3.gym_patches) for the rest of the process.
_EVALUATE_EACH = (
    "import sys\nfrom training import evaluate\nfor argv in {argvs!r}:\n    assert evaluate.main(argv) == 0, argv\n"
)


def _run(code: str, log_dir: Path) -> None:
    """Run ``code`` in a new interpreter; SB3's logger writes to ``log_dir`` (it would make folders in /tmp)."""
    environment = {**os.environ, "SB3_LOGDIR": str(log_dir)}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, timeout=600, env=environment
    )
    assert done.returncode == 0, done.stderr[-3000:]


@pytest.fixture(scope="module")
def zoo_runs(tmp_path_factory) -> dict[str, Path]:
    """Each config of ``CASES`` trained by the RL Zoo, then scored by ``training.evaluate``: {algo: its folder}.

    (Under xdist the module's tests run on one worker: ``ONE_WORKER_MODULES`` in ``tests/conftest.py``.)
    """
    # Found, not imported: importing rl_zoo3 patches gymnasium's TimeLimit for the whole worker (rl_zoo3.gym_patches
    # adds "TimeLimit.truncated" to every info), which would leak into the tests that run after this one
    # (tests/conftest.py fails any test that leaves the patch behind).
    assert importlib.util.find_spec("rl_zoo3") is not None, "rl_zoo3 is a test dependency: pip install -e '.[test]'"
    root = tmp_path_factory.mktemp("zoo")
    trains, scores = [], []
    for algo, (env_id, budget) in sorted(CASES.items()):
        logs = root / algo
        trains.append(
            ["rl_zoo3.train", "--algo", algo, "--env", env_id, "--gym-packages", "envs"]
            + ["-conf", str(default_config_path(algo)), "-n", str(TIMESTEPS)]
            # one torch thread, as in the tests' own processes: more are ~4× slower on a shared core
            + ["--num-threads", "1", "--eval-freq", "-1", "-f", str(logs), "--seed", "0", "--hyperparams", *budget]
        )
        run = logs / algo / f"{env_id}_1"
        scores.append(["--run", str(run), "--episodes", "1", "--seed", "10000", "--out", str(logs / "eval")])
    _run(_TRAIN_EACH.format(argvs=trains), root)
    _run(_EVALUATE_EACH.format(argvs=scores), root)
    return {algo: root / algo for algo in CASES}


@pytest.mark.slow
@pytest.mark.parametrize("algo", sorted(CASES))
def test_rl_zoo_trains_the_shipped_config_and_evaluate_scores_its_run(algo, zoo_runs):
    """``python -m rl_zoo3.train -conf training/<algo>.yml`` runs; ``training.evaluate --run`` reads its folder."""
    env_id, _ = CASES[algo]
    run = zoo_runs[algo] / algo / f"{env_id}_1"
    assert (run / f"{env_id}.zip").is_file(), sorted(p.name for p in run.iterdir())
    config = evaluate.read_run_config(run)
    assert (config["algo"], config["env_id"], config["source"]) == (algo, env_id, "rl_zoo3")
    metrics = json.loads((zoo_runs[algo] / "eval" / "metrics.json").read_text())
    assert metrics["episodes"] == 1 and 0.0 <= metrics["success_rate"] <= 1.0
