"""Benchmark env.step of Planar3RPRReach-v0 against Gymnasium's Pendulum-v1, both through gym.make.

Run with ``python -m benchmarks.bench_env_step [--steps 20000] [--rounds 5] [--profile]``. Both
environments are made with their default wrappers (order enforcing, passive checker, time limit);
actions are drawn in advance from each action space; resets on termination or truncation are part of
the timed loop. The two take turns over the rounds (A B, B A, A B, …) so that a change of machine load
affects them alike; the median over the rounds is reported in microseconds per step.
"""

from __future__ import annotations

import cProfile
import os
import platform
import pstats
import statistics
import sys
import time

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from benchmarks._cli import parse_positive, step_parser

OURS = "Planar3RPRReach-v0"
REFERENCE = "Pendulum-v1"


class SteppedEnv:
    """An environment made once, with pre-generated actions, that can run ``steps`` steps on demand."""

    def __init__(self, env_id: str, steps: int, seed: int) -> None:
        """Make the env, reset it and draw its actions (setup stays out of the timings)."""
        self.env_id = env_id
        self.env = gym.make(env_id)
        self.env.action_space.seed(seed)
        self.actions = [self.env.action_space.sample() for _ in range(steps)]
        self.env.reset(seed=seed)
        self.resets = 0

    def run(self) -> float:
        """Step through every pre-generated action (resetting at episode ends); returns seconds taken."""
        env, resets = self.env, 0
        start = time.perf_counter()
        for action in self.actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
                resets += 1
        elapsed = time.perf_counter() - start
        self.resets += resets
        return elapsed


def profile(stepper: SteppedEnv, top: int = 15) -> None:
    """Print the ``top`` functions by own time (tottime) of one run of ``stepper``."""
    profiler = cProfile.Profile()
    profiler.enable()
    stepper.run()
    profiler.disable()
    print(f"\ncProfile of {len(stepper.actions)} steps of {stepper.env_id}, top {top} by tottime:")
    pstats.Stats(profiler, stream=sys.stdout).strip_dirs().sort_stats("tottime").print_stats(top)


def main(argv: list[str] | None = None) -> None:
    """Time both environments in alternating rounds and print the medians and their ratio."""
    args = parse_positive(step_parser(__doc__, "our env"), argv, "steps", "rounds")

    ours, reference = SteppedEnv(OURS, args.steps, args.seed), SteppedEnv(REFERENCE, args.steps, args.seed)
    warm_up = min(args.steps, 500)
    for stepper in (ours, reference):
        for action in stepper.actions[:warm_up]:
            _, _, terminated, truncated, _ = stepper.env.step(action)
            if terminated or truncated:
                stepper.env.reset()

    samples: dict[str, list[float]] = {OURS: [], REFERENCE: []}
    for round_index in range(args.rounds):
        order = (ours, reference) if round_index % 2 == 0 else (reference, ours)
        for stepper in order:
            samples[stepper.env_id].append(stepper.run() / args.steps * 1e6)
    median = {env_id: statistics.median(values) for env_id, values in samples.items()}
    ratio = median[OURS] / median[REFERENCE]

    processor = platform.processor() or platform.machine()
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print("env.step through gym.make (default wrappers), random actions drawn in advance, resets counted in")
    print(f"machine: {processor}, cpu_count {os.cpu_count()} (usable {affinity}), {platform.system()}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, gymnasium {gym.__version__}")
    print(f"steps per round: {args.steps}, rounds: {args.rounds} (alternating order), warm-up {warm_up} steps")
    print()
    print(f"{'env':<22}{'median us/step':>16}{'min':>10}{'max':>10}{'resets':>9}")
    for stepper in (ours, reference):
        values = samples[stepper.env_id]
        print(
            f"{stepper.env_id:<22}{median[stepper.env_id]:>16.2f}{min(values):>10.2f}{max(values):>10.2f}"
            f"{stepper.resets:>9d}"
        )
    print()
    verdict = "ok" if ratio <= 1.0 else "ABOVE TARGET"
    print(f"ratio {OURS} / {REFERENCE}: {ratio:.2f}   (target <= 1.0: {verdict})")

    if args.profile:
        profile(ours)
    for stepper in (ours, reference):
        stepper.env.close()


if __name__ == "__main__":
    main()
