"""The public compiled kernels of the distance-constraint family, gathered from the modules that hold them.

One step, reward, observation and set of tasks for every robot of the family, split by role:
``envs.kernels.packing`` (the packed constants and the layouts of the outputs), ``envs.kernels.pose``
(rotations and pose-space operations), ``envs.kernels.constraints`` (Φ, the Jacobians, inverse and forward
kinematics, k), ``envs.kernels.step`` (the transition and the fused step), ``envs.kernels.evaluation`` (reference,
reward and observation), ``envs.tasks.certificate`` (the safe set) and ``envs.tasks.samplers`` (certified tasks).
"""

from __future__ import annotations

from envs.kernels.constraints import forward_batch, singularity_batch
from envs.kernels.evaluation import reference_batch
from envs.kernels.layout import C_SIZE, E_COST1, E_FIXED, PATH_VERTICES
from envs.kernels.modes import evaluate_batch, holding_batch, initial_batch, strokes_batch, transition_batch
from envs.kernels.packing import (
    evaluation_rows,
    observation_layout,
    pack_certificate,
    pack_family,
    read_only,
    row_path,
)
from envs.kernels.records import StepCall
from envs.kernels.setup import ONE_THREAD, PARALLEL_MIN_BATCH, random_streams, uses_every_core
from envs.kernels.step import (
    allocate_step,
    path_kernels,
    step_batch,
    step_call,
    step_on_every_core,
)
from envs.tasks.certificate import (
    SEGMENT_MAX_POINTS,
    certified_segment_batch,
    safe_batch,
    safety_batch,
    segment_batch,
    segment_min_safety_batch,
)
from envs.tasks.samplers import (
    PARALLEL_MIN_SAMPLES,
    SAMPLER_TRIES,
    WAYPOINT_TRIES,
    sample_reach_batch,
    sample_track_batch,
)

__all__ = [
    "C_SIZE",
    "E_COST1",
    "E_FIXED",
    "ONE_THREAD",
    "PARALLEL_MIN_BATCH",
    "PARALLEL_MIN_SAMPLES",
    "PATH_VERTICES",
    "SAMPLER_TRIES",
    "SEGMENT_MAX_POINTS",
    "WAYPOINT_TRIES",
    "StepCall",
    "allocate_step",
    "certified_segment_batch",
    "evaluate_batch",
    "evaluation_rows",
    "forward_batch",
    "holding_batch",
    "initial_batch",
    "observation_layout",
    "pack_certificate",
    "pack_family",
    "path_kernels",
    "random_streams",
    "read_only",
    "reference_batch",
    "row_path",
    "safe_batch",
    "safety_batch",
    "sample_reach_batch",
    "sample_track_batch",
    "segment_batch",
    "segment_min_safety_batch",
    "singularity_batch",
    "step_batch",
    "step_call",
    "step_on_every_core",
    "strokes_batch",
    "transition_batch",
    "uses_every_core",
]
