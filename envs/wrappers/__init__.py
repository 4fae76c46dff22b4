"""Wrappers of the environments: the shield, the goal view for HER, the previous action."""

from envs.wrappers.goal import GoalReachWrapper
from envs.wrappers.previous_action import PreviousActionWrapper, VectorPreviousActionWrapper
from envs.wrappers.shield import SingularityShield, VectorSingularityShield

__all__ = [
    "GoalReachWrapper",
    "PreviousActionWrapper",
    "SingularityShield",
    "VectorPreviousActionWrapper",
    "VectorSingularityShield",
]
