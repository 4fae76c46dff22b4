"""The Delta's adept cycle under its drive limits: computed torque on time-optimal trajectories.

Usage::

    python -m experiments.pick_and_place --out docs/results/pick_and_place [--dt 0.002] [--bandwidth 40]
        [--policy RUN [RUN ...] --periods 1.0 1.2 1.5 2.0]

The adept cycle (25 mm up, 305 mm across, 25 mm down to the place point, and back the same way; centred on the
Delta's home pose, along x) is parametrised time-optimally from rest to rest at every corner with the drives'
limits scaled by a margin σ ≤ 1 (``robot_control.TimeOptimalPath``, TOPP-RA on the env's own model and
``force_limits``): σ = 1 saturates a drive all along the cycle and leaves no effort for the feedback. Computed
torque (``ComputedTorqueController``: the reference's acceleration fed forward, K_p = ω², K_d = 2 ω, clipped to the
limits) follows each trajectory in ``DeltaForceReach-v0`` (the compiled force-control step) at a control period
``--dt``. A cycle counts when the platform is within 1 mm of the place point when the reference arrives there and
of the pick point at the end of the cycle. ``table.md`` lists every σ (cycle time, those errors, the largest
tracking error, peak effort, saturated periods); ``cycle.gif`` shows the shortest cycle that counts.

With ``--policy``, each policy trained on ``DeltaForceTrack-v0`` (the same cycle as a moving target, rest at every
corner, cosine time law, a random heading per episode; ``training.train`` or ``training.distill``) runs
``--cycles`` cycles of ``--episodes`` episodes at each period of ``--periods`` (its run's env settings,
``track_period`` replaced): the errors at the place and pick points are read when its reference arrives there, and
a period counts when every one is ≤ 1 mm.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from envs.kernels.force import actions_of_efforts
from envs.kernels.packing import observation_layout
from robot_control.computed_torque import ComputedTorqueController, TimeOptimalPath

__all__ = ["adept_waypoints", "follow", "main", "policy_cycles"]

#: Largest error at the pick and place points of a cycle that counts [m].
TOLERANCE = 1e-3
ENV_ID, TRACK_ID = "DeltaForceReach-v0", "DeltaForceTrack-v0"


def adept_waypoints(centre: np.ndarray, across: float = 0.305, lift: float = 0.025) -> np.ndarray:
    """The adept cycle's corners from the pick point back to it, shape (7, 3) [m]; ``centre`` (3,) is midway."""
    pick = np.asarray(centre, dtype=np.float64) - [across / 2.0, 0.0, 0.0]
    place = pick + [across, 0.0, 0.0]
    up = np.array([0.0, 0.0, lift])
    return np.stack([pick, pick + up, place + up, place, place + up, pick + up, pick])


