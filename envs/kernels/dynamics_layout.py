"""The packed inertial data of the equations of motion (``pack_inertia``), its offsets, and the rows of their work.

``INERTIA`` is the one table of the packed inertia: (name, entries, meaning) in order; each name's offset
``I_<name>`` is the sum of the entries before it (``envs.kernels.layout.offsets``), and ``C_INERTIA_SIZE`` is the
total. Points and vectors have three entries (a planar robot's z is 0); per-leg blocks have ``MAX_LEGS``. The
bodies are ``kinematics.inertia.InertialParameters``'s; the per-leg weights are the combinations the equations
of motion read (``kinematics.dynamics.RobotDynamics``): with the leg kinds' indicators leg_i, crank_i, slider_i,

    W_Q_i = crank_i J_i + slider_i m_a,i           (weight of q̇_i²: a crank's rotor and arm, a slider's carriage)
    W_U_i = leg_i (m_a,i c_a,i² + I_a,i) + I_d,i   (weight of |u̇_i|²: a leg's cylinder, the rod's rotation)
    LEVER_i = leg_i c_a,i                           (a cylinder's centre of mass moves with LEVER_i u̇_i)
    ARM_i = crank_i c_a,i / a_i + slider_i          (an arm's or carriage's centre of mass moves with ARM_i A_i′ q̇_i)

``DYNAMICS_WORK`` lists the rows of the work array of one robot (``envs.kernels.dynamics._dynamics_work``, six
columns): row ``D_<name>`` is the first of the name's rows.
"""

from __future__ import annotations

import numpy as np

from envs.kernels.layout import MAX_LEGS, offsets

_ONE, _VECTOR, _LEGS = 1, 3, MAX_LEGS

#: (name, entries, meaning) of every block of the packed inertia, in order.
INERTIA: tuple[tuple[str, int, str], ...] = (
    ("N", _ONE, "number of legs n the data are for"),
    ("MASS", _ONE, "platform mass m [kg]"),
    ("COM", _VECTOR, "platform centre of mass c in {P} [m]"),
    ("INERTIA", 9, "platform inertia about c in {P} axes [kg·m²], row-major 3 × 3 (planar: I_zz at (2, 2) only)"),
    ("GRAVITY", _VECTOR, "gravitational acceleration g in {B} [m/s²]"),
    ("AMASS", _LEGS, "actuator body masses m_a [kg]"),
    ("LEVER", _LEGS, "leg_i c_a,i [m]"),
    ("ARM", _LEGS, "crank_i c_a,i / a_i + slider_i"),
    ("WQ", _LEGS, "weight of q̇_i² [kg or kg·m²]"),
    ("WU", _LEGS, "weight of |u̇_i|² [kg·m²]"),
    ("DMASS", _LEGS, "distal rod masses m_d [kg]"),
    ("DCOM", _LEGS, "distal rod centres of mass from P_i along the rod [m]"),
    ("DAMP", _LEGS, "viscous friction b of the actuated joints [N·s/m, N·m·s/rad for cranks]"),
    ("JDAMP", _LEGS, "viscous friction b of the passive joints at the actuators [N·m·s/rad]"),
    ("LIMIT", _LEGS, "drive limits |τ_i| ≤ τ_max,i of force control [N, N·m for cranks]"),
    ("SUBSTEPS", _ONE, "RKMK4 steps per control period of force control"),
)

INERTIA_OFFSETS, C_INERTIA_SIZE = offsets(INERTIA, "I_")
globals().update(INERTIA_OFFSETS)  # I_N, I_MASS, …: the names the kernels import

