"""Train → run folder → evaluate, end to end with tiny budgets, for PPO, SAC and TD3 (and the train CLI)."""

from __future__ import annotations

import csv
import json
import os
import shlex
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from tests.training.conftest import REACH
from training import evaluate
from training.train import train

REPO_ROOT = Path(__file__).resolve().parents[2]

#: Tiny budgets: each run completes at least one 200-step episode per environment and a few evaluations.
TINY = {
    "ppo": {
        "timesteps": 400,
        "n_envs": 2,
        "eval": {"eval_freq": 200, "eval_episodes": 1},
        "overrides": {
            "n_steps": 64,
            "batch_size": 64,
            "n_epochs": 2,
            "policy_kwargs": {"net_arch": [32, 32]},
        },
    },
    **{
        algo: {
            "timesteps": 300,
            "n_envs": 1,
            "eval": {"eval_freq": 150, "eval_episodes": 1},
            "overrides": {
                "learning_starts": 50,
                "buffer_size": 1000,
                "batch_size": 32,
                "policy_kwargs": {"net_arch": [32, 32]},
            },
        }
        for algo in ("sac", "td3", "tqc")
    },
}

#: Aggregates metrics.json must hold.
METRICS = (
    "success_rate",
    "final_position_error_mm",
    "final_orientation_error_deg",
    "return",
    "min_inverse_condition",
    "singularity_terminations",
    "cost_fraction",
    "episode_length",
)


def _open_in_this_process(folder: Path) -> list[str]:
    """The files below ``folder`` that this process holds open (``/proc/self/fd``; empty where there is none)."""
    fds = Path("/proc/self/fd")
    if not fds.is_dir():
        return []
    paths = []
    for fd in fds.iterdir():
        try:
            target = os.readlink(fd)
        except OSError:  # closed meanwhile
            continue
        if target.startswith(str(folder)):
            paths.append(target)
    return paths


def _assert_png(path: Path) -> None:
    """The file is a non-trivial PNG image."""
    assert path.is_file(), f"{path.name} missing"
    with Image.open(path) as image:
        assert image.format == "PNG"
        assert min(image.size) > 50


def _check_run_folder(run: Path, algo: str, spec: dict, command: str) -> None:
    """Every file of the run folder layout is there and says what it should."""
    names = ("model.zip", "best_model.zip", "vecnormalize.pkl", "best_vecnormalize.pkl", "config.yml", "command.txt")
    for name in (*names, "summary.json", "progress.csv"):
        assert (run / name).is_file(), f"{name} missing from {sorted(p.name for p in run.iterdir())}"
    _assert_png(run / "learning_curve.png")

    config = yaml.safe_load((run / "config.yml").read_text())
    assert (config["algo"], config["env_id"], config["seed"]) == (algo, REACH, 0)
    hyper = config["hyperparams"]
    assert hyper["n_timesteps"] == spec["timesteps"]
    assert hyper["n_envs"] == spec["n_envs"]
    for key, value in spec["overrides"].items():
        assert hyper[key] == value, key
    assert hyper["gamma"] == 0.98, "keys not overridden keep the shipped file's value"
    assert hyper["normalize"], "the shipped configs normalise observations"
    assert set(config["versions"]) >= {"python", "numpy", "gymnasium", "stable_baselines3", "torch"}

    assert (run / "command.txt").read_text().strip() == command

    logs = sorted((run / "monitor").glob("*.monitor.csv"))
    assert logs, "no Monitor log"
    episodes = 0
    for log in logs:
        lines = log.read_text().splitlines()
        assert {"r", "l", "is_success", "cost"} <= set(lines[1].split(",")), lines[1]
        rows = list(csv.DictReader(lines[1:]))
        assert {r["is_success"] for r in rows} <= {"True", "False"}
        episodes += len(rows)
    assert episodes >= spec["n_envs"], "every environment finishes at least one 200-step episode"

    data = np.load(run / "evaluations.npz")
    assert len(data["timesteps"]) >= 1
    assert data["results"].shape[1] == spec["eval"]["eval_episodes"]
    assert "successes" in data.files, "EvalCallback saw no is_success in the infos"

    summary = json.loads((run / "summary.json").read_text())
    assert summary["timesteps"] >= spec["timesteps"]
    assert summary["wall_time_s"] >= 0.0
    assert np.isfinite(summary["best_mean_reward"])


