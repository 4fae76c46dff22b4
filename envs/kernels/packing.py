"""The family's constants packed for the kernels, the layouts of their outputs, and the compile-time codes.

A robot is data: its pose space (planar, spatial or translational), its number of legs n (= m, the pose
coordinates) and its geometry travel in one float64 vector (``pack_family``, at the offsets of
``envs.kernels.layout``); the kernels read them and never ask which robot they run. The constants reach the
kernels read-only (``read_only``): a writable copy would be a second specialisation of every kernel.
``row_path`` and ``pose_space_code`` are the two compile-time constants the entry kernels of
``envs.kernels.step`` are specialised by; ``_literal_path`` and ``_literal_space`` read them in the overloads.
"""

from __future__ import annotations

import numpy as np
from numba.core import errors, types

from envs.kernels.layout import (
    C_A,
    C_B,
    C_BONUS,
    C_BRANCH,
    C_DT,
    C_E,
    C_ELL,
    C_HARD,
    C_HARD1,
    C_HARD_KIND,
    C_HIGH,
    C_JUMP,
    C_LAM,
    C_LC,
    C_LEGS,
    C_LMAX,
    C_LMIN,
    C_LOW,
    C_MARGIN,
    C_MAX_SUBSTEP,
    C_MAX_SUBSTEPS,
    C_N,
    C_NEWTON_IT,
    C_NEWTON_TOL,
    C_OMEGA,
    C_P,
    C_PATH,
    C_PATH_T,
    C_PATH_W,
    C_PENALTY,
    C_RATE,
    C_RK4,
    C_SAFE,
    C_SAFE1,
    C_SCALE,
    C_SHIGH,
    C_SIZE,
    C_SLOW,
    C_SPACING,
    C_SPATIAL,
    C_SUCC_O,
    C_SUCC_P,
    C_TRANSLATIONAL,
    C_U,
    C_V,
    C_WA,
    C_WO,
    C_WP,
    C_WS,
    C_WS1,
    E_COST1,
    E_FIXED,
    EVALUATION,
    PATH_VERTICES,
)
from envs.kernels.pose import _TWO_PI

__all__ = [
    "C_SIZE",
    "E_COST1",
    "E_FIXED",
    "PATH_VERTICES",
    "PLANAR_LEGS",
    "PLANAR_SPACE",
    "POSE_CODES",
    "ROW_PATHS",
    "SPATIAL_SPACE",
    "THREE",
    "TRANSLATIONAL_SPACE",
    "WORK_ARRAYS",
    "evaluation_rows",
    "observation_layout",
    "pack_certificate",
    "pack_family",
    "pose_space_code",
    "read_only",
    "row_path",
]


def pack_certificate(
    robot, stroke_limits, stroke_margin, safe_threshold, actuator_safe_threshold, hard_threshold=0.0
) -> np.ndarray:
    """The constants the certificate reads (``safety_batch``, ``segment_min_safety_batch``), shape (C_SIZE,).

    The robot's geometry, actuation and pose scale, its stroke limits and margin and the safe thresholds; every
    other entry is 0 (``pack_family`` fills them).

    Args:
        robot: A ``DistanceConstraintMechanism``.
        stroke_limits: (q_min, q_max) of every actuator [m, or rad for cranks].
        stroke_margin: Distance a safe pose keeps from both limits [m, rad].
        safe_threshold: k_safe.
        actuator_safe_threshold: k_I,safe (unused for legs).
        hard_threshold: k_hard.

    Returns:
        Read-only float64 vector indexed by the ``C_*`` offsets.
    """
    n, m = robot.n_actuators, robot.n_pose
    c = np.zeros(C_SIZE)
    c[C_N] = n
    c[C_SPATIAL] = 1.0 if robot.pose_space.name == "spatial" else 0.0
    c[C_TRANSLATIONAL] = 1.0 if robot.pose_space.name == "translational" else 0.0
    c[C_LC] = robot.characteristic_length
    c[C_LMIN], c[C_LMAX] = stroke_limits
    c[C_MARGIN] = stroke_margin
    c[C_SAFE], c[C_HARD], c[C_SAFE1] = safe_threshold, hard_threshold, actuator_safe_threshold
    c[C_SCALE : C_SCALE + m] = robot.pose_scale
    d = robot.base.shape[1]
    c[C_B : C_B + 3 * n] = np.pad(robot.base, ((0, 0), (0, 3 - d))).ravel()
    c[C_P : C_P + 3 * n] = np.pad(robot.platform, ((0, 0), (0, 3 - d))).ravel()
    c[C_LEGS] = 1.0 if all(kind == "leg" for kind in robot.actuator_kinds) else 0.0
    c[C_A : C_A + n] = robot.crank_radii
    axes = robot.crank_axes
    c[C_U : C_U + 3 * n] = np.pad(axes[:, 0], ((0, 0), (0, 3 - d))).ravel()
    c[C_V : C_V + 3 * n] = np.pad(axes[:, 1], ((0, 0), (0, 3 - d))).ravel()
    c[C_E : C_E + 3 * n] = np.pad(robot.rails, ((0, 0), (0, 3 - d))).ravel()
    c[C_LAM : C_LAM + n] = [1.0 if kind == "leg" else 0.0 for kind in robot.actuator_kinds]
    c[C_ELL : C_ELL + n] = robot.link_lengths
    c[C_BRANCH : C_BRANCH + n] = robot.branches
    c.setflags(write=False)
    return c


