#!/usr/bin/env bash
# The planner, resolved-rate and singularity-aware controllers on every robot's hard targets (the 3-PRR, which has
# no hard id: standard), 100 episodes from reset seed 5000; then the table from the saved metrics.
set -euo pipefail
cd "$(dirname "$0")/../../.."
OUT=docs/results/planner_family
PY=${PY:-.venv/bin/python}
run() { "$PY" -m training.evaluate --episodes 100 --seed 5000 "$@" > /dev/null; }
for env in Planar3RPRReachHard-v0 StewartGoughReachHard-v0 DeltaReachHard-v0 Planar3RRRReachHard-v0; do
  for controller in planner resolved-rate singularity-aware; do
    run --controller "$controller" --env "$env" --out "$OUT/$controller-$env"
  done
done
run --controller planner --planner ompl --env Planar3RPRReachHard-v0 --out "$OUT/planner-ompl-Planar3RPRReachHard-v0"
for controller in planner resolved-rate; do
  run --controller "$controller" --env Planar3PRRReach-v0 --out "$OUT/$controller-Planar3PRRReach-v0"
done
"$PY" -m training.family_report "$OUT/table.md" --by-env "$OUT"/*/
