"""Benchmark the native vector env against SyncVectorEnv of single envs: env-steps per second at N = 1 … 16384.

Run with ``python -m benchmarks.bench_vector_env [--env Planar3RPRReach-v0] [--rounds 3] [--profile]``.
Both vector envs are made with ``gym.make_vec`` (``vector_entry_point`` and ``sync``, default NEXT_STEP
autoreset), reset with the same seed and fed the same random actions (uniform in [−1, 1], drawn in
advance), so they run the same episodes; autoresets are part of the timed steps. At each N the two
take turns over the rounds (native, Sync, Sync, native, …) so that a change of machine load affects
them alike; the median env-steps per second is reported, with the ratio native / Sync (the anchor,
measured in the same run). SyncVectorEnv is run up to N = 1024. The share of the native step spent
starting new episodes (task sampling: one compiled call for all the robots that restart) is measured by
timing those calls.
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
import tracemalloc

import gymnasium as gym
import numba
import numpy as np
from gymnasium.utils import seeding

import envs
from envs.kernels import setup as numba_setup

SIZES = (1, 64, 1024, 16384)
SYNC_MAX_N = 1024
#: Env-steps per timed round: native, Sync (each round takes at least MIN_STEPS vector steps).
NATIVE_BUDGET, SYNC_BUDGET = 65_536, 4_096
MIN_STEPS, MAX_STEPS = 8, 1_000
WARM_UP_STEPS = 2
TARGET_RATIO_AT_1024 = 30.0
TARGET_RATE_AT_16384 = 5_000_000.0


class SteppedVectorEnv:
    """A vector env made and reset once, with pre-generated actions, stepped ``steps`` at a time."""

    def __init__(
        self, env_id: str, mode: str, n: int, steps: int, rounds: int, seed: int, actions: str = "fresh"
    ) -> None:
        """Make, reset and warm up the env and draw all its actions (setup stays out of the timings).

        ``actions``: "fresh" (uniform random actions drawn anew every step) or "constant" (one uniform random
        action per robot, kept for the whole run: a robot driving one way, as a policy heading for its target
        does, ends its episodes more often).
        """
        if actions not in ("fresh", "constant"):
            raise ValueError(f"actions must be 'fresh' or 'constant', got {actions!r}")
        self.mode, self.n, self.steps = mode, n, steps
        self.env = gym.make_vec(env_id, num_envs=n, vectorization_mode=mode)
        total = WARM_UP_STEPS + steps * rounds
        rng = np.random.default_rng(seed)
        shape = (total, n, *self.env.single_action_space.shape)
        if actions == "fresh":
            self.actions = rng.uniform(-1.0, 1.0, size=shape).astype(np.float32)
        else:
            self.actions = np.broadcast_to(rng.uniform(-1.0, 1.0, size=shape[1:]).astype(np.float32), shape)
        self.cursor = 0
        self.ends = 0
        self.starts = 0
        self.sampling_seconds = 0.0
        self.env.reset(seed=seed)
        if mode == "vector_entry_point":
            self._time_task_sampling()
        self.run(WARM_UP_STEPS)
        self.ends, self.starts, self.sampling_seconds = 0, 0, 0.0

    def _time_task_sampling(self) -> None:
        """Accumulate the time the native env spends starting new episodes (an instance-level wrapper)."""
        inner = self.env._start_episodes

        def timed(rows: np.ndarray, options: dict) -> object:
            start = time.perf_counter()
            try:
                return inner(rows, options)
            finally:
                self.sampling_seconds += time.perf_counter() - start
                self.starts += len(rows)

        self.env._start_episodes = timed

    def run(self, steps: int | None = None) -> float:
        """Step through the next ``steps`` pre-generated actions; returns the seconds taken."""
        steps = self.steps if steps is None else steps
        env, actions = self.env, self.actions[self.cursor : self.cursor + steps]
        self.cursor += steps
        ends = 0
        start = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            ends += int(np.count_nonzero(terminated | truncated))
        elapsed = time.perf_counter() - start
        self.ends += ends
        return elapsed


def steps_for(budget: int, n: int) -> int:
    """Vector steps per round for an env-step budget, within [MIN_STEPS, MAX_STEPS]."""
    return int(min(MAX_STEPS, max(MIN_STEPS, round(budget / n))))


def memory_per_robot(env_id: str, n: int, seed: int) -> dict[str, float]:
    """Bytes per robot of the native env at N = n: state arrays, observations, generator, step peak."""
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    env.reset(seed=seed)
    actions = np.zeros((n, *env.single_action_space.shape), dtype=np.float32)
    env.step(actions)
    tracemalloc.start()
    generators = [seeding.np_random(i)[0] for i in range(256)]
    generator_bytes = tracemalloc.get_traced_memory()[0] / len(generators)
    del generators
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    result = env.step(actions)
    current, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    del result
    return {
        "state": env.state_nbytes() / n,
        "observations": 4.0 * env.single_observation_space.shape[0],
        "generator": generator_bytes,
        "step peak": (peak - base) / n,
        "step retained": (current - base) / n,
    }


def profile_native(env_id: str, n: int, steps: int, seed: int, top: int = 20) -> None:
    """Print the ``top`` functions by own time (tottime) of native steps at N = n.

    Two profiles: random actions with autoresets (as timed), then the step alone (no episode ends:
    zero actions inside long episodes), to separate the step's own cost from task sampling.
    """
    stepper = SteppedVectorEnv(env_id, "vector_entry_point", n, steps, 1, seed)
    quiet = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", max_episode_steps=10**9)
    quiet.reset(seed=seed)
    zeros = np.zeros((n, *quiet.single_action_space.shape), dtype=np.float32)
    quiet.step(zeros)
    for title, run in (
        (f"{steps} native steps at N = {n}, random actions, autoresets included", stepper.run),
        (
            f"{steps} native steps at N = {n}, no episode end (the step alone)",
            lambda: [quiet.step(zeros) for _ in range(steps)],
        ),
    ):
        profiler = cProfile.Profile()
        profiler.enable()
        run()
        profiler.disable()
        print(f"\ncProfile of {title} ({env_id}), top {top} by tottime:")
        pstats.Stats(profiler, stream=sys.stdout).strip_dirs().sort_stats("tottime").print_stats(top)


def main(argv: list[str] | None = None) -> None:
    """Time native and Sync vector envs at each N and print the table, the ratios and the targets."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Planar3RPRReach-v0", choices=envs.ENV_IDS, help="env id")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds per N (default 3)")
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="values of N")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and of the first reset")
    parser.add_argument("--profile", action="store_true", help="also profile the native step at the largest N")
    args = parser.parse_args(argv)
    if args.rounds < 1 or min(args.sizes) < 1:
        parser.error(f"--rounds and --sizes must be ≥ 1, got {args.rounds} and {args.sizes}")

    processor = platform.processor() or platform.machine()
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"native vector env vs SyncVectorEnv of gym.make envs, {args.env}, random actions, autoreset included")
    print(f"machine: {processor}, cpu_count {os.cpu_count()} (usable {affinity}), {platform.system()}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, gymnasium {gym.__version__}")
    print(f"numba {numba.__version__}, {numba_setup.THREADS} threads from N = {numba_setup.PARALLEL_MIN_BATCH}")
    print(f"rounds: {args.rounds} (alternating order), median reported; warm-up {WARM_UP_STEPS} steps")
    print()
    header = (
        f"{'N':>6}{'native steps/s':>16}{'Sync steps/s':>14}{'native/Sync':>13}"
        f"{'ends/1k native':>16}{'ends/1k Sync':>14}{'sampling share':>16}{'native w/o sampling':>21}"
    )
    print(header)
    results: dict[int, tuple[float, float | None]] = {}
    for n in args.sizes:
        native = SteppedVectorEnv(
            args.env, "vector_entry_point", n, steps_for(NATIVE_BUDGET, n), args.rounds, args.seed
        )
        runners: list[SteppedVectorEnv] = [native]
        if n <= SYNC_MAX_N:
            runners.append(SteppedVectorEnv(args.env, "sync", n, steps_for(SYNC_BUDGET, n), args.rounds, args.seed))
        rates: dict[str, list[float]] = {r.mode: [] for r in runners}
        native_seconds = 0.0
        for round_index in range(args.rounds):
            order = runners if round_index % 2 == 0 else runners[::-1]
            for runner in order:
                seconds = runner.run()
                rates[runner.mode].append(runner.steps * n / seconds)
                if runner is native:
                    native_seconds += seconds
        native_rate = statistics.median(rates["vector_entry_point"])
        sync_rate = statistics.median(rates["sync"]) if "sync" in rates else None
        results[n] = (native_rate, sync_rate)
        env_steps = native.steps * n * args.rounds
        share = native.sampling_seconds / native_seconds
        without = env_steps / (native_seconds - native.sampling_seconds)
        sync_text = f"{sync_rate:>14,.0f}" if sync_rate else f"{'-':>14}"
        ratio_text = f"{native_rate / sync_rate:>12.1f}x" if sync_rate else f"{'-':>13}"
        sync_ends = (
            f"{1000 * runners[1].ends / (runners[1].steps * n * args.rounds):>14.2f}" if sync_rate else f"{'-':>14}"
        )
        print(
            f"{n:>6}{native_rate:>16,.0f}{sync_text}{ratio_text}"
            f"{1000 * native.ends / env_steps:>16.2f}{sync_ends}{share:>15.0%} {without:>20,.0f}"
        )
        for runner in runners:
            runner.env.close()
    print()
    if 1024 in results and results[1024][1]:
        ratio = results[1024][0] / results[1024][1]
        verdict = "PASS" if ratio >= TARGET_RATIO_AT_1024 else "MISS"
        print(f"target native/Sync >= {TARGET_RATIO_AT_1024:.0f}x at N = 1024: {ratio:.1f}x  {verdict}")
    if 16384 in results:
        rate = results[16384][0]
        verdict = "PASS" if rate >= TARGET_RATE_AT_16384 else "MISS"
        print(f"target >= {TARGET_RATE_AT_16384:,.0f} env-steps/s at N = 16384: {rate:,.0f}  {verdict}")

    n_mem = max(args.sizes)
    memory = memory_per_robot(args.env, n_mem, args.seed)
    print(f"\nmemory per robot at N = {n_mem} [bytes]: " + ", ".join(f"{k} {v:,.0f}" for k, v in memory.items()))

    if args.profile:
        n_profile = max(args.sizes)
        profile_native(args.env, n_profile, steps_for(NATIVE_BUDGET, n_profile), args.seed)


if __name__ == "__main__":
    main()