def pack_family(params) -> np.ndarray:
    """The constants of ``params`` (an ``envs.params.FamilyParams``) as the kernels' float64 vector, shape (C_SIZE,).

    Args:
        params: Environment constants with a ``DistanceConstraintMechanism`` as ``robot``.

    Returns:
        Read-only float64 vector indexed by the ``C_*`` offsets (the certificate's part is ``pack_certificate``).
    """
    m = params.robot.n_pose
    c = pack_certificate(
        params.robot,
        params.stroke_limits,
        params.stroke_margin,
        params.safe_threshold,
        params.actuator_safe_threshold,
        params.hard_threshold,
    ).copy()
    c[C_DT], c[C_RATE] = params.dt, params.max_rate
    c[C_RK4] = 1.0 if params.integrator == "rk4" else 0.0
    c[C_WP], c[C_WO] = params.position_weight, params.orientation_weight
    c[C_WS], c[C_WA] = params.singularity_weight, params.action_weight
    c[C_PENALTY], c[C_BONUS] = params.termination_penalty, params.success_reward
    c[C_SUCC_P], c[C_SUCC_O] = params.success_position_tolerance, params.success_orientation_tolerance
    c[C_NEWTON_TOL], c[C_NEWTON_IT] = params.newton_tolerance, params.newton_max_iterations
    c[C_JUMP], c[C_MAX_SUBSTEP], c[C_MAX_SUBSTEPS] = params.jump_tolerance, params.max_substep, params.max_substeps
    c[C_OMEGA] = _TWO_PI / params.track_period
    c[C_SPACING] = params.segment_spacing
    c[C_LOW : C_LOW + m] = params.pose_low
    c[C_HIGH : C_HIGH + m] = params.pose_high
    c[C_SLOW : C_SLOW + m] = params.sample_low
    c[C_SHIGH : C_SHIGH + m] = params.sample_high
    c[C_HARD_KIND] = 1.0 if params.hard_kind == "ill_conditioned" else 0.0
    c[C_HARD1] = params.actuator_hard_threshold
    c[C_WS1] = params.actuator_singularity_weight
    path = np.asarray(params.track_path, dtype=np.float64).reshape(-1, m)
    if len(path):
        c[C_PATH] = len(path)
        for k, vertex in enumerate(path):
            c[C_PATH_W + 6 * k : C_PATH_W + 6 * k + m] = vertex
        c[C_PATH_T : C_PATH_T + len(path)] = np.cumsum(params.track_path_times) / np.sum(params.track_path_times)
        c[C_PATH_T + len(path) - 1] = 1.0
    c.setflags(write=False)
    return c


def read_only(a: np.ndarray) -> np.ndarray:
    """``a``, or a read-only view of it: the kernels take their constants read-only, one compiled signature for all.

    A writable and a read-only array are two types to Numba, so a kernel given both would be compiled twice.
    """
    if not a.flags.writeable:
        return a
    view = a.view()
    view.setflags(write=False)
    return view


def evaluation_rows(m: int) -> dict[str, int | slice]:
    """Rows of the evaluation (``evaluate_batch``, ``step_batch``) for m pose coordinates; column i is robot i."""
    rows: dict[str, int | slice] = {info: row for row, (_, info) in enumerate(EVALUATION)}
    rows.update(
        target=slice(E_FIXED, E_FIXED + m),
        target_velocity=slice(E_FIXED + m, E_FIXED + 2 * m),
        pose=slice(E_FIXED + 2 * m, E_FIXED + 3 * m),
    )
    return rows


