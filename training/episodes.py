"""Fixed-seed evaluation episodes: single-env and native-vector rollouts, their records and aggregate metrics."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

import envs
from envs.state import TERMINATION_REASONS
from kinematics import SingularConfigurationError
from training.records import EpisodeRecord
from training.runs import Agent, EvaluationError, evaluation_env_kwargs, wrap_for_run, wrap_vector_for_run

__all__ = [
    "SINGULARITY_REASONS",
    "TARGET_SETS",
    "TRACKING_MAX_LAG_S",
    "TRACKING_SETTLING_S",
    "aggregate",
    "evaluate_agent",
    "evaluate_rows",
    "evaluate_vector",
    "make_vector_env",
    "tracking_metrics",
]

#: Termination reasons that mean the robot met a singularity (Type II, and Type I for cranks and sliders).
SINGULARITY_REASONS = ("singular", "singularity_crossed", "assembly_mode_change", "newton_failed", "actuator_singular")
#: The target sets a Reach env's reset option ``targets`` takes.
TARGET_SETS = ("standard", "hard")

#: Settling time excluded from the tracking metrics [s]: the platform starts on the reference, and the first
#: second is the controller's transient.
TRACKING_SETTLING_S = 1.0
#: Largest lag searched when estimating the tracking lag [s].
TRACKING_MAX_LAG_S = 1.0


def tracking_metrics(
    position_errors: np.ndarray,
    orientation_errors: np.ndarray,
    costs: np.ndarray,
    positions: np.ndarray,
    target_positions: np.ndarray,
    dt: float,
) -> dict[str, float]:
    """RMS and maximum tracking errors, cost fraction and lag of one Track episode, after the settling time.

    The lag is the delay τ (a multiple of dt, 0 … ``TRACKING_MAX_LAG_S``) that minimises the mean distance
    between the platform position at t and the target position at t − τ.

    Args:
        position_errors: ‖p* − p‖ per step, including the start [m], shape (T + 1,).
        orientation_errors: Orientation error per step [rad], shape (T + 1,).
        costs: ``cost`` per step (after each action), shape (T,).
        positions: Platform positions [m], shape (T + 1, d).
        target_positions: Target positions [m], shape (T + 1, d).
        dt: Control period [s].

    Returns:
        {"rms_position_mm", "max_position_mm", "rms_orientation_deg", "max_orientation_deg", "cost_fraction",
        "lag_s", "settling_s"}; NaN where the episode ended before the settling time.
    """
    skip = int(round(TRACKING_SETTLING_S / dt))
    pe, oe, cost = position_errors[skip:], orientation_errors[skip:], costs[skip:]
    if pe.size == 0:
        nan = float("nan")
        return dict.fromkeys(
            (
                "rms_position_mm",
                "max_position_mm",
                "rms_orientation_deg",
                "max_orientation_deg",
                "cost_fraction",
                "lag_s",
            ),
            nan,
        ) | {"settling_s": TRACKING_SETTLING_S}
    lags = range(min(int(round(TRACKING_MAX_LAG_S / dt)), len(positions) - skip - 1) + 1)
    mismatch = [
        float(np.mean(np.linalg.norm(positions[skip + s :] - target_positions[skip : len(positions) - s], axis=-1)))
        for s in lags
    ]
    return {
        "rms_position_mm": 1000.0 * float(np.sqrt(np.mean(pe**2))),
        "max_position_mm": 1000.0 * float(np.max(pe)),
        "rms_orientation_deg": float(np.degrees(np.sqrt(np.mean(oe**2)))),
        "max_orientation_deg": float(np.degrees(np.max(oe))),
        "cost_fraction": float(np.mean(cost)) if cost.size else 0.0,
        "lag_s": float(np.argmin(mismatch)) * dt,
        "settling_s": TRACKING_SETTLING_S,
    }


def _target_options(env: Any, targets: str | None) -> dict[str, str] | None:
    """The reset options for ``targets`` (None keeps the env's own setting); refuses what the env cannot take."""
    if targets is None:
        return None
    if targets not in TARGET_SETS:
        raise EvaluationError(f"--targets must be one of {list(TARGET_SETS)}, got {targets!r}")
    base = env.unwrapped
    options = getattr(base, "reset_options", None) or getattr(getattr(base, "_sampler", None), "reset_options", ())
    if "targets" not in options:
        name = env.spec.id if getattr(env, "spec", None) else type(base).__name__
        raise EvaluationError(f"--targets applies only to the Reach environments, not {name}")
    return {"targets": targets}


def _episode_record(
    base: Any,
    episode: int,
    last: dict[str, Any],
    total: float,
    series: dict[str, np.ndarray],
    costs: np.ndarray,
    planner: dict[str, float] | None,
    efforts: tuple[np.ndarray, np.ndarray] | None = None,
) -> EpisodeRecord:
    """The record of one finished episode.

    Args:
        base: The unwrapped env (single or vector: ``with_velocity`` and ``params``).
        episode: Its index.
        last: The last step's info of this episode (scalars).
        total: Sum of its rewards.
        series: "pose", "target" (T + 1, m), "inverse_condition_number", "position_error", "orientation_error",
            "is_success" (T + 1,): from the reset to the last step.
        costs: ``cost`` per step, shape (T,).
        planner: The planning agent's ``episode_metrics``, or None.
        efforts: Under force control, (largest |τ_i| / τ_max,i, saturated) per step, each shape (T,); else None.
    """
    reason = last["termination_reason"]
    tracking = None
    if getattr(base, "with_velocity", False):  # a Track environment
        poses, goal = series["pose"], series["target"]
        d = 3 if poses.shape[1] == 6 else 2  # position coordinates of the pose (spatial or planar)
        tracking = tracking_metrics(
            series["position_error"], series["orientation_error"], costs, poses[:, :d], goal[:, :d],
            float(base.params.dt),
        )  # fmt: skip
    reached = np.flatnonzero(series["is_success"])
    dt = getattr(getattr(base, "params", None), "dt", None)  # the family envs' control period; else unknown
    return EpisodeRecord(
        episode=episode,
        success=bool(last["is_success"]),
        final_position_error_mm=1000.0 * last["position_error"],
        final_orientation_error_deg=float(np.degrees(last["orientation_error"])),
        episode_return=total,
        min_inverse_condition=float(np.min(series["inverse_condition_number"])),
        singularity_termination=reason in SINGULARITY_REASONS,
        termination_reason=reason,
        cost_fraction=float(np.mean(costs)) if costs.size else 0.0,
        length=len(costs),
        poses=series["pose"],
        targets=series["target"],
        inverse_condition=series["inverse_condition_number"],
        tracking=tracking,
        planner=planner,
        time_to_target_s=float(reached[0] * dt) if reached.size and dt is not None else None,
        peak_effort=None if efforts is None or not efforts[0].size else float(np.max(efforts[0])),
        saturation_fraction=None if efforts is None or not efforts[1].size else float(np.mean(efforts[1])),
        target_holding_effort=None if efforts is None else _holding_effort(base.params, series["target"][0]),
    )


def _holding_effort(params: Any, target: np.ndarray) -> float:
    """max_i |τ_h,i| / τ_max,i at ``target`` (m,): the effort that holds the platform still there (NumPy model)."""
    try:
        q = params.robot.inverse_kinematics(target, validate=False)
        return float(np.max(np.abs(params.dynamics.holding_forces(q, target)) / params.force_limit_array))
    except SingularConfigurationError:
        return float("inf")


def _efforts(base: Any, info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """(largest |τ_i| / τ_max,i, saturated) of a step's info (single env: scalars; vector: (N,)); None for rates."""
    if "actuator_forces" not in info:
        return None
    limits = base.params.force_limit_array
    return np.max(np.abs(np.asarray(info["actuator_forces"])) / limits, axis=-1), np.asarray(info["saturated"])


#: The per-step info entries an episode record keeps.
_SERIES = ("pose", "target", "inverse_condition_number", "position_error", "orientation_error", "is_success")


def evaluate_agent(
    agent: Agent,
    env: gym.Env,
    episodes: int,
    seed: int = 0,
    targets: str | None = None,
    frames: list[np.ndarray] | None = None,
    video_episodes: int = 3,
) -> list[EpisodeRecord]:
    """Run fixed-seed episodes (episode i resets with seed + i) and record them.

    Args:
        agent: Batched agent.
        env: A ``gym.make`` environment (with its TimeLimit).
        episodes: Number of episodes.
        seed: Seed of the first episode.
        targets: "standard" or "hard" (Reach environments only); None keeps the env's own setting
            (``Planar3RPRReachHard-v0`` samples hard targets).
        frames: If given, RGB frames of the first ``video_episodes`` episodes are appended to it.
        video_episodes: Episodes to film.

    Returns:
        One record per episode.
    """
    options = _target_options(env, targets)
    records = []
    for episode in range(episodes):
        obs, info = env.reset(seed=seed + episode, options=options)
        series = {key: [info[key]] for key in _SERIES}
        costs: list[float] = []
        efforts: list[tuple[np.ndarray, np.ndarray]] = []
        total, done = 0.0, False
        film = frames is not None and episode < video_episodes
        if film:
            frames.append(env.render())
        while not done:
            batch = {key: value[None] for key, value in obs.items()} if isinstance(obs, dict) else obs[None]
            action = agent(batch)[0]
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            done = terminated or truncated
            for key in _SERIES:
                series[key].append(info[key])
            costs.append(info["cost"])
            effort = _efforts(env.unwrapped, info)
            if effort is not None:
                efforts.append(effort)
            if film:
                frames.append(env.render())
        planner = agent.episode_metrics() if hasattr(agent, "episode_metrics") else None
        arrays = {key: np.array(values) for key, values in series.items()}
        effort_series = tuple(np.array(column) for column in zip(*efforts)) if efforts else None
        records.append(
            _episode_record(env.unwrapped, episode, info, total, arrays, np.array(costs), planner, effort_series)
        )
    return records


def make_vector_env(
    env_id: str, episodes: int, env_kwargs: dict[str, Any] | None = None, shield: float | None = None
) -> gym.vector.VectorEnv:
    """The native vector env of ``env_id`` with one row per episode (behind ``envs.VectorSingularityShield``)."""
    if env_id not in envs.ENV_IDS or gym.spec(env_id).vector_entry_point is None:
        raise EvaluationError(f"{env_id} has no native vector env of envs; ids: {list(envs.ENV_IDS)}")
    venv = gym.make_vec(env_id, num_envs=episodes, vectorization_mode="vector_entry_point", **(env_kwargs or {}))
    return venv if shield is None else envs.VectorSingularityShield(venv, k_guard=shield)


def evaluate_vector(
    agent: Agent, venv: gym.vector.VectorEnv, seed: int = 0, targets: str | None = None
) -> list[EpisodeRecord]:
    """Run one fixed-seed episode per row of a native vector env at once and record them.

    Row i resets with seed + i and is recorded up to its first end, so that its record is the one
    ``evaluate_agent`` makes of episode i on the single env (the vector env's row i is that single env to the
    last bit; a policy's actions for a batch may differ from its actions one at a time in the last bit of
    float32). The agent acts on every row at each step, which is where the time goes: one batched call per step
    instead of one per step and episode.

    Args:
        agent: Batched agent (a ``PlannerController`` plans per row).
        venv: ``make_vector_env(env_id, episodes, ...)``: a native vector env in ``AutoresetMode.NEXT_STEP``
            (rows that end restart at the next step and are no longer recorded).
        seed: Seed of the first row.
        targets: As ``evaluate_agent``.

    Returns:
        One record per row, in row order.
    """
    options = _target_options(venv, targets)
    n = venv.num_envs
    obs, info = venv.reset(seed=seed, options=options)
    series = {key: [np.array(info[key])] for key in _SERIES}
    costs: list[np.ndarray] = []
    efforts: list[tuple[np.ndarray, np.ndarray]] = []
    totals = np.zeros(n)
    active = np.ones(n, dtype=bool)
    ends: dict[int, tuple[int, dict[str, Any], dict[str, float] | None]] = {}
    while active.any():
        obs, reward, terminated, truncated, info = venv.step(agent(obs))
        totals[active] += reward[active]  # the same additions, in the same order, as the single env's loop
        for key in _SERIES:
            series[key].append(np.array(info[key]))
        costs.append(np.array(info["cost"]))
        effort = _efforts(venv.unwrapped, info)
        if effort is not None:
            efforts.append(effort)
        for i in np.flatnonzero(active & (terminated | truncated)):
            last = {
                "is_success": bool(info["is_success"][i]),
                "termination_reason": str(info["termination_reason"][i]),
                "position_error": float(info["position_error"][i]),
                "orientation_error": float(info["orientation_error"][i]),
            }
            planner = agent.episode_metrics(int(i)) if hasattr(agent, "episode_metrics") else None
            ends[int(i)] = (len(costs), last, planner)
            active[i] = False
    stacked = {key: np.stack(values) for key, values in series.items()}
    cost_steps = np.stack(costs)
    peaks, saturated = (np.stack(column) for column in zip(*efforts)) if efforts else (None, None)
    records = []
    for i in range(n):
        length, last, planner = ends[i]
        row = {key: np.ascontiguousarray(values[: length + 1, i]) for key, values in stacked.items()}
        effort = None if peaks is None else (peaks[:length, i], saturated[:length, i])
        records.append(
            _episode_record(
                venv.unwrapped, i, last, float(totals[i]), row, cost_steps[:length, i].copy(), planner, effort
            )
        )
    return records


def evaluate_rows(
    agent: Agent,
    config: dict[str, Any],
    env_id: str,
    episodes: int,
    seed: int,
    targets: str | None,
    shield: float | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> list[EpisodeRecord]:
    """Episodes i = 0 … episodes − 1 (reset seed ``seed + i``) of ``agent`` on ``env_id``, behind the shield if set.

    The env is built with ``env_kwargs`` (default: the run's own but its reward, ``evaluation_env_kwargs(config)``);
    ``config`` is the
    run's config ({} for a classical controller).

    All episodes run at once on the id's native vector env (``evaluate_vector``, with the vector
    form of the run's ``env_wrapper``), except for a run whose wrapper has no vector form (the goal view of HER),
    which runs them one after the other (``evaluate_agent``). The records are the same either way (a policy's
    batched actions aside, which may differ in the last bit of float32). The shield sits inside the run's wrapper:
    it filters the action the env receives (a residual policy's sum).
    """
    env_kwargs = evaluation_env_kwargs(config) if env_kwargs is None else env_kwargs
    if env_id in envs.ENV_IDS:
        plain = make_vector_env(env_id, episodes, env_kwargs, shield)
        venv = wrap_vector_for_run(plain, config)
        try:
            if venv is not None:
                return evaluate_vector(agent, venv, seed, targets)
        finally:
            plain.close()
    env = gym.make(env_id, **env_kwargs)
    if shield is not None:
        env = envs.SingularityShield(env, k_guard=shield)
    env = wrap_for_run(env, config)
    try:
        return evaluate_agent(agent, env, episodes, seed, targets)
    finally:
        env.close()


def aggregate(records: list[EpisodeRecord]) -> dict[str, Any]:
    """Aggregate metrics over episodes (means with standard deviations where it makes sense).

    Args:
        records: Evaluated episodes.

    Returns:
        A JSON-ready dict.
    """

    def stats(values: list[float]) -> dict[str, float]:
        arr = np.asarray(values, dtype=float)
        return {"mean": float(arr.mean()), "std": float(arr.std()), "median": float(np.median(arr))}

    reasons = [r.termination_reason for r in records]
    tracking = {}
    if records and all(r.tracking is not None for r in records):
        keys = [k for k in records[0].tracking if k != "settling_s"]
        tracking = {
            "tracking": {
                "settling_s": records[0].tracking["settling_s"],
                **{k: stats([r.tracking[k] for r in records if np.isfinite(r.tracking[k])] or [np.nan]) for k in keys},
            }
        }
    planner = {}
    if records and all(r.planner is not None for r in records):
        planner = {
            "planner": {
                "path_found_rate": float(np.mean([r.planner["path_found"] for r in records])),
                **{
                    k: stats([r.planner[k] for r in records])
                    for k in ("planned_length_ratio", "planned_min_k", "planning_s")
                },
            }
        }
    reached = [r.time_to_target_s for r in records if r.time_to_target_s is not None]
    time_to_target = {"time_to_target_s": {**stats(reached), "episodes": len(reached)}} if reached else {}
    force = {}
    if records and all(r.peak_effort is not None for r in records):
        force = {
            "peak_effort": {**stats([r.peak_effort for r in records]), "max": max(r.peak_effort for r in records)},
            "saturation_fraction": stats([r.saturation_fraction for r in records]),
        }
        holding = [r.target_holding_effort for r in records if r.target_holding_effort is not None]
        if holding:
            force["target_holding_effort"] = {**stats(holding), "max": max(holding)}
    return {
        "episodes": len(records),
        "success_rate": float(np.mean([r.success for r in records])),
        "final_position_error_mm": stats([r.final_position_error_mm for r in records]),
        "final_orientation_error_deg": stats([r.final_orientation_error_deg for r in records]),
        "return": stats([r.episode_return for r in records]),
        "min_inverse_condition": {
            **stats([r.min_inverse_condition for r in records]),
            "min": float(min(r.min_inverse_condition for r in records)),
        },
        "singularity_terminations": int(sum(r.singularity_termination for r in records)),
        "terminations": {name: reasons.count(name) for name in TERMINATION_REASONS[1:] if reasons.count(name)},
        "cost_fraction": stats([r.cost_fraction for r in records]),
        "episode_length": stats([r.length for r in records]),
        **tracking,
        **planner,
        **time_to_target,
        **force,
    }
