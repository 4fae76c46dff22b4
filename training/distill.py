"""Plan-free policies: the planner distilled into an SB3 policy by behaviour cloning, then DAgger.

Usage::

    python -m training.distill --env Planar3RPRReachMixed-v0 --seed 1 --run-dir runs/distill-3rpr-s1
    python -m training.evaluate --run runs/distill-3rpr-s1 --env Planar3RPRReach-v0 --targets hard --episodes 100

The *expert* is ``robot_control.controllers.PlannerController`` whose ``robot_control.planner.PathFollower`` plans
afresh whenever the platform is more than ``replan_distance`` from its path, so that its action is a function of the
pose and the target alone (what a policy that sees only the observation can learn); under force control
(``control="force"``) it is computed torque along that path (``PlannerComputedTorqueAgent``). With ``--expert
computed-torque`` it is computed torque toward the observed target (Reach and Track ids), and with
``--reference-acceleration`` a privileged teacher that also feeds forward the Track reference's acceleration, read
from the env's state (``training.distill_rollouts.ReferenceTeacher``). The *learner* is Stable-Baselines3
PPO's ``MlpPolicy`` on the env's own observation, normalised by fixed statistics of the expert's data (no planner
at run time). Training (the DAgger of Ross, Gordon and Bagnell, 2011, written on SB3's policy class because the
``imitation`` library pins Gymnasium 0.29):

1. Behaviour cloning: ``expert_episodes`` episodes driven by the expert; the learner's Gaussian mean is fitted to
   the expert's actions (mean squared error, Adam) on the (observation, action) pairs.
2. DAgger: ``iterations`` rounds of ``episodes`` episodes in which the learner acts (the expert instead, per
   step, with probability β: ``beta`` in the first round, 0 after) and the expert labels every state visited;
   the learner is refitted on all pairs gathered so far. With ``band_weight`` w > 0 each pair's squared error is
   weighted by 1 + w · clip((k_safe − k) / (k_safe − k_hard), 0, 1), where k is the inverse condition number of
   J_x at the pair's state and k_safe, k_hard are the env's ``safe_threshold`` and ``hard_threshold``: the few
   states near the band, where an error of a few per cent of the rate range ends the episode, weigh up to 1 + w
   times the many far from it.
3. With ``select_round="best"``, the learner of the round that did best when it acted (success rate minus
   singularity terminations per episode (every reason of ``training.evaluate.SINGULARITY_REASONS``, Newton
   failures and assembly-mode changes included), on that round's training episodes; the last learner is scored on
   ``episodes`` more) is kept, as DAgger's guarantee is for the best of its policies; with "last", the last one.
   With "validated", every round's learner (the behaviour-cloned one included) acts alone on the same
   ``select_episodes`` hard and ``select_episodes`` standard validation episodes (reset seeds from
   ``3_000_000 · (seed + 1)`` on, away from the training and the evaluation seeds; no expert, no labels) and the
   one with the highest success rate minus singularity terminations per episode, over both sets, is kept: the
   rounds' own training episodes are few and on mixed targets, so their scores differ by less than their noise.
4. Optionally ``ppo_steps`` of PPO fine-tuning of the folder, in place (``finetune``).

With ``start_episodes`` N > 0, each round (behaviour cloning included) also runs N episodes cut after
``start_steps`` steps, acted as the round's full episodes are and labelled the same way: most pairs of full
episodes hold the platform at its target, while the approach, where a step at full speed beside a thin band must
be precise (the 3-RRR), is a few per cent of them.

With ``damped_output``, ``hold_fraction`` or ``error_gain`` the learner is ``training.policies.PlanFreeMlpPolicy``,
whose mean passes through fixed layers of the observation: the expert's own damping factor f(k) of the observed k
(the network then fits the undamped step), an in-position hold (the mean is 0 while the observed errors are within
``hold_fraction`` times the env's success tolerances), and an error gain (the network gives a matrix that
multiplies the observed pose error, so that the action is 0 at the target).

With ``platform_loss`` λ > 0 each pair's loss also counts the platform motion its action error causes:
λ ‖G (μ(o) − a)‖², G = diag(1/tolerances) · J_f(q, x) · max_rate · dt (``platform_gains``), the one-step pose
change of a unit action error in success tolerances at the pair's state. Beside a Type II band J_f is large, and an
action error too small to matter elsewhere turns the platform into the band; the plain squared error weighs it
as it weighs the same error far from the band.

With ``action_noise`` σ > 0 every training episode (the expert's, the cut ones and the learner's) executes its action
plus Gaussian noise of standard deviation σ per actuator (in units of the rate range, clipped to it), while the
label stays the expert's clean action: the noise injection of DART (Laskey et al., 2017). The learner then sees
labelled states around its own path, in the directions its errors take it, rather than only on it. The rounds'
figures (and the ``select_round="best"`` scores) are those of the noisy episodes.

With ``previous_action`` the learner sees its own previous action too (``envs.PreviousActionWrapper``, named as
the run's ``env_wrapper``): the direction it is moving in, which tells the way around already taken where the
pose alone leaves two about equally good; the expert still reads the env's own observation.

``finetune`` (``--from-run``) fine-tunes a distilled run with PPO on the env's own reward: the critic alone is
fitted first (``warmup_steps``, the actor frozen, so that the first policy updates use a value function of the
distilled policy rather than a random one), then actor and critic together with a small step (learning rate
``learning_rate``, clip range 0.1 and an early stop at a KL divergence of ``target_kl`` per update).

The run folder is a ``training.train`` run folder (``config.yml``, ``model.zip``, ``vecnormalize.pkl``), so
``training.evaluate --run`` scores it like any other; ``distill.json`` holds the per-round figures and the time
per decision of the learner against the expert's planning time. Episodes reset with seeds from
``1_000_000 · (seed + 1)`` on, away from the evaluation seeds.
"""

