#!/usr/bin/env bash
# The planner controller on the 3-RPR's hard targets when it plans afresh whenever the platform is farther than
# D from its path (D = 3 cm, the distillation expert's setting; 1 cm; 0.1 mm, about every step), 100 episodes from
# reset seed 5000; then the table from the saved metrics. An evaluation whose metrics.json exists is kept.
set -euo pipefail
cd "$(dirname "$0")/../../.."
OUT=docs/results/expert_replanning
PY=${PY:-.venv/bin/python}
for distance in 0.03 0.01 0.0001; do
  out="$OUT/replan-$distance"
  [ -f "$out/metrics.json" ] || "$PY" -m training.evaluate --controller planner --env Planar3RPRReach-v0 \
    --targets hard --episodes 100 --seed 5000 --replan-distance "$distance" --out "$out" > /dev/null
done
"$PY" -m experiments.family_report "$OUT/table.md" "$OUT"/replan-*/
