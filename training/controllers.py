"""The classical controllers of the evaluation harness, by command-line name.

They are NumPy only and live in ``envs.controllers`` (the residual wrapper ``envs.PlannerResidualWrapper``
builds on the planner controller); this module is where the training side finds them.
"""

from __future__ import annotations

from envs.controllers import (
    CONTROLLERS,
    FAMILY_CONTROLLERS,
    FamilyResolvedRateController,
    PlannerController,
    ResolvedRateController,
    SingularityAwareController,
    decode_observation,
)

__all__ = [
    "CONTROLLERS",
    "FAMILY_CONTROLLERS",
    "FamilyResolvedRateController",
    "PlannerController",
    "ResolvedRateController",
    "SingularityAwareController",
    "decode_observation",
]
