#!/usr/bin/env bash
# The planner, resolved-rate and singularity-aware controllers on every robot's hard targets (the 3-PRR, which has
# no hard id: standard; the 3-RPR also on its box detour tasks through the generic id), 100 episodes from reset
# seed 5000; then the table from the saved metrics. An evaluation whose metrics.json exists is kept.
set -euo pipefail
cd "$(dirname "$0")/../../.."
OUT=docs/results/planner_family
PY=${PY:-.venv/bin/python}
run() {  # run OUT_NAME ARGS...
  local out="$OUT/$1"; shift
  [ -f "$out/metrics.json" ] || "$PY" -m training.evaluate --episodes 100 --seed 5000 "$@" --out "$out" > /dev/null
}
BOX_DETOUR=(--env ParallelRobotReachHard-v0 --env-kwargs robot:planar_3rpr task_region:box hard_kind:detour track_shape:sinusoid)
for controller in planner resolved-rate singularity-aware; do
  for env in Planar3RPRReachHard-v0 StewartGoughReachHard-v0 DeltaReachHard-v0 Planar3RRRReachHard-v0; do
    run "$controller-$env" --controller "$controller" --env "$env"
  done
  run "$controller-Planar3PRRReach-v0" --controller "$controller" --env Planar3PRRReach-v0
  run "$controller-3rpr-box-detour" --controller "$controller" "${BOX_DETOUR[@]}"
done
run planner-ompl-Planar3RPRReachHard-v0 --controller planner --planner ompl --env Planar3RPRReachHard-v0
run planner-ompl-3rpr-box-detour --controller planner --planner ompl "${BOX_DETOUR[@]}"
"$PY" -m experiments.family_report "$OUT/table.md" --by-env "$OUT"/*/
