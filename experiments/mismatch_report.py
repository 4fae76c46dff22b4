r"""Agents on robots built off their drawings: success, final error and singularities against the tolerance.

Usage::

    python -m experiments.mismatch_report --env Planar3RPRReach-v0 \\
        --run training/pretrained/ppo-Planar3RPRReach-v0 --tolerances 0 0.5 1 2 4 8 \\
        --out docs/results/mismatch_planar3rpr

Evaluates (``training.evaluate``, ``--episodes`` from reset seed ``--seed``) resolved-rate control, singularity-aware
control and each ``--run`` on the env with ``geometry_tolerance`` = each of ``--tolerances`` [mm] (each episode's
robot drawn within ± that of the nominal one, which every agent assumes: ``envs.hardware``) and, unless
``--observation-source pose``, encoder observations (the pose estimated from noisy strokes by the nominal forward
kinematics). The same reset seeds draw the same tasks and the same unit perturbations at every tolerance. Writes
each evaluation's folder, ``table.md`` (every figure from their ``metrics.json``) and ``mismatch.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import envs  # noqa: F401  (registers the ids)
from training import evaluate

__all__ = ["main", "table"]

CONTROLLERS = ("resolved-rate", "singularity-aware")


def _agents(runs: list[str]) -> dict[str, list[str]]:
    agents = {name: ["--controller", name] for name in CONTROLLERS}
    for run in runs:
        agents[Path(run).name] = ["--run", run]
    return agents


def table(cells: dict[str, dict[float, dict]]) -> str:
    """A Markdown table: one row per agent and tolerance, from ``metrics.json`` contents (agent → mm → metrics)."""
    lines = [
        "| agent | tolerance [mm] | success | final pos. error [mm] (median / mean ± std) "
        "| final orient. error [°] (median) | singularity terminations | min k (mean) |",
        "|---|---|---|---|---|---|---|",
    ]
    for agent, by_tolerance in cells.items():
        for mm, m in sorted(by_tolerance.items()):
            p = m["final_position_error_mm"]
            lines.append(
                f"| {agent} | {mm:g} | {100 * m['success_rate']:.0f} % | {p['median']:.2f} / {p['mean']:.2f} ± "
                f"{p['std']:.2f} | {m['final_orientation_error_deg']['median']:.2f} "
                f"| {m['singularity_terminations']} / {m['episodes']} | {m['min_inverse_condition']['mean']:.3f} |"
            )
    return "\n".join(lines) + "\n"


def _figure(cells: dict[str, dict[float, dict]], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for agent, by_tolerance in cells.items():
        mm = sorted(by_tolerance)
        metrics = [by_tolerance[t] for t in mm]
        axes[0].plot(mm, [100 * m["success_rate"] for m in metrics], "o-", label=agent)
        axes[1].plot(mm, [m["final_position_error_mm"]["median"] for m in metrics], "o-", label=agent)
        axes[2].plot(mm, [m["singularity_terminations"] for m in metrics], "o-", label=agent)
    for ax, label in zip(axes, ("success [%]", "final position error [mm] (median)", "singularity terminations")):
        ax.set_xlabel("geometry tolerance ± [mm]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m experiments.mismatch_report", description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, help="the Reach id to evaluate on")
    parser.add_argument("--run", action="append", default=[], help="a run folder to evaluate too (repeatable)")
    parser.add_argument("--tolerances", type=float, nargs="+", default=[0, 0.5, 1, 2, 4, 8], help="[mm]")
    parser.add_argument("--observation-source", default="encoders", choices=("pose", "encoders"))
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5000)
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cells: dict[str, dict[float, dict]] = {}
    for agent, source in _agents(args.run).items():
        for mm in args.tolerances:
            kwargs = [f"geometry_tolerance:{mm / 1000.0!r}", f"observation_source:{args.observation_source}"]
            common = ["--env", args.env, "--episodes", str(args.episodes), "--seed", str(args.seed)]
            argv = [*source, *common, "--env-kwargs", *kwargs]
            cells.setdefault(agent, {})[mm] = evaluate.cached_metrics(
                out / f"{agent}-{mm:g}mm", lambda folder, argv=argv: evaluate.main([*argv, "--out", str(folder)])
            )
    text = (
        f"{args.env}, {args.episodes} episodes from reset seed {args.seed}, observations from "
        f"{'the encoders' if args.observation_source == 'encoders' else 'the true pose'}.\n\n" + table(cells)
    )
    (out / "table.md").write_text(text)
    _figure(cells, f"{args.env}: robots built within ± tolerance of the nominal geometry", out / "mismatch.png")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
