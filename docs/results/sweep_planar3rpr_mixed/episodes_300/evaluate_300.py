"""Score a Reach run on the 100 held-out episodes (reset seeds 10000-10099) with episodes of a given length.

Usage: ``python docs/results/sweep_planar3rpr_mixed/episodes_300/evaluate_300.py RUN STEPS TARGETS`` (from the
repository root); writes ``evals/long/<targets>-<steps>/metrics.json``.
"""

import json
import pathlib
import sys

import gymnasium as gym

import envs  # noqa: F401  (registers the ids)
from training.evaluate import aggregate, evaluate_agent, load_run, wrap_for_run

run, steps, targets = sys.argv[1], int(sys.argv[2]), sys.argv[3]
agent, config = load_run(run)
env = wrap_for_run(gym.make("Planar3RPRReach-v0", max_episode_steps=steps), config)
metrics = aggregate(evaluate_agent(agent, env, 100, 10000, targets))
metrics["label"] = f"ppo ({run.rstrip('/').split('/')[-1]}, {steps}-step episodes) @ {targets}"
print(targets, steps, metrics["success_rate"], metrics["singularity_terminations"], metrics["terminations"])
out = pathlib.Path(f"evals/long/{targets}-{steps}")
out.mkdir(parents=True, exist_ok=True)
(out / "metrics.json").write_text(json.dumps(metrics, indent=2))
