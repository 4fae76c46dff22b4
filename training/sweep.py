"""Multi-seed sweeps on Ray Tune: algorithms × env ids × seeds (× hyperparameter values), evaluated and aggregated.

Usage::

    python -m training.sweep --name hexapod --algos ppo --envs StewartGoughReach-v0 --seeds 0 1 2
    python -m training.sweep --name hexapod --resume             # re-runs only the trials that did not finish

Every trial is a normal ``training.train`` run with its own run folder (``sweeps/<name>/trials/<trial>/run``),
then scored by ``training.evaluate``'s functions on held-out episodes: standard targets on the env itself and,
for a Reach id, hard targets on its ``…ReachHard-v0`` sibling, each with and without the singularity shield. A
trial writes ``result.json`` only when everything is done, so an interrupted sweep (Ctrl-C) keeps its finished
trials and a resumed one skips them. Ray starts locally on this machine's cores by default (``--max-concurrent``
bounds the trials run at once); ``--address`` runs the same sweep on an existing Ray cluster; called from Python,
``main`` uses a Ray session the caller has already started and leaves it running.

The results are aggregated over seeds with ``rliable`` (interquartile mean, mean, 95 % stratified-bootstrap
confidence intervals, performance profiles) into ``sweep_results.json`` and ``report.md`` with its plots; the
report's tables are what the documentation shows, never typed by hand.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import envs
from envs._extras import require, require_all
from training.config import ALGORITHMS, ConfigError, parse_overrides

__all__ = ["aggregate_results", "connect_ray", "main", "plan_trials", "run_trial"]

#: Guard level of the shielded evaluations.
SHIELD = 0.05


def plan_trials(
    algos: list[str], env_ids: list[str], seeds: list[int], grid: dict[str, list[Any]]
) -> list[dict[str, Any]]:
    """Every trial of the sweep: the product of algorithms, env ids, seeds and the grid's values.

    Args:
        algos: Algorithm names (keys of ``training.config.ALGORITHMS``).
        env_ids: Registered env ids.
        seeds: Training seeds.
        grid: Hyperparameter name → values to try (may be empty).

    Returns:
        Trials, each {"name", "algo", "env_id", "seed", "overrides"}; the name is unique and file-safe.

    Raises:
        ConfigError: For an unknown algorithm or env id.
    """
    for algo in algos:
        if algo not in ALGORITHMS:
            raise ConfigError(f"unknown algorithm {algo!r}; valid choices: {sorted(ALGORITHMS)}")
    for env_id in env_ids:
        if env_id not in envs.ENV_IDS:
            raise ConfigError(f"unknown env id {env_id!r}; valid choices: {list(envs.ENV_IDS)}")
    keys = sorted(grid)
    trials = []
    for algo, env_id, values in itertools.product(algos, env_ids, itertools.product(*(grid[k] for k in keys))):
        overrides = dict(zip(keys, values))
        tag = "".join(f"-{k}={v}" for k, v in overrides.items())
        for seed in seeds:
            name = f"{algo}-{env_id}{tag}-s{seed}".replace("/", "_").replace(" ", "")
            trials.append({"name": name, "algo": algo, "env_id": env_id, "seed": seed, "overrides": overrides})
    return trials


def _target_sets(env_id: str) -> list[tuple[str, str | None, str]]:
    """(env id, target option, label) of each target set a trial is scored on.

    A Reach or ReachHard id is scored on standard targets (the Reach id) and on hard ones (the ReachHard id),
    whichever it was trained on; any other id on its own task ("track").
    """
    if "Reach" not in env_id:
        return [(env_id, None, "track")]
    standard = env_id.replace("ReachHard-", "Reach-")
    hard = standard.replace("Reach-", "ReachHard-")
    sets = [(standard, "standard", "standard")]
    if hard in envs.ENV_IDS:
        sets.append((hard, "hard", "hard"))
    return sets


def run_trial(trial: dict[str, Any], folder: str | Path, timesteps: int | None, episodes: int, seed: int) -> dict:
    """Train one trial, score it, write ``result.json`` last; a finished trial is read back, not re-run.

    Args:
        trial: One entry of ``plan_trials``.
        folder: The trial's folder (created).
        timesteps: Training budget; None keeps the config's ``n_timesteps``.
        episodes: Held-out episodes per target set (reset seeds ``seed`` … ``seed + episodes − 1``).
        seed: Seed of the first held-out episode.

    Returns:
        The result: the trial, its training summary and {"<target set>[+shield]": aggregated metrics}.
    """
    import gymnasium as gym

    from training.evaluate import aggregate, evaluate_agent, load_run, wrap_for_run
    from training.train import train

    folder = Path(folder)
    done = folder / "result.json"
    if done.is_file():
        return json.loads(done.read_text())
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    run = train(
        trial["algo"],
        trial["env_id"],
        seed=trial["seed"],
        timesteps=timesteps,
        run_dir=folder / "run",
        overrides=trial["overrides"] or None,
        vec="native",
        progress_bar=False,
        command=f"training.sweep trial {trial['name']}",
    )
    agent, config = load_run(run)
    scores = {}
    for env_id, targets, label in _target_sets(trial["env_id"]):
        for shielded in (False, True):
            env = gym.make(env_id)
            if shielded:  # inside the run's wrapper: it filters the action the env receives
                env = envs.SingularityShield(env, k_guard=SHIELD)
            env = wrap_for_run(env, config)
            try:
                records = evaluate_agent(agent, env, episodes, seed, targets)
            finally:
                env.close()
            scores[label + ("+shield" if shielded else "")] = aggregate(records)
    result = {
        "trial": trial,
        "summary": json.loads((run / "summary.json").read_text()),
        "wall_time_s": round(time.perf_counter() - start, 1),
        "scores": scores,
    }
    partial = folder / "result.json.tmp"
    partial.write_text(json.dumps(result, indent=2) + "\n")
    os.replace(partial, done)  # atomic: a trial is finished exactly when result.json exists
    return result


def aggregate_results(results: list[dict], out: Path, reps: int = 2000) -> dict[str, Any]:
    """Aggregate finished trials over seeds with rliable; write ``sweep_results.json``, ``report.md`` and plots.

    Groups are (algo, env id, grid values); tasks are the target sets. Success rates are the scores.

    Args:
        results: ``run_trial`` results.
        out: The sweep folder.
        reps: Bootstrap resamples.

    Returns:
        The aggregated results.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from rliable import library as rly
    from rliable import metrics, plot_utils

    groups: dict[str, list[dict]] = {}
    for result in results:
        trial = result["trial"]
        tag = "".join(f" {k}={v}" for k, v in sorted(trial["overrides"].items()))
        groups.setdefault(f"{trial['algo']} @ {trial['env_id']}{tag}", []).append(result)
    rows: dict[str, Any] = {}
    for label, members in sorted(groups.items()):
        tasks = sorted(members[0]["scores"])
        score = np.array([[m["scores"][t]["success_rate"] for t in tasks] for m in members])  # (seeds, tasks)
        per_task = {}
        for j, task in enumerate(tasks):
            point, interval = rly.get_interval_estimates(
                {label: score[:, j : j + 1]}, lambda s: np.array([metrics.aggregate_mean(s)]), reps=reps
            )
            per_task[task] = {
                "mean": float(point[label][0]),
                "ci95": [float(interval[label][0, 0]), float(interval[label][1, 0])],
                "iqm": float(metrics.aggregate_iqm(score[:, j : j + 1])),
                "singularity_terminations": int(sum(_singular_count(m["scores"][task]) for m in members)),
                "episodes": int(sum(m["scores"][task]["episodes"] for m in members)),
                "final_position_error_mm_median": float(
                    np.median([m["scores"][task]["final_position_error_mm"]["median"] for m in members])
                ),
                "min_inverse_condition_worst": float(
                    min(m["scores"][task]["min_inverse_condition"]["min"] for m in members)
                ),
            }
            if all("tracking" in m["scores"][task] for m in members):  # Track envs: errors after settling
                rms = [m["scores"][task]["tracking"]["rms_position_mm"]["mean"] for m in members]
                peak = [m["scores"][task]["tracking"]["max_position_mm"]["mean"] for m in members]
                per_task[task]["tracking_rms_position_mm"] = float(np.mean(rms))
                per_task[task]["tracking_rms_position_mm_std"] = float(np.std(rms))
                per_task[task]["tracking_max_position_mm"] = float(np.mean(peak))
                per_task[task]["tracking_max_position_mm_std"] = float(np.std(peak))
                per_task[task]["tracking_rms_orientation_deg"] = float(
                    np.mean([m["scores"][task]["tracking"]["rms_orientation_deg"]["mean"] for m in members])
                )
                per_task[task]["tracking_lag_s"] = float(
                    np.mean([m["scores"][task]["tracking"]["lag_s"]["mean"] for m in members])
                )
        rows[label] = {
            "seeds": sorted(m["trial"]["seed"] for m in members),
            "tasks": per_task,
            "wall_time_s": [m["summary"]["wall_time_s"] for m in members],
        }
    scores = {
        label: np.array([[m["scores"][t]["success_rate"] for t in sorted(ms[0]["scores"])] for m in ms])
        for label, ms in groups.items()
    }
    thresholds = np.linspace(0.0, 1.0, 41)
    distributions, cis = rly.create_performance_profile(scores, thresholds, reps=min(reps, 500))
    fig, ax = plt.subplots(figsize=(6.5, 4))
    plot_utils.plot_performance_profiles(
        distributions, thresholds, performance_profile_cis=cis, xlabel=r"success rate $\tau$", ax=ax
    )
    ax.legend(list(scores), fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(out / "performance_profile.png", dpi=110)
    plt.close(fig)
    data = {"trials": len(results), "groups": rows}
    (out / "sweep_results.json").write_text(json.dumps(data, indent=2) + "\n")
    (out / "report.md").write_text(report_markdown(data))
    return data


def _singular_count(score: dict[str, Any]) -> int:
    """Singularity terminations of a trial's score: its ``terminations`` counted over ``SINGULARITY_REASONS``.

    Recounted from the reasons, so that a report of older trials follows the current list (Type I included).
    """
    from training.evaluate import SINGULARITY_REASONS

    if "terminations" not in score:
        return int(score["singularity_terminations"])
    return int(sum(count for reason, count in score["terminations"].items() if reason in SINGULARITY_REASONS))


def report_markdown(data: dict[str, Any]) -> str:
    """The sweep's table: one row per group and target set (success mean, 95 % CI, IQM over seeds)."""
    lines = [
        "# Sweep report",
        "",
        f"{data['trials']} trials. Success rate over seeds: mean, 95 % stratified-bootstrap confidence interval "
        "and interquartile mean (`rliable`); singularity terminations summed over the seeds' episodes.",
        "",
        "| algo @ env | targets | seeds | success (mean) | 95 % CI | IQM | singularity terminations "
        "| final pos. error [mm] (median) | min k (worst) | training wall time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, row in data["groups"].items():
        for task, t in row["tasks"].items():
            lo, hi = t["ci95"]
            wall = ", ".join(f"{w:.0f}" for w in row["wall_time_s"])
            lines.append(
                f"| {label} | {task} | {len(row['seeds'])} | {100 * t['mean']:.1f} % "
                f"| [{100 * lo:.1f}, {100 * hi:.1f}] % "
                f"| {100 * t['iqm']:.1f} % | {t['singularity_terminations']} / {t['episodes']} "
                f"| {t['final_position_error_mm_median']:.2f} | {t['min_inverse_condition_worst']:.3f} | {wall} |"
            )
    tracked = [
        (label, task, t)
        for label, row in data["groups"].items()
        for task, t in row["tasks"].items()
        if "tracking_rms_position_mm" in t
    ]
    if tracked:
        lines += [
            "",
            "Tracking (after a 1 s settling time; the per-seed means over episodes, then mean ± std over seeds; "
            "max: an episode's largest position error):",
            "",
            "| algo @ env | task | RMS position error [mm] | max position error [mm] | RMS orientation error [°] "
            "| lag [s] |",
            "|---|---|---|---|---|---|",
        ]
        for label, task, t in tracked:
            peak = "–"
            if "tracking_max_position_mm" in t:  # (sweeps reported before the column was added lack it)
                peak = f"{t['tracking_max_position_mm']:.2f} ± {t['tracking_max_position_mm_std']:.2f}"
            rms = f"{t['tracking_rms_position_mm']:.2f}"
            if "tracking_rms_position_mm_std" in t:
                rms += f" ± {t['tracking_rms_position_mm_std']:.2f}"
            lines.append(
                f"| {label} | {task} | {rms} | {peak} | {t['tracking_rms_orientation_deg']:.2f} "
                f"| {t['tracking_lag_s']:.2f} |"
            )
    lines += ["", "![performance profile](performance_profile.png)", ""]
    return "\n".join(lines)


def _parse_grid(items: list[str]) -> dict[str, list[Any]]:
    grid: dict[str, list[Any]] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--grid takes KEY=V1,V2,..., got {item!r}")
        key, values = item.split("=", 1)
        grid[key] = [parse_overrides([f"{key}={v}"])[key] for v in values.split(",")]
    return grid


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(prog="python -m training.sweep", description=__doc__.split("\n")[0])
    parser.add_argument("--name", required=True, help="sweep name; results go to <root>/<name>")
    parser.add_argument("--root", default="sweeps", help="folder of the sweeps (default sweeps/)")
    parser.add_argument("--algos", nargs="+", default=["ppo"], help=f"some of {sorted(ALGORITHMS)}")
    parser.add_argument("--envs", nargs="+", default=None, help="env ids (default: the sweep's saved plan)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--grid", nargs="*", default=[], metavar="KEY=V1,V2", help="hyperparameter values to try")
    parser.add_argument("--timesteps", type=int, default=None, help="training budget (default: the config's)")
    parser.add_argument("--episodes", type=int, default=100, help="held-out episodes per target set")
    parser.add_argument("--eval-seed", type=int, default=10_000, help="reset seed of the first held-out episode")
    parser.add_argument("--max-concurrent", type=int, default=None, help="trials at once (default: the CPUs)")
    parser.add_argument("--cpus-per-trial", type=float, default=1.0)
    parser.add_argument("--address", default=None, help="an existing Ray cluster (default: start a local Ray)")
    parser.add_argument("--resume", action="store_true", help="continue the sweep of that name: skip finished trials")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="run nothing: aggregate the finished trials of the sweep of that name (while it runs, or after Ctrl-C)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m training.sweep``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.report_only:  # before the plan is written: the trials run on Ray
        require_all(["ray"], "sweep", "the sweep")
    out = Path(args.root) / args.name
    plan_file = out / "plan.json"
    try:
        if args.resume or args.report_only:
            if not plan_file.is_file():
                flag = "--report-only" if args.report_only else "--resume"
                raise ConfigError(f"{flag}: no sweep named {args.name!r} in {args.root!r}")
            plan = json.loads(plan_file.read_text())
        else:
            if plan_file.is_file():
                raise ConfigError(f"sweep {args.name!r} exists in {args.root!r}; pass --resume or another --name")
            if not args.envs:
                raise ConfigError("--envs is required for a new sweep")
            if args.episodes < 1 or (args.timesteps is not None and args.timesteps < 1):
                raise ConfigError("--episodes and --timesteps must be ≥ 1")
            plan = {
                "trials": plan_trials(args.algos, args.envs, args.seeds, _parse_grid(args.grid)),
                "timesteps": args.timesteps,
                "episodes": args.episodes,
                "eval_seed": args.eval_seed,
                "command": " ".join(["python -m training.sweep", *(argv if argv is not None else sys.argv[1:])]),
            }
            out.mkdir(parents=True, exist_ok=True)
            plan_file.write_text(json.dumps(plan, indent=2) + "\n")
    except ConfigError as exc:
        parser.error(str(exc))
    if args.report_only:
        results, failures = finished_trials(plan, out)
        if not results:
            parser.error(f"--report-only: none of the {len(plan['trials'])} trials of {args.name!r} has finished")
        aggregate_results(results, out)
        unfinished = ", ".join(name for name, _ in failures) or "none"
        total = len(plan["trials"])
        print(f"{len(results)} of {total} trials finished (unfinished: {unfinished}); report: {out / 'report.md'}")
        return 0
    results, failures = run_on_ray(plan, out, args.max_concurrent, args.cpus_per_trial, args.address)
    for name, error in failures:
        print(f"trial {name} failed: {error}  (fix it, then: python -m training.sweep --name {args.name} --resume)")
    if results:
        aggregate_results(results, out)
        print(f"{len(results)} of {len(plan['trials'])} trials finished; report: {out / 'report.md'}")
    return 1 if failures else 0


def run_on_ray(
    plan: dict[str, Any], out: Path, max_concurrent: int | None, cpus: float, address: str | None
) -> tuple[list[dict], list[tuple[str, str]]]:
    """Run the plan's unfinished trials as Ray Tune trials; return (finished results, [(trial, error)])."""
    ray = require("ray", "sweep", "the sweep")
    tune = require("ray.tune", "sweep", "the sweep")

    pending = [t for t in plan["trials"] if not (out / "trials" / t["name"] / "result.json").is_file()]
    if pending:
        started = connect_ray(address)
        folder = str(out.resolve() / "trials")
        timesteps, episodes, seed = plan["timesteps"], plan["episodes"], plan["eval_seed"]
        root = str(Path(__file__).resolve().parent.parent)

        def trainable(config: dict[str, Any]) -> dict[str, Any]:
            os.chdir(root)  # Ray runs trials in their own working folder
            trial = config["trial"]
            result = run_trial(trial, Path(folder) / trial["name"], timesteps, episodes, seed)
            return {f"success_{k}": v["success_rate"] for k, v in result["scores"].items()}

        tuner = tune.Tuner(
            tune.with_resources(trainable, {"cpu": cpus}),
            param_space={"trial": tune.grid_search(pending)},
            # a worker process runs trial after trial: torch, SB3 and the compiled kernels are loaded once
            tune_config=tune.TuneConfig(max_concurrent_trials=max_concurrent, reuse_actors=True),
            run_config=tune.RunConfig(
                name="tune", storage_path=str(out.resolve() / "ray"), verbose=0, failure_config=None
            ),
        )
        try:
            tuner.fit()
        finally:
            if started:
                ray.shutdown()
    return finished_trials(plan, out)


def connect_ray(address: str | None = None) -> bool:
    """Connect to Ray: a session already open in this process is used as it is, else one is started.

    Args:
        address: An existing Ray cluster; None starts a local Ray on this machine's cores.

    Returns:
        Whether the session was started here (the sweep then shuts it down when its trials end).
    """
    ray = require("ray", "sweep", "the sweep")
    if ray.is_initialized():
        return False
    ray.init(address=address, include_dashboard=False, log_to_driver=False)
    return True


def finished_trials(plan: dict[str, Any], out: Path) -> tuple[list[dict], list[tuple[str, str]]]:
    """The results of the plan's finished trials (those with a ``result.json``) and [(trial, why)] of the others."""
    results, failures = [], []
    for trial in plan["trials"]:
        path = out / "trials" / trial["name"] / "result.json"
        if path.is_file():
            results.append(json.loads(path.read_text()))
        else:
            failures.append((trial["name"], f"did not finish (Ray's logs: {out / 'ray'})"))
    return results, failures


if __name__ == "__main__":
    sys.exit(main())
