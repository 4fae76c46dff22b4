"""Fixtures shared by the training tests: run folders built by hand (no learning) and environment factories."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import pytest
import yaml

import envs  # noqa: F401  (registers the ids)
from training.config import ALGORITHMS

#: The env every run- and controller-level test uses unless it says otherwise.
REACH = "Planar3RPRReach-v0"


@pytest.fixture(scope="session", autouse=True)
def one_torch_thread() -> None:
    """Run torch on one thread: with two xdist workers on two cores, more threads make policy inference ~10× slower."""
    import torch

    torch.set_num_threads(1)


def write_run_folder(run: Path, algo: str, env_id: str = REACH, normalize: bool = True) -> Path:
    """Write a run folder with the layout of ``training.train`` holding an untrained (randomly initialised) model.

    Args:
        run: Folder to create.
        algo: "ppo", "sac" or "td3".
        env_id: Env the model is built for (sets its observation shape).
        normalize: Whether to save VecNormalize statistics and record ``normalize: true``.

    Returns:
        ``run``.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    run.mkdir(parents=True, exist_ok=True)
    venv = DummyVecEnv([lambda: gym.make(env_id)])
    if normalize:
        venv = VecNormalize(venv)
        venv.save(str(run / "vecnormalize.pkl"))
    extra = {"n_steps": 64, "batch_size": 64} if algo == "ppo" else {"buffer_size": 100}
    model = ALGORITHMS[algo]("MlpPolicy", venv, seed=0, device="cpu", policy_kwargs={"net_arch": [16]}, **extra)
    model.save(run / "model.zip")
    venv.close()
    config = {"algo": algo, "env_id": env_id, "seed": 0, "hyperparams": {"normalize": normalize}}
    (run / "config.yml").write_text(yaml.safe_dump(config, sort_keys=False))
    return run


@pytest.fixture
def make_run_folder(tmp_path: Path) -> Callable[..., Path]:
    """Factory of hand-built run folders under ``tmp_path`` (see ``write_run_folder``)."""

    def _make(algo: str = "ppo", env_id: str = REACH, normalize: bool = True, name: str | None = None) -> Path:
        return write_run_folder(tmp_path / (name or f"{algo}-run"), algo, env_id, normalize)

    return _make
