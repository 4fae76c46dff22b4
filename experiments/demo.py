"""The main job: evaluate the shipped pre-trained policies and the classical baselines, and write a report.

Usage::

    python -m experiments.demo [--episodes 50] [--out reports/demo] [--run training/pretrained/<run>]
    python -m experiments.demo --from-metrics --out docs/results/demo     # re-write the reports, evaluate nothing

On standard and hard targets of Planar3RPRReach-v0 (the same fixed seeds for every agent: the shipped
policies, resolved-rate, singularity-aware and the planner, each also behind the shield), it writes
``report.md`` (the comparison table), ``metrics.json``, ``trajectories_hard.png`` and
``trajectories_standard.png`` (paths over the conditioning map, one row per agent),
``condition_number_hard.png`` (k over time) and ``policy_hard.gif`` (the policy for both kinds of target on
hard targets). On Planar3RPRTrack-v0 it compares the shipped Track policy with resolved-rate (with the
reference's feed-forward velocity) in ``track.md``; each family robot with a shipped policy (the hexapod, the
Delta, the 3-RRR, the 3-PRR) gets ``<robot>.md`` (its policies and resolved-rate on standard and hard targets),
and the Delta's adept-cycle Track policy ``track_delta.md``. Each report is written from its metrics file
(``metrics.json``, ``track_metrics.json``, ``<robot>_metrics.json``), and ``--from-metrics`` writes them again
from those files alone.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib import resources
from pathlib import Path

import gymnasium as gym
import numpy as np

from experiments import family_report
from training import plots
from training.evaluate import (
    EvaluationError,
    aggregate,
    evaluate_agent,
    evaluate_rows,
    format_table,
    load_controller,
    load_run,
    print_table,
    read_run_config,
    run_env_kwargs,
    wrap_for_run,
)

__all__ = [
    "FAMILY_DEMOS",
    "PRETRAINED_HEXAPOD_RUN",
    "PRETRAINED_RUN",
    "family_text",
    "main",
    "policy_label",
    "record_regression",
    "render_from_metrics",
    "report_text",
    "run_demo",
    "run_family_demo",
    "run_hexapod_demo",
    "run_track_demo",
    "track_text",
]

#: The run folder of the policy that ships with the project (trained by ``training.train``).
PRETRAINED_RUN = Path(str(resources.files("training").joinpath("pretrained", "ppo-Planar3RPRReach-v0")))
#: A second shipped policy, trained on hard targets (Planar3RPRReachHard-v0), shown when present.
PRETRAINED_HARD_RUN = Path(str(resources.files("training").joinpath("pretrained", "ppo-Planar3RPRReachHard-v0")))
#: The shipped policy for both kinds of target (Planar3RPRReachMixed-v0, with the planner's waypoint in its
#: observation), shown in place of the hard-trained one when present.
PRETRAINED_MIXED_RUN = Path(str(resources.files("training").joinpath("pretrained", "ppo-Planar3RPRReachMixed-v0")))
#: The shipped plan-free policy (``training.distill``: the planner distilled by DAgger; no planner at run time),
#: shown beside the others when present.
PRETRAINED_PLAN_FREE_RUN = Path(
    str(resources.files("training").joinpath("pretrained", "distill-Planar3RPRReachMixed-v0"))
)
#: The shipped Track policy (Planar3RPRTrack-v0), compared with resolved-rate in ``track.md`` when present.
PRETRAINED_TRACK_RUN = Path(str(resources.files("training").joinpath("pretrained", "ppo-Planar3RPRTrack-v0")))


#: The shipped Stewart–Gough hexapod policy (StewartGoughReach-v0), shown in its own section when present.
PRETRAINED_HEXAPOD_RUN = Path(str(resources.files("training").joinpath("pretrained", "ppo-StewartGoughReach-v0")))

#: The shipped hexapod policy trained on hard (ill-conditioned) targets, shown beside it when present.
PRETRAINED_HEXAPOD_HARD_RUN = Path(
    str(resources.files("training").joinpath("pretrained", "ppo-StewartGoughReachHard-v0"))
)


def _pretrained(name: str) -> Path:
    """The folder of a shipped run under ``training/pretrained``."""
    return Path(str(resources.files("training").joinpath("pretrained", name)))


#: Guard level of the singularity shield in the demo's shielded rows.
DEMO_SHIELD = 0.05


def _shown(path: Path) -> str:
    """``path`` as a report shows it: relative to the working directory when it lies below it."""
    path = Path(path)
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _progress(total: int, desc: str):
    """A progress bar over a section's evaluation rows (on stderr)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="row", leave=False, file=sys.stderr)