#: Width of the pose code and number of pose coordinates m of each pose space: (x, y, cos φ, sin φ) and
#: (x, y, φ); (p, quaternion) and (p, rotation vector); p and p.
POSE_CODES = {"planar": (4, 3), "spatial": (7, 6), "translational": (3, 3)}


def observation_layout(pose_space: str, n: int, with_velocity: bool, force: bool = False) -> dict[str, slice]:
    """Slices of the observation vector (see ``envs.FamilyReachEnv``).

    Args:
        pose_space: "planar", "spatial" or "translational" (a ``PoseSpace.name``).
        n: Number of actuators.
        with_velocity: Whether the observation ends with the target velocity (Track).
        force: Whether the robot is under force control (the platform twist and the actuator rates follow k).

    Returns:
        name → slice: pose, target, error, strokes, stroke_error, k (and twist, actuator_rates; target_velocity).
    """
    if pose_space not in POSE_CODES:
        raise ValueError(f"pose_space must be one of {sorted(POSE_CODES)}, got {pose_space!r}")
    pose, m = POSE_CODES[pose_space]
    names = [("pose", pose), ("target", pose), ("error", m), ("strokes", n), ("stroke_error", n), ("k", 1)]
    if force:
        names += [("twist", m), ("actuator_rates", n)]
    if with_velocity:
        names.append(("target_velocity", m))
    out, start = {}, 0
    for name, size in names:
        out[name] = slice(start, start + size)
        start += size
    return out


#: Row paths of the step (``envs.kernels.paths``): three legs on the planar pose space in registers, three
#: actuators of any kind on the planar or translational pose space in registers, any pose space over work
#: arrays. The path is a compile-time constant of the entry kernels (``_path_kernels``): a robot compiles its own
#: path only.
PLANAR_LEGS, THREE, WORK_ARRAYS = 0, 1, 2
ROW_PATHS = (PLANAR_LEGS, THREE, WORK_ARRAYS)


def row_path(cs) -> int:
    """The row path (``PLANAR_LEGS``, ``THREE`` or ``WORK_ARRAYS``) that steps the robot of ``cs``.

    Args:
        cs: Packed constants, shape (C_SIZE,) or (N, C_SIZE) (the robots of one batch share their pose space and
            actuator kinds; the first row is read).
    """
    spatial = cs.item(C_SPATIAL)
    if spatial == 0.0 and cs.item(C_LEGS) != 0.0 and cs.item(C_TRANSLATIONAL) == 0.0:
        return PLANAR_LEGS
    if spatial == 0.0 and cs.item(C_N) == 3.0:  # cranks or sliders, planar or translational
        return THREE
    return WORK_ARRAYS


#: Pose spaces, the second compile-time constant of the entry kernels (the evaluation encodes and compares poses
#: of its own space only).
PLANAR_SPACE, SPATIAL_SPACE, TRANSLATIONAL_SPACE = 0, 1, 2


def pose_space_code(cs) -> int:
    """The pose space (``PLANAR_SPACE``, ``SPATIAL_SPACE`` or ``TRANSLATIONAL_SPACE``) of the robot of ``cs``."""
    if cs.item(C_SPATIAL) != 0.0:
        return SPATIAL_SPACE
    return TRANSLATIONAL_SPACE if cs.item(C_TRANSLATIONAL) != 0.0 else PLANAR_SPACE


def _literal_space(space) -> int:
    """The value of a pose space typed as a compile-time constant."""
    if not isinstance(space, types.IntegerLiteral) or space.literal_value not in (0, 1, 2):
        raise errors.TypingError(f"the pose space must be a compile-time constant in (0, 1, 2), got {space}")
    return space.literal_value


def _literal_path(path) -> int:
    """The value of a row path typed as a compile-time constant (the overloads below choose code by it)."""
    if not isinstance(path, types.IntegerLiteral) or path.literal_value not in ROW_PATHS:
        raise errors.TypingError(f"the row path must be a compile-time constant in {ROW_PATHS}, got {path}")
    return path.literal_value


#: What the overloads that choose a row path's code are compiled with (as ``setup.jit``).
_OVERLOAD_OPTIONS = {"nogil": True, "error_model": "numpy"}
