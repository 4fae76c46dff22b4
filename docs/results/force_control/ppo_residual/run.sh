#!/bin/bash
# Residual PPO over computed torque on Planar3RPRForceReach-v0 (standard targets): 3 seeds at scale 0.5, one at
# scale 0.25, each evaluated on 100 held-out episodes without and behind the shield; computed torque behind the shield.
set -e
for s in 0 1 2; do
  .venv/bin/python -m training.train --algo ppo --env Planar3RPRForceReach-v0 --seed $s --run-dir runs/ct-residual-s$s \
    --hyperparams env_wrapper=robot_control.ComputedTorqueResidualWrapper
done
.venv/bin/python -m training.train --algo ppo --env Planar3RPRForceReach-v0 --seed 0 --run-dir runs/ct-residual-scale0.25-s0 \
  --hyperparams 'env_wrapper={robot_control.ComputedTorqueResidualWrapper: {scale: 0.25}}'
out=docs/results/force_control/ppo_residual
for r in ct-residual-s0 ct-residual-s1 ct-residual-s2 ct-residual-scale0.25-s0; do
  .venv/bin/python -m training.evaluate --run runs/$r --episodes 100 --out $out/$r
  .venv/bin/python -m training.evaluate --run runs/$r --episodes 100 --shield 0.05 --out $out/$r-shield
done
.venv/bin/python -m training.evaluate --controller computed-torque --env Planar3RPRForceReach-v0 --episodes 100 \
  --shield 0.05 --out $out/ct-shield
.venv/bin/python -m experiments.family_report $out/table.md $out/*/ --by-recipe