#: (name, rows, meaning) of the work array of the equations of motion of one robot, in order.
DYNAMICS_WORK: tuple[tuple[str, int, str], ...] = (
    ("M", 6, "mass matrix M, m × m"),
    ("LU", 6, "elimination copy of M"),
    ("BIAS", 1, "c + G"),
    ("GRAV", 1, "G, gravity's share of c + G"),
    ("FORCE", 1, "J_iᵀ τ"),
    ("RHS", 1, "J_iᵀ τ − c − G"),
    ("ACC", 1, "ẍ"),
    # force control (``envs.kernels.force``)
    ("ZERO", 1, "zeros (ẋ = 0, τ = 0 of the holding forces)"),
    ("JT", 6, "J_iᵀ, column i = K_iᵀ g_i"),
    ("HOLD", 1, "holding forces τ_h"),
    ("TAU", 1, "applied efforts τ"),
    ("APPLIED", 1, "τ / τ_max"),
    ("XD", 1, "platform twist ẋ at the substep's start"),
    ("NU", 1, "a stage's twist"),
    ("POSE", 1, "a stage's pose"),
    ("Q", 1, "a stage's actuator coordinates"),
    ("XI", 4, "the stages' chart rates ξ̇ (the first is ẋ itself: rows 1–3 used)"),
    ("STAGE", 4, "the stages' twist rates ẍ"),
    ("MEAN", 2, "the mean chart rate and the mean twist rate"),
    ("NEXT", 2, "the pose and the twist at the substep's end"),
    ("RATE", 1, "mean actuator rates of the period"),
)
DYNAMICS_ROWS, D_SIZE = offsets(DYNAMICS_WORK, "D_")
globals().update(DYNAMICS_ROWS)  # D_M, D_LU, …


def pack_inertia(mechanism, inertia, limits=None, substeps: int = 1) -> np.ndarray:
    """The inertial data of a robot as the kernels' float64 vector, shape (C_INERTIA_SIZE,).

    Args:
        mechanism: The robot, a ``kinematics.DistanceConstraintMechanism`` (its actuator kinds and crank radii
            enter the per-leg weights).
        inertia: Its ``kinematics.inertia.InertialParameters``.
        limits: The drive limits τ_max of force control, shape (n,) [N, N·m for cranks], > 0; None: infinite.
        substeps: RKMK4 steps per control period of force control, ≥ 1.

    Returns:
        Read-only vector indexed by the ``I_*`` offsets (``INERTIA``).

    Raises:
        TypeError: If ``inertia`` is not an ``InertialParameters``.
        ValueError: If its number of legs or point dimension differ from the mechanism's, or if ``limits`` or
            ``substeps`` are not as above.
    """
    from kinematics.inertia import InertialParameters

    if not isinstance(inertia, InertialParameters):
        raise TypeError(f"inertia must be a kinematics.InertialParameters, got {type(inertia).__name__}")
    n, d = mechanism.n_actuators, mechanism.pose_space.point_dim
    if inertia.n_legs != n or inertia.point_dim != d:
        raise ValueError(
            f"inertial parameters for {inertia.n_legs} legs with {inertia.point_dim}-D points do not fit a robot "
            f"with {n} legs and {d}-D points"
        )
    if limits is not None:
        limits = np.asarray(limits, dtype=np.float64)
        if limits.shape != (n,) or not (limits > 0).all():
            raise ValueError(f"limits must be {n} drive limits > 0, got {limits.tolist()}")
    if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
        raise ValueError(f"substeps must be an integer ≥ 1, got {substeps!r}")
    kinds = np.array(mechanism.actuator_kinds)
    leg, crank, slider = ((kinds == kind).astype(np.float64) for kind in ("leg", "crank", "slider"))
    radii = np.where(mechanism.crank_radii > 0, mechanism.crank_radii, 1.0)
    tensor = inertia.platform_inertia.ravel() if d == 3 else [0.0] * 8 + [float(inertia.platform_inertia[0, 0])]
    mass_a, com_a, inertia_a = inertia.actuator_mass, inertia.actuator_com, inertia.actuator_inertia
    blocks = {
        "N": [n],
        "MASS": [inertia.platform_mass],
        "COM": inertia.platform_com,
        "INERTIA": tensor,
        "GRAVITY": inertia.gravity,
        "AMASS": mass_a,
        "LEVER": leg * com_a,
        "ARM": crank * com_a / radii + slider,
        "WQ": crank * inertia_a + slider * mass_a,
        "WU": leg * (mass_a * com_a**2 + inertia_a) + inertia.distal_inertia,
        "DMASS": inertia.distal_mass,
        "DCOM": inertia.distal_com,
        "DAMP": inertia.actuator_damping,
        "JDAMP": inertia.joint_damping,
        "LIMIT": np.full(n, np.inf) if limits is None else np.asarray(limits, dtype=np.float64),
        "SUBSTEPS": [substeps],
    }
    ci = np.zeros(C_INERTIA_SIZE)
    for name, value in blocks.items():
        start = INERTIA_OFFSETS["I_" + name]
        ci[start : start + len(value)] = value
    ci.setflags(write=False)
    return ci
