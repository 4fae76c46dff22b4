"""PPO fine-tuning of a distilled run on its env's own reward (``training.distill --from-run``)."""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from training.config import resolve_env_wrapper
from training.distill_config import FinetuneConfig

__all__ = ["finetune"]


def finetune(source: Path, run_dir: Path, config: FinetuneConfig, log=print) -> dict[str, Any]:
    """Fine-tune the distilled run ``source`` with PPO on its env's reward; write the run folder ``run_dir``.

    The observation normalisation of ``source`` stays frozen, so the fine-tuned policy reads the observation the
    way the distilled one did. Episodes reset with seeds from ``2_000_000 · (seed + 1)`` on, away from the
    distillation's and the evaluation's seeds.

    Returns:
        The figures written to ``finetune.json`` (wall time, the rollouts' success rate per phase).
    """
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    from training.train import make_training_env

    source_config = yaml.safe_load((source / "config.yml").read_text())
    if not source_config.get("distilled_from"):
        raise ValueError(
            f"--from-run must be a training.distill run folder, got {source} ({source_config.get('algo')})"
        )
    env_id = source_config["env_id"]
    torch.manual_seed(config.seed)
    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    env_kwargs = {**(source_config.get("hyperparams", {}).get("env_kwargs") or {}), **config.reward_kwargs}
    wrapper = resolve_env_wrapper(source_config.get("hyperparams", {}).get("env_wrapper"))
    vec = "native" if wrapper is None else "dummy"  # a wrapper applies to single envs
    venv = make_training_env(env_id, config.n_envs, 2_000_000 * (config.seed + 1), vec, run_dir, env_kwargs, wrapper)
    venv = VecNormalize.load(str(source / "vecnormalize.pkl"), venv)
    venv.training, venv.norm_reward = False, False
    model = PPO.load(
        source / "model.zip",
        env=venv,
        device="cpu",
        seed=config.seed,
        custom_objects={
            "n_steps": config.n_steps,
            "batch_size": config.batch_size,
            "n_epochs": config.n_epochs,
            "learning_rate": config.learning_rate,
            "clip_range": config.clip_range,
            "target_kl": config.target_kl,
            "gamma": config.gamma,
            "gae_lambda": config.gae_lambda,
            "ent_coef": 0.0,
        },
    )
    logger = configure(str(run_dir), ["csv"])  # progress.csv in the run folder, not a temp folder
    model.set_logger(logger)
    policy = model.policy
    with torch.no_grad():
        policy.log_std.fill_(config.log_std)
    actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(), policy.log_std]
    phases = []
    clock = time.perf_counter()
    try:
        for name, steps, frozen in (("critic", config.warmup_steps, True), ("both", config.steps, False)):
            if steps <= 0:
                continue
            for parameter in actor:
                parameter.requires_grad_(not frozen)
            start = time.perf_counter()
            model.learn(steps, reset_num_timesteps=False, progress_bar=False)
            buffer = list(model.ep_info_buffer)
            success = float(np.mean([info.get("is_success", 0.0) for info in buffer])) if buffer else float("nan")
            phases.append({"phase": name, "steps": steps, "seconds": time.perf_counter() - start,
                           "recent_success": success})  # fmt: skip
            log(f"{name}: {steps} steps, recent rollouts {success:.0%} success")
    finally:
        logger.close()  # the CSV file, else left open until garbage collection (a ResourceWarning)
    model.save(run_dir / "model.zip")
    venv.save(str(run_dir / "vecnormalize.pkl"))
    run_config = {**source_config, "finetuned_from": str(source), "finetune": asdict(config)}
    (run_dir / "config.yml").write_text(yaml.safe_dump(run_config, sort_keys=False))
    (run_dir / "command.txt").write_text(" ".join(["python -m training.distill", *sys.argv[1:]]) + "\n")
    result = {"source": str(source), "config": asdict(config), "phases": phases,
              "wall_time_s": time.perf_counter() - clock}  # fmt: skip
    (run_dir / "finetune.json").write_text(json.dumps(result, indent=2))
    venv.close()
    return result
