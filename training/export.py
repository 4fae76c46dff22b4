r"""A trained policy as one TorchScript function: observation in, action out, no SB3 or Gymnasium needed to run it.

Usage::

    python -m training.export --run training/pretrained/distill-Planar3RPRReachMixed-v0 --out policy.pt

The exported module holds the run's observation normalisation (``VecNormalize``'s running mean and variance,
ε and clip), the policy's deterministic action (``policy._predict(obs, deterministic=True)``: the Gaussian's
mean for PPO, the squashed actor for SAC, TQC and TD3) and the step ``BasePolicy.predict`` applies after it
(squashed actions rescaled to the action box, others clipped to it). It maps float32 observations of shape
(B, d) to float32 actions of shape (B, n), equal to ``training.evaluate.load_run``'s agent up to float32
rounding. Load it with ``torch.jit.load(path)`` (or libtorch's ``torch::jit::load`` in C++); it is what a robot's
controller would run at every step. TorchScript rather than ``torch.export``: a loaded exported program costs
about as much per call as the eager policy, a TorchScript function about a quarter of that.

Runs with a dict observation (HER's goal view) are refused.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from training.evaluate import EvaluationError, load_model

__all__ = ["deployed_module", "export_run", "main"]


def deployed_module(model: Any, normalizer: Any) -> Any:
    """A ``torch.nn.Module`` computing the run's deterministic action from a raw observation batch (B, d).

    Args:
        model: The SB3 model (``training.evaluate.load_model``).
        normalizer: Its ``VecNormalize`` (evaluation mode) or None.

    Raises:
        EvaluationError: If the observation space is not a flat Box.
    """
    import gymnasium as gym
    import torch

    space = model.observation_space
    if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
        raise EvaluationError(f"only flat Box observations can be exported, got {space}")
    if normalizer is not None and not normalizer.norm_obs:
        normalizer = None
    actions = model.action_space

    class Deployed(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.policy = model.policy
            d = space.shape[0]
            mean = np.zeros(d) if normalizer is None else normalizer.obs_rms.mean
            var = np.ones(d) if normalizer is None else normalizer.obs_rms.var
            eps = 0.0 if normalizer is None else normalizer.epsilon
            clip = np.inf if normalizer is None else normalizer.clip_obs
            # VecNormalize computes in float64 and casts to float32
            self.register_buffer("mean", torch.as_tensor(np.asarray(mean, dtype=np.float64)))
            self.register_buffer("scale", torch.as_tensor(np.sqrt(np.asarray(var, dtype=np.float64) + eps)))
            self.clip = float(clip)
            self.normalise = normalizer is not None
            self.squashed = bool(model.policy.squash_output)
            self.register_buffer("low", torch.as_tensor(actions.low, dtype=torch.float32))
            self.register_buffer("high", torch.as_tensor(actions.high, dtype=torch.float32))

        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            x = obs
            if self.normalise:
                x = torch.clamp((obs.double() - self.mean) / self.scale, -self.clip, self.clip).float()
            action = self.policy._predict(x, deterministic=True)
            if self.squashed:
                return self.low + 0.5 * (action + 1.0) * (self.high - self.low)
            return torch.minimum(torch.maximum(action, self.low), self.high)

    module = Deployed().eval()
    for parameter in module.parameters():
        parameter.requires_grad_(False)
    return module


def export_run(run_dir: str | Path, out: str | Path, which: str = "final") -> Path:
    """Write a run's deterministic policy as TorchScript (``torch.jit.trace``) to ``out``; return ``out``.

    Args:
        run_dir: A run folder (``training.train``, ``training.distill``, the RL Zoo).
        out: The ``.pt`` file to write (its folder is created).
        which: "final" or "best" model.

    Raises:
        EvaluationError: As ``load_model``, or for a dict observation.
    """
    import torch

    model, normalizer, _config = load_model(run_dir, which)
    module = deployed_module(model, normalizer)
    example = torch.as_tensor(model.observation_space.sample()[None], dtype=torch.float32)
    validate = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)  # no data-dependent checks in the trace
    try:
        with torch.no_grad():
            traced = torch.jit.trace(module, example, check_trace=False)
    finally:
        torch.distributions.Distribution.set_default_validate_args(validate)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    traced.save(str(out))
    return out


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m training.export", description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True, help="run folder")
    parser.add_argument("--out", required=True, help="TorchScript file to write (.pt)")
    parser.add_argument("--model", choices=("final", "best"), default="final")
    args = parser.parse_args(argv)
    try:
        print(export_run(args.run, args.out, args.model))
    except EvaluationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
