r"""Results of the plan-free policies: every agent on standard and hard targets, a table, a picture, timings.

Usage::

    python -m experiments.plan_free_report --runs runs/distill-3rpr-s0 runs/distill-3rpr-s1 runs/distill-3rpr-s2 \\
        --env Planar3RPRReach-v0 --residual training/pretrained/ppo-Planar3RPRReachMixed-v0 \\
        --out docs/results/plan_free_planar3rpr

Evaluates (``training.evaluate``, ``--episodes`` from reset seed ``--seed``, held out from training) on the env's
standard and hard targets: the planner, the distilled plan-free runs (each seed), the residual policy over the
planner, resolved-rate and singularity-aware control, and the plan-free runs behind ``envs.SingularityShield``.
On a force-control env (``control="force"``) the classical controllers are planner-computed-torque (the
distillation's expert there) and computed torque.
Writes each evaluation's folder, ``table.md`` (``experiments.family_report``: mean ± std over seeds),
``timing.md`` (the plan-free policy's time per decision, as ``training.evaluate`` runs it and exported by
``training.export``, against the
planner's planning time per hard episode; and its time to the target against the planner's on the hard episodes
both reach) and ``paths_hard.png`` (the planner's and the first plan-free run's
paths on the same hard episodes over the map of k; robots with a certified grid). An evaluation whose
``metrics.json`` exists is kept; ``--from-metrics`` only writes ``table.md`` again from those files (no
evaluation, no timing, no picture).
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym

import envs  # noqa: F401  (registers the ids)
from experiments import family_report
from training import evaluate, export, plots

__all__ = ["main"]

#: The classical controllers every rate-control report evaluates, the planner (the distillation's expert) first.
CONTROLLERS = ("planner", "resolved-rate", "singularity-aware")


def _decision_seconds(run: str, env_id: str, folder: Path, repeats: int = 2000) -> tuple[float, float]:
    """Wall time of one decision of a run's policy, one observation at a time: (through SB3, exported).

    Through SB3: ``training.evaluate.load_run``'s agent (VecNormalize, then ``predict``), as the evaluations run
    it. Exported: the same policy as one TorchScript function (``training.export``), as a robot would run it.
    """
    import torch

    agent, config = evaluate.load_run(run)
    deployed = torch.jit.load(str(export.export_run(run, folder / f"{Path(run).name}.pt")))
    env = evaluate.wrap_for_run(gym.make(env_id), config)
    obs, _ = env.reset(seed=0)
    batch = obs[None]
    tensor = torch.as_tensor(batch)

    def clock(decide) -> float:
        for _ in range(50):
            decide()
        start = time.perf_counter()
        for _ in range(repeats):
            decide()
        return (time.perf_counter() - start) / repeats

    with torch.inference_mode():
        return clock(lambda: agent(batch)), clock(lambda: deployed(tensor))


def _mean_std(values: list[float], digits: int) -> str:
    """Mean ± std of values with ``digits`` decimals (the mean alone for one value, "-" for none)."""
    if not values:
        return "-"
    spread = f" ± {statistics.stdev(values):.{digits}f}" if len(values) > 1 else ""
    return f"{statistics.mean(values):.{digits}f}{spread}"


def _ratio(value: float) -> str:
    """A speed ratio: whole numbers from 10 on, two significant digits below (0.14×, 6.2×)."""
    return f"{value:.0f}×" if value >= 10 else f"{value:.2g}×"


def _times_to_target(folder: Path) -> dict[int, float]:
    """Episode → time to the target [s] of an evaluation folder's ``episodes.csv`` (episodes that reached it)."""
    with (folder / "episodes.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    if rows and "time_to_target_s" not in rows[0]:
        raise SystemExit(f"{folder / 'episodes.csv'} has no time_to_target_s: delete {folder} to evaluate it again")
    return {int(row["episode"]): float(row["time_to_target_s"]) for row in rows if row["time_to_target_s"]}


def time_to_target_table(out: Path, runs: list[str], expert: str = "planner") -> str:
    """Markdown: each plan-free run's time to the hard targets against the planner's, on the episodes both reach.

    Per run, the mean over those episodes of the plan-free policy's time and of the planner's (the evaluation
    folder ``{expert}-hard``), and of their ratio; the table gives the mean ± std of these over runs.
    """
    planner = _times_to_target(out / f"{expert}-hard")
    columns: dict[str, list[float]] = {"pairs": [], "policy": [], "planner": [], "ratio": []}
    for run in runs:
        policy = _times_to_target(out / f"{Path(run).name}-hard")
        both = sorted(set(policy) & set(planner))
        if not both:
            continue
        columns["pairs"].append(len(both))
        columns["policy"].append(statistics.mean(policy[e] for e in both))
        columns["planner"].append(statistics.mean(planner[e] for e in both))
        columns["ratio"].append(statistics.mean(policy[e] / planner[e] for e in both))

    return (
        "| hard episodes both reach (per run) | plan-free policy: time to the target [s] | planner: time to the "
        "target [s] | ratio plan-free / planner |\n|---|---|---|---|\n"
        f"| {_mean_std(columns['pairs'], 1)} | {_mean_std(columns['policy'], 2)} | {_mean_std(columns['planner'], 2)} "
        f"| {_mean_std(columns['ratio'], 2)} |\n"
    )


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m experiments.plan_free_report", description=__doc__.splitlines()[0])
    parser.add_argument("--runs", nargs="+", required=True, help="run folders of training.distill")
    parser.add_argument("--env", required=True, help="the Reach id to evaluate on")
    parser.add_argument("--residual", default=None, help="run folder of a residual policy over the planner")
    parser.add_argument("--out", required=True)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5000)
    parser.add_argument("--shield", type=float, default=0.05, help="k_guard of the shielded plan-free runs")
    parser.add_argument(
        "--from-metrics", action="store_true", help="only write table.md again from the evaluations' metrics.json"
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    common = ["--env", args.env, "--episodes", str(args.episodes), "--seed", str(args.seed)]
    groups: dict[str, list[dict]] = {}
    force = gym.make(args.env).unwrapped.params.control == "force"
    controllers = ("planner-computed-torque", "computed-torque") if force else CONTROLLERS
    expert = controllers[0]

    def add(label: str, folder: Path, source: list[str]) -> None:
        def evaluate_into(folder: Path) -> None:
            evaluate.main([*source, "--out", str(folder)])

        try:
            metrics = evaluate.cached_metrics(folder, None if args.from_metrics else evaluate_into)
        except evaluate.EvaluationError as exc:
            parser.error(f"--from-metrics: {exc}")
        groups.setdefault(label, []).append(metrics)

    for targets in ("standard", "hard"):
        tail = [*common, "--targets", targets]
        for controller in controllers:
            add(f"{controller} @ {targets}", out / f"{controller}-{targets}", ["--controller", controller, *tail])
        for run in args.runs:
            name = Path(run).name
            add(f"plan-free @ {targets}", out / f"{name}-{targets}", ["--run", run, *tail])
            shield = ["--shield", str(args.shield)]
            add(f"plan-free + shield @ {targets}", out / f"{name}-{targets}-shield", ["--run", run, *tail, *shield])
        if args.residual:
            add(f"residual over the planner @ {targets}", out / f"residual-{targets}", ["--run", args.residual, *tail])
    groups = dict(sorted(groups.items(), key=lambda item: (item[0].split(" @ ")[1] != "hard", item[0])))
    plans = family_report.planner_table(groups)
    (out / "table.md").write_text(
        f"{args.episodes} episodes per run and target set from reset seed {args.seed} on `{args.env}` "
        f"(plan-free: {len(args.runs)} seed{'s' if len(args.runs) > 1 else ''}, mean ± std over seeds; shield "
        f"k_guard = {args.shield}).\n\n"
        + family_report.table(groups)
        + (f"\nThe planner's plans:\n\n{plans}" if plans else "")
    )
    if args.from_metrics:
        print((out / "table.md").read_text())
        return 0

    # time per decision of each plan-free run (normalise, one forward pass of one observation) against the
    # planner's planning time per episode on the same hard episodes, measured here one after the other
    planner_metrics = json.loads((out / f"{expert}-hard" / "metrics.json").read_text())
    planning_ms = 1e3 * planner_metrics["planner"]["planning_s"]["mean"]
    with tempfile.TemporaryDirectory() as scratch:
        seconds = [_decision_seconds(run, args.env, Path(scratch)) for run in args.runs]
    sb3_ms, exported_ms = ([1e3 * s[i] for s in seconds] for i in (0, 1))

    (out / "timing.md").write_text(
        "| plan-free policy: time per decision through SB3 [ms] | exported (TorchScript) [ms] | planner: planning "
        "time per hard episode [ms] (mean) | ratio, through SB3 | ratio, exported |\n|---|---|---|---|---|\n"
        f"| {_mean_std(sb3_ms, 3)} | {_mean_std(exported_ms, 3)} | {planning_ms:.2f} "
        f"| {_ratio(planning_ms / statistics.mean(sb3_ms))} "
        f"| {_ratio(planning_ms / statistics.mean(exported_ms))} |\n\n"
        "Times per decision: one observation at a time, mean ± std over runs; through SB3 is VecNormalize and "
        "`predict`, as `training.evaluate` runs it; exported is `training.export`'s TorchScript function of the "
        "same policy.\n\n"
        "Time to the target (the end of the first step within the success tolerances), mean over the hard "
        "episodes both the plan-free run and the planner reach, mean ± std over runs:\n\n"
        + time_to_target_table(out, args.runs, expert)
    )

    # the planner's and the first plan-free run's paths on the same hard episodes
    env = gym.make(args.env)
    workspace = getattr(env.unwrapped, "workspace", None)
    if workspace is not None:
        runs = {}
        planner = evaluate.load_controller(expert, env)
        runs["planner"] = evaluate.evaluate_agent(planner, env, 4, args.seed, "hard")
        agent, config = evaluate.load_run(args.runs[0])
        runs["plan-free"] = evaluate.evaluate_agent(agent, evaluate.wrap_for_run(env, config), 4, args.seed, "hard")
        plots.trajectories_figure(runs, env.unwrapped.params, workspace, out / "paths_hard.png")
    print((out / "table.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