from __future__ import annotations

import copy
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from training.distill_config import DistillConfig, FinetuneConfig, build_parser, config_from_args
from training.distill_learner import _make_env, _normalizer, _policy, band_weights, fit, pair_loss, platform_gains
from training.distill_rollouts import _expert, collect, validate
from training.evaluate import EvaluationError, parse_env_kwargs
from training.finetune import finetune

__all__ = [
    "DistillConfig",
    "FinetuneConfig",
    "band_weights",
    "collect",
    "distill",
    "finetune",
    "fit",
    "main",
    "pair_loss",
    "platform_gains",
    "validate",
]


def distill(config: DistillConfig, run_dir: Path, log=print) -> dict[str, Any]:
    """Train a plan-free policy (see the module docstring) and write its run folder; returns the figures."""
    import torch
    from stable_baselines3 import PPO

    torch.manual_seed(config.seed)
    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(config.seed)
    env = _make_env(config)
    expert = _expert(env, config)
    seed = 1_000_000 * (config.seed + 1)
    clock = time.perf_counter()
    params = env.unwrapped.params

    def weigh(k: np.ndarray) -> np.ndarray:
        return band_weights(k, params.safe_threshold, params.hard_threshold, config.band_weight)

    def gains(states: np.ndarray) -> np.ndarray | None:
        """√λ G of each pair (``platform_gains``), or None without a platform loss."""
        if config.platform_loss == 0.0:
            return None
        return np.sqrt(config.platform_loss) * platform_gains(params, states)

    def with_starts(obs, act, k, states, learner, beta):
        """The round's pairs and those of its ``start_episodes`` cut episodes (each array concatenated)."""
        nonlocal seed
        if config.start_episodes == 0:
            return obs, act, k, states
        more = collect(
            env, expert, learner, config.start_episodes, beta, seed, rng, config.start_steps, noise=config.action_noise
        )
        seed += config.start_episodes
        return tuple(np.concatenate([a, b]) for a, b in zip((obs, act, k, states), (*more[:3], more[4]), strict=True))

    weigh(np.zeros(1))  # refuse a bad band weight before any episode
    obs, act, k, figures, states = collect(
        env, expert, None, config.expert_episodes, 1.0, seed, rng, noise=config.action_noise
    )
    seed += config.expert_episodes
    obs, act, k, states = with_starts(obs, act, k, states, None, 1.0)
    rounds = [{"round": 0, "beta": 1.0, "pairs": len(obs), **figures, "seconds": time.perf_counter() - clock}]
    log(f"expert: {figures['success_rate']:.0%} success, {len(obs)} pairs")
    normalizer = _normalizer(config, obs)
    policy_name, policy_kwargs = _policy(config, params, normalizer)
    model = PPO(policy_name, normalizer, seed=config.seed, device="cpu", policy_kwargs=policy_kwargs, verbose=0)
    policy = model.policy

    def learner(o: np.ndarray) -> np.ndarray:
        action, _ = model.predict(normalizer.normalize_obs(o[None]), deterministic=True)
        return np.clip(action[0], -1.0, 1.0)

    all_obs, all_act, all_k, all_states = [obs], [act], [k], [states]
    rounds[0]["mse"] = fit(policy, normalizer.normalize_obs(obs), act, config, config.seed, weigh(k), gains(states))
    snapshots = [copy.deepcopy(policy.state_dict())]  # the learner after each round's fit
    for r in range(1, config.iterations + 1):
        clock = time.perf_counter()
        beta = config.beta if r == 1 else 0.0
        obs, act, k, figures, states = collect(
            env, expert, learner, config.episodes, beta, seed, rng, noise=config.action_noise
        )
        seed += config.episodes
        obs, act, k, states = with_starts(obs, act, k, states, learner, beta)
        all_obs.append(obs)
        all_act.append(act)
        all_k.append(k)
        all_states.append(states)
        data_obs, data_act = np.concatenate(all_obs), np.concatenate(all_act)
        data_weights, data_gains = weigh(np.concatenate(all_k)), gains(np.concatenate(all_states))
        mse = fit(
            policy, normalizer.normalize_obs(data_obs), data_act, config, config.seed + r, data_weights, data_gains
        )
        rounds.append(
            {"round": r, "beta": beta, "pairs": len(data_obs), **figures, "mse": mse,
             "seconds": time.perf_counter() - clock}
        )  # fmt: skip
        snapshots.append(copy.deepcopy(policy.state_dict()))
        log(
            f"round {r} (β {beta}): learner {figures['success_rate']:.0%} success, "
            f"{figures['singular_terminations']:.2f} singular/episode; {len(data_obs)} pairs, fit loss {mse:.4f}"
        )
    kept = len(snapshots) - 1
    if config.select_round == "best" and config.iterations > 0:
        # the last learner has not acted yet: score it on as many fresh training episodes
        _, _, _, figures, _ = collect(env, expert, learner, config.episodes, 0.0, seed, rng, noise=config.action_noise)
        seed += config.episodes
        rounds.append({"round": len(snapshots), "beta": 0.0, "scoring_only": True, **figures})
        # round r's figures score the learner fitted after round r − 1 (rounds with β > 0 are the expert's too)
        scores = {
            r["round"] - 1: r["success_rate"] - r["singular_terminations"] for r in rounds[1:] if r["beta"] == 0.0
        }
        kept = max(scores, key=lambda i: (scores[i], i))
        policy.load_state_dict(snapshots[kept])
        log(f"kept the learner of round {kept} (score {scores[kept]:.2f}: success − singular per episode)")
    elif config.select_round == "validated":
        validation = []
        for i, snapshot in enumerate(snapshots):
            policy.load_state_dict(snapshot)
            figures = validate(env, learner, config.select_episodes, 3_000_000 * (config.seed + 1))
            validation.append(
                {"round": i, **figures, "score": figures["success_rate"] - figures["singular_terminations"]}
            )
            log(
                f"validated round {i}: {figures['success_rate']:.1%} success, "
                f"{figures['singular_terminations']:.3f} singular/episode"
            )
        kept = max(range(len(snapshots)), key=lambda i: (validation[i]["score"], i))
        policy.load_state_dict(snapshots[kept])
        rounds_validation = validation
        log(f"kept the learner of round {kept} (validation score {validation[kept]['score']:.3f})")
    model.save(run_dir / "model.zip")
    normalizer.save(str(run_dir / "vecnormalize.pkl"))
    # time per decision of the learner (one observation) against the expert's planning time per episode
    sample = np.concatenate(all_obs)[:200]
    clock = time.perf_counter()
    for o in sample:
        learner(o)
    decision_s = (time.perf_counter() - clock) / len(sample)
    planning = [p["mean_planning_s"] for p in rounds if p["mean_planning_s"] > 0]
    result = {
        "config": asdict(config),
        "rounds": rounds,
        "kept_round": kept,
        **({"validation": rounds_validation} if config.select_round == "validated" else {}),
        "decision_s": decision_s,
        "expert_planning_s": float(np.mean(planning)) if planning else 0.0,
    }
    (run_dir / "distill.json").write_text(json.dumps(result, indent=2))
    hyperparams = {
        "policy": policy_name if isinstance(policy_name, str) else f"{policy_name.__module__}.{policy_name.__name__}",
        "normalize": {"norm_obs": True, "norm_reward": False},
        "policy_kwargs": policy_kwargs,
        **({"env_kwargs": dict(config.env_kwargs)} if config.env_kwargs else {}),
        **({"env_wrapper": "envs.PreviousActionWrapper"} if config.previous_action else {}),
    }
    run_config = {
        "algo": "ppo",
        "env_id": config.env_id,
        "seed": config.seed,
        "vec": "dummy",
        "hyperparams": hyperparams,
        "distilled_from": config.expert,
    }
    (run_dir / "config.yml").write_text(yaml.safe_dump(run_config, sort_keys=False))
    (run_dir / "command.txt").write_text(" ".join(["python -m training.distill", *sys.argv[1:]]) + "\n")
    if config.ppo_steps > 0:  # fine-tune the folder in place
        result["finetune"] = finetune(run_dir, run_dir, FinetuneConfig(steps=config.ppo_steps, seed=config.seed), log)
    return result


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = build_parser(__doc__.splitlines()[0])
    args = parser.parse_args(argv)
    if args.from_run is not None:
        steps = args.ppo_steps or FinetuneConfig.steps
        if steps < 1 or args.warmup_steps < 0:
            parser.error(f"--ppo-steps must be ≥ 1 and --warmup-steps ≥ 0, got {steps} and {args.warmup_steps}")
        if not np.isfinite(args.log_std):
            parser.error(f"--log-std must be finite, got {args.log_std}")
        try:
            config = FinetuneConfig(
                steps,
                args.warmup_steps,
                log_std=args.log_std,
                seed=args.seed,
                reward_kwargs=parse_env_kwargs(args.reward_kwargs),
            )
            finetune(Path(args.from_run), Path(args.run_dir), config)
        except (ValueError, FileNotFoundError, EvaluationError) as exc:
            parser.error(str(exc))
        return 0
    config = config_from_args(parser, args)
    distill(config, Path(args.run_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main())