def _check_evaluation(out: Path, episodes: int) -> dict:
    """evaluate.main wrote metrics.json, episodes.csv (one row per episode) and both figures."""
    metrics = json.loads((out / "metrics.json").read_text())
    for key in METRICS:
        assert key in metrics, key
    assert metrics["episodes"] == episodes
    assert 0.0 <= metrics["success_rate"] <= 1.0
    with open(out / "episodes.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == episodes
    assert [int(r["episode"]) for r in rows] == list(range(episodes))
    _assert_png(out / "trajectories.png")
    _assert_png(out / "condition_number.png")
    assert not (out / "episodes.gif").exists(), "no GIF without --video"
    return metrics


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ppo", "sac", "td3", "tqc"])
def test_train_then_evaluate(algo, tmp_path, capsys):
    """A tiny run writes the whole run folder, and evaluate.main reloads it from that folder alone."""
    spec = TINY[algo]
    command = f"python -m training.train --algo {algo} --env {REACH} (test)"
    run = train(
        algo,
        REACH,
        seed=0,
        timesteps=spec["timesteps"],
        n_envs=spec["n_envs"],
        run_dir=tmp_path / "run",
        overrides=spec["overrides"],
        **spec["eval"],
        progress_bar=False,
        command=command,
    )
    assert run == tmp_path / "run"
    assert not _open_in_this_process(run), "train() left files of its run folder open (SB3's CSV logger)"
    _check_run_folder(run, algo, spec, command)
    if algo == "td3":  # the shipped exploration noise (noise_type / noise_std in td3.yml) reaches the model
        from stable_baselines3 import TD3
        from stable_baselines3.common.noise import NormalActionNoise

        with warnings.catch_warnings():  # the saved NStepReplayBuffer makes SB3 warn that n_steps is ignored on load
            warnings.filterwarnings("ignore", message=r"`n_steps=\d+` is ignored", category=UserWarning)
            noise = TD3.load(run / "model.zip", device="cpu").action_noise
        assert isinstance(noise, NormalActionNoise)
        assert noise._sigma.tolist() == [0.1, 0.1, 0.1]

    out = tmp_path / "eval"
    assert evaluate.main(["--run", str(run), "--episodes", "2", "--out", str(out)]) == 0
    _check_evaluation(out, episodes=2)
    assert "outputs written to" in capsys.readouterr().out
    best = tmp_path / "eval-best"
    assert evaluate.main(["--run", str(run), "--model", "best", "--episodes", "1", "--out", str(best)]) == 0
    _check_evaluation(best, episodes=1)


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3", "tqc"])
def test_evaluate_run_is_deterministic(algo, make_run_folder, tmp_path):
    """Evaluating the same run folder twice with the same seed gives identical episodes (no training needed)."""
    run = make_run_folder(algo)
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        assert evaluate.main(["--run", str(run), "--episodes", "2", "--seed", "7", "--out", str(out)]) == 0
    _check_evaluation(outs[0], episodes=2)
    assert (outs[0] / "episodes.csv").read_text() == (outs[1] / "episodes.csv").read_text()


def test_evaluate_best_model_and_default_out(make_run_folder):
    """--model best reads best_model.zip and best_vecnormalize.pkl; the default --out is <run>/eval-<targets>."""
    run = make_run_folder("ppo")
    for final, best in (("model.zip", "best_model.zip"), ("vecnormalize.pkl", "best_vecnormalize.pkl")):
        (run / best).write_bytes((run / final).read_bytes())
        (run / final).write_bytes(b"damaged")  # the final model and its statistics must not be read
    assert evaluate.main(["--run", str(run), "--model", "best", "--episodes", "1", "--targets", "hard"]) == 0
    _check_evaluation(run / "eval-Planar3RPRReach-v0-hard", episodes=1)


@pytest.mark.slow
def test_train_cli_entry_point(tmp_path):
    """The CLI `python -m training.train` runs end to end in a fresh interpreter and records its exact command."""
    run = tmp_path / "cli-run"
    args = [
        "--algo",
        "ppo",
        "--env",
        REACH,
        "--seed",
        "3",
        "--timesteps",
        "128",
        "--n-envs",
        "1",
        "--run-dir",
        str(run),
        "--hyperparams",
        "n_steps=64",
        "batch_size=64",
        "n_epochs=1",
        "policy_kwargs={net_arch: [16]}",
        "--eval-freq",
        "64",
        "--eval-episodes",
        "1",
        "--no-progress-bar",
    ]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    done = subprocess.run(
        [sys.executable, "-m", "training.train", *args],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert f"run folder: {run}" in done.stdout
    recorded = shlex.split((run / "command.txt").read_text())
    assert recorded[1:] == ["-m", "training.train", *args]
    assert Path(recorded[0]).name.startswith("python")
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["seed"] == 3
    assert config["hyperparams"]["policy_kwargs"] == {"net_arch": [16]}
    assert (run / "model.zip").is_file()


def test_sac_with_her_trains_and_evaluates(tmp_path):
    """SAC + HerReplayBuffer on the goal view (env_wrapper): tiny run, then evaluate reloads it wrapped."""
    run = train(
        "sac",
        REACH,
        seed=0,
        timesteps=300,
        n_envs=1,
        run_dir=tmp_path / "her",
        vec="native",  # falls back to dummy: the wrapper applies to single envs
        progress_bar=False,
        overrides={
            "env_wrapper": "envs.GoalReachWrapper",
            "policy": "MultiInputPolicy",
            "replay_buffer_class": "HerReplayBuffer",
            "replay_buffer_kwargs": {"n_sampled_goal": 4, "goal_selection_strategy": "future", "copy_info_dict": True},
            "n_steps": 1,  # HerReplayBuffer has no n-step returns
            "learning_starts": 50,
            "buffer_size": 1000,
            "batch_size": 32,
            "policy_kwargs": {"net_arch": [32, 32]},
        },
        eval_freq=150,
        eval_episodes=1,
    )
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["vec"] == "dummy" and config["hyperparams"]["env_wrapper"] == "envs.GoalReachWrapper"
    out = tmp_path / "eval"
    assert evaluate.main(["--run", str(run), "--episodes", "2", "--seed", "10000", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["episodes"] == 2 and 0.0 <= metrics["success_rate"] <= 1.0


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        (
            "env_wrapper",
            "os.system",
            r"env_wrapper 'os.system' is not one of \['envs.GoalReachWrapper', "
            r"'robot_control.ComputedTorqueResidualWrapper', 'robot_control.PlannerResidualWrapper', "
            r"'robot_control.PlannerWaypointWrapper', 'envs.PreviousActionWrapper'\]",
        ),
        ("replay_buffer_class", "Evil", r"replay_buffer_class 'Evil' is not one of \['HerReplayBuffer'\]"),
    ],
)
def test_wrapper_and_buffer_names_are_allow_listed(tmp_path, key, value, message):
    """Names in a config are looked up in an allow-list, never imported."""
    from training.config import ConfigError

    with pytest.raises(ConfigError, match=message):
        train("sac", REACH, timesteps=10, run_dir=tmp_path / "x", progress_bar=False, overrides={key: value})
