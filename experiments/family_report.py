"""Write a results table (Markdown) from the ``metrics.json`` files of ``training.evaluate`` runs.

Run as ``python -m experiments.family_report OUT.md EVAL_DIR [EVAL_DIR ...]``; every figure of the table comes
from those files, so re-running the evaluations and this command is how the table is updated. The success rate
has its 95 % interval (``training.intervals``: rliable's stratified bootstrap over each run's episodes; the seeds
are not resampled) beside its mean ± std over runs. Evaluations of
the planner (``--controller planner``) also get a table of its plans: how often a certified path was found,
its length against the straight line, its smallest k and the planning time per episode; Track evaluations a
table of their tracking errors; force-control evaluations a table of their drive efforts.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
from pathlib import Path

from training.intervals import SUCCESS_CI_NOTE, format_success_interval

__all__ = ["main", "planner_table", "table", "tracking_table"]


def _row(label: str, metrics: list[dict], with_return: bool = False) -> str:
    success = [100.0 * m["success_rate"] for m in metrics]
    spread = f" ± {statistics.stdev(success):.1f}" if len(success) > 1 else ""
    position = statistics.mean(m["final_position_error_mm"]["median"] for m in metrics)
    orientation = statistics.mean(m["final_orientation_error_deg"]["median"] for m in metrics)
    k_mean = statistics.mean(m["min_inverse_condition"]["mean"] for m in metrics)
    k_min = min(m["min_inverse_condition"]["min"] for m in metrics)
    singular = sum(m["singularity_terminations"] for m in metrics)
    episodes = sum(m["episodes"] for m in metrics)
    cost = statistics.mean(m["cost_fraction"]["mean"] for m in metrics)
    row = (
        f"| {label} | {len(metrics)} | {statistics.mean(success):.1f}{spread} % | {format_success_interval(metrics)} "
        f"| {position:.2f} | {orientation:.2f} "
        f"| {k_mean:.3f} / {k_min:.3f} | {singular} / {episodes} | {cost:.3f} |"
    )
    if with_return:
        returns = [m["return"]["mean"] for m in metrics]
        spread = f" ± {statistics.stdev(returns):.1f}" if len(returns) > 1 else ""
        row += f" {statistics.mean(returns):.1f}{spread} |"
    return row


def table(groups: dict[str, list[dict]], with_return: bool = False) -> str:
    """A Markdown table with one row per group of evaluations (seeds of one agent on one target set), and its note.

    "success 95 % CI" is ``training.intervals.success_interval`` of the group: rliable's stratified bootstrap
    (95 %, percentile) of the mean success over the runs, resampling each run's episodes; the seeds are not
    resampled, so it does not hold the spread over seeds (the ± of the success column). A line under the table
    says so. With ``with_return``, a last column holds the episode return (mean over episodes; mean ± std over
    runs).
    """
    lines = [
        "| agent @ targets | runs | success (mean ± std over runs) | success 95 % CI | final pos. error [mm] (median) "
        "| final orient. error [°] (median) | min k (mean / worst) | singularity terminations | cost fraction |"
        + (" return (mean) |" if with_return else ""),
        "|---|---|---|---|---|---|---|---|---|" + ("---|" if with_return else ""),
    ]
    lines += [_row(label, metrics, with_return) for label, metrics in groups.items()]
    return "\n".join(lines) + f"\n\n{SUCCESS_CI_NOTE}\n"


def planner_table(groups: dict[str, list[dict]]) -> str:
    """A Markdown table of the plans of the groups that have them (``aggregate``'s ``planner`` block); "" if none."""
    rows = {label: ms for label, ms in groups.items() if all("planner" in m for m in ms)}
    if not rows:
        return ""
    lines = [
        "| agent @ targets | episodes | certified path found | planned / straight length (mean ± std) "
        "| planned path's min k (mean) | planning time per episode [ms] (mean / median) |",
        "|---|---|---|---|---|---|",
    ]
    for label, ms in rows.items():
        episodes = sum(m["episodes"] for m in ms)
        found = sum(m["planner"]["path_found_rate"] * m["episodes"] for m in ms) / episodes
        ratio = statistics.mean(m["planner"]["planned_length_ratio"]["mean"] for m in ms)
        ratio_std = statistics.mean(m["planner"]["planned_length_ratio"]["std"] for m in ms)
        min_k = statistics.mean(m["planner"]["planned_min_k"]["mean"] for m in ms)
        t_mean = 1000.0 * statistics.mean(m["planner"]["planning_s"]["mean"] for m in ms)
        t_median = 1000.0 * statistics.mean(m["planner"]["planning_s"]["median"] for m in ms)
        lines.append(
            f"| {label} | {episodes} | {100 * found:.0f} % | {ratio:.2f} ± {ratio_std:.2f} | {min_k:.3f} "
            f"| {t_mean:.1f} / {t_median:.1f} |"
        )
    return "\n".join(lines) + "\n"


def tracking_table(groups: dict[str, list[dict]]) -> str:
    """A Markdown table of the tracking metrics of the groups that have them (Track envs); "" if none.

    Each figure is the mean over the group's runs of the per-run mean over episodes; ± is the standard
    deviation of those per-run means (over seeds), when there are several runs.
    """
    rows = {label: ms for label, ms in groups.items() if all("tracking" in m for m in ms)}
    if not rows:
        return ""

    def cell(ms: list[dict], key: str, digits: int) -> str:
        values = [m["tracking"][key]["mean"] for m in ms]
        spread = f" ± {statistics.stdev(values):.{digits}f}" if len(values) > 1 else ""
        return f"{statistics.mean(values):.{digits}f}{spread}"

    lines = [
        "| agent @ task | runs | RMS position error [mm] | max position error [mm] | RMS orientation error [°] "
        "| cost fraction | lag [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, ms in rows.items():
        lines.append(
            f"| {label} | {len(ms)} | {cell(ms, 'rms_position_mm', 2)} | {cell(ms, 'max_position_mm', 2)} "
            f"| {cell(ms, 'rms_orientation_deg', 3)} | {cell(ms, 'cost_fraction', 3)} | {cell(ms, 'lag_s', 2)} |"
        )
    settling = next(iter(rows.values()))[0]["tracking"]["settling_s"]
    return "\n".join(lines) + f"\n\nAfter a settling time of {settling:g} s.\n"


def effort_table(groups: dict[str, list[dict]]) -> str:
    """A Markdown table of the drive efforts of the groups under force control (``peak_effort``); "" if none.

    Peak effort: the largest |τ_i| / τ_max,i of an episode (1: a drive at its limit); saturation: the fraction of
    its steps with a drive at its limit. Means over the group's episodes (runs weighted by their episodes). The
    holding effort at the target, max_i |τ_h,i| / τ_max,i there (above 1 no drive holds the platform still), where
    the evaluations have it.
    """
    rows = {label: ms for label, ms in groups.items() if all("peak_effort" in m for m in ms)}
    if not rows:
        return ""
    holding = all("target_holding_effort" in m for ms in rows.values() for m in ms)
    lines = [
        "| agent @ targets | episodes | peak effort abs(τ) / τ_max (mean / median / max) | saturated steps (mean) |"
        + (" holding effort at the target (median / max) |" if holding else ""),
        "|---|---|---|---|" + ("---|" if holding else ""),
    ]
    for label, ms in rows.items():
        episodes = sum(m["episodes"] for m in ms)
        mean = sum(m["peak_effort"]["mean"] * m["episodes"] for m in ms) / episodes
        median = statistics.mean(m["peak_effort"]["median"] for m in ms)
        peak = max(m["peak_effort"]["max"] for m in ms)
        saturated = sum(m["saturation_fraction"]["mean"] * m["episodes"] for m in ms) / episodes
        line = f"| {label} | {episodes} | {mean:.2f} / {median:.2f} / {peak:.2f} | {100 * saturated:.1f} % |"
        if holding:
            hold = [m["target_holding_effort"] for m in ms]
            line += f" {statistics.mean(h['median'] for h in hold):.2f} / {max(h['max'] for h in hold):.2f} |"
        lines.append(line)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Group the evaluations by agent and target set (their label without the run name) and write the table."""
    parser = argparse.ArgumentParser(prog="python -m experiments.family_report", description=__doc__.split("\n")[0])
    parser.add_argument("out")
    parser.add_argument("evals", nargs="+", help="folders holding a metrics.json")
    parser.add_argument("--with-return", action="store_true", help="add a column of the episode return")
    parser.add_argument(
        "--by-recipe",
        action="store_true",
        help="keep the run's name without its seed suffix: rows 'ppo (distill-lrd) @ hard' group seeds of one recipe",
    )
    parser.add_argument(
        "--by-env", action="store_true", help="group by env id too: rows 'agent @ env (targets)' (from metrics.json)"
    )
    args = parser.parse_args(argv)
    groups: dict[str, list[dict]] = {}
    for folder in args.evals:
        metrics = json.loads((Path(folder) / "metrics.json").read_text())
        agent, targets = metrics["label"].rsplit(" @ ", 1)
        shielded = " + shield" in agent or "shield" in Path(folder).name
        agent = agent.replace(" + shield", "")
        if args.by_recipe and agent.endswith(")") and " (" in agent:  # "ppo (run-s0)" → "ppo (run)"
            agent = re.sub(r"-s\d+\)$", ")", agent)
        elif not agent.endswith(("(ompl)", "(grid)", "(auto)")):  # the planner's kind stays in the label
            agent = agent.split(" (")[0]  # "ppo (run-s0)" → "ppo": seeds are grouped
        label = f"{agent}{' + shield' if shielded else ''} @ {targets}"
        if args.by_env:
            label = f"{agent}{' + shield' if shielded else ''} @ {metrics.get('env_id')} ({targets})"
        groups.setdefault(label, []).append(metrics)
    plans, tracking, efforts = planner_table(groups), tracking_table(groups), effort_table(groups)
    Path(args.out).write_text(
        table(groups, args.with_return)
        + (f"\nThe planner's plans:\n\n{plans}" if plans else "")
        + (f"\nTracking:\n\n{tracking}" if tracking else "")
        + (f"\nDrive efforts (force control):\n\n{efforts}" if efforts else "")
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
