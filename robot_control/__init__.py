"""Baselines that control the environments: classical controllers, the certified-path planner and its wrappers.

Layered between ``envs`` (which it drives and never changes) and ``training`` (which scores it and distils it):
NumPy, SciPy and Gymnasium only, with OMPL imported where a planner first needs it (the ``planner`` extra).
"""

from robot_control.computed_torque import (
    ComputedTorqueCommand,
    ComputedTorqueController,
    MinimumJerkPath,
    Reference,
    minimum_jerk,
)
from robot_control.controllers import (
    CONTROLLERS,
    DAMPING_FLOOR,
    PlannerController,
    ResolvedRateController,
    SingularityAwareController,
    damping_factor,
    decode_observation,
    pose_error,
)
from robot_control.planner import PLANNERS, PathFollower, Plan, SafeGraph, SafePlanner, make_planner, safe_graph
from robot_control.wrappers import (
    ComputedTorqueResidualWrapper,
    PlannerResidualWrapper,
    PlannerWaypointWrapper,
    VectorComputedTorqueResidualWrapper,
    VectorPlannerResidualWrapper,
    VectorPlannerWaypointWrapper,
)

__all__ = [
    "CONTROLLERS",
    "DAMPING_FLOOR",
    "PLANNERS",
    "ComputedTorqueCommand",
    "ComputedTorqueController",
    "ComputedTorqueResidualWrapper",
    "MinimumJerkPath",
    "PathFollower",
    "Plan",
    "PlannerController",
    "PlannerResidualWrapper",
    "PlannerWaypointWrapper",
    "Reference",
    "ResolvedRateController",
    "SafeGraph",
    "SafePlanner",
    "SingularityAwareController",
    "VectorComputedTorqueResidualWrapper",
    "VectorPlannerResidualWrapper",
    "VectorPlannerWaypointWrapper",
    "damping_factor",
    "decode_observation",
    "make_planner",
    "minimum_jerk",
    "pose_error",
    "safe_graph",
]
