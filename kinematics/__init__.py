"""Constraint-based kinematics of fully parallel robots (pure NumPy).

Conventions (used by every module of the project):

The family
    Every robot here is a *distance-constraint mechanism* (``DistanceConstraintMechanism``): leg i keeps a
    platform point P_i at a distance ℓ_i(q_i) from an anchor A_i(q_i), Φ_i = ‖p + R P_i − A_i‖² − ℓ_i²,
    and a robot is data: a pose space (planar, spatial or translational), each leg's actuator kind (leg,
    crank or slider) and a geometry. The 3-RPR (``Planar3RPR``), the Stewart–Gough hexapod
    (``StewartGough``), the Delta (``Delta``), the 3-RRR (``Planar3RRR``) and the 3-PRR (``Planar3PRR``) are
    members; a user's own geometry needs no new code. For spatial poses the velocity is the platform twist
    (v, ω) in {B} and J_x, J_f and J_i refer to it (see ``kinematics.family``).

Frames
    {B} is the fixed base frame, {P} the moving platform frame. A platform point given in {P} is
    mapped to {B} by ``p + R(φ) P_i``.

Symbols
    q   actuator coordinates (for the 3-RPR: leg lengths L_1, L_2, L_3) [m], shape (..., n).
    x   platform pose of {P} in {B} (for planar robots: x [m], y [m], φ [rad]), shape (..., m).
    Φ   holonomic constraints Φ(q, x) = 0, shape (..., k). Planar 3-RPR (the lesson's squared form):
        Φ_i = d_iᵀ d_i − L_i² with d_i = p + R(φ) P_i − B_i  [m²].
    J_q = ∂Φ/∂q, shape (..., k, n);  J_x = ∂Φ/∂x, shape (..., k, m).
    J_f = −J_x⁻¹ J_q, the *forward* Jacobian: ẋ = J_f q̇ (actuator rates → platform velocity).
    J_i = −J_q⁻¹ J_x, the *inverse* Jacobian: q̇ = J_i ẋ (platform velocity → actuator rates).

Units
    SI throughout: metres, radians, seconds, newtons. Angles are counter-clockwise positive.

Singularities (Gosselin & Angeles 1990)
    Type I  (serial):   J_q singular, the platform can resist motion in some direction without
                        actuator effort; for the 3-RPR, a leg of zero length; for a crank, its link in
                        line with its arm (``actuator_condition_number``, ``actuator_mobility``).
    Type II (parallel): J_x singular, the platform gains a motion with the actuators locked and small
                        actuator rates give huge platform motion.

Dynamics
    ``RobotDynamics(mechanism, InertialParameters)`` gives M(x) ẍ + c(x, ẋ) + G(x) = J_iᵀ τ with ẋ the
    platform velocity above (the twist (v, ω) in {B} for spatial poses) and an integrator on the pose space
    (see ``kinematics.dynamics``).

Every function accepts leading batch dimensions and broadcasts ``q`` against ``x``.
"""

from kinematics.delta import Delta
from kinematics.dynamics import InertialParameters, RobotDynamics, default_inertia
from kinematics.family import ACTUATOR_KINDS, POSE_SPACES, DistanceConstraintMechanism, PoseSpace, load_mechanism
from kinematics.mechanism import (
    ForwardKinematicsResult,
    ParallelMechanism,
    SingularConfigurationError,
)
from kinematics.planar_3rpr import Planar3RPR
from kinematics.planar_rrr_prr import Planar3PRR, Planar3RRR
from kinematics.stewart_gough import StewartGough

__all__ = [
    "ACTUATOR_KINDS",
    "POSE_SPACES",
    "Delta",
    "DistanceConstraintMechanism",
    "ForwardKinematicsResult",
    "InertialParameters",
    "ParallelMechanism",
    "Planar3PRR",
    "Planar3RPR",
    "Planar3RRR",
    "PoseSpace",
    "RobotDynamics",
    "SingularConfigurationError",
    "StewartGough",
    "default_inertia",
    "load_mechanism",
]
