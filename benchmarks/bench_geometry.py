"""Benchmark per-robot geometry in the compiled step: N robots each with its own constants against one shared set.

Run with ``python -m benchmarks.bench_geometry [--envs ...] [--n 16384] [--rounds 7] [--steps 20]``.
Anchor, timed in the same run: the same step (``envs.physics.step``, fused transition and evaluation) of the same
N robots from the same state with one geometry for all (``plant`` None: the (1, C_SIZE) constants). The timed run
gives every robot its own row of constants (``FamilyState.plant``, (N, C_SIZE): the robots as built, drawn with
``geometry_tolerance=1 mm``). Each round steps both from the state of a fresh reset for ``--steps`` steps of
random actions (drawn in advance, the same for both), the two taking turns (per-robot, shared, shared, per-robot,
…); the median env-steps per second of each is reported with the ratio per-robot / shared.
Target: ≥ 0.80 at N = 16384.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from envs import physics

DEFAULT_ENVS = ("Planar3RPRReach-v0", "StewartGoughReach-v0", "DeltaReach-v0")
TARGET_RATIO = 0.80


def _rate(params, state, actions, buffers) -> float:
    clock = time.perf_counter()
    for t, action in enumerate(actions):
        state, *_ = physics.step(params, state, action, False, buffers[t % 2], validate=False)
    return len(actions) * len(action) / (time.perf_counter() - clock)


def main(argv: list[str] | None = None) -> None:
    """Time the per-robot and the shared-geometry step and print the ratio against the target."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=list(DEFAULT_ENVS))
    parser.add_argument("--n", type=int, default=16384)
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args(argv)
    print(f"N = {args.n}, {args.rounds} rounds of {args.steps} steps; median env-steps/s")
    print("| env | shared geometry [M/s] | per-robot geometry [M/s] | ratio | target ≥ |")
    print("|---|---|---|---|---|")
    for env_id in args.envs:
        vec = gym.make_vec(env_id, num_envs=args.n, vectorization_mode="vector_entry_point", geometry_tolerance=0.001)
        vec.reset(seed=0)
        base = vec.unwrapped
        params, start = base.params, base.state
        shared = start._replace(plant=None)
        actions = np.random.default_rng(0).uniform(-1, 1, size=(args.steps, args.n, params.robot.n_actuators))
        buffers = [physics.StepBuffers(params, args.n, False) for _ in range(2)]
        _rate(params, start, actions[:2], buffers)  # compile and warm up both signatures
        _rate(params, shared, actions[:2], buffers)
        rates: dict[str, list[float]] = {"per-robot": [], "shared": []}
        for r in range(args.rounds):
            order = ("per-robot", "shared") if r % 2 == 0 else ("shared", "per-robot")
            for name in order:
                rates[name].append(_rate(params, start if name == "per-robot" else shared, actions, buffers))
        own, one = statistics.median(rates["per-robot"]), statistics.median(rates["shared"])
        print(f"| {env_id} | {one / 1e6:.3f} | {own / 1e6:.3f} | {own / one:.2f} | {TARGET_RATIO:.2f} |")
        vec.close()


if __name__ == "__main__":
    main()