def policy_label(config: dict, main: bool) -> str:
    """A shipped policy's row label from its run config.

    "plan-free policy (distilled planner)" for a ``training.distill`` run; else "<ALGO> policy", followed for a
    policy other than the section's ``main`` one by the targets it was trained on and its kind, e.g. "PPO policy
    (mixed, residual over the planner)" or "PPO policy (hard-trained)".
    """
    if config.get("distilled_from") == "planner":
        return "plan-free policy (distilled planner)"
    name = f"{config['algo'].upper()} policy"
    if main:
        return name
    targets = run_env_kwargs(config).get("targets") or gym.spec(config["env_id"]).kwargs.get("targets", "standard")
    wrapper = str(config.get("hyperparams", {}).get("env_wrapper") or "")
    kind = f"{targets}-trained"
    if "PlannerResidualWrapper" in wrapper:
        kind = f"{targets}, residual over the planner"
    elif "PlannerWaypointWrapper" in wrapper:
        kind = f"{targets}, waypoint"
    return f"{name} ({kind})"


def run_demo(
    run: Path,
    out: Path,
    episodes: int,
    seed: int = 1000,
    video_episodes: int = 3,
    hard_run: Path | None = None,
    shield: float | None = DEMO_SHIELD,
) -> dict:
    """Evaluate the policy of ``run``, a second one and the three baselines on standard and hard targets.

    Args:
        run: Run folder of the policy.
        hard_run: Run folder of a second policy (trained on hard or on mixed targets), evaluated too and
            filmed on hard targets (None: skip it). Each policy sees the observation it was trained with
            (its ``env_wrapper``).
        out: Report folder (created).
        episodes: Episodes per agent and target set.
        seed: Seed of the first episode (episode i resets with seed + i for every agent).
        video_episodes: Hard episodes of the policy filmed into the GIF.
        shield: Guard level of ``envs.SingularityShield``: every agent is also evaluated behind the shield
            on both target sets, rows "<agent> + shield" (None: skip them).

    Returns:
        Label → aggregated metrics.
    """
    out.mkdir(parents=True, exist_ok=True)
    policy, config = load_run(run)
    env_id = config["env_id"]
    env = gym.make(env_id, render_mode="rgb_array")
    agents = {f"{config['algo'].upper()} policy": (policy, config)}
    filmed = next(iter(agents))
    if hard_run is not None:
        hard_policy, hard_config = load_run(hard_run)
        filmed = policy_label(hard_config, main=False)
        agents[filmed] = (hard_policy, hard_config)
    if PRETRAINED_PLAN_FREE_RUN.is_dir() and PRETRAINED_PLAN_FREE_RUN != run:
        plan_free, plan_free_config = load_run(PRETRAINED_PLAN_FREE_RUN)
        agents["plan-free policy (distilled planner)"] = (plan_free, plan_free_config)
    for name in ("resolved-rate", "singularity-aware", "planner"):
        agents[name] = (load_controller(name, env), {})
    metrics, records = {}, {}
    frames: list[np.ndarray] = []
    rows = len(agents) * 2 * (2 if shield is not None else 1)
    with _progress(rows, "3-RPR") as bar:
        for targets in ("standard", "hard"):
            records[targets] = {}
            for name, (agent, agent_config) in agents.items():
                records[targets][name] = evaluate_rows(agent, agent_config, env_id, episodes, seed, targets)
                metrics[f"{name} @ {targets}"] = aggregate(records[targets][name])
                bar.update()
                if targets == "hard" and name == filmed:
                    evaluate_agent(agent, wrap_for_run(env, agent_config), video_episodes, seed, targets, frames)
        if shield is not None:
            for targets in ("standard", "hard"):
                for name, (agent, agent_config) in agents.items():
                    recs = evaluate_rows(agent, agent_config, env_id, episodes, seed, targets, shield)
                    metrics[f"{name} + shield @ {targets}"] = aggregate(recs)
                    bar.update()
    params, workspace = env.unwrapped.params, env.unwrapped.workspace
    for targets in ("standard", "hard"):
        plots.trajectories_figure(records[targets], params, workspace, out / f"trajectories_{targets}.png")
    plots.condition_figure(records["hard"], params, out / "condition_number_hard.png")
    plots.save_gif(frames, out / "policy_hard.gif", fps=env.unwrapped.metadata["render_fps"])
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    (out / "report.md").write_text(report_text(metrics, env_id, seed, run, hard_run))
    env.close()
    return metrics


