#!/bin/bash
# TQC under force control, one seed each; every run evaluated on 100 held-out episodes without and behind the shield.
set -e
out=docs/results/force_control/tqc
train() { name=$1; shift; .venv/bin/python -m training.train --algo tqc --seed 0 --run-dir runs/$name "$@"; }
train tqc-delta-s0 --env DeltaForceReach-v0                                   # tqc.yml's rate settings, 900 k steps
train tqc-planar3rpr-s0 --env Planar3RPRForceReach-v0
train tqc-delta-sde-s0 --env DeltaForceReach-v0 --hyperparams n_timesteps=300000 use_sde=True \
  'policy_kwargs={net_arch: [256, 256], log_std_init: -3}'
train tqc-delta-sr-s0 --env DeltaForceReach-v0 --hyperparams n_timesteps=300000 'env_kwargs={success_reward: 0.5}' \
  ent_coef=auto_0.01
train tqc-ct-residual-s0 --env Planar3RPRForceReach-v0 --hyperparams env_wrapper=robot_control.ComputedTorqueResidualWrapper
for r in tqc-delta-s0 tqc-planar3rpr-s0 tqc-delta-sde-s0 tqc-delta-sr-s0 tqc-ct-residual-s0; do
  .venv/bin/python -m training.evaluate --run runs/$r --episodes 100 --out $out/$r
  .venv/bin/python -m training.evaluate --run runs/$r --episodes 100 --shield 0.05 --out $out/$r-shield
done
.venv/bin/python -m experiments.family_report $out/table.md $out/*/ --by-recipe --by-env
