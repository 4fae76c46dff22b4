"""Benchmark the batched evaluation (``training.evaluate.evaluate_vector``) against one episode at a time.

Run with ``python -m benchmarks.bench_evaluate [--episodes 100] [--rounds 3]``.
Anchor, timed in the same run: ``training.evaluate.evaluate_agent`` on the single env, episode i reset with seed
5000 + i, the same agent. The timed run: ``evaluate_vector`` on the native vector env with one row per episode.
Agents: resolved-rate on the 3-RPR's hard targets (behind the shield, the main job's slowest kind of row before
batching), the shipped PPO policy on the same, and the shipped residual policy over the planner (its wrapper's
vector form). The two take turns; the median wall time of each is reported with the ratio.
Target: the main job (``python -m experiments.demo``) in ≤ 4 minutes on two cores, which this ratio makes possible.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym

import envs
from experiments.demo import PRETRAINED_MIXED_RUN, PRETRAINED_RUN
from training.evaluate import (
    evaluate_agent,
    evaluate_vector,
    load_controller,
    load_run,
    make_vector_env,
    wrap_for_run,
    wrap_vector_for_run,
)

ENV_ID = "Planar3RPRReach-v0"


def main(argv: list[str] | None = None) -> None:
    """Time both evaluations per agent and print the table of ratios."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    shield = 0.05
    probe = gym.make(ENV_ID)
    rows = {
        "resolved-rate + shield": (load_controller("resolved-rate", probe), {}, shield),
        "PPO policy": (*load_run(PRETRAINED_RUN), None),
        "residual over the planner": (*load_run(PRETRAINED_MIXED_RUN), None),
    }
    print(f"{ENV_ID}, hard targets, {args.episodes} episodes, {args.rounds} rounds; median wall time")
    print("| agent | one at a time [s] | batched [s] | speed-up |")
    print("|---|---|---|---|")
    for label, (agent, config, guard) in rows.items():
        times: dict[str, list[float]] = {"single": [], "vector": []}
        for r in range(args.rounds + 1):  # round 0 compiles and warms up
            for name in ("single", "vector") if r % 2 else ("vector", "single"):
                if name == "single":
                    env = gym.make(ENV_ID)
                    env = wrap_for_run(env if guard is None else envs.SingularityShield(env, k_guard=guard), config)
                    clock = time.perf_counter()
                    evaluate_agent(agent, env, args.episodes, 5000, "hard")
                else:
                    venv = wrap_vector_for_run(make_vector_env(ENV_ID, args.episodes, shield=guard), config)
                    clock = time.perf_counter()
                    evaluate_vector(agent, venv, 5000, "hard")
                if r > 0:
                    times[name].append(time.perf_counter() - clock)
        single, vector = statistics.median(times["single"]), statistics.median(times["vector"])
        print(f"| {label} | {single:.2f} | {vector:.2f} | {single / vector:.1f}× |")


if __name__ == "__main__":
    main()