def follow(env: gym.Env, path: TimeOptimalPath, bandwidth: float, frame_every: int = 0) -> dict:
    """Computed torque along ``path`` in ``env`` (a force-control Delta env, reset by this function) for one cycle.

    Returns:
        The cycle time [s], the errors at the place and pick points [mm], the largest tracking error [mm], the
        peak effort max |τ_i| / τ_max,i, the fraction of saturated periods, the largest closure residual, the
        termination reason (None for none) and the frames (every ``frame_every``-th period; none for 0).
    """
    params = env.unwrapped.params
    limits = params.force_limit_array
    robot, model = params.robot, params.dynamics
    controller = ComputedTorqueController.critically_damped(robot, model.inertia, bandwidth=bandwidth,
                                                            force_limits=limits)  # fmt: skip
    points = path.waypoints
    twist_columns = observation_layout(robot.pose_space.name, robot.n_actuators, True, force=True)["twist"]
    obs, info = env.reset(seed=0, options={"start": points[0], "target": points[3]})
    pose, twist = np.asarray(info["pose"], dtype=np.float64), np.asarray(obs[twist_columns], dtype=np.float64)
    dt = params.dt
    arrive = {"place": path.times[3], "pick": path.times[-1]}
    errors, peak, saturated, residual, tracking, frames = {}, 0.0, 0, 0.0, 0.0, []
    steps = int(np.ceil(path.duration / dt - 1e-9))
    reason = None
    for step in range(steps + 1):
        t = step * dt
        for name, when in arrive.items():
            if name not in errors and t >= when - 1e-9:
                goal = points[3] if name == "place" else points[0]
                errors[name] = 1e3 * float(np.linalg.norm(pose - goal))
        if step == steps:
            break
        ref = path(t)
        tracking = max(tracking, 1e3 * float(np.linalg.norm(ref.x - pose)))
        q = robot.inverse_kinematics(pose, validate=False)
        command = controller.compute(q, pose, twist, ref.x, ref.xdot, ref.xddot)
        hold = model.holding_forces(q, pose)
        action = actions_of_efforts(hold, command.tau, limits).astype(np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        peak = max(peak, float(np.max(np.abs(info["actuator_forces"]) / limits)))
        saturated += bool(info["saturated"])
        residual = max(residual, float(info["constraint_residual"]))
        if frame_every and step % frame_every == 0:
            frames.append(env.render())
        if terminated or truncated:
            reason = info["termination_reason"] or "truncated"
            break
        pose, twist = np.asarray(info["pose"], dtype=np.float64), np.asarray(obs[twist_columns], dtype=np.float64)
    return {
        "cycle_time_s": path.duration,
        "place_error_mm": errors.get("place", float("nan")),
        "pick_error_mm": errors.get("pick", float("nan")),
        "max_tracking_error_mm": tracking,
        "peak_effort": peak,
        "saturated_fraction": saturated / max(step, 1),
        "max_residual": residual,
        "termination": reason,
        "frames": frames,
    }


def policy_cycles(agent, env_kwargs: dict, period: float, episodes: int, cycles: int, frame_every: int = 0) -> dict:
    """A Track policy on the adept cycle at ``period`` [s]: its errors at the place and pick points [mm].

    The reference reaches the place point at half the period and the pick point at its end (``ADEPT_CYCLE``'s
    shares), which must fall on control periods.

    Returns:
        The period, the median and largest errors at the place and pick points over every cycle of every
        episode, the peak effort, the saturated fraction, the episodes that ended early and, with
        ``frame_every`` > 0, the first episode's frames every ``frame_every`` control periods ("frames").

    Raises:
        ValueError: If half the period is not a whole number of control periods.
    """
    render = {"render_mode": "rgb_array"} if frame_every else {}
    env = gym.make(TRACK_ID, **{**env_kwargs, "track_period": period}, max_episode_steps=10**6, **render)
    dt = env.unwrapped.params.dt
    half = period / 2.0 / dt
    if abs(half - round(half)) > 1e-6:
        raise ValueError(f"half the period ({period / 2} s) must be a whole number of control periods ({dt} s)")
    place, whole = round(half), 2 * round(half)
    limits = env.unwrapped.params.force_limit_array
    errors: dict[str, list[float]] = {"place": [], "pick": []}
    peak, saturated, steps, ended, frames = 0.0, 0, 0, 0, []
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        for step in range(1, cycles * whole + 1):
            obs, _, terminated, truncated, info = env.step(agent(obs[None])[0])
            peak = max(peak, float(np.max(np.abs(info["actuator_forces"]) / limits)))
            saturated, steps = saturated + bool(info["saturated"]), steps + 1
            if terminated or truncated:
                ended += 1
                break
            if step % whole in (place, 0):
                errors["place" if step % whole == place else "pick"].append(1e3 * float(info["position_error"]))
            if frame_every and episode == 0 and step % frame_every == 0:
                frames.append(env.render())
    env.close()
    out = {"period_s": period, "peak_effort": peak, "saturated_fraction": saturated / max(steps, 1), "ended": ended}
    if frame_every:
        out["frames"] = frames
    for name, values in errors.items():
        values = values or [float("nan")]
        out[f"{name}_error_mm"] = {"median": float(np.median(values)), "max": float(np.max(values))}
    return out


def _policy_table(rows: list[dict], run: Path, config: dict, episodes: int, cycles: int) -> str:
    command = run / "command.txt"
    trained = ""
    if command.is_file():  # the training command without the interpreter's path and the run folder
        words = command.read_text().split()
        words = ["python", *words[words.index("-m") :]] if "-m" in words else words
        if "--run-dir" in words:
            del words[words.index("--run-dir") : words.index("--run-dir") + 2]
        trained = f", trained by `{' '.join(words)}`"
    lines = [
        "",
        f"{_policy_kind(run, config)} of `DeltaForceTrack-v0` (`{run.name}`{trained}) on the same cycle as a moving "
        f"target: {episodes} episodes of {cycles} cycles per period, errors when the reference arrives "
        "(median / largest).",
        "",
        "| cycle time [s] | place error [mm] | pick error [mm] | peak abs(τ)/τ_max | saturated periods | ended early "
        "| counts |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        place, pick = row["place_error_mm"], row["pick_error_mm"]
        ok = _counts(row)
        lines.append(
            f"| {row['period_s']:.2f} | {place['median']:.2f} / {place['max']:.2f} | {pick['median']:.2f} / "
            f"{pick['max']:.2f} | {row['peak_effort']:.2f} | {100 * row['saturated_fraction']:.1f} % | "
            f"{row['ended']} | {'yes' if ok else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def _counts(row: dict) -> bool:
    """Whether a ``policy_cycles`` row counts: no episode ended early, every error ≤ ``TOLERANCE``."""
    worst = max(row["place_error_mm"]["max"], row["pick_error_mm"]["max"])
    return row["ended"] == 0 and worst <= TOLERANCE * 1e3


def _frame_every(dt: float) -> int:
    """The control periods between two frames of a GIF: about 20 ms (at least one)."""
    return max(1, int(round(0.02 / dt)))


#: How the tables name the experts of ``training.distill`` (``distilled_from``).
_EXPERT_NAMES = {"planner": "the planner", "computed-torque": "computed torque"}


def _policy_kind(run: Path, config: dict) -> str:
    """The kind of a run's policy: "A PPO policy", or "A policy distilled from ..." for a training.distill run."""
    expert = config.get("distilled_from")
    if not expert:
        return f"A {config.get('algo', 'ppo').upper()} policy"
    settings = json.loads((run / "distill.json").read_text())["config"] if (run / "distill.json").is_file() else {}
    if settings.get("reference_acceleration"):
        expert = "computed torque with the reference's acceleration fed forward"
    return f"A policy distilled from {_EXPERT_NAMES.get(expert, expert)} (`training.distill`)"


def _table(rows: list[dict], command: str, dt: float, bandwidth: float, limits: np.ndarray) -> str:
    lines = [
        "# The Delta's adept cycle: computed torque on time-optimal trajectories",
        "",
        f"`{command}`",
        "",
        f"Drive limits τ_max = {', '.join(f'{v:g}' for v in limits)} N·m (`DeltaForceReach-v0`'s); control period "
        f"{dt * 1e3:g} ms; ω = {bandwidth:g} rad/s. The trajectory is time-optimal for σ τ_max (TOPP-RA, at rest at "
        "every corner); a cycle counts with both errors ≤ 1 mm.",
        "",
        "| σ | cycle time [s] | place error [mm] | pick error [mm] | largest tracking error [mm] | peak abs(τ)/τ_max "
        "| saturated periods | counts |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        ok = row["place_error_mm"] <= TOLERANCE * 1e3 and row["pick_error_mm"] <= TOLERANCE * 1e3
        lines.append(
            f"| {row['margin']:.2f} | {row['cycle_time_s']:.3f} | {row['place_error_mm']:.3f} | "
            f"{row['pick_error_mm']:.3f} | {row['max_tracking_error_mm']:.2f} | {row['peak_effort']:.2f} | "
            f"{100 * row['saturated_fraction']:.1f} % | {'yes' if ok else 'no'} |"
        )
    best = [r for r in rows if r["place_error_mm"] <= 1.0 and r["pick_error_mm"] <= 1.0]
    if best:
        fastest = min(best, key=lambda r: r["cycle_time_s"])
        lines += ["", f"Shortest cycle that counts: **{fastest['cycle_time_s']:.3f} s** (σ = {fastest['margin']:.2f}).",
                  "", "![the shortest cycle](cycle.gif)"]  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the cycle at every margin and write ``table.md``, ``results.json`` and ``cycle.gif`` under ``--out``."""
    parser = argparse.ArgumentParser(prog="python -m experiments.pick_and_place", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--dt", type=float, default=0.002, help="control period [s]")
    parser.add_argument("--bandwidth", type=float, default=40.0, help="ω of computed torque [rad/s]")
    parser.add_argument("--margins", type=float, nargs="+", default=[1.0, 0.95, 0.9, 0.8, 0.6])
    parser.add_argument("--grid", type=int, default=100, help="TOPP-RA grid intervals per segment")
    parser.add_argument(
        "--policy", type=Path, nargs="+", default=[], help="DeltaForceTrack-v0 run folders (training.train, .distill)"
    )
    parser.add_argument("--model", default="final", choices=("final", "best"))
    parser.add_argument("--periods", type=float, nargs="+", default=[1.0, 1.2, 1.5, 2.0], help="policy cycle times [s]")
    parser.add_argument("--episodes", type=int, default=5, help="policy episodes per period")
    parser.add_argument("--cycles", type=int, default=3, help="cycles per policy episode")
    args = parser.parse_args(argv)
    if not all(0.0 < m <= 1.0 for m in args.margins):
        parser.error(f"--margins must lie in (0, 1], got {args.margins}")
    from training.plots import save_gif

    env = gym.make(ENV_ID, dt=args.dt, max_episode_steps=10**6, render_mode="rgb_array")
    params = env.unwrapped.params
    limits = params.force_limit_array
    points = adept_waypoints(params.robot.home_pose())
    rows = []
    for margin in sorted(args.margins, reverse=True):
        path = TimeOptimalPath(params.dynamics, points, margin * limits, grid=args.grid)
        row = follow(env, path, args.bandwidth)
        row.pop("frames")
        rows.append({"margin": margin, **row})
        print(json.dumps(rows[-1]), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    command = "python -m experiments.pick_and_place " + " ".join(argv if argv is not None else sys.argv[1:])
    table, policy_rows = _table(rows, command, args.dt, args.bandwidth, limits), []
    from training.runs import load_run, run_env_kwargs

    agents = [load_run(run, args.model) for run in args.policy]
    for run, (agent, config) in zip(args.policy, agents, strict=True):
        policy_rows.append([])
        for period in args.periods:
            policy_rows[-1].append(policy_cycles(agent, run_env_kwargs(config), period, args.episodes, args.cycles))
            print(json.dumps(policy_rows[-1][-1]), flush=True)
        table += _policy_table(policy_rows[-1], run, config, args.episodes, args.cycles)
    fastest = min(
        ((row["period_s"], i) for i, rows_ in enumerate(policy_rows) for row in rows_ if _counts(row)), default=None
    )
    if fastest is not None:  # the shortest cycle a policy makes within 1 mm, one cycle of its first episode
        period, i = fastest
        agent, config = agents[i]
        dt = float(gym.make(TRACK_ID, **run_env_kwargs(config)).unwrapped.params.dt)  # the run's control period
        every = _frame_every(dt)
        frames = policy_cycles(agent, run_env_kwargs(config), period, 1, 1, frame_every=every)["frames"]
        save_gif(frames, args.out / "policy_cycle.gif", fps=1.0 / (every * dt))
        table += f"\n`{args.policy[i].name}` at {period:.2f} s, one cycle:\n\n![the policy's cycle](policy_cycle.gif)\n"
    results = {"command": command, "rows": rows, "policies": [str(run) for run in args.policy], "policy": policy_rows}
    (args.out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (args.out / "table.md").write_text(table)
    counted = [r for r in rows if r["place_error_mm"] <= 1.0 and r["pick_error_mm"] <= 1.0]
    if counted:
        fastest = min(counted, key=lambda r: r["cycle_time_s"])
        path = TimeOptimalPath(params.dynamics, points, fastest["margin"] * limits, grid=args.grid)
        every = _frame_every(args.dt)
        frames = follow(env, path, args.bandwidth, frame_every=every)["frames"]
        save_gif(frames, args.out / "cycle.gif", fps=1.0 / (every * args.dt))
    env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
