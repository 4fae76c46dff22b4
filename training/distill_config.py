"""Settings of a distillation and of its PPO fine-tuning, and the command line of ``training.distill``."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import envs
from training.evaluate import EvaluationError, parse_env_kwargs

__all__ = ["EXPERTS", "DistillConfig", "FinetuneConfig", "build_parser", "config_from_args"]

#: The labelling experts ``training.distill`` knows (``DistillConfig.expert``).
EXPERTS = ("planner", "computed-torque")


@dataclass(frozen=True)
class DistillConfig:
    """Settings of one distillation run (the command-line options of ``main``)."""

    env_id: str = "Planar3RPRReachMixed-v0"
    #: Keyword arguments of ``gym.make`` (``{"targets": "mixed"}`` on a robot without a Mixed id).
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    expert_episodes: int = 200
    iterations: int = 6
    episodes: int = 100
    beta: float = 0.5
    epochs: int = 15
    batch_size: int = 256
    learning_rate: float = 1e-3
    net_arch: tuple[int, ...] = (256, 256)
    planner: str = "auto"
    replan_distance: float = 0.03
    lookahead: float = 0.1
    ppo_steps: int = 0
    #: "last": keep the last round's learner; "best": the round's learner that did best when it acted;
    #: "validated": the one that does best on ``select_episodes`` validation episodes per target set.
    select_round: str = "last"
    select_episodes: int = 200
    #: The expert's speed damping near the band (``PlannerController``'s ``damping``; the shipped plan-free
    #: policies were distilled with it).
    expert_damping: bool = False
    #: k_d of the expert's damping (``PlannerController``'s ``damping_threshold``); None: the env's k_safe.
    damping_threshold: float | None = None
    #: The expert's ``PlannerController`` ``damping_kind``: "scale" or "cap".
    damping_kind: str = "scale"
    #: w of the band weighting of the fit (0: every pair weighs the same; see the module docstring).
    band_weight: float = 0.0
    #: Anneal each fit's learning rate to 0 on a cosine over its epochs (False: constant ``learning_rate``), so
    #: that the learner a round keeps is a converged iterate rather than the last of Adam's full-size steps.
    lr_decay: bool = False
    #: Label with the first-order resolved-rate step J_i ẋ (``PlannerController``'s ``exact_step=False``) instead
    #: of the exact step to the aimed pose.
    first_order_expert: bool = False
    #: The learner also sees its own previous action (``envs.PreviousActionWrapper``; the run's ``env_wrapper``).
    previous_action: bool = False
    #: Each round also runs this many episodes cut after ``start_steps`` steps (the expert acting in round 0, as
    #: the round's full episodes otherwise): the approach, where a step at full speed beside the band must be
    #: precise, is a few per cent of full episodes' pairs, most of which hold the platform at its target.
    start_episodes: int = 0
    start_steps: int = 40
    #: The learner's mean is its network's output times the expert's damping factor of the observed k
    #: (``training.policies.PlanFreeMlpPolicy``); needs ``expert_damping`` with ``damping_kind`` "scale".
    damped_output: bool = False
    #: h > 0: the learner's mean is 0 while the observed position and orientation errors are within h times the
    #: env's success tolerances (``training.policies.PlanFreeMlpPolicy``'s in-position hold); 0: no hold.
    hold_fraction: float = 0.0
    #: The learner's network gives a gain matrix that multiplies the observed pose error
    #: (``training.policies.PlanFreeMlpPolicy``'s error gain): its action is 0 at the target.
    error_gain: bool = False
    #: λ ≥ 0 of the platform term λ ‖G (μ(o) − a)‖² of each pair's loss (``platform_gains``; 0: none).
    platform_loss: float = 0.0
    #: σ ≥ 0 of the Gaussian noise on every training episode's executed action (DART; 0: none).
    action_noise: float = 0.0
    #: The labelling expert: "planner" (the planner controller; under force control, computed torque along the
    #: planner's path) or "computed-torque" (force control: computed torque toward the observed target, on Track
    #: ids with the reference's observed velocity fed forward).
    expert: str = "planner"
    #: ω [rad/s] of the computed-torque experts' error dynamics (K_p = ω², K_d = 2 ω).
    bandwidth: float = 4.0
    #: The computed-torque expert also feeds forward the Track reference's acceleration, read from the env's
    #: state (``training.distill_rollouts.ReferenceTeacher``, a privileged teacher).
    reference_acceleration: bool = False

    def __post_init__(self) -> None:
        if self.expert not in EXPERTS:
            raise ValueError(f"expert must be one of {EXPERTS}, got {self.expert!r}")
        if not (np.isfinite(self.bandwidth) and self.bandwidth > 0.0):
            raise ValueError(f"bandwidth must be finite and > 0 [rad/s], got {self.bandwidth}")
        if self.reference_acceleration and self.expert != "computed-torque":
            raise ValueError(f"reference_acceleration needs the computed-torque expert, got {self.expert!r}")
        if not (np.isfinite(self.action_noise) and 0.0 <= self.action_noise < 1.0):
            raise ValueError(f"action_noise must be in [0, 1), got {self.action_noise}")
        if not (np.isfinite(self.platform_loss) and self.platform_loss >= 0.0):
            raise ValueError(f"platform_loss must be finite and ≥ 0, got {self.platform_loss}")
        if not 0.0 <= self.hold_fraction < 1.0:
            raise ValueError(f"hold_fraction must be in [0, 1), got {self.hold_fraction}")
        if self.start_episodes < 0 or self.start_steps < 1:
            raise ValueError(
                f"start_episodes must be ≥ 0 and start_steps ≥ 1, got {self.start_episodes} and {self.start_steps}"
            )
        if self.damped_output and not (self.expert_damping and self.damping_kind == "scale"):
            raise ValueError(
                "damped_output needs expert_damping with damping_kind 'scale' (the label is then f times the "
                f"network's target), got expert_damping={self.expert_damping}, damping_kind={self.damping_kind!r}"
            )


@dataclass(frozen=True)
class FinetuneConfig:
    """Settings of a PPO fine-tuning of a distilled run (``finetune``)."""

    steps: int = 1_000_000
    warmup_steps: int = 100_000
    n_envs: int = 16
    n_steps: int = 128
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 1e-4
    clip_range: float = 0.1
    target_kl: float = 0.02
    gamma: float = 0.98
    gae_lambda: float = 0.95
    log_std: float = -1.6
    seed: int = 0
    #: Env keyword arguments of the fine-tuning env only, over the distilled run's (a reward setting such as
    #: ``termination_penalty``); the run folder keeps the distilled run's, so it is evaluated on the env it was
    #: distilled on.
    reward_kwargs: dict[str, Any] = field(default_factory=dict)


def build_parser(description: str) -> argparse.ArgumentParser:
    """The command line of ``python -m training.distill`` (``description``: its first line of help)."""
    defaults = DistillConfig()
    parser = argparse.ArgumentParser(prog="python -m training.distill", description=description)
    parser.add_argument(
        "--env",
        default=defaults.env_id,
        help="a Reach id, or a Track id with --expert computed-torque (default %(default)s)",
    )
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--run-dir", required=True)
    parser.add_argument(
        "--env-kwargs", nargs="*", default=[], metavar="KEY:VALUE", help="gym.make keyword arguments (targets:mixed)"
    )
    counts = ("expert_episodes", "iterations", "episodes", "epochs", "batch_size", "ppo_steps")
    for name in (*counts, "start_episodes", "start_steps"):
        parser.add_argument("--" + name.replace("_", "-"), type=int, default=getattr(defaults, name))
    for name in ("beta", "learning_rate", "replan_distance", "lookahead", "band_weight"):
        parser.add_argument("--" + name.replace("_", "-"), type=float, default=getattr(defaults, name))
    parser.add_argument(
        "--net-arch",
        type=int,
        nargs="+",
        default=list(defaults.net_arch),
        metavar="WIDTH",
        help="the learner's hidden layer widths (default %(default)s)",
    )
    parser.add_argument("--planner", default=defaults.planner, choices=("auto", "ompl", "grid"))
    parser.add_argument(
        "--expert",
        default=defaults.expert,
        choices=EXPERTS,
        help="the labelling expert: the planner controller (force control: computed torque along its path) or "
        "computed torque toward the observed target (force control; default %(default)s)",
    )
    parser.add_argument(
        "--bandwidth", type=float, default=defaults.bandwidth, help="ω [rad/s] of a computed-torque expert"
    )
    parser.add_argument(
        "--reference-acceleration",
        action="store_true",
        help="the computed-torque expert also feeds forward the Track reference's acceleration (a privileged teacher)",
    )
    parser.add_argument(
        "--select-round",
        default=defaults.select_round,
        choices=("last", "best", "validated"),
        help="keep the last round's learner, the one that did best when it acted, or the one that does best on "
        "--select-episodes validation episodes per target set (default %(default)s)",
    )
    parser.add_argument("--select-episodes", type=int, default=defaults.select_episodes)
    parser.add_argument(
        "--expert-damping", action="store_true", help="label with the planner controller's damping near the band"
    )
    parser.add_argument(
        "--damping-threshold",
        type=float,
        default=None,
        help="k below which the expert's damping slows down (with --expert-damping; default the env's k_safe)",
    )
    parser.add_argument(
        "--damping-kind",
        default=DistillConfig.damping_kind,
        choices=("scale", "cap"),
        help="the expert's damping: scale the action, or cap its largest rate (default %(default)s)",
    )
    parser.add_argument(
        "--lr-decay", action="store_true", help="anneal each fit's learning rate to 0 on a cosine over its epochs"
    )
    parser.add_argument(
        "--first-order-expert",
        action="store_true",
        help="label with the first-order step J_i xdot instead of the exact step to the aimed pose",
    )
    parser.add_argument(
        "--previous-action",
        action="store_true",
        help="the learner also sees its own previous action (envs.PreviousActionWrapper)",
    )
    parser.add_argument(
        "--damped-output",
        action="store_true",
        help="the learner's action is its network's output times the expert's damping of the observed k "
        "(training.policies.PlanFreeMlpPolicy; needs --expert-damping)",
    )
    parser.add_argument(
        "--error-gain",
        action="store_true",
        help="the learner's network gives a gain matrix times the observed pose error "
        "(training.policies.PlanFreeMlpPolicy): its action is 0 at the target",
    )
    parser.add_argument(
        "--hold-fraction",
        type=float,
        default=defaults.hold_fraction,
        help="the learner's action is 0 while its observed errors are within this fraction of the success "
        "tolerances (training.policies.PlanFreeMlpPolicy's in-position hold; default %(default)s: none)",
    )
    parser.add_argument(
        "--platform-loss",
        type=float,
        default=defaults.platform_loss,
        help="λ of the loss's platform term λ ‖G (μ − a)‖², G = J_f · max_rate · dt over the success tolerances: "
        "the pose change an action error causes (default %(default)s: none)",
    )
    parser.add_argument(
        "--action-noise",
        type=float,
        default=defaults.action_noise,
        help="σ of the Gaussian noise on every training episode's executed action, in units of the rate range; "
        "the labels stay the expert's (DART; default %(default)s: none)",
    )
    parser.add_argument(
        "--from-run", default=None, help="fine-tune this distilled run with PPO (--ppo-steps, default 1M) instead"
    )
    parser.add_argument("--warmup-steps", type=int, default=FinetuneConfig.warmup_steps, help="critic-only steps")
    parser.add_argument(
        "--log-std",
        type=float,
        default=FinetuneConfig.log_std,
        help="the fine-tuned policy's initial log σ of its Gaussian (default %(default)s)",
    )
    parser.add_argument(
        "--reward-kwargs",
        nargs="*",
        default=[],
        metavar="KEY:VALUE",
        help="env keyword arguments of the fine-tuning env only (termination_penalty:200)",
    )
    return parser


def config_from_args(parser: argparse.ArgumentParser, args: argparse.Namespace) -> DistillConfig:
    """The distillation the parsed command line asks for; ``parser.error`` (exit 2) on a refused option."""
    kinds = ("Reach", "Track") if args.expert == "computed-torque" else ("Reach",)
    if args.env not in envs.ENV_IDS or not any(kind in args.env for kind in kinds):
        parser.error(f"--env must be a {' or '.join(kinds)} id of {envs.ENV_IDS}, got {args.env!r}")
    if "Track" in args.env and args.select_round == "validated":
        parser.error("--select-round validated scores standard and hard targets: a Reach id only")
    if not (np.isfinite(args.bandwidth) and args.bandwidth > 0.0):
        parser.error(f"--bandwidth must be finite and > 0, got {args.bandwidth}")
    if args.reference_acceleration and args.expert != "computed-torque":
        parser.error("--reference-acceleration needs --expert computed-torque")
    for name in ("expert_episodes", "epochs", "batch_size", "select_episodes", "start_steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be ≥ 1, got {getattr(args, name)}")
    if min(args.net_arch) < 1:
        parser.error(f"--net-arch widths must be ≥ 1, got {args.net_arch}")
    if not 0.0 <= args.hold_fraction < 1.0:
        parser.error(f"--hold-fraction must be in [0, 1), got {args.hold_fraction}")
    if args.start_episodes < 0:
        parser.error(f"--start-episodes must be ≥ 0, got {args.start_episodes}")
    if not 0.0 <= args.beta <= 1.0:
        parser.error(f"--beta must be in [0, 1], got {args.beta}")
    if args.damping_threshold is not None and not (args.expert_damping and 0.0 < args.damping_threshold <= 1.0):
        parser.error(f"--damping-threshold needs --expert-damping and a value in (0, 1], got {args.damping_threshold}")
    if args.damping_kind != DistillConfig.damping_kind and not args.expert_damping:
        parser.error(f"--damping-kind {args.damping_kind} needs --expert-damping")
    if args.damped_output and not (args.expert_damping and args.damping_kind == "scale"):
        parser.error(
            "--damped-output needs --expert-damping and --damping-kind scale, got "
            f"{'' if args.expert_damping else 'no '}--expert-damping and --damping-kind {args.damping_kind}"
        )
    for name in ("band_weight", "platform_loss"):
        if not (np.isfinite(getattr(args, name)) and getattr(args, name) >= 0.0):
            parser.error(f"--{name.replace('_', '-')} must be finite and ≥ 0, got {getattr(args, name)}")
    if not (np.isfinite(args.action_noise) and 0.0 <= args.action_noise < 1.0):
        parser.error(f"--action-noise must be in [0, 1), got {args.action_noise}")
    try:
        env_kwargs = parse_env_kwargs(args.env_kwargs)
    except EvaluationError as exc:
        parser.error(str(exc))
    return DistillConfig(
        env_id=args.env,
        env_kwargs=env_kwargs,
        seed=args.seed,
        expert_episodes=args.expert_episodes,
        iterations=args.iterations,
        episodes=args.episodes,
        beta=args.beta,
        epochs=args.epochs,
        batch_size=args.batch_size,
        learning_rate=args.learning_rate,
        net_arch=tuple(args.net_arch),
        planner=args.planner,
        replan_distance=args.replan_distance,
        lookahead=args.lookahead,
        ppo_steps=args.ppo_steps,
        expert_damping=args.expert_damping,
        select_round=args.select_round,
        select_episodes=args.select_episodes,
        band_weight=args.band_weight,
        lr_decay=args.lr_decay,
        damping_threshold=args.damping_threshold,
        damping_kind=args.damping_kind,
        previous_action=args.previous_action,
        first_order_expert=args.first_order_expert,
        damped_output=args.damped_output,
        hold_fraction=args.hold_fraction,
        error_gain=args.error_gain,
        start_episodes=args.start_episodes,
        start_steps=args.start_steps,
        platform_loss=args.platform_loss,
        action_noise=args.action_noise,
        expert=args.expert,
        bandwidth=args.bandwidth,
        reference_acceleration=args.reference_acceleration,
    )
