"""Wrappers of the environments: the singularity shield, the goal view for HER and the planner's wrappers."""

from envs.wrappers.goal import GoalReachWrapper
from envs.wrappers.planner import (
    PlannerResidualWrapper,
    PlannerWaypointWrapper,
    VectorPlannerResidualWrapper,
    VectorPlannerWaypointWrapper,
)
from envs.wrappers.shield import SingularityShield, VectorSingularityShield

__all__ = [
    "GoalReachWrapper",
    "PlannerResidualWrapper",
    "PlannerWaypointWrapper",
    "SingularityShield",
    "VectorPlannerResidualWrapper",
    "VectorPlannerWaypointWrapper",
    "VectorSingularityShield",
]
