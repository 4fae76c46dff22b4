"""Benchmark env.step of the family's robots against Pendulum-v1 and MuJoCo's Reacher-v5, all through gym.make.

Run with ``python -m benchmarks.bench_family_step [--steps 20000] [--rounds 5] [--profile]``.
Anchors, timed in the same run: Gymnasium's ``Pendulum-v1`` and MuJoCo's ``Reacher-v5`` (the ``bench`` extra:
``pip install -e ".[bench]"``; without MuJoCo the script says so and times the rest). ``Planar3RPRReach-v0``
is timed too, and the crank-driven ``DeltaReach-v0`` and ``Planar3RRRReach-v0``, so that one run shows every
robot against Pendulum.
Protocol (``bench_env_step``'s): every environment is made with its default wrappers (order enforcing,
passive checker, time limit); actions are drawn in advance from each action space; resets on termination or
truncation are part of the timed loop; 500 warm-up steps; the environments take turns over the rounds, the
order reversed every other round (A B C D, D C B A, …) so that a change of machine load affects them alike;
the median over the rounds is reported in microseconds per step.
Targets: hexapod / Pendulum ≤ 1.3, hexapod / Reacher ≤ 1.0, Planar 3-RPR, Delta and 3-RRR / Pendulum ≤ 1.0.
"""

from __future__ import annotations

import os
import platform
import statistics
import sys

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from benchmarks._cli import parse_positive, step_parser
from benchmarks.bench_env_step import SteppedEnv, profile

HEXAPOD = "StewartGoughReach-v0"
PLANAR = "Planar3RPRReach-v0"
DELTA = "DeltaReach-v0"
RRR = "Planar3RRRReach-v0"
PENDULUM = "Pendulum-v1"
REACHER = "Reacher-v5"
#: (subject, anchor, largest ratio subject / anchor of the median times per step).
TARGETS = (
    (HEXAPOD, PENDULUM, 1.3),
    (HEXAPOD, REACHER, 1.0),
    (PLANAR, PENDULUM, 1.0),
    (DELTA, PENDULUM, 1.0),
    (RRR, PENDULUM, 1.0),
)
WARM_UP_STEPS = 500


def make_reacher(steps: int, seed: int) -> tuple[SteppedEnv | None, str]:
    """``Reacher-v5`` ready to step, or None and the reason it cannot be made (MuJoCo missing)."""
    try:
        import mujoco
    except ImportError as exc:
        return None, f"MuJoCo is not installed ({exc}); install the bench extra: pip install -e '.[bench]'"
    try:
        return SteppedEnv(REACHER, steps, seed), f"mujoco {mujoco.__version__}"
    except (gym.error.DependencyNotInstalled, ImportError, OSError) as exc:
        return None, f"{REACHER} cannot be made with mujoco {mujoco.__version__}: {exc}"


def main(argv: list[str] | None = None) -> None:
    """Time the environments in alternating rounds and print the medians, the ratios and the targets."""
    args = parse_positive(step_parser(__doc__, "the hexapod"), argv, "steps", "rounds")

    steppers = [SteppedEnv(env_id, args.steps, args.seed) for env_id in (HEXAPOD, PLANAR, DELTA, RRR, PENDULUM)]
    reacher, reacher_note = make_reacher(args.steps, args.seed)
    if reacher is not None:
        steppers.append(reacher)
    warm_up = min(args.steps, WARM_UP_STEPS)
    for stepper in steppers:
        for action in stepper.actions[:warm_up]:
            _, _, terminated, truncated, _ = stepper.env.step(action)
            if terminated or truncated:
                stepper.env.reset()

    samples: dict[str, list[float]] = {stepper.env_id: [] for stepper in steppers}
    for round_index in range(args.rounds):
        order = steppers if round_index % 2 == 0 else steppers[::-1]
        for stepper in order:
            samples[stepper.env_id].append(stepper.run() / args.steps * 1e6)
    median = {env_id: statistics.median(values) for env_id, values in samples.items()}

    processor = platform.processor() or platform.machine()
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print("env.step through gym.make (default wrappers), random actions drawn in advance, resets counted in")
    print(f"machine: {processor}, cpu_count {os.cpu_count()} (usable {affinity}), {platform.system()}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, gymnasium {gym.__version__}")
    print(f"{REACHER}: {reacher_note}")
    print(f"steps per round: {args.steps}, rounds: {args.rounds} (alternating order), warm-up {warm_up} steps")
    print()
    print(f"{'env':<22}{'median us/step':>16}{'min':>10}{'max':>10}{'resets':>9}")
    for stepper in steppers:
        values = samples[stepper.env_id]
        print(
            f"{stepper.env_id:<22}{median[stepper.env_id]:>16.2f}{min(values):>10.2f}{max(values):>10.2f}"
            f"{stepper.resets:>9d}"
        )
    print()
    for subject, anchor, target in TARGETS:
        if anchor not in median:
            print(f"ratio {subject} / {anchor}: not measured ({REACHER} unavailable, see above)")
            continue
        ratio = median[subject] / median[anchor]
        verdict = "PASS" if ratio <= target else "MISS"
        print(f"ratio {subject} / {anchor}: {ratio:.2f}   (target <= {target:.1f}: {verdict})")

    if args.profile:
        profile(steppers[0])
    for stepper in steppers:
        stepper.env.close()


if __name__ == "__main__":
    main()
