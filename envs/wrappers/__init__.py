"""Wrappers of the environments: the shield, the goal view for HER, the planner's wrappers, the previous action."""

from envs.wrappers.goal import GoalReachWrapper
from envs.wrappers.planner import (
    PlannerResidualWrapper,
    PlannerWaypointWrapper,
    VectorPlannerResidualWrapper,
    VectorPlannerWaypointWrapper,
)
from envs.wrappers.previous_action import PreviousActionWrapper, VectorPreviousActionWrapper
from envs.wrappers.shield import SingularityShield, VectorSingularityShield

__all__ = [
    "GoalReachWrapper",
    "PlannerResidualWrapper",
    "PlannerWaypointWrapper",
    "PreviousActionWrapper",
    "SingularityShield",
    "VectorPlannerResidualWrapper",
    "VectorPlannerWaypointWrapper",
    "VectorPreviousActionWrapper",
    "VectorSingularityShield",
]
