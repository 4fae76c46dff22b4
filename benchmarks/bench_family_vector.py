"""Benchmark the native vector envs of every robot: env-steps per second, and the cost of an episode start.

Run with ``python -m benchmarks.bench_family_vector [--envs ...] [--sizes 1024 16384] [--rounds 5]``.
Anchor, timed in the same run: ``SyncVectorEnv`` of ``gym.make`` single envs of the same id at N = 1024.
Protocol (``bench_vector_env``'s, whose ``SteppedVectorEnv`` and step budgets it reuses): both vector envs
are made with ``gym.make_vec`` (``vector_entry_point`` and ``sync``, NEXT_STEP autoreset), reset with the same
seed and fed random actions (uniform in [−1, 1], drawn in advance: fresh every step, or with ``--actions constant``
one per robot for the whole run, which ends episodes more often); autoresets are part of the timed steps;
2 warm-up steps; at each N the native env and the anchor take turns over the rounds (native, Sync, Sync,
native, …) and the median env-steps per second of each is reported, with the ratio native / Sync. The
"sampling share" is the part of the native step spent starting new episodes, "µs/start" that time per started
episode (task drawn and certified, state at t = 0; wall time on every core).
Targets at N = 16384, fresh actions: ≥ 0.65 M env-steps/s for the hexapod, ≥ 2.5 M for the planar 3-RPR, ≥ 2.2 M
for the Delta, the 3-RRR and the 3-PRR; with constant actions, ≥ 70 % of those.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys

import gymnasium as gym
import numba
import numpy as np

import envs
from benchmarks.bench_vector_env import NATIVE_BUDGET, SYNC_BUDGET, WARM_UP_STEPS, SteppedVectorEnv, steps_for
from envs.kernels import setup as numba_setup

HEXAPOD = "StewartGoughReach-v0"
PLANAR = "Planar3RPRReach-v0"
DEFAULT_ENVS = (HEXAPOD, PLANAR, "DeltaReach-v0", "Planar3RRRReach-v0", "Planar3PRRReach-v0")
SIZES = (1024, 16384)
ANCHOR_N = 1024
TARGET_N = 16384
#: Least native env-steps per second at N = TARGET_N, by env id.
TARGET_RATES = {
    HEXAPOD: 650_000.0,
    PLANAR: 2_500_000.0,
    "DeltaReach-v0": 2_200_000.0,
    "Planar3RRRReach-v0": 2_200_000.0,
    "Planar3PRRReach-v0": 2_200_000.0,
}
#: Share of the fresh-action target a run with constant actions must reach.
CONSTANT_SHARE = 0.7


def main(argv: list[str] | None = None) -> None:
    """Time the native vector envs next to their Sync anchor and print the table, the ratios and the targets."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--envs",
        nargs="+",
        default=list(DEFAULT_ENVS),
        choices=envs.ENV_IDS,
        metavar="ID",
        help=f"env ids, from {', '.join(envs.ENV_IDS)} (default {' '.join(DEFAULT_ENVS)})",
    )
    parser.add_argument(
        "--actions",
        choices=("fresh", "constant"),
        default="fresh",
        help="random actions: fresh every step or one per robot",
    )
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="values of N (default 1024 16384)")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds per N (default 5)")
    parser.add_argument("--anchor-n", type=int, default=ANCHOR_N, help="N of the SyncVectorEnv anchor (default 1024)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and of the first reset")
    args = parser.parse_args(argv)
    if args.rounds < 1 or min(args.sizes) < 1 or args.anchor_n < 1:
        parser.error(
            f"--rounds, --sizes and --anchor-n must be ≥ 1, got {args.rounds}, {args.sizes} and {args.anchor_n}"
        )

    processor = platform.processor() or platform.machine()
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(
        f"native vector env vs SyncVectorEnv of gym.make envs at N = {args.anchor_n}, {args.actions} random actions, "
        "autoreset included"
    )
    print(f"machine: {processor}, cpu_count {os.cpu_count()} (usable {affinity}), {platform.system()}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, gymnasium {gym.__version__}")
    print(f"numba {numba.__version__}, {numba_setup.THREADS} threads from N = {numba_setup.PARALLEL_MIN_BATCH}")
    print(f"rounds: {args.rounds} (alternating order), median reported; warm-up {WARM_UP_STEPS} steps")
    print()
    sync_label = f"Sync@{args.anchor_n} steps/s"
    print(
        f"{'env':<22}{'N':>6}{'native steps/s':>16}{sync_label:>20}{'native/Sync':>13}"
        f"{'ends/1k native':>16}{'sampling share':>16}{'µs/start':>10}"
    )
    results: dict[tuple[str, int], float] = {}
    for env_id in args.envs:
        anchor = SteppedVectorEnv(
            env_id,
            "sync",
            args.anchor_n,
            steps_for(SYNC_BUDGET, args.anchor_n),
            args.rounds * len(args.sizes),
            args.seed,
            args.actions,
        )
        for n in args.sizes:
            native = SteppedVectorEnv(
                env_id, "vector_entry_point", n, steps_for(NATIVE_BUDGET, n), args.rounds, args.seed, args.actions
            )
            runners = (native, anchor)
            rates: dict[str, list[float]] = {runner.mode: [] for runner in runners}
            native_seconds = 0.0
            for round_index in range(args.rounds):
                for runner in runners if round_index % 2 == 0 else runners[::-1]:
                    seconds = runner.run()
                    rates[runner.mode].append(runner.steps * runner.n / seconds)
                    if runner is native:
                        native_seconds += seconds
            native_rate = statistics.median(rates["vector_entry_point"])
            sync_rate = statistics.median(rates["sync"])
            results[env_id, n] = native_rate
            env_steps = native.steps * n * args.rounds
            print(
                f"{env_id:<22}{n:>6}{native_rate:>16,.0f}{sync_rate:>20,.0f}{native_rate / sync_rate:>12.1f}x"
                f"{1000 * native.ends / env_steps:>16.2f}{native.sampling_seconds / native_seconds:>16.0%}"
                f"{1e6 * native.sampling_seconds / max(native.starts, 1):>10.2f}"
            )
            native.env.close()
        anchor.env.close()
    print()
    for env_id in args.envs:
        if (env_id, TARGET_N) in results and env_id in TARGET_RATES:
            rate = results[env_id, TARGET_N]
            target = TARGET_RATES[env_id] * (CONSTANT_SHARE if args.actions == "constant" else 1.0)
            verdict = "PASS" if rate >= target else "MISS"
            print(
                f"target {env_id} ({args.actions} actions) >= {target:,.0f} env-steps/s at N = {TARGET_N}: "
                f"{rate:,.0f}  {verdict}"
            )


if __name__ == "__main__":
    main()
