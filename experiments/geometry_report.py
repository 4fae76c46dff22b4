r"""One policy for a family of geometries against one trained on the nominal geometry, on geometries never seen.

Usage::

    python -m experiments.geometry_report --family runs/family-s0 --nominal runs/nominal-s0 \\
        --env Planar3RPRReachFamily-v0 --out docs/results/geometry_family

Scores, on ``--episodes`` episodes from reset seed ``--seed`` (each episode draws its own robot of the family: held-out
geometries, none of them met in training), standard and hard targets (the family's hard targets are ill-conditioned
ones, 2 k_hard ≤ k < k_safe: detour tasks are too rare on some robots of the family to draw them):

* the ``--family`` run (trained on the family, its geometry's codes in its observation);
* the ``--nominal`` run (trained on the nominal geometry alone, ``geometry_variation: 0``): on the same robots it
  sees the same observation without the codes (computed with each robot's own model, as the family's is), and on
  the nominal robot itself for reference.

Writes each evaluation's folder (``training.evaluate``'s files) and ``table.md`` (every figure from their
``metrics.json``). An evaluation whose ``metrics.json`` exists is kept (its run is not loaded); with
``--from-metrics`` a missing one is an error, so the table is only written again from the stored files.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym

import envs  # noqa: F401  (registers the ids)
from experiments import family_report
from training import evaluate

__all__ = ["main", "without_codes"]


def without_codes(env: gym.Env) -> gym.Env:
    """``env`` with the codes of its robot's geometry cut from the end of the observation (for a nominal policy)."""
    d = env.unwrapped.params.robot.base.shape[1]
    space = env.observation_space
    cut = gym.spaces.Box(space.low[: -2 * d * d], space.high[: -2 * d * d], dtype=space.dtype)
    return gym.wrappers.TransformObservation(env, lambda obs: obs[: -2 * d * d], cut)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m experiments.geometry_report", description=__doc__.splitlines()[0])
    parser.add_argument("--family", nargs="+", required=True, help="run folders trained on the family")
    parser.add_argument("--nominal", nargs="+", required=True, help="run folders trained on the nominal geometry")
    parser.add_argument("--env", default="Planar3RPRReachFamily-v0")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5000)
    parser.add_argument("--out", required=True)
    parser.add_argument(
        "--from-metrics", action="store_true", help="evaluate nothing: write table.md from the stored metrics.json"
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    groups: dict[str, list[dict]] = {}

    def score(label: str, folder: Path, run: str, make_env: Callable[[], gym.Env], targets: str) -> None:
        def evaluate_into(folder: Path) -> None:
            agent, env = evaluate.load_run(run)[0], make_env()
            records = evaluate.evaluate_agent(agent, env, args.episodes, args.seed, targets)
            evaluate.write_outputs(folder, label, env, records, None)

        try:
            metrics = evaluate.cached_metrics(folder, None if args.from_metrics else evaluate_into)
        except evaluate.EvaluationError as exc:
            parser.error(f"--from-metrics: {exc}")
        groups.setdefault(label, []).append(metrics)

    for targets in ("standard", "hard"):
        for run in args.family:
            label = f"family policy, unseen geometries @ {targets}"
            folder = out / f"{Path(run).name}-family-{targets}"
            score(label, folder, run, lambda: gym.make(args.env), targets)
        for run in args.nominal:
            label = f"nominal policy, unseen geometries @ {targets}"
            folder = out / f"{Path(run).name}-family-{targets}"
            score(label, folder, run, lambda: without_codes(gym.make(args.env)), targets)
            label = f"nominal policy, nominal geometry @ {targets}"
            folder = out / f"{Path(run).name}-nominal-{targets}"
            score(label, folder, run, lambda: gym.make(args.env, geometry_variation=0.0), targets)
    variation = gym.make(args.env).unwrapped.params.geometry_variation
    text = (
        f"# One policy for a family of geometries\n\n{args.env} (base and platform scaled and sheared by up to "
        f"±{100 * variation:.0f} %), {args.episodes} episodes from reset seed {args.seed}, each on its own robot; "
        "hard = ill-conditioned targets (2 k_hard ≤ k < k_safe). "
        f"Runs: family {', '.join(Path(r).name for r in args.family)}; nominal "
        f"{', '.join(Path(r).name for r in args.nominal)}.\n\n" + family_report.table(groups)
    )
    (out / "table.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
