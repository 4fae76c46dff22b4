"""Benchmark SB3 PPO training throughput: the native vector env adapter against DummyVecEnv of single envs.

Run with ``python -m benchmarks.bench_sb3_ppo [--timesteps 32768] [--n-envs 64] [--rounds 1] [--profile]``.
Both runs use the shipped hyperparameters of ``training/ppo.yml`` for the env (VecNormalize included) with a
fixed budget of env steps and ``n_envs`` environments, built by ``training.train.make_training_env`` with
``vec="native"`` (adapter + VecMonitor) or ``vec="dummy"`` (DummyVecEnv of Monitor-wrapped ``gym.make``
envs), one torch thread, on the CPU. Throughput is env steps per wall-second of ``model.learn``; the time
inside ``collect_rollouts`` (stepping the envs and the policy's forward passes) and inside ``train``
(gradient updates) is measured by wrapping those two methods with a timer. With several rounds the two
take turns (native, dummy, dummy, native, …) and the medians are reported; the ratio uses the dummy run
of the same invocation as its anchor.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import platform
import pstats
import statistics
import sys
import time
from typing import Any

import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

import envs
from training.config import load_hyperparams, resolve_policy_kwargs, resolve_schedules
from training.train import make_training_env

#: Run keys of an entry of ppo.yml (not PPO arguments).
_RUN_KEYS = ("n_timesteps", "n_envs", "policy", "normalize", "eval_freq", "n_eval_episodes", "env_kwargs")


def build_model(env_id: str, vec: str, n_envs: int, seed: int) -> PPO:
    """PPO with the shipped hyperparameters of ``env_id`` on a ``vec`` training env of ``n_envs`` envs."""
    config = load_hyperparams("ppo", env_id)
    normalize = config.get("normalize", False)
    env_kwargs = config.get("env_kwargs") or {}
    policy = config.get("policy", "MlpPolicy")
    hyper = {key: value for key, value in config.items() if key not in _RUN_KEYS}
    if "policy_kwargs" in hyper:
        hyper["policy_kwargs"] = resolve_policy_kwargs(hyper["policy_kwargs"])
    hyper = resolve_schedules(hyper)
    venv = make_training_env(env_id, n_envs, seed, vec, None, env_kwargs)
    if normalize:
        venv = VecNormalize(venv, gamma=hyper.get("gamma", 0.99), **(normalize if isinstance(normalize, dict) else {}))
    return PPO(policy, venv, seed=seed, verbose=0, device="cpu", **hyper)


def timed_learn(model: PPO, timesteps: int) -> dict[str, float]:
    """Run ``model.learn`` and return its wall time and the time spent in collect_rollouts and train [s]."""
    spent = {"collect_rollouts": 0.0, "train": 0.0}

    def timer(name: str, method: Any) -> Any:
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return method(*args, **kwargs)
            finally:
                spent[name] += time.perf_counter() - start

        return wrapped

    model.collect_rollouts = timer("collect_rollouts", model.collect_rollouts)
    model.train = timer("train", model.train)
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps)
    spent["learn"] = time.perf_counter() - start
    spent["steps"] = float(model.num_timesteps)
    del model.collect_rollouts, model.train
    return spent


def main(argv: list[str] | None = None) -> None:
    """Time PPO's learn with both vectorisations and print throughput, ratio and time shares."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Planar3RPRReach-v0", choices=envs.ENV_IDS, help="env id")
    parser.add_argument("--timesteps", type=int, default=32_768, help="env steps per learn (default 32768)")
    parser.add_argument("--n-envs", type=int, default=64, help="environments (default 64)")
    parser.add_argument("--rounds", type=int, default=1, help="alternating rounds (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the envs and the networks")
    parser.add_argument("--profile", action="store_true", help="also profile one native learn (cProfile)")
    args = parser.parse_args(argv)
    if args.timesteps < 1 or args.n_envs < 1 or args.rounds < 1:
        parser.error("--timesteps, --n-envs and --rounds must be ≥ 1")

    torch.set_num_threads(1)
    config = load_hyperparams("ppo", args.env)
    processor = platform.processor() or platform.machine()
    print(f"SB3 PPO learn on {args.env}: native adapter vs DummyVecEnv, {args.timesteps} env steps, {args.n_envs} envs")
    print(f"machine: {processor}, cpu_count {os.cpu_count()}, {platform.system()}; torch threads 1, device cpu")
    print(
        f"python {sys.version.split()[0]}, numpy {np.__version__}, torch {torch.__version__}, "
        f"stable-baselines3 {stable_baselines3.__version__}"
    )
    shown = {k: config[k] for k in ("n_steps", "batch_size", "n_epochs", "normalize", "policy_kwargs") if k in config}
    print(f"hyperparameters (training/ppo.yml): {shown}; rounds {args.rounds} (alternating order)")
    print()

    samples: dict[str, list[dict[str, float]]] = {"native": [], "dummy": []}
    for round_index in range(args.rounds):
        order = ("native", "dummy") if round_index % 2 == 0 else ("dummy", "native")
        for vec in order:
            model = build_model(args.env, vec, args.n_envs, args.seed)
            samples[vec].append(timed_learn(model, args.timesteps))
            model.get_env().close()

    def median(vec: str, key: str) -> float:
        return statistics.median(s[key] for s in samples[vec])

    print(f"{'vec':<8}{'steps/s of learn':>18}{'learn [s]':>11}{'collect share':>15}{'train share':>13}{'other':>8}")
    rate = {}
    for vec in ("native", "dummy"):
        learn, collect, train = median(vec, "learn"), median(vec, "collect_rollouts"), median(vec, "train")
        rate[vec] = median(vec, "steps") / learn
        other = 1.0 - (collect + train) / learn
        print(f"{vec:<8}{rate[vec]:>18,.0f}{learn:>11.1f}{collect / learn:>15.0%}{train / learn:>13.0%}{other:>8.0%}")
    print()
    print(f"ratio native / dummy (steps per second of learn): {rate['native'] / rate['dummy']:.2f}x")
    for vec in ("native", "dummy"):
        collect_rate = median(vec, "steps") / median(vec, "collect_rollouts")
        print(f"{vec}: env steps per second inside collect_rollouts {collect_rate:,.0f}")

    if args.profile:
        model = build_model(args.env, "native", args.n_envs, args.seed)
        profiler = cProfile.Profile()
        profiler.enable()
        model.learn(total_timesteps=args.timesteps)
        profiler.disable()
        print(f"\ncProfile of one native learn ({args.timesteps} steps), top 25 by tottime:")
        pstats.Stats(profiler, stream=sys.stdout).strip_dirs().sort_stats("tottime").print_stats(25)
        model.get_env().close()


if __name__ == "__main__":
    main()
