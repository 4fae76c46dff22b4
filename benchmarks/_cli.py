"""The command-line options the benchmarks share, defined once."""

from __future__ import annotations

import argparse


def step_parser(doc: str, profiled: str) -> argparse.ArgumentParser:
    """Options of the single-step benchmarks: --steps, --rounds, --seed and --profile (of ``profiled``)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="steps per round and env (default 20000)")
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and of the first reset")
    parser.add_argument("--profile", action="store_true", help=f"also print cProfile's top 15 for {profiled}")
    return parser


def kinematics_parser(doc: str) -> argparse.ArgumentParser:
    """Options of the J_f benchmarks: --n, --repeats, --lesson-n and --seed."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000, help="number of configurations (default 10000)")
    parser.add_argument("--repeats", type=int, default=7, help="repetitions per measurement (default 7)")
    parser.add_argument(
        "--lesson-n",
        type=int,
        default=None,
        help="time the lesson's per-configuration loop on the first LESSON_N configurations only "
        "(default: all of them)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the random configurations")
    return parser


def parse_positive(parser: argparse.ArgumentParser, argv: list[str] | None, *names: str) -> argparse.Namespace:
    """Parse ``argv`` and exit with a usage error naming the values if any of the options ``names`` is < 1."""
    args = parser.parse_args(argv)
    values = [getattr(args, name) for name in names]
    if any((min(v) if isinstance(v, list) else v) < 1 for v in values):
        options = " and ".join(f"--{name.replace('_', '-')}" for name in names)
        parser.error(f"{options} must be ≥ 1, got {' and '.join(str(v) for v in values)}")
    return args
