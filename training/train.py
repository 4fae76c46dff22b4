"""Train a Stable-Baselines3 policy on a registered environment and write a self-describing run folder.

Usage::

    python -m training.train --algo ppo --env Planar3RPRReach-v0 [--seed 0] [--timesteps N]
                             [--n-envs K] [--run-dir DIR] [--hyperparams key=value ...]

The run folder holds: ``model.zip`` (final), ``best_model.zip`` (best periodic evaluation),
``vecnormalize.pkl`` and ``best_vecnormalize.pkl`` (their normalisation statistics, when used),
``config.yml`` (the resolved configuration), ``command.txt`` (the exact command),
``monitor/`` (Monitor logs with ``is_success`` and ``cost``),
``evaluations.npz`` (EvalCallback), ``progress.csv`` (SB3's training log), ``learning_curve.png`` and
``summary.json``.
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import envs
from training.config import (
    ALGORITHMS,
    EVAL_DEFAULTS,
    ConfigError,
    algorithm_class,
    load_hyperparams,
    parse_overrides,
    resolve_action_noise,
    resolve_env_wrapper,
    resolve_policy_kwargs,
    resolve_replay_buffer,
    resolve_schedules,
    vector_wrapper,
)

__all__ = ["main", "make_training_env", "train"]

VEC_KINDS = ("native", "dummy", "subproc")


def _check_env_id(env_id: str) -> None:
    if env_id not in envs.ENV_IDS:
        raise ConfigError(f"unknown env id {env_id!r}; valid choices: {list(envs.ENV_IDS)}")


def make_training_env(
    env_id: str,
    n_envs: int,
    seed: int,
    vec: str = "dummy",
    monitor_dir: str | Path | None = None,
    env_kwargs: dict[str, Any] | None = None,
    wrapper_class: type | None = None,
):
    """A vectorised, monitored training environment (SB3 ``VecEnv``).

    Args:
        env_id: A registered id (see ``envs.ENV_IDS``).
        n_envs: Number of environments.
        seed: Seed of the first environment (the others get seed + i).
        vec: "native" (the id's native vector env, ``training.vec_adapter.NativeVecEnvAdapter``, with a
            ``VecMonitor``), "dummy" (one process) or "subproc" (one process per environment).
        monitor_dir: Folder for the Monitor CSV logs (with ``is_success`` and ``cost``), or None.
        env_kwargs: Keyword arguments for ``gym.make`` (or ``gym.make_vec`` for "native").
        wrapper_class: A wrapper applied to each single env over its Monitor; with "native", its vector form
            (``vector_form``) wraps the native vector env.

    Returns:
        The SB3 ``VecEnv``.
    """
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor

    _check_env_id(env_id)
    if vec not in VEC_KINDS:
        raise ConfigError(f"unknown vectorisation {vec!r}; valid choices: {list(VEC_KINDS)}")
    if vec == "native":
        from training.vec_adapter import NativeVecEnvAdapter

        if gym.spec(env_id).vector_entry_point is None:
            raise ConfigError(f"{env_id} has no native vector env; use --vec dummy or subproc")
        vector_form = vector_wrapper(wrapper_class)
        if wrapper_class is not None and vector_form is None:
            name = getattr(wrapper_class, "__name__", None) or wrapper_class.func.__name__
            raise ConfigError(f"env_wrapper {name} wraps single envs; use --vec dummy or subproc")
        adapter = NativeVecEnvAdapter.from_id(env_id, n_envs, vector_form, **(env_kwargs or {}))
        adapter.seed(seed)
        filename = None if monitor_dir is None else str(Path(monitor_dir) / "native.monitor.csv")
        return VecMonitor(adapter, filename=filename, info_keywords=("is_success", "cost"))
    return make_vec_env(
        env_id,
        n_envs=n_envs,
        seed=seed,
        env_kwargs=env_kwargs,
        monitor_dir=None if monitor_dir is None else str(monitor_dir),
        monitor_kwargs={"info_keywords": ("is_success", "cost")},
        wrapper_class=wrapper_class,
        vec_env_cls=SubprocVecEnv if vec == "subproc" else DummyVecEnv,
    )


def read_monitor(folder: Path) -> dict[str, np.ndarray]:
    """Episodes of every Monitor CSV in ``folder``, in the order they ended.

    Args:
        folder: Folder of ``*.monitor.csv`` files (SB3's format: a JSON comment line, then a header).

    Returns:
        Columns "r" (return), "l" (length), "t" (wall time [s]), "is_success" and "cost" (the values of
        the episode's last info, as Monitor records them), each of shape (episodes,).
    """
    rows: list[dict[str, str]] = []
    for path in sorted(Path(folder).glob("*monitor.csv")):
        with open(path, newline="") as fh:
            fh.readline()  # the JSON header line
            rows.extend(csv.DictReader(fh))
    rows.sort(key=lambda row: float(row["t"]))

    def column(name: str) -> np.ndarray:
        return np.array(
            [float(row[name] == "True") if row[name] in ("True", "False") else float(row[name] or 0) for row in rows]
        )

    return (
        {name: column(name) for name in ("r", "l", "t", "is_success", "cost")}
        if rows
        else {name: np.zeros(0) for name in ("r", "l", "t", "is_success", "cost")}
    )


def _plot_learning_curve(run_dir: Path, env_id: str, algo: str) -> Path:
    """Episode return and success (Monitor) and periodic evaluations against timesteps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_r, ax_s) = plt.subplots(1, 2, figsize=(11, 4))
    monitor = read_monitor(run_dir / "monitor")
    if len(monitor["r"]):
        steps = np.cumsum(monitor["l"])
        window = max(1, min(50, len(steps) // 10))
        kernel = np.ones(window) / window
        ax_r.plot(steps, monitor["r"], color="0.8", lw=0.5, label="episode return")
        ax_r.plot(
            steps[window - 1 :], np.convolve(monitor["r"], kernel, mode="valid"), color="C0", label=f"mean of {window}"
        )
        success = np.convolve(monitor["is_success"], kernel, mode="valid")
        ax_s.plot(steps[window - 1 :], success, color="C0", label="training episodes")
    evaluations = run_dir / "evaluations.npz"
    if evaluations.is_file():
        data = np.load(evaluations)
        ax_r.errorbar(
            data["timesteps"],
            data["results"].mean(axis=1),
            yerr=data["results"].std(axis=1),
            color="C3",
            marker="o",
            ms=3,
            label="evaluation",
        )
        if "successes" in data and data["successes"].size:
            ax_s.plot(data["timesteps"], data["successes"].mean(axis=1), "o-", color="C3", ms=3, label="evaluation")
    ax_r.set(xlabel="environment steps", ylabel="return", title=f"{algo.upper()} on {env_id}")
    ax_s.set(xlabel="environment steps", ylabel="success rate", ylim=(-0.02, 1.02), title="success")
    for ax in (ax_r, ax_s):
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
    fig.tight_layout()
    path = run_dir / "learning_curve.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def train(
    algo: str,
    env_id: str,
    *,
    seed: int = 0,
    timesteps: int | None = None,
    n_envs: int | None = None,
    run_dir: str | Path | None = None,
    overrides: dict[str, Any] | None = None,
    config_path: str | Path | None = None,
    vec: str = "dummy",
    progress_bar: bool = True,
    command: str | None = None,
    eval_freq: int | None = None,
    eval_episodes: int | None = None,
) -> Path:
    """Train ``algo`` on ``env_id`` with the shipped hyperparameters (plus overrides); return the run folder.

    Args:
        algo: "ppo", "sac", "td3" or "tqc".
        env_id: A registered id.
        seed: Random seed (environments, networks).
        timesteps: Environment steps; default the config's ``n_timesteps``.
        n_envs: Parallel environments; default the config's ``n_envs``.
        run_dir: Output folder; default ``runs/<algo>-<env>-s<seed>``.
        overrides: Hyperparameters replacing the file's.
        config_path: YAML file; default ``training/<algo>.yml``.
        vec: Vectorisation, "dummy" or "subproc".
        progress_bar: Show SB3's progress bar.
        command: The command line to record; default ``sys.argv``.
        eval_freq: Evaluate every so many environment steps; default ``config.EVAL_DEFAULTS`` of ``algo``.
        eval_episodes: Episodes per periodic evaluation; default ``config.EVAL_DEFAULTS`` of ``algo``.

    Returns:
        The run folder.
    """
    import torch
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    cls = algorithm_class(algo)
    algo = algo.lower()
    _check_env_id(env_id)
    if vec not in VEC_KINDS:
        raise ConfigError(f"unknown vectorisation {vec!r}; valid choices: {list(VEC_KINDS)}")
    counts = {"n_timesteps": timesteps, "n_envs": n_envs}
    overrides = {**(overrides or {}), **{key: value for key, value in counts.items() if value is not None}}
    config = load_hyperparams(algo, env_id, config_path, overrides)
    run = Path(run_dir) if run_dir is not None else Path("runs") / f"{algo}-{env_id}-s{seed}"
    run.mkdir(parents=True, exist_ok=True)
    (run / "monitor").mkdir(exist_ok=True)

    hyper = dict(config)
    total = int(hyper.pop("n_timesteps", 100_000))
    count = int(hyper.pop("n_envs", 1))
    policy = hyper.pop("policy", "MlpPolicy")
    normalize = hyper.pop("normalize", False)
    default_freq, default_episodes = EVAL_DEFAULTS[algo]
    eval_freq = default_freq if eval_freq is None else eval_freq
    n_eval = default_episodes if eval_episodes is None else eval_episodes
    for name, value in (("eval_freq", eval_freq), ("eval_episodes", n_eval)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f"{name} must be an integer ≥ 1, got {value!r}")
    env_kwargs = hyper.pop("env_kwargs", None) or {}
    wrapper = resolve_env_wrapper(hyper.pop("env_wrapper", None))
    if wrapper is not None and vec == "native" and vector_wrapper(wrapper) is None:
        vec = "dummy"  # a wrapper without a vector form applies to single envs only
    if "policy_kwargs" in hyper:
        hyper["policy_kwargs"] = resolve_policy_kwargs(hyper["policy_kwargs"])
    hyper = resolve_replay_buffer(resolve_schedules(hyper))
    noise_type, noise_std = hyper.pop("noise_type", None), hyper.pop("noise_std", None)
    resolve_action_noise(noise_type, noise_std, 1)  # refuse a bad entry before anything is built

    resolved = {
        "algo": algo,
        "env_id": env_id,
        "seed": seed,
        "vec": vec,
        "hyperparams": {**config, "n_timesteps": total, "n_envs": count},
        "eval_freq": eval_freq,
        "eval_episodes": n_eval,
        "versions": _versions(),
    }
    (run / "config.yml").write_text(yaml.safe_dump(resolved, sort_keys=False))
    cmd = command if command is not None else shlex.join([sys.executable, "-m", "training.train", *sys.argv[1:]])
    (run / "command.txt").write_text(cmd + "\n")

    torch.set_num_threads(1)
    venv = make_training_env(env_id, count, seed, vec, run / "monitor", env_kwargs, wrapper)
    # Wrapped like the training env (VecNormalize syncs its statistics through the same wrapper stack).
    eval_vec = "native" if vec == "native" else "dummy"
    eval_env = make_training_env(env_id, 1, seed + 10_000, eval_vec, None, env_kwargs, wrapper)
    if normalize:
        norm = normalize if isinstance(normalize, dict) else {}
        gamma = hyper.get("gamma", 0.99)
        venv = VecNormalize(venv, gamma=gamma, **norm)
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False, gamma=gamma)
    action_noise = resolve_action_noise(noise_type, noise_std, int(np.prod(venv.action_space.shape)))
    if action_noise is not None:
        hyper["action_noise"] = action_noise
    model = cls(policy, venv, seed=seed, verbose=0, device="cpu", **hyper)
    logger = configure(str(run), ["csv"])  # progress.csv in the run folder (SB3 would make a temp folder)
    model.set_logger(logger)
    callback = EvalCallback(
        eval_env,
        n_eval_episodes=n_eval,
        eval_freq=max(eval_freq // count, 1),
        log_path=str(run),
        best_model_save_path=str(run),
        callback_on_new_best=_SaveNormalization(run / "best_vecnormalize.pkl") if normalize else None,
        deterministic=True,
        verbose=0,
    )
    start = time.perf_counter()
    try:
        model.learn(total_timesteps=total, callback=callback, progress_bar=progress_bar)
    finally:
        logger.close()  # the CSV file, else left open until garbage collection (a ResourceWarning)
    wall = time.perf_counter() - start
    model.save(run / "model.zip")
    if normalize:
        venv.save(str(run / "vecnormalize.pkl"))
    _plot_learning_curve(run, env_id, algo)
    summary = {
        "wall_time_s": round(wall, 1),
        "timesteps": int(model.num_timesteps),
        "best_mean_reward": float(callback.best_mean_reward),
    }
    (run / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    venv.close()
    eval_env.close()
    return run


def _SaveNormalization(path: Path):  # a class factory: SB3 is imported lazily
    """A callback that saves the training VecNormalize statistics next to each new best model."""
    from stable_baselines3.common.callbacks import BaseCallback

    class SaveNormalization(BaseCallback):
        def _on_step(self) -> bool:
            normalizer = self.model.get_vec_normalize_env()
            if normalizer is not None:
                normalizer.save(str(path))
            return True

    return SaveNormalization()


def _versions() -> dict[str, str]:
    import stable_baselines3
    import torch

    return {
        "python": platform.python_version(),
        "numpy": str(np.__version__),
        "gymnasium": str(gym.__version__),
        "stable_baselines3": str(stable_baselines3.__version__),
        "torch": str(torch.__version__),
    }


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(prog="python -m training.train", description=__doc__.split("\n")[0])
    parser.add_argument("--algo", required=True, help=f"one of {sorted(ALGORITHMS)}")
    parser.add_argument("--env", required=True, help=f"one of {list(envs.ENV_IDS)}")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timesteps", type=int, default=None, help="default: the config's n_timesteps")
    parser.add_argument("--n-envs", type=int, default=None, help="default: the config's n_envs")
    parser.add_argument("--run-dir", default=None, help="default: runs/<algo>-<env>-s<seed>")
    parser.add_argument("--config", default=None, help="YAML file; default training/<algo>.yml")
    parser.add_argument(
        "--vec",
        default="native",
        help=f"one of {list(VEC_KINDS)}; default native (every registered id has a native vector env)",
    )
    parser.add_argument(
        "--hyperparams", nargs="*", default=[], metavar="KEY=VALUE", help="override config keys (YAML values)"
    )
    parser.add_argument("--no-progress-bar", action="store_true", help="hide SB3's progress bar")
    parser.add_argument(
        "--eval-freq", type=int, default=None, help="evaluate every so many env steps (default per algorithm)"
    )
    parser.add_argument(
        "--eval-episodes", type=int, default=None, help="episodes per periodic evaluation (default per algorithm)"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m training.train``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.timesteps is not None and args.timesteps < 1:
            raise ConfigError(f"--timesteps must be ≥ 1, got {args.timesteps}")
        if args.n_envs is not None and args.n_envs < 1:
            raise ConfigError(f"--n-envs must be ≥ 1, got {args.n_envs}")
        run = train(
            args.algo,
            args.env,
            seed=args.seed,
            timesteps=args.timesteps,
            n_envs=args.n_envs,
            run_dir=args.run_dir,
            overrides=parse_overrides(args.hyperparams),
            config_path=args.config,
            vec=args.vec,
            progress_bar=not args.no_progress_bar,
            eval_freq=args.eval_freq,
            eval_episodes=args.eval_episodes,
        )
    except ConfigError as exc:
        parser.error(str(exc))
    print(f"run folder: {run}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
