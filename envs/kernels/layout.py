"""Offsets into the packed constants of the distance-constraint family (``envs.kernels.packing.pack_family``).

``LAYOUT`` is the one table: (name, entries, meaning) in order; each name's offset ``C_<name>`` is the sum of the
entries before it, and ``C_SIZE`` is the total. The ``C_*`` names are module-level integers generated from the
table, so the compiled kernels read them as constants. Shared by ``envs.kernels.packing`` and the kernels over
work arrays (``constraints``, ``step``, ``evaluation``; the certificate and the samplers of ``envs.tasks``),
``envs.kernels.three`` (three actuators in registers) and ``envs.tasks.grid_kernels`` (tasks on a certified
grid).
"""

from __future__ import annotations

MAX_LEGS = 6  # most actuators (= pose coordinates) a robot of the family has
PATH_VERTICES = 8  # most vertices of a polyline path
_ONE, _POSE, _POINTS = 1, MAX_LEGS, 3 * MAX_LEGS  # a scalar, one value per pose coordinate or actuator, n points

#: (name, entries, meaning) of every block of the packed constants, in order.
LAYOUT: tuple[tuple[str, int, str], ...] = (
    ("N", _ONE, "number of actuators n (= pose coordinates m)"),
    ("SPATIAL", _ONE, "1.0 for the spatial pose space, 0.0 otherwise"),
    ("LC", _ONE, "characteristic length ℓ_c [m]"),
    ("LMIN", _ONE, "lower stroke limit"),
    ("LMAX", _ONE, "upper stroke limit"),
    ("DT", _ONE, "control period [s]"),
    ("RATE", _ONE, "largest stroke rate"),
    ("RK4", _ONE, "1.0 for the RK4 predictor, 0.0 for Euler"),
    ("SAFE", _ONE, "k below which the singularity penalty and the cost start"),
    ("HARD", _ONE, "k below which the episode terminates"),
    ("WP", _ONE, "weight of the position error"),
    ("WO", _ONE, "weight of the orientation error (times ℓ_c)"),
    ("WS", _ONE, "weight of the singularity penalty"),
    ("WA", _ONE, "weight of the action penalty"),
    ("PENALTY", _ONE, "termination penalty"),
    ("BONUS", _ONE, "success reward, added at a step that ends within the success tolerances"),
    ("SUCC_P", _ONE, "position tolerance of success [m]"),
    ("SUCC_O", _ONE, "orientation tolerance of success [rad]"),
    ("NEWTON_TOL", _ONE, "tolerance of Newton's correction [m²]"),
    ("NEWTON_IT", _ONE, "most iterations of Newton's correction"),
    ("JUMP", _ONE, "largest correction before an assembly-mode change [m]"),
    ("MAX_SUBSTEP", _ONE, "largest predicted motion of one substep [m]"),
    ("MAX_SUBSTEPS", _ONE, "most substeps of one control period"),
    ("OMEGA", _ONE, "angular frequency of the Track references [rad/s]"),
    ("MARGIN", _ONE, "stroke margin of the safe set [m]"),
    ("SPACING", _ONE, "largest distance between checked points of a certified segment [m]"),
    ("LOW", _POSE, "lower pose bounds"),
    ("HIGH", _POSE, "upper pose bounds"),
    ("SCALE", _POSE, "pose_scale of the homogeneous Jacobian"),
    ("B", _POINTS, "base anchors B_i (x, y, z) [m]"),
    ("P", _POINTS, "platform points P_i (x, y, z) in {P} [m]"),
    ("SLOW", _POSE, "lower corner of the box tasks are drawn from"),
    ("SHIGH", _POSE, "upper corner of the box tasks are drawn from"),
    ("HARD_KIND", _ONE, "0: the straight path dips below k_safe and a detour is certified; 1: ill-conditioned"),
    # the actuation, leg by leg: A_i(q) = B_i + a_i (cos q u_i + sin q v_i) + q e_i, ℓ_i(q) = λ_i q + l_i
    ("LEGS", _ONE, "1.0 when every actuator is an extensible leg (A_i = B_i, ℓ_i = q_i): the fast path"),
    ("TRANSLATIONAL", _ONE, "1.0 for the translational pose space (x = p, R = I)"),
    ("A", _POSE, "crank radii a_i [m] (0 for other kinds)"),
    ("U", _POINTS, "crank axes u_i"),
    ("V", _POINTS, "crank axes v_i"),
    ("E", _POINTS, "rail directions e_i"),
    ("LAM", _POSE, "λ_i: 1 for a leg, 0 otherwise"),
    ("ELL", _POSE, "link lengths l_i [m] of cranks and sliders"),
    ("BRANCH", _POSE, "inverse-kinematics branch (±1) of each crank and slider"),
    ("HARD1", _ONE, "actuator condition number (Type I measure) below which the episode terminates"),
    ("SAFE1", _ONE, "actuator condition number below which the Type I penalty and the cost start"),
    ("WS1", _ONE, "weight of the Type I penalty"),
    # the Track reference's path: sinusoids (C_PATH = 0) or a closed polyline of up to PATH_VERTICES vertices
    ("PATH", _ONE, "number of vertices K of the path (0: x*_j = c_j + a_j sin(ω t + θ_j))"),
    ("PATH_W", PATH_VERTICES * _POSE, "vertices W_k, normalised (x*_j = c_j + a_j W_kj at vertex k)"),
    ("PATH_T", PATH_VERTICES, "fraction of the period at which segment k → k + 1 (mod K) ends (the last is 1)"),
)


