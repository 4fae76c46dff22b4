"""Constraint-based kinematics of fully parallel robots (pure NumPy).

Conventions (used by every module of the project):

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
                        actuator effort; for the 3-RPR, a leg of zero length.
    Type II (parallel): J_x singular, the platform gains a motion with the actuators locked and small
                        actuator rates give huge platform motion.

Every function accepts leading batch dimensions and broadcasts ``q`` against ``x``.
"""

from kinematics.mechanism import (
    ForwardKinematicsResult,
    ParallelMechanism,
    SingularConfigurationError,
)
from kinematics.planar_3rpr import Planar3RPR

__all__ = [
    "ForwardKinematicsResult",
    "ParallelMechanism",
    "Planar3RPR",
    "SingularConfigurationError",
]