def _episodes(metrics: dict) -> int:
    """The episodes per row of a report's metrics (every row has the same)."""
    return next(iter(metrics.values()))["episodes"]


def report_text(metrics: dict, env_id: str, seed: int, run: Path, hard_run: Path | None) -> str:
    """``report.md`` of ``run_demo``: its header, ``format_table(metrics)`` and the names of the pictures.

    Args:
        metrics: Label → aggregated metrics (``metrics.json``).
        env_id: The evaluated env id.
        seed: Seed of the first episode.
        run: Run folder of the policy.
        hard_run: Run folder of the second policy, or None.

    Returns:
        The Markdown text.
    """
    episodes = _episodes(metrics)
    return (
        f"# Evaluation report\n\nEnvironment `{env_id}`, {episodes} episodes per row (reset seeds {seed}…"
        f"{seed + episodes - 1}, identical for every agent). Policy: `{_shown(run)}`"
        + (f"; second policy: `{_shown(hard_run)}`" if hard_run is not None else "")
        + f".\n\n{format_table(metrics)}\n"
        "Pictures: `trajectories_standard.png`, `trajectories_hard.png`, `condition_number_hard.png`, "
        "`policy_hard.gif`.\n"
    )


#: The family robots of the report: file stem → (title, {targets: env id}, shipped runs (first: the main policy)).
FAMILY_DEMOS: dict[str, tuple[str, dict[str, str], tuple[Path, ...]]] = {
    "hexapod": (
        "Stewart–Gough hexapod",
        {"standard": "StewartGoughReach-v0", "hard": "StewartGoughReachHard-v0"},
        (
            PRETRAINED_HEXAPOD_RUN,
            PRETRAINED_HEXAPOD_HARD_RUN,
            _pretrained("ppo-residual-StewartGoughReachHard-v0"),
            _pretrained("distill-StewartGoughReachHard-v0"),
        ),
    ),
    "delta": (
        "Delta robot (cranks, translational plate)",
        {"standard": "DeltaReach-v0", "hard": "DeltaReachHard-v0"},
        (
            _pretrained("ppo-DeltaReach-v0"),
            _pretrained("ppo-residual-DeltaReachHard-v0"),
            _pretrained("distill-DeltaReachHard-v0"),
        ),
    ),
    "planar_3rrr": (
        "Planar 3-RRR (cranks)",
        {"standard": "Planar3RRRReach-v0", "hard": "Planar3RRRReachHard-v0"},
        (
            _pretrained("ppo-Planar3RRRReach-v0"),
            _pretrained("ppo-residual-Planar3RRRReach-v0"),
            _pretrained("distill-Planar3RRRReach-v0"),
        ),
    ),
    "planar_3prr": (
        "Planar 3-PRR (sliders)",
        {"standard": "Planar3PRRReach-v0"},
        (_pretrained("ppo-Planar3PRRReach-v0"),),
    ),
}
#: Shipped Track policies of the family robots, compared with resolved-rate (``track_<stem>.md``) when present.
FAMILY_TRACK_DEMOS: dict[str, Path] = {"delta": _pretrained("ppo-DeltaTrack-v0")}


