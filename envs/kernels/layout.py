"""Offsets into the packed constants of the distance-constraint family (``envs.kernels.generic.pack_family``).

Shared by the family's kernels: ``envs.kernels.generic`` (any pose space over work arrays), ``envs.kernels.planar``
(the planar pose space in scalars), ``envs.kernels.three`` (three actuators in registers) and
``envs.tasks.grid_kernels`` (tasks on a certified grid).
"""

from __future__ import annotations

# -- offsets into the packed constants (fixed, sized for up to 6 legs) --------------------------------
C_N = 0  # number of legs n (= pose coordinates m)
C_SPATIAL = 1  # 1.0 for the spatial pose space, 0.0 for planar
C_LC = 2  # characteristic length ℓ_c [m]
C_LMIN = 3
C_LMAX = 4
C_DT = 5
C_RATE = 6
C_RK4 = 7
C_SAFE = 8
C_HARD = 9
C_WP = 10
C_WO = 11
C_WS = 12
C_WA = 13
C_PENALTY = 14
C_SUCC_P = 15
C_SUCC_O = 16
C_NEWTON_TOL = 17
C_NEWTON_IT = 18
C_JUMP = 19
C_MAX_SUBSTEP = 20
C_MAX_SUBSTEPS = 21
C_OMEGA = 22  # angular frequency of the Track references [rad/s]
C_MARGIN = 23  # stroke margin of the safe set [m]
C_SPACING = 24  # largest distance between checked points of a certified segment [m]
C_LOW = 25  # pose bounds, 6 entries
C_HIGH = 31
C_SCALE = 37  # pose_scale of the homogeneous Jacobian, 6 entries
C_B = 43  # base anchors B_i (x, y, z) [m], 6 × 3 entries
C_P = 61  # platform points P_i (x, y, z) in {P} [m], 6 × 3 entries
C_SLOW = 79  # box tasks are drawn from, 6 entries
C_SHIGH = 85
C_HARD_KIND = 91  # 0: the straight path dips below k_safe and a detour is certified; 1: ill-conditioned targets
# -- the actuation, leg by leg: A_i(q) = B_i + a_i (cos q u_i + sin q v_i) + q e_i, ℓ_i(q) = λ_i q + l_i ---------
C_LEGS = 92  # 1.0 when every actuator is an extensible leg (A_i = B_i, ℓ_i = q_i): the kernels' fast path
C_TRANSLATIONAL = 93  # 1.0 for the translational pose space (x = p, R = I)
C_A = 94  # crank radii a_i [m], 6 entries (0 for other kinds)
C_U = 100  # crank axes u_i, 6 × 3 entries
C_V = 118  # crank axes v_i, 6 × 3 entries
C_E = 136  # rail directions e_i, 6 × 3 entries
C_LAM = 154  # λ_i: 1 for a leg, 0 otherwise, 6 entries
C_ELL = 160  # link lengths l_i [m] of cranks and sliders, 6 entries
C_BRANCH = 166  # inverse-kinematics branch (±1) of each crank and slider, 6 entries
C_HARD1 = 172  # actuator condition number (Type I measure) below which the episode terminates
C_SAFE1 = 173  # actuator condition number below which the Type I penalty and the cost start
C_WS1 = 174  # weight of the Type I penalty
# -- the Track reference's path: sinusoids (C_PATH = 0) or a closed polyline of up to 8 vertices ----------------
C_PATH = 175  # number of vertices K of the path (0: x*_j = c_j + a_j sin(ω t + θ_j))
C_PATH_W = 176  # vertices W_k, normalised (x*_j = c_j + a_j W_kj at vertex k), 8 × 6 entries
C_PATH_T = 224  # the fraction of the period at which segment k → k + 1 (mod K) ends, 8 entries (the last is 1)
C_SIZE = 232
PATH_VERTICES = 8  # most vertices of a polyline path

# Termination reason codes (the order of ``envs.family.TERMINATION_REASONS``).
_NEWTON_FAILED, _ASSEMBLY_MODE_CHANGE, _SINGULARITY_CROSSED, _SINGULAR, _OUT_OF_BOUNDS = 1, 2, 3, 4, 5
_ACTUATOR_SINGULAR = 6  # a Type I singularity (J_q singular): a crank's link in line with its arm
