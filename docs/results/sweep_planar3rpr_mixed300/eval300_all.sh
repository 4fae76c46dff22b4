#!/bin/bash
cd /work/main
for s in 0 1 2; do
  R=$(ls -d sweeps/planar3rpr-mixed300/trials/*-s$s/run)
  for t in hard standard; do
    .venv/bin/python - "$R" 300 $t $s <<'PY'
import json, pathlib, sys
import gymnasium as gym
import envs  # noqa: F401
from training.evaluate import aggregate, evaluate_agent, load_run, wrap_for_run
run, steps, targets, seed = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
agent, config = load_run(run)
env = wrap_for_run(gym.make("Planar3RPRReach-v0", max_episode_steps=steps), config)
m = aggregate(evaluate_agent(agent, env, 100, 10000, targets))
m["label"] = f"ppo (seed {seed}, trained and scored with {steps}-step episodes) @ {targets}"
out = pathlib.Path(f"docs/results/sweep_planar3rpr_mixed300/eval300/s{seed}-{targets}"); out.mkdir(parents=True, exist_ok=True)
(out / "metrics.json").write_text(json.dumps(m, indent=2))
print(seed, targets, m["success_rate"], m["singularity_terminations"], m["terminations"])
PY
  done &
done
wait
echo done