def run_family_demo(
    name: str, out: Path, episodes: int, seed: int = 1000, shield: float | None = DEMO_SHIELD
) -> dict | None:
    """Evaluate a family robot's shipped policies, resolved-rate and the planner on its targets; write ``<name>.md``.

    Standard targets come from the robot's Reach id, hard ones (where it has them) from its ReachHard id; every
    agent is also evaluated behind the shield when ``shield`` is set.

    Args:
        name: A key of ``FAMILY_DEMOS`` ("hexapod", "delta", "planar_3rrr", "planar_3prr").
        out: Report folder (created).
        episodes: Episodes per agent and target set.
        seed: Seed of the first episode.
        shield: Guard level of ``envs.SingularityShield`` (None: no shielded rows).

    Returns:
        Label → aggregated metrics, or None when the robot's main policy is not shipped.
    """
    _title, ids, runs = FAMILY_DEMOS[name]
    shipped = [run for run in runs if run.is_dir()]
    if not shipped or shipped[0] != runs[0]:
        return None
    out.mkdir(parents=True, exist_ok=True)
    policies = {}
    for i, run in enumerate(shipped):
        policy, config = load_run(run)
        policies[policy_label(config, main=i == 0)] = (policy, config)
    metrics: dict = {}
    frames: list[np.ndarray] = []
    with _progress(len(ids) * (len(policies) + 2) * (2 if shield is not None else 1), name) as bar:
        for targets, env_id in ids.items():
            env = gym.make(env_id, render_mode="rgb_array")
            agents = {
                **policies,
                "resolved-rate": (load_controller("resolved-rate", env), {}),
                "planner": (load_controller("planner", env), {}),
            }
            for label, (agent, config) in agents.items():
                metrics[f"{label} @ {targets}"] = aggregate(
                    evaluate_rows(agent, config, env_id, episodes, seed, targets)
                )
                bar.update()
                if targets == "standard" and label == next(iter(policies)):
                    evaluate_agent(agent, env, 2, seed, targets, frames, 2)
                if shield is not None:
                    recs = evaluate_rows(agent, config, env_id, episodes, seed, targets, shield)
                    metrics[f"{label} + shield @ {targets}"] = aggregate(recs)
                    bar.update()
            env.close()
    plots.save_gif(frames, out / f"{name}_policy.gif", fps=20)
    (out / f"{name}_metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    (out / f"{name}.md").write_text(family_text(name, metrics, seed))
    return metrics


def family_text(name: str, metrics: dict, seed: int) -> str:
    """``<name>.md`` of ``run_family_demo``: its header, ``format_table(metrics)`` and the name of the GIF.

    Args:
        name: A key of ``FAMILY_DEMOS``.
        metrics: Label → aggregated metrics (``<name>_metrics.json``).
        seed: Seed of the first episode.

    Returns:
        The Markdown text.
    """
    title, ids, runs = FAMILY_DEMOS[name]
    shipped = [run for run in runs if run.is_dir()]
    episodes = _episodes(metrics)
    kinds = "; ".join(f"{targets} targets: `{env_id}`" for targets, env_id in ids.items())
    return (
        f"# {title}\n\n{kinds[0].upper() + kinds[1:]}. {episodes} episodes per row (reset seeds {seed}…"
        f"{seed + episodes - 1}). Policies: " + ", ".join(f"`{_shown(run)}`" for run in shipped) + ".\n\n"
        f"{format_table(metrics)}\nPicture: `{name}_policy.gif`.\n"
    )


def run_hexapod_demo(run: Path, out: Path, episodes: int, seed: int = 1000, shield: float | None = DEMO_SHIELD) -> dict:
    """The hexapod's section (``run_family_demo("hexapod", ...)``; ``run`` must be the shipped policy)."""
    if Path(run) != PRETRAINED_HEXAPOD_RUN:
        raise EvaluationError(f"the hexapod section evaluates the shipped {PRETRAINED_HEXAPOD_RUN}, got {run}")
    return run_family_demo("hexapod", out, episodes, seed, shield)


def run_track_demo(run: Path, out: Path, episodes: int, seed: int = 1000, stem: str = "track") -> dict:
    """Compare a Track policy with resolved-rate (feed-forward) on its Track id; write ``<stem>.md``.

    Args:
        run: Run folder of the Track policy (Planar3RPRTrack-v0, DeltaTrack-v0, …).
        out: Report folder (created).
        episodes: Episodes per agent.
        seed: Seed of the first episode.
        stem: File stem of the report and its metrics.

    Returns:
        Label → aggregated metrics (with their ``tracking`` block).
    """
    out.mkdir(parents=True, exist_ok=True)
    policy, config = load_run(run)
    env = gym.make(config["env_id"])
    agents = {
        f"{config['algo'].upper()} policy": (policy, config),
        "resolved-rate": (load_controller("resolved-rate", env), {}),
    }
    metrics = {
        f"{name} @ track": aggregate(evaluate_rows(a, agent_config, config["env_id"], episodes, seed, None))
        for name, (a, agent_config) in agents.items()
    }
    env.close()
    (out / f"{stem}_metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    (out / f"{stem}.md").write_text(track_text(metrics, config["env_id"], seed, run))
    return metrics


def track_text(metrics: dict, env_id: str, seed: int, run: Path) -> str:
    """``<stem>.md`` of ``run_track_demo``: its header, ``family_report.table`` and ``tracking_table``.

    Args:
        metrics: Label → aggregated metrics (``<stem>_metrics.json``), one run per agent.
        env_id: The Track id.
        seed: Seed of the first episode.
        run: Run folder of the Track policy.

    Returns:
        The Markdown text.
    """
    episodes = _episodes(metrics)
    groups = {label.split(" @ ")[0]: [m] for label, m in metrics.items()}  # one run per agent
    return (
        f"# Tracking on `{env_id}`\n\n{episodes} episodes per row "
        f"(reset seeds {seed}…{seed + episodes - 1}). Policy: `{_shown(run)}`; resolved-rate steers with the "
        "reference's feed-forward velocity.\n\n"
        + family_report.table(groups)
        + f"\n{family_report.tracking_table(groups)}"
    )


def render_from_metrics(out: Path, run: Path, hard_run: Path | None, seed: int = 1000) -> list[str]:
    """Write the reports again from the metrics files of a report folder, without evaluating anything.

    ``report.md`` from ``metrics.json``, ``track.md`` from ``track_metrics.json``, ``<robot>.md`` from
    ``<robot>_metrics.json`` and ``track_<robot>.md`` from ``track_<robot>_metrics.json``, each where its metrics
    file exists; ``run``, ``hard_run`` and ``seed`` must be those the folder was evaluated with (its reports
    name them). Pictures are kept.

    Args:
        out: The report folder.
        run: Run folder of the policy.
        hard_run: Run folder of the second policy, or None.
        seed: Seed of the first episode.

    Returns:
        The names of the reports written.

    Raises:
        EvaluationError: If the folder has no ``metrics.json``.
    """
    if not (out / "metrics.json").is_file():
        raise EvaluationError(f"{str(out)!r} holds no metrics.json to render the report from")

    def read(name: str) -> dict:
        return json.loads((out / name).read_text())

    written = ["report.md"]
    (out / "report.md").write_text(
        report_text(read("metrics.json"), read_run_config(run)["env_id"], seed, run, hard_run)
    )
    tracks = {"track": PRETRAINED_TRACK_RUN} | {f"track_{name}": r for name, r in FAMILY_TRACK_DEMOS.items()}
    for stem, track_run in tracks.items():
        if (out / f"{stem}_metrics.json").is_file():
            env_id = read_run_config(track_run)["env_id"]
            (out / f"{stem}.md").write_text(track_text(read(f"{stem}_metrics.json"), env_id, seed, track_run))
            written.append(f"{stem}.md")
    for name in FAMILY_DEMOS:
        if (out / f"{name}_metrics.json").is_file():
            (out / f"{name}.md").write_text(family_text(name, read(f"{name}_metrics.json"), seed))
            written.append(f"{name}.md")
    return written


def record_regression(run: Path, episodes: int = 20, seed: int = 5000, targets: str | None = None) -> dict:
    """Evaluate a run on fixed seeds and store the result as ``regression.json``.

    The test suite re-runs exactly these episodes and checks the policy still reaches this success rate.

    Args:
        run: Run folder of the policy (its ``env_wrapper``, if any, is applied).
        episodes: Number of episodes.
        seed: Seed of the first episode.
        targets: "standard" or "hard" for a Reach run (default: hard for a run trained on mixed or hard
            targets, else standard); ignored for a Track run ("track").

    Returns:
        The recorded dict.
    """
    policy, config = load_run(run)
    env = wrap_for_run(gym.make(config["env_id"], **run_env_kwargs(config)), config)
    if "targets" not in type(env.unwrapped).reset_options:
        targets, option = "track", None
    else:
        targets = targets or ("standard" if env.unwrapped.targets == "standard" else "hard")
        option = targets
    metrics = aggregate(evaluate_agent(policy, env, episodes, seed, option))
    record = {
        "env_id": config["env_id"],
        "targets": targets,
        "seed": seed,
        "episodes": episodes,
        "success_rate": metrics["success_rate"],
        "singularity_terminations": metrics["singularity_terminations"],
    }
    (run / "regression.json").write_text(json.dumps(record, indent=2) + "\n")
    return record


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m experiments.demo``; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m experiments.demo", description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=50, help="episodes per agent and target set")
    parser.add_argument("--out", default="reports/demo", help="report folder")
    parser.add_argument("--run", default=str(PRETRAINED_RUN), help="run folder of the policy")
    second = next((r for r in (PRETRAINED_MIXED_RUN, PRETRAINED_HARD_RUN) if r.is_dir()), None)
    parser.add_argument(
        "--hard-run",
        default=str(second) if second is not None else None,
        help="run folder of a second policy, for hard targets (default: the shipped mixed-target one, if any)",
    )
    parser.add_argument("--seed", type=int, default=1000, help="seed of the first episode")
    parser.add_argument(
        "--shield",
        type=float,
        default=DEMO_SHIELD,
        help=f"guard level of the shielded rows (default {DEMO_SHIELD}; 0 leaves them out)",
    )
    parser.add_argument(
        "--record-regression", action="store_true", help="only write <run>/regression.json (for the test suite)"
    )
    parser.add_argument(
        "--from-metrics",
        action="store_true",
        help="evaluate nothing: write the reports of --out again from its metrics files (same --run, --hard-run, "
        "--seed as when they were evaluated)",
    )
    args = parser.parse_args(argv)
    if args.from_metrics:
        hard_run = Path(args.hard_run) if args.hard_run else None
        try:
            written = render_from_metrics(Path(args.out), Path(args.run), hard_run, args.seed)
        except (EvaluationError, OSError) as exc:
            parser.error(str(exc))
        print(f"reports written to {args.out} from its metrics: {', '.join(written)}")
        return 0
    if args.record_regression:
        try:
            print(json.dumps(record_regression(Path(args.run)), indent=2))
        except EvaluationError as exc:
            parser.error(str(exc))
        return 0
    start = time.perf_counter()
    try:
        if args.episodes < 1:
            raise EvaluationError(f"--episodes must be ≥ 1, got {args.episodes}")
        if not 0.0 <= args.shield < 1.0:
            raise EvaluationError(f"--shield must be in [0, 1), got {args.shield}")
        hard_run = Path(args.hard_run) if args.hard_run else None
        shield = args.shield or None
        metrics = run_demo(Path(args.run), Path(args.out), args.episodes, args.seed, hard_run=hard_run, shield=shield)
    except EvaluationError as exc:
        parser.error(str(exc))
    print_table(metrics)
    written = ["report.md"]
    if Path(args.run) == PRETRAINED_RUN:
        if PRETRAINED_TRACK_RUN.is_dir():
            print_table(run_track_demo(PRETRAINED_TRACK_RUN, Path(args.out), args.episodes, args.seed))
            written.append("track.md")
        for name in FAMILY_DEMOS:
            family_metrics = run_family_demo(name, Path(args.out), args.episodes, args.seed, args.shield or None)
            if family_metrics is not None:
                print_table(family_metrics)
                written.append(f"{name}.md")
        for name, run in FAMILY_TRACK_DEMOS.items():
            if run.is_dir():
                print_table(run_track_demo(run, Path(args.out), args.episodes, args.seed, stem=f"track_{name}"))
                written.append(f"track_{name}.md")
    print(f"report written to {args.out}: {', '.join(written)} ({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