def offsets(table: tuple[tuple[str, int, str], ...], prefix: str = "C_") -> tuple[dict[str, int], int]:
    """({prefix + name: offset}, total size) of a layout table: each offset is the sum of the entries before it."""
    out, start = {}, 0
    for name, size, _ in table:
        out[prefix + name] = start
        start += size
    return out, start


OFFSETS, C_SIZE = offsets(LAYOUT)
globals().update(OFFSETS)  # C_N, C_SPATIAL, …: the names the kernels import

#: (name, rows, meaning) of the work array of one robot (``envs.kernels.constraints._work``), in order: row
#: ``W_<name>`` is the first of the name's rows; each row holds up to 6 numbers.
WORK: tuple[tuple[str, int, str], ...] = (
    ("A", 6, "A = J_x / 2, n × m"),
    ("LU", 6, "elimination copy of A"),
    ("H", 6, "homogeneous J_i, for the SVD"),
    ("ELL", 1, "link lengths ℓ_i(q_i) [m] (for legs q_i)"),
    ("DQ", 1, "d_iᵀ A_i′ + ℓ_i ℓ_i′ = −(J_q)_ii / 2"),
    ("SPEED", 1, "‖(A_i′, ℓ_i′)‖"),
    ("SQ", 1, "squared leg lengths d_iᵀ d_i"),
    ("RHS", 1, "right-hand side of a system"),
    ("SOL", 1, "solution of a system"),
    ("V", 1, "twist rate"),
    ("K1", 1, "RK4 stage"),
    ("K2", 1, "RK4 stage"),
    ("K3", 1, "RK4 stage"),
    ("XM", 1, "an intermediate pose"),
    ("KQ", 1, "strokes of the current substep"),
    ("KX", 1, "pose of the current substep"),
    ("NQ", 1, "strokes at the end of the step"),
    ("QR", 1, "achieved stroke rates"),
    ("PRED", 1, "predicted pose"),
    ("Y", 1, "Newton's pose"),
    ("T", 1, "strokes of a substep"),
    ("QM", 1, "intermediate strokes"),
    ("ACT", 1, "applied action"),
    ("TGT", 1, "target pose"),
    ("VEL", 1, "target velocity"),
    ("DIFF", 1, "a pose difference"),
    ("SEG", 1, "a point of a segment"),
    ("SEG_D", 1, "a segment's direction"),
    # The anchors of cranks and sliders depend on q alone: cached per leg for the q they were computed at (Newton's
    # iterations and the substep's checks move x at fixed q). ``_work`` marks the cache empty (NaN).
    ("CQ", 1, "the q_i the cached anchor values belong to"),
    ("CA", 3, "A_i(q_i), one row per coordinate"),
    ("CD", 3, "A_i′(q_i), one row per coordinate"),
    ("CELL", 1, "ℓ_i(q_i)"),
    ("CSPEED", 1, "‖(A_i′, ℓ_i′)‖"),
)
WORK_ROWS, W_SIZE = offsets(WORK, "W_")
globals().update(WORK_ROWS)  # W_A, W_LU, …: the names the kernels import


#: (name, meaning) of the rows of the lane array of a block of spatial robots (``envs.kernels.step.allocate_lanes``),
#: in order: row ``L_<name>`` holds the name's value of every robot of the block.
LANES_ROWS: tuple[tuple[str, str], ...] = (
    ("K", "inverse condition number k"),
    ("WORST", "the Jacobi SVD's work: the largest cos² between two columns in a sweep"),
    ("ACTIVE", "whether the Jacobi SVD still rotates the robot's matrix"),
    ("SIGN", "sign(det J_x)"),
    ("FLAGS", "1: the correction failed; + 2: the pose left its bounds"),
    ("K1", "actuator condition number k_I"),
)
globals().update({"L_" + name: row for row, (name, _) in enumerate(LANES_ROWS)})  # L_K, …

#: (name, info key) of the rows of the evaluation (``modes.evaluate_batch``) that do not depend on m, in order;
#: row ``E_<name>`` holds the info key's value of every robot. The target, its velocity and the pose follow from
#: row ``E_FIXED`` (m rows each).
EVALUATION: tuple[tuple[str, str], ...] = (
    ("TRACKING", "reward_tracking"),
    ("SINGULARITY", "reward_singularity"),
    ("ACTION", "reward_action"),
    ("TERMINATION", "reward_termination"),
    ("BONUS", "reward_success"),
    ("REWARD", "reward"),
    ("POSITION_ERROR", "position_error"),
    ("ORIENTATION_ERROR", "orientation_error"),
    ("SUCCESS", "is_success"),
    ("COST", "cost"),
    ("K", "inverse_condition_number"),
    ("RESIDUAL", "constraint_residual"),
    ("ACTUATOR", "reward_actuator_singularity"),  # the Type I penalty
    ("K1", "actuator_condition_number"),  # the Type I measure (1 for legs)
    ("COST1", "cost_actuator_singularity"),  # 1 while the actuator condition number is below its safe threshold
    ("SATURATED", "saturated"),  # force control: 1 while a drive is at its limit (|τ_i / τ_max,i| ≥ 1); else 0
)
E_FIXED = len(EVALUATION)
globals().update({"E_" + name: row for row, (name, _) in enumerate(EVALUATION)})  # E_TRACKING, …

# Termination reason codes (the order of ``envs.state.TERMINATION_REASONS``).
_NEWTON_FAILED, _ASSEMBLY_MODE_CHANGE, _SINGULARITY_CROSSED, _SINGULAR, _OUT_OF_BOUNDS = 1, 2, 3, 4, 5
_ACTUATOR_SINGULAR = 6  # a Type I singularity (J_q singular): a crank's link in line with its arm
