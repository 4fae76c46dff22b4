"""Headless evaluation of a trained run or a classical controller on fixed-seed episodes.

Usage::

    python -m training.evaluate --run DIR | --controller resolved-rate|singularity-aware|planner
                                [--env ID] [--episodes 100] [--seed 0] [--targets standard|hard]
                                [--video] [--out DIR] [--model final|best] [--planner auto|ompl|grid]
                                [--env-kwargs KEY:VALUE ...]

Without ``--video`` every episode runs at once on the id's native vector env (``evaluate_vector``); with it, one
after the other on the single env (``evaluate_agent``), filmed. Writes ``metrics.json`` (aggregates),
``episodes.csv`` (one row per episode), ``trajectories.png`` (paths over the inverse-condition-number map),
``condition_number.png`` (k over time) and, with ``--video``, ``episodes.gif``; prints the metrics as a table.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs
from robot_control.controllers import CONTROLLERS
from training.config import ConfigError
from training.episodes import (
    SINGULARITY_REASONS,
    TARGET_SETS,
    TRACKING_MAX_LAG_S,
    TRACKING_SETTLING_S,
    aggregate,
    evaluate_agent,
    evaluate_rows,
    evaluate_vector,
    make_vector_env,
    tracking_metrics,
)
from training.intervals import SUCCESS_CI_NOTE, format_success_interval
from training.records import EpisodeRecord
from training.runs import (
    Agent,
    EvaluationError,
    check_compatible,
    evaluation_env_kwargs,
    load_controller,
    load_model,
    load_run,
    read_run_config,
    run_env_kwargs,
    wrap_for_run,
    wrap_vector_for_run,
    zoo_layout,
)

__all__ = [
    "SINGULARITY_REASONS",
    "TARGET_SETS",
    "TRACKING_MAX_LAG_S",
    "TRACKING_SETTLING_S",
    "Agent",
    "EpisodeRecord",
    "EvaluationError",
    "aggregate",
    "build_parser",
    "cached_metrics",
    "check_compatible",
    "evaluate_agent",
    "evaluate_rows",
    "evaluate_vector",
    "evaluation_env_kwargs",
    "format_table",
    "load_controller",
    "load_model",
    "load_run",
    "main",
    "make_vector_env",
    "parse_env_kwargs",
    "print_table",
    "read_run_config",
    "run_env_kwargs",
    "tracking_metrics",
    "wrap_for_run",
    "wrap_vector_for_run",
    "write_outputs",
    "zoo_layout",
]


def format_table(rows: dict[str, dict[str, Any]]) -> str:
    """A Markdown table of aggregated metrics, one row per agent/target set, and its note.

    "success 95 % CI" is ``training.intervals.success_interval`` of the row's one run: rliable's stratified
    bootstrap (95 %, percentile) of the success rate, resampling the run's episodes. A line under the table says so.

    Args:
        rows: Label → ``aggregate`` output.

    Returns:
        The table and its note as Markdown text.
    """
    head = (
        "| agent | targets | success | success 95 % CI | final pos. error [mm] | final orient. error [deg] "
        "| min k (mean / worst) | singularity terminations | cost fraction | return |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for label, m in rows.items():
        agent, _, targets = label.partition(" @ ")
        lines.append(
            f"| {agent} | {targets or '-'} | {100 * m['success_rate']:.0f} % | {format_success_interval([m])} "
            f"| {m['final_position_error_mm']['median']:.2f} (median) "
            f"| {m['final_orientation_error_deg']['median']:.2f} (median) "
            f"| {m['min_inverse_condition']['mean']:.3f} / {m['min_inverse_condition']['min']:.3f} "
            f"| {m['singularity_terminations']} / {m['episodes']} "
            f"| {m['cost_fraction']['mean']:.3f} | {m['return']['mean']:.1f} ± {m['return']['std']:.1f} |"
        )
    return head + "\n".join(lines) + f"\n\n{SUCCESS_CI_NOTE}\n"


def print_table(rows: dict[str, dict[str, Any]]) -> None:
    """Print aggregated metrics as a table on the terminal (rich)."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title="evaluation")
    for name in ("agent @ targets", "success", "pos. err [mm]", "orient. err [deg]", "min k", "sing. term.", "cost"):
        table.add_column(name)
    for label, m in rows.items():
        table.add_row(
            label,
            f"{100 * m['success_rate']:.0f} %",
            f"{m['final_position_error_mm']['median']:.2f}",
            f"{m['final_orientation_error_deg']['median']:.2f}",
            f"{m['min_inverse_condition']['mean']:.3f} / {m['min_inverse_condition']['min']:.3f}",
            f"{m['singularity_terminations']} / {m['episodes']}",
            f"{m['cost_fraction']['mean']:.3f}",
        )
    Console(width=140).print(table)


