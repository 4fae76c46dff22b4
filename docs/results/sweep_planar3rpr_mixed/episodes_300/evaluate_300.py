import json, sys
import gymnasium as gym, envs
from training.evaluate import aggregate, evaluate_agent, load_run, wrap_for_run
run = sys.argv[1]; steps = int(sys.argv[2]); targets = sys.argv[3]
agent, config = load_run(run)
env = wrap_for_run(gym.make("Planar3RPRReach-v0", max_episode_steps=steps), config)
m = aggregate(evaluate_agent(agent, env, 100, 10000, targets))
m["label"] = f"ppo ({run.rstrip('/').split('/')[-1]}, {steps}-step episodes) @ {targets}"
print(targets, steps, m["success_rate"], m["singularity_terminations"], m["terminations"])
import pathlib
out = pathlib.Path(f"evals/long/{targets}-{steps}"); out.mkdir(parents=True, exist_ok=True)
(out / "metrics.json").write_text(json.dumps(m, indent=2))