# -- output ----------------------------------------------------------------------------------------


def write_outputs(
    out: Path, label: str, env: gym.Env, records: list[EpisodeRecord], frames: list[np.ndarray] | None
) -> dict[str, Any]:
    """Write metrics.json, episodes.csv, the pictures and the GIF of one evaluation.

    Args:
        out: Output folder (created).
        label: Name of the agent and target set, for titles.
        env: The evaluated environment.
        records: Its episodes.
        frames: Video frames, or None.

    Returns:
        The aggregated metrics.
    """
    from training import plots

    out.mkdir(parents=True, exist_ok=True)
    metrics = aggregate(records)
    env_id = env.spec.id if env.spec is not None else None
    (out / "metrics.json").write_text(json.dumps({"label": label, "env_id": env_id, **metrics}, indent=2) + "\n")
    with open(out / "episodes.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(records[0].row()))
        writer.writeheader()
        for r in records:
            writer.writerow(r.row())
    params = env.unwrapped.params
    workspace = getattr(env.unwrapped, "workspace", None)  # the planar 3-RPR's certified grid
    if workspace is not None:
        plots.trajectories_figure({label: records}, params, workspace, out / "trajectories.png")
    plots.condition_figure({label: records}, params, out / "condition_number.png")
    if frames:
        plots.save_gif(frames, out / "episodes.gif", fps=env.unwrapped.metadata["render_fps"])
    return metrics


def cached_metrics(folder: Path, evaluate_into: Callable[[Path], object] | None) -> dict[str, Any]:
    """The aggregated metrics of the evaluation in ``folder`` (its ``metrics.json``), evaluated there first if absent.

    Every report keeps its evaluations this way: run again, it evaluates only what is missing.

    Args:
        folder: An evaluation's output folder (``write_outputs``'s files).
        evaluate_into: Writes the evaluation's files into the folder it is given (for example ``main`` with
            ``--out``); None evaluates nothing (a report's ``--from-metrics``).

    Returns:
        The contents of ``metrics.json``.

    Raises:
        EvaluationError: If ``evaluate_into`` is None and ``folder`` has no ``metrics.json`` ("... is missing").
    """
    path = folder / "metrics.json"
    if not path.is_file():
        if evaluate_into is None:
            raise EvaluationError(f"{path} is missing")
        evaluate_into(folder)
    return json.loads(path.read_text())


def parse_env_kwargs(items: list[str]) -> dict[str, Any]:
    """Env keyword arguments from ``KEY:VALUE`` strings (the RL Zoo's ``--env-kwargs``; values read as YAML).

    Raises:
        EvaluationError: On an item without a colon, an empty key, a repeated key or a value YAML cannot read.
    """
    kwargs: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition(":")
        if not sep or not key:
            raise EvaluationError(f"--env-kwargs takes KEY:VALUE items, got {item!r}")
        if key in kwargs:
            raise EvaluationError(f"--env-kwargs gives {key!r} twice")
        try:
            kwargs[key] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise EvaluationError(f"--env-kwargs {item!r}: the value is not YAML ({exc})") from None
    return kwargs


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(prog="python -m training.evaluate", description=__doc__.split("\n")[0])
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--run", help="run folder written by training.train or by the RL Zoo (rl_zoo3.train)")
    source.add_argument("--controller", help=f"one of {sorted(CONTROLLERS)}")
    parser.add_argument("--env", default=None, help=f"one of {list(envs.ENV_IDS)}; default: the run's env")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0, help="episode i resets with seed + i")
    parser.add_argument(
        "--targets", default=None, help=f"one of {list(TARGET_SETS)} (Reach only); default: the env's own"
    )
    parser.add_argument("--video", action="store_true", help="write a GIF of the first episodes")
    parser.add_argument("--out", default=None, help="output folder; default: <run>/eval-<targets> or evals/...")
    parser.add_argument("--model", default="final", help="final (model.zip) or best (best_model.zip)")
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        default=[],
        metavar="KEY:VALUE",
        help="keyword arguments of the env, in the RL Zoo's form (values read as YAML: task_region:box, "
        "sample_low:[-0.1,-0.1,-0.5], robot:planar_3rpr)",
    )
    parser.add_argument(
        "--planner",
        default=None,
        choices=("auto", "ompl", "grid"),
        help="the planner controller's planner (default auto: the certified grid where the env has one, else OMPL)",
    )
    parser.add_argument(
        "--replan-distance",
        type=float,
        default=None,
        metavar="METRES",
        help="the planner controller plans afresh whenever the platform is farther than this from its path "
        "(default: one plan per episode)",
    )
    parser.add_argument(
        "--shield",
        type=float,
        default=None,
        metavar="K_GUARD",
        help="wrap the env in envs.SingularityShield with this guard level (for example 0.05)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m training.evaluate``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.episodes < 1:
            raise EvaluationError(f"--episodes must be ≥ 1, got {args.episodes}")
        run_kwargs: dict[str, Any] = {}
        if args.run is not None:
            config = read_run_config(args.run)
            env_id = args.env or config["env_id"]
            if env_id == config["env_id"]:  # the run's env as it was trained (its reward aside), unless told otherwise
                run_kwargs = evaluation_env_kwargs(config)
        else:
            env_id = args.env or "Planar3RPRReach-v0"
        if env_id not in envs.ENV_IDS:
            raise EvaluationError(f"unknown env id {env_id!r}; valid choices: {list(envs.ENV_IDS)}")
        if args.targets is not None and args.targets not in TARGET_SETS:
            raise EvaluationError(f"--targets must be one of {list(TARGET_SETS)}, got {args.targets!r}")
        env_kwargs = {**run_kwargs, **parse_env_kwargs(args.env_kwargs)}
        try:
            env = gym.make(env_id, render_mode="rgb_array" if args.video else None, **env_kwargs)
        except (TypeError, ValueError) as exc:
            raise EvaluationError(f"--env-kwargs {' '.join(args.env_kwargs)}: {exc}") from None
        shielded = " + shield" if args.shield is not None else ""
        if shielded:
            try:
                env = envs.SingularityShield(env, k_guard=args.shield)
            except ValueError as exc:
                raise EvaluationError(f"--shield: {exc}") from None
        reach = "targets" in type(env.unwrapped).reset_options
        targets = args.targets or (getattr(env.unwrapped, "targets", "standard") if reach else "track")
        if args.run is not None:
            agent, _ = load_run(args.run, args.model)
            env = wrap_for_run(env, config)
            check_compatible(agent, env, f"run {args.run!r}")
            name = f"{config['algo']} ({Path(args.run).name}){shielded}"
            out = Path(args.out) if args.out else Path(args.run) / f"eval-{env_id}-{targets}"
        else:
            for option in ("planner", "replan_distance"):
                if getattr(args, option) is not None and args.controller != "planner":
                    flag = "--" + option.replace("_", "-")
                    raise EvaluationError(f"{flag} applies to --controller planner, not {args.controller!r}")
            agent = load_controller(args.controller, env, args.planner, args.replan_distance)
            name = args.controller + (f" ({args.planner})" if args.planner else "") + shielded
            if args.replan_distance is not None:
                name += f", replanning {args.replan_distance:g} m off its path"
            out = Path(args.out) if args.out else Path("evals") / f"{args.controller}-{env_id}-{targets}"
        if shielded and args.out is None:
            out = out.with_name(f"{out.name}-shield")
        frames: list[np.ndarray] | None = [] if args.video else None
        if frames is None:  # every episode at once where the env (and the run's wrapper) has a vector form
            run_config = config if args.run is not None else {}
            records = evaluate_rows(
                agent, run_config, env_id, args.episodes, args.seed, args.targets, args.shield, env_kwargs
            )
        else:
            records = evaluate_agent(agent, env, args.episodes, args.seed, args.targets, frames)
        label = f"{name} @ {targets}"
        metrics = write_outputs(out, label, env, records, frames)
    except (EvaluationError, ConfigError) as exc:
        parser.error(str(exc))
    print_table({label: metrics})
    print(f"outputs written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
