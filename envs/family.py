"""Pure batched physics and the Gymnasium environments of any robot of the distance-constraint family.

The ``phys2d`` pattern again: constants in a frozen dataclass (``FamilyParams``), the state of N robots in
arrays with a leading dimension N, pure functions (``initial_state``, ``transition``, ``evaluate``,
``step``, ``reward_terms``) over the compiled kernels of ``envs.family_kernels``. The single environments
(N = 1), the native vector environment, the shield, the HER goal view and the evaluation all call them.
A robot is a ``kinematics.DistanceConstraintMechanism`` given as data; ``ROBOT_PRESETS`` holds the
documented defaults of the robots with registered ids (the Stewart–Gough hexapod).
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs import family_kernels as fk
from envs import workspace_kernels
from envs.rendering import HumanWindow
from envs.workspace import WorkspaceMap, WorkspaceSpec, certify_workspace
from kinematics import Delta, DistanceConstraintMechanism, Planar3PRR, Planar3RPR, Planar3RRR, StewartGough

__all__ = [
    "ADEPT_CYCLE",
    "REWARD_TERMS",
    "ROBOTS",
    "ROBOT_PRESETS",
    "TERMINATION_REASONS",
    "FamilyParams",
    "FamilyReachEnv",
    "FamilyReference",
    "FamilyState",
    "FamilyTrackEnv",
    "NonFiniteActionError",
    "evaluate",
    "initial_state",
    "observation_bounds",
    "reward_terms",
    "step",
    "step_info",
    "transition",
    "wrap_angle",
]

#: Termination reason codes (index) and names; 0 means the episode goes on.
TERMINATION_REASONS = (
    "",
    "newton_failed",
    "assembly_mode_change",
    "singularity_crossed",
    "singular",
    "out_of_bounds",
    "actuator_singular",
)
NEWTON_FAILED, ASSEMBLY_MODE_CHANGE, SINGULARITY_CROSSED, SINGULAR, OUT_OF_BOUNDS, ACTUATOR_SINGULAR = range(1, 7)
_REASON_NAMES = np.asarray(TERMINATION_REASONS, dtype=object)


class NonFiniteActionError(ValueError):
    """An action with a NaN or an infinity; ``rows`` holds the indices of the robots that got one."""

    def __init__(self, message: str, rows: np.ndarray) -> None:
        super().__init__(message)
        self.rows = rows


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Wrap angles to [−π, π).

    Args:
        angle: Angles [rad], any shape.

    Returns:
        Wrapped angles [rad], same shape.
    """
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


REWARD_TERMS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "reward_actuator_singularity",
)
_TARGET_MODES = ("standard", "hard", "mixed")
_HARD_KINDS = ("detour", "ill_conditioned", "crossing")
_TASK_REGIONS = ("box", "grid")
_TRACK_SHAPES = ("sinusoid", "circle")
_INTEGRATORS = ("euler", "rk4")
TRAIL_LENGTH = 200


@dataclass(frozen=True)
class FamilyParams:
    """Every constant of a family environment (see ``FamilyReachEnv`` for meanings and units).

    Attributes:
        robot: The mechanism (pose space, legs, geometry, ℓ_c).
        stroke_limits: (q_min, q_max) hard stops of every actuator [m, or rad for cranks].
        dt: Control period [s].
        max_rate: Stroke rate of a unit action [m/s].
        integrator: "euler" or "rk4" prediction of the twist J_f q̇ (on the rotation group).
        pose_low: Lower pose bounds, shape (m,) [m, rad]; leaving them terminates.
        pose_high: Upper pose bounds, shape (m,).
        sample_low: Lower corner of the box starts and targets are drawn from, shape (m,).
        sample_high: Upper corner of that box, shape (m,).
        safe_threshold: k below which the penalty and the cost start.
        hard_threshold: k below which the episode terminates.
        actuator_hard_threshold: Actuator condition number (the Type I measure of cranks and sliders; 1 for
            legs) below which the episode terminates ("actuator_singular").
        actuator_safe_threshold: Actuator condition number below which the Type I penalty and the cost start.
        actuator_singularity_weight: w_s1, the weight of the Type I penalty.
        position_weight: w_p [1/m].
        orientation_weight: w_o [1/m] (multiplies ℓ_c · orientation error).
        singularity_weight: w_s.
        action_weight: w_a.
        termination_penalty: P.
        success_position_tolerance: [m].
        success_orientation_tolerance: [rad].
        newton_tolerance: Residual max_i |Φ_i| of the correction [m²].
        newton_max_iterations: Newton iterations per substep.
        jump_tolerance: Largest ‖(δp, ℓ_c δθ)‖ between prediction and correction [m].
        max_substep: Largest predicted motion per substep [m].
        max_substeps: Most substeps per period.
        track_period: Period of the Track references [s].
        track_amplitude: Largest amplitude of each pose coordinate of a Track reference, shape (m,); with a
            ``track_path``, the scale a_j of its coordinate j.
        track_path: Vertices W_k of a closed polyline Track reference, each of m normalised coordinates
            (x*_j = c_j + a_j W_kj at vertex k, the first two turned by a random heading); () for sinusoids.
        track_path_times: The share of the period each segment W_k → W_k+1 (mod K) takes, K positive values.
        stroke_margin: Strokes of the safe set keep this far from the limits [m].
        segment_spacing: Largest gap between checked points of a certified path [m].
        min_distance: Smallest ‖(δp, ℓ_c δθ)‖ between start and target [m].
        hard_kind: What makes a hard target: "detour" (the straight path dips below k_safe, a detour is
            certified), "ill_conditioned" (the target lies where 2 k_hard ≤ k < k_safe) or "crossing" (the
            straight line in pose space dips below k_hard; start and target in one region of the grid, which
            certifies a detour; needs ``task_region="grid"``).
        task_region: Where starts and targets are drawn: "box" (uniformly in the sampling box, paths certified
            segment by segment) or "grid" (three pose coordinates only: in one connected safe region of a
            certified grid over the pose bounds, ``envs.workspace``).
        grid_cell: Grid spacing of ``task_region="grid"``, shape (3,) [m, rad].
        track_shape: The Track reference: "sinusoid" (x*_j = c_j + a_j sin(ω t + θ_j), or the ``track_path``) or
            "circle" (three pose coordinates, ``task_region="grid"``: a circle of radius r in the first two
            coordinates, the third oscillating by ±a, all of one period in one safe region).
        track_radius_range: (r_min, r_max) of a circle reference [m].
        track_angle_range: (a_min, a_max) of a circle reference's third coordinate [rad, or m if translational].
    """

    robot: DistanceConstraintMechanism = field(default_factory=StewartGough)
    stroke_limits: tuple[float, float] = (0.45, 0.75)
    dt: float = 0.05
    max_rate: float = 0.1
    integrator: str = "euler"
    pose_low: tuple[float, ...] = (-0.2, -0.2, 0.3, -0.6, -0.6, -1.9)
    pose_high: tuple[float, ...] = (0.2, 0.2, 0.75, 0.6, 0.6, 1.9)
    sample_low: tuple[float, ...] = (-0.1, -0.1, 0.4, -0.2, -0.2, -0.5)
    sample_high: tuple[float, ...] = (0.1, 0.1, 0.6, 0.2, 0.2, 0.5)
    safe_threshold: float = 0.1
    hard_threshold: float = 0.03
    actuator_hard_threshold: float = 0.02
    actuator_safe_threshold: float = 0.1
    actuator_singularity_weight: float = 1.0
    position_weight: float = 1.0
    orientation_weight: float = 1.0
    singularity_weight: float = 1.0
    action_weight: float = 0.01
    termination_penalty: float = 50.0
    success_position_tolerance: float = 0.01
    success_orientation_tolerance: float = 0.05
    newton_tolerance: float = 1e-12
    newton_max_iterations: int = 8
    jump_tolerance: float = 0.02
    max_substep: float = 0.01
    max_substeps: int = 16
    track_period: float = 8.0
    track_amplitude: tuple[float, ...] = (0.05, 0.0, 0.04, 0.0, 0.1, 0.0)
    track_path: tuple[tuple[float, ...], ...] = ()
    track_path_times: tuple[float, ...] = ()
    stroke_margin: float = 0.02
    segment_spacing: float = 0.01
    min_distance: float = 0.05
    hard_kind: str = "detour"
    task_region: str = "box"
    grid_cell: tuple[float, float, float] = (0.025, 0.025, 0.05)
    track_shape: str = "sinusoid"
    track_radius_range: tuple[float, float] = (0.05, 0.15)
    track_angle_range: tuple[float, float] = (0.0, 0.4)

    @functools.cached_property
    def workspace(self) -> WorkspaceMap | None:
        """The certified grid of ``task_region="grid"`` (cached per geometry and limits), else None."""
        if self.task_region != "grid":
            return None
        return certify_workspace(
            WorkspaceSpec(
                robot=self.robot,
                stroke_limits=self.stroke_limits,
                pose_low=self.pose_low,
                pose_high=self.pose_high,
                safe_threshold=self.safe_threshold,
                actuator_safe_threshold=self.actuator_safe_threshold,
                stroke_margin=self.stroke_margin,
                cell=self.grid_cell,
            )
        )

    @property
    def pose_metric(self) -> np.ndarray:
        """1 for positions, ℓ_c for angles: multiplies a pose difference into metres, (δp, ℓ_c δθ), shape (m,)."""
        return 1.0 / self.robot.pose_scale

    @functools.cached_property
    def packed(self) -> np.ndarray:
        """The kernels' float64 constants (``family_kernels.pack_family``), read-only."""
        return fk.pack_family(self)

    @functools.cached_property
    def spatial(self) -> bool:
        """Whether the pose space is spatial (else planar)."""
        return self.robot.pose_space.name == "spatial"

    @functools.cached_property
    def evaluation_rows(self) -> dict[str, int | slice]:
        """Rows of ``evaluate`` / ``step``'s evaluation array."""
        return fk.evaluation_rows(self.robot.n_pose)

    @functools.cached_property
    def observation_bounds(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``observation_bounds`` without (index 0) and with (index 1) the target velocity."""
        return _observation_bounds(self, False), _observation_bounds(self, True)


#: The robots a family environment builds by name (``robot="delta"``), each with its default geometry.
ROBOTS: dict[str, type[DistanceConstraintMechanism]] = {
    "planar_3rpr": Planar3RPR,
    "stewart_gough": StewartGough,
    "delta": Delta,
    "planar_3rrr": Planar3RRR,
    "planar_3prr": Planar3PRR,
}

#: The "adept cycle" of pick-and-place benchmarks as a Track path of a translational robot: from the pick point up
#: 25 mm, across 305 mm, down 25 mm to the place point, and back the same way (vertices in units of
#: ``track_amplitude`` = (0.305, 0, 0.025) m; the heading in the horizontal plane is drawn per episode). The
#: vertical moves take 1/10 of the period each, the moves across 3/10, at rest at every corner.
ADEPT_CYCLE: dict[str, Any] = {
    "track_path": (
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 1.0),
        (1.0, 0.0, 1.0),
        (1.0, 0.0, 0.0),
        (1.0, 0.0, 1.0),
        (0.0, 0.0, 1.0),
    ),
    "track_path_times": (1.0, 3.0, 1.0, 1.0, 3.0, 1.0),
    "track_amplitude": (0.305, 0.0, 0.025),
}

_DELTA: dict[str, Any] = {
    # Williams' ABB IRB 360 (``kinematics.DEFAULT_DELTA``), plate below the base (z < 0). Motors turn 1 rad/s at a unit
    # action, within −0.6 to 1.7 rad (0: arm horizontal, positive down). Tasks in a 1.2 m square, 0.7 m deep
    # (z −1.7 to −1.0 m; the home, every arm 30° down, is at z = −1.366 m); the plate must stay within ±0.75 m,
    # z −1.8 to −0.85 m. Its Type II zone (k < 0.1) is the outer, lower edge of that box: hard targets are there.
    "robot": "delta",
    "stroke_limits": (-0.6, 1.7),
    "max_rate": 1.0,
    "pose_low": (-0.75, -0.75, -1.8),
    "pose_high": (0.75, 0.75, -0.85),
    "sample_low": (-0.6, -0.6, -1.7),
    "sample_high": (0.6, 0.6, -1.0),
    "min_distance": 0.1,
    "stroke_margin": 0.05,
    "track_period": 4.0,
    "hard_kind": "ill_conditioned",
    # Substeps of up to 3 cm of predicted motion, and certified paths checked every 3 cm (1 cm for the smaller
    # robots): 2.5 % of the 1.24 m forearms.
    "max_substep": 0.03,
    "segment_spacing": 0.03,
}

_PLANAR_3RRR: dict[str, Any] = {
    # ``kinematics.Planar3RRR()`` (base radius 0.25 m, cranks and links 0.14 m, elbows "−−−"): cranks turn
    # 0.5 rad/s at a unit action within −2.2 to 0.6 rad. Tasks within ±0.1 m and φ ±0.7 rad, where a band of
    # Type II singularities (the links' lines concurrent) lies near φ ≈ 0.3–0.6 rad.
    "robot": "planar_3rrr",
    "stroke_limits": (-2.2, 0.6),
    "max_rate": 0.5,
    "pose_low": (-0.125, -0.125, -0.9),
    "pose_high": (0.125, 0.125, 0.9),
    "sample_low": (-0.1, -0.1, -0.7),
    "sample_high": (0.1, 0.1, 0.7),
    "stroke_margin": 0.05,
}

_PLANAR_3RPR: dict[str, Any] = {
    # The lesson's 3-RPR (``kinematics.Planar3RPR()``): legs 0.3-1.0 m at 0.25 m/s, the pose within x -0.2-1.2 m,
    # y -0.3-1.2 m, φ ±π/2. Tasks come from the certified grid (cells of 2.5 cm, 2.5 cm, 0.05 rad) inside those
    # bounds less (5 cm, 5 cm, 0.1 rad): start and target in one safe region (k ≥ 0.15), at least 0.1 m apart.
    # Hard targets: the straight line from the start crosses k < 0.03 (``hard_kind="crossing"``). Track: a
    # circle of radius 5-15 cm with φ oscillating by up to ±0.4 rad, every 10 s.
    "robot": "planar_3rpr",
    "stroke_limits": (0.3, 1.0),
    "max_rate": 0.25,
    "pose_low": (-0.2, -0.3, -np.pi / 2),
    "pose_high": (1.2, 1.2, np.pi / 2),
    "sample_low": (-0.2 + 0.05, -0.3 + 0.05, -np.pi / 2 + 0.1),
    "sample_high": (1.2 - 0.05, 1.2 - 0.05, np.pi / 2 - 0.1),
    "safe_threshold": 0.15,
    "success_position_tolerance": 0.02,
    "success_orientation_tolerance": 0.1,
    "min_distance": 0.1,
    "task_region": "grid",
    "hard_kind": "crossing",
    "track_shape": "circle",
    "track_period": 10.0,
}

#: Documented defaults of the robots with registered ids: constructor keyword arguments of the envs.
ROBOT_PRESETS: dict[str, dict[str, Any]] = {
    "planar_3rpr": _PLANAR_3RPR,
    # A symmetric 6-6 hexapod (``kinematics.StewartGough()``): base radius 0.5 m, platform radius 0.3 m, legs
    # 0.59 m at the home pose p = (0, 0, 0.5) m. Strokes 0.45-0.75 m at 0.1 m/s. Standard tasks keep to a box of
    # ±0.1 m, z 0.4-0.6 m, tilts ±0.2 rad and yaw ±0.5 rad, where k ≥ 0.2. Hard tasks widen the tilts to
    # ±0.35 rad and the yaw to ±1.3 rad, toward Fichter's singularity at yaw ±90°.
    "stewart_gough": {
        "robot": "stewart_gough",
        **{
            name: FamilyParams.__dataclass_fields__[name].default
            for name in ("stroke_limits", "pose_low", "pose_high", "sample_low", "sample_high", "track_amplitude")
        },
    },
    # In this workspace no straight path between two safe poses dips below k_safe (0 of 10 000 pairs, even
    # with k_safe = 0.25: k is quasi-concave there), so hard targets are ill-conditioned ones instead: toward
    # Fichter's singularity, where 2 k_hard ≤ k < k_safe, reached from a safe start. Large yaws stretch the
    # legs, so this task's hexapod has longer strokes (0.40-0.85 m).
    "stewart_gough_hard": {
        "robot": "stewart_gough",
        "pose_low": FamilyParams.pose_low,
        "pose_high": FamilyParams.pose_high,
        "track_amplitude": FamilyParams.track_amplitude,
        "stroke_limits": (0.40, 0.85),
        "sample_low": (-0.12, -0.12, 0.38, -0.3, -0.3, -1.45),
        "sample_high": (0.12, 0.12, 0.62, 0.3, 0.3, 1.45),
        "hard_kind": "ill_conditioned",
    },
    "delta": _DELTA,
    "delta_track": {**_DELTA, **ADEPT_CYCLE},
    "planar_3rrr": _PLANAR_3RRR,
    # ``kinematics.Planar3PRR()``: sliders along the base triangle's sides at 0.1 m/s; bounds around its home.
    "planar_3prr": {"robot": "planar_3prr"},
}


class FamilyReference(NamedTuple):
    """Target trajectories of N robots: x*_j(t) = c_j + a_j sin(ω t + θ_j), ω = 2π / track_period.

    For spatial poses the coordinates are (p, rotation vector); a reference that moves one rotation
    coordinate alone (as Track's pitch) turns about a fixed axis, where ṙ is the angular velocity. A fixed
    target (Reach) has a = 0.

    Attributes:
        center: c, shape (N, m).
        amplitude: a, shape (N, m).
        phase: θ [rad], shape (N, m).
        strokes: The actuator coordinates of c (closed-form inverse kinematics, ``family_kernels.strokes_batch``),
            shape (N, n), or None: ``initial_state`` fills it. The observation's stroke errors read it while a
            target is fixed, so that a crank's inverse kinematics is solved once per episode, not once per step.
    """

    center: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    strokes: np.ndarray | None = None


def with_strokes(params: FamilyParams, reference: FamilyReference) -> FamilyReference:
    """``reference`` with its ``strokes`` (computed from its centres if they are missing)."""
    if reference.strokes is not None:
        return reference
    return reference._replace(strokes=fk.strokes_batch(params.packed, np.ascontiguousarray(reference.center)))


class FamilyState(NamedTuple):
    """State of N robots.

    Attributes:
        q: Leg lengths [m], shape (N, n).
        x: Platform poses of {P} in {B}, shape (N, m).
        t: Steps taken in the episode, shape (N,) (int).
        det_sign: sign(det J_x) at the start of the episode (the working mode), shape (N,).
        inverse_condition: Homogeneous inverse condition number k at (q, x) (Type II measure), shape (N,).
        actuator_condition: Actuator condition number at (q, x) (Type I measure; 1 for legs), shape (N,).
        residual: Constraint residual max_i |Φ_i| [m²], shape (N,).
        reference: The targets' trajectories.
    """

    q: np.ndarray
    x: np.ndarray
    t: np.ndarray
    det_sign: np.ndarray
    inverse_condition: np.ndarray
    actuator_condition: np.ndarray
    residual: np.ndarray
    reference: FamilyReference


class FamilyOutcome(NamedTuple):
    """What a transition reports besides the new state.

    Attributes:
        action: The applied (clipped) action, shape (N, n).
        q_rate: Achieved stroke rates [m/s], shape (N, n).
        reason: Termination reason codes (``TERMINATION_REASONS``), shape (N,).
        jump: Largest prediction–correction gap ‖(δp, ℓ_c δθ)‖ [m], shape (N,).
    """

    action: np.ndarray
    q_rate: np.ndarray
    reason: np.ndarray
    jump: np.ndarray


def _observation_bounds(params: FamilyParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    n = params.robot.n_actuators
    space = params.robot.pose_space.name
    low_p, high_p = np.array(params.pose_low), np.array(params.pose_high)
    d = 2 if space == "planar" else 3
    span = high_p[:d] - low_p[:d]
    if space == "spatial":
        code_lo, code_hi = [0.0, -1.0, -1.0, -1.0], [1.0, 1.0, 1.0, 1.0]
        rot_err = [np.pi] * 3
    elif space == "translational":
        code_lo, code_hi, rot_err = [], [], []
    else:
        code_lo, code_hi = [-1.0, -1.0], [1.0, 1.0]
        rot_err = [np.pi]
    pose_lo = [*low_p[:d], *code_lo]
    pose_hi = [*high_p[:d], *code_hi]
    low = [*pose_lo, *pose_lo, *(-span), *(-np.array(rot_err)), *[-1.0] * (2 * n), 0.0]
    high = [*pose_hi, *pose_hi, *span, *rot_err, *[1.0] * (2 * n), 1.0]
    if with_velocity:
        # |ẋ*_j| ≤ a_j ω; coordinates that do not move keep a small non-empty range (Gymnasium's checker).
        v_max = np.maximum(_track_speed_bounds(params), 1e-3)
        low += list(-v_max)
        high += list(v_max)
    low_arr, high_arr = np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)
    low_arr.setflags(write=False)
    high_arr.setflags(write=False)
    return low_arr, high_arr


def _track_speed_bounds(params: FamilyParams) -> np.ndarray:
    """Largest |ẋ*_j| of a Track reference, shape (m,).

    a_j ω for sinusoids; for a path, the peak rate of its cosine profile on each segment, π |a_j ΔW_j| / (2 D_k),
    with the first two coordinates' norm for both (any heading).
    """
    if params.track_shape == "circle":
        # |ṗ*| ≤ ω · (the largest span of the first two coordinates) / 2, the third ≤ ω · its span / 2: a bound
        # every circle inside the pose bounds keeps.
        omega = 2.0 * np.pi / params.track_period
        span = np.array(params.pose_high) - np.array(params.pose_low)
        v_max = omega * float(np.max(span[:2])) / 2.0
        return np.array([v_max, v_max, omega * float(span[2]) / 2.0])
    amplitude = np.array(params.track_amplitude)
    if not params.track_path:
        return amplitude * 2.0 * np.pi / params.track_period
    path = np.array(params.track_path)
    times = np.array(params.track_path_times) / np.sum(params.track_path_times) * params.track_period
    step = (np.roll(path, -1, axis=0) - path) * amplitude
    peak = np.pi * np.abs(step) / (2.0 * times[:, None])
    if len(amplitude) >= 2:
        peak[:, :2] = np.pi * np.linalg.norm(step[:, :2], axis=1, keepdims=True) / (2.0 * times[:, None])
    return peak.max(axis=0)


def observation_bounds(params: FamilyParams, with_velocity: bool) -> tuple[np.ndarray, np.ndarray]:
    """Finite float32 bounds of the observation (layout in ``FamilyReachEnv``'s docstring).

    Args:
        params: Environment constants.
        with_velocity: Whether the target velocity is appended (Track).

    Returns:
        (low, high), read-only float32 arrays.
    """
    return params.observation_bounds[bool(with_velocity)]


def _rows(a: Any, width: int, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (N, {width}), got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def initial_state(params: FamilyParams, start: np.ndarray, reference: FamilyReference) -> FamilyState:
    """State of N robots at rest at ``start`` (shape (N, m)), strokes from the inverse kinematics."""
    start = _rows(start, params.robot.n_pose, "start")
    q, k, k1, det_sign, residual = fk.initial_batch(params.packed, start)
    reference = with_strokes(params, reference)
    return FamilyState(q, start.copy(), np.zeros(len(start), dtype=np.int64), det_sign, k, k1, residual, reference)


def transition(params: FamilyParams, state: FamilyState, action: np.ndarray) -> tuple[FamilyState, FamilyOutcome]:
    """Advance N robots by one control period: predict, correct, measure, terminate.

    Strokes advance by the clipped action · max_rate · dt, clamped to the hard stops; the step is split into
    substeps of at most ``max_substep`` of predicted motion; each predicts the pose with the twist
    J_f(q, x) q̇ (Euler or RK4, on the rotation group) and corrects it onto Φ = 0 by Newton's method. A robot
    whose correction fails stays where it was; the others are checked for an assembly-mode jump, a flip of
    sign(det J_x), k < hard_threshold and leaving the pose bounds, in that order.

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, n), finite.

    Returns:
        (the new state, the outcome).
    """
    action = _rows(action, params.robot.n_actuators, "action")
    if not np.isfinite(action).all():
        rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
        raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}", rows)
    q, x, k, k1, residual, a, q_rate, reason, jump = fk.transition_batch(
        params.packed, state.q, state.x, state.det_sign, state.residual, action
    )
    new = FamilyState(q, x, state.t + 1, state.det_sign, k, k1, residual, state.reference)
    return new, FamilyOutcome(a, q_rate, reason, jump)


def evaluate(
    params: FamilyParams, state: FamilyState, action: np.ndarray, reason: np.ndarray, with_velocity: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Reward terms, errors, success, cost, targets and observations of a state, in one compiled pass.

    Args:
        params: Environment constants.
        state: The robots' state.
        action: The applied actions, shape (N, n).
        reason: Termination reason codes, shape (N,).
        with_velocity: Whether the observation ends with the target velocity.

    Returns:
        (evaluation (rows of ``params.evaluation_rows``, N) float64, observations (N, D) float32).
    """
    action = _rows(action, params.robot.n_actuators, "action")
    low, high = observation_bounds(params, with_velocity)
    ref = with_strokes(params, state.reference)
    return fk.evaluate_batch(
        params.packed,
        low,
        high,
        bool(with_velocity),
        state.q,
        state.x,
        state.t,
        state.inverse_condition,
        state.actuator_condition,
        state.residual,
        ref.center,
        ref.amplitude,
        ref.phase,
        ref.strokes,
        action,
        np.asarray(reason, dtype=np.int64),
    )


def reward_terms(
    params: FamilyParams,
    x: np.ndarray,
    target: np.ndarray,
    inverse_condition: np.ndarray,
    action: np.ndarray,
    reason: np.ndarray,
    actuator_condition: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Every term of the reward of N poses against fixed targets (what HER's ``compute_reward`` calls).

    Args:
        params: Environment constants.
        x: Poses, shape (N, m).
        target: Target poses, shape (N, m).
        inverse_condition: k, shape (N,).
        action: Applied actions, shape (N, n).
        reason: Termination reason codes, shape (N,).
        actuator_condition: k_I, shape (N,) (default 1: no Type I penalty, as for legs).

    Returns:
        The ``REWARD_TERMS``, each shape (N,).
    """
    m = params.robot.n_pose
    x, target = _rows(x, m, "x"), _rows(target, m, "target")
    n = len(x)
    k = np.asarray(inverse_condition, dtype=np.float64).reshape(n)
    k1 = np.ones(n) if actuator_condition is None else np.asarray(actuator_condition, dtype=np.float64).reshape(n)
    ref = FamilyReference(target, np.zeros((n, m)), np.zeros((n, m)))
    strokes = np.full((n, m), np.mean(params.stroke_limits))
    state = FamilyState(strokes, x, np.zeros(n, dtype=np.int64), np.ones(n), k, k1, np.zeros(n), ref)
    evaluation, _ = evaluate(params, state, action, reason, False)
    rows = params.evaluation_rows
    return {name: evaluation[rows[name]].copy() for name in REWARD_TERMS}


class StepBuffers:
    """Output arrays of ``step`` for N robots, reused by every step (an env alternates two of them)."""

    def __init__(self, params: FamilyParams, n: int, with_velocity: bool) -> None:
        obs_dim = observation_bounds(params, with_velocity)[0].shape[0]
        self.arrays = fk.allocate_step(n, params.robot.n_pose, obs_dim)
        q, x, t, k, k1, residual, a, q_rate, reason, jump, evaluation, observations = self.arrays
        self.outcome = FamilyOutcome(a, q_rate, reason, jump)
        self.evaluation, self.observations = evaluation, observations
        self.fields = (q, x, t, k, k1, residual)


def step(
    params: FamilyParams, state: FamilyState, action: np.ndarray, with_velocity: bool, out: StepBuffers | None = None
) -> tuple[FamilyState, FamilyOutcome, np.ndarray, np.ndarray]:
    """``transition`` then ``evaluate``, fused in one compiled pass (on every core for large N).

    Args:
        params: Environment constants.
        state: The robots' state.
        action: Normalised stroke rates, shape (N, n), float64.
        with_velocity: Whether the observation ends with the target velocity.
        out: Buffers to write into (none of them may hold ``state``), or None.

    Returns:
        (new state, outcome, evaluation, observations).

    Raises:
        NonFiniteActionError: If an action is not finite (``state`` is untouched).
    """
    n = state.q.shape[0]
    if action.shape != state.q.shape or action.dtype != np.float64:
        action = _rows(action, params.robot.n_actuators, "action")
        if action.shape[0] != n:
            raise ValueError(f"action must have shape {state.q.shape}, got {action.shape}")
    if out is None:
        out = StepBuffers(params, n, with_velocity)
    ref = with_strokes(params, state.reference)
    low, high = observation_bounds(params, with_velocity)
    bad = fk.step_batch(
        params.packed,
        low,
        high,
        bool(with_velocity),
        state.q,
        state.x,
        state.t,
        state.det_sign,
        state.residual,
        ref.center,
        ref.amplitude,
        ref.phase,
        ref.strokes,
        action,
        out.arrays,
    )
    if bad:
        rows = np.flatnonzero(~np.isfinite(action).all(axis=-1))
        where = f" (row(s) {rows[:10].tolist()} of {n})" if n > 1 else ""
        raise NonFiniteActionError(f"action must be finite, got {action[rows[0]].tolist()}{where}", rows)
    q, x, t, k, k1, residual = out.fields
    return FamilyState(q, x, t, state.det_sign, k, k1, residual, ref), out.outcome, out.evaluation, out.observations


def copy_state(state: FamilyState) -> FamilyState:
    """A deep copy of ``state`` (every array copied)."""
    ref = FamilyReference(*(None if a is None else a.copy() for a in state.reference))
    return FamilyState(*(a.copy() for a in state[:-1]), ref)


def step_info(params: FamilyParams, evaluation: np.ndarray, reason: np.ndarray) -> dict[str, np.ndarray]:
    """Per-robot info arrays (leading dimension N) from an evaluation, in the single env's key order.

    The 3-RPR's ``step_info`` over this core's row layout (``params.evaluation_rows``), with the Type I
    terms after it.
    """
    rows = params.evaluation_rows
    info = {name: evaluation[rows[name]].copy() for name in _INFO_SCALARS[:8]}
    info["is_success"] = evaluation[rows["is_success"]] != 0.0
    info["cost"] = evaluation[rows["cost"]].copy()
    info["termination_reason"] = _REASON_NAMES[reason]
    info["pose"] = evaluation[rows["pose"]].T.copy()
    info["target"] = evaluation[rows["target"]].T.copy()
    for name in _TYPE_I_INFO:
        info[name] = evaluation[rows[name]].copy()
    return info


# -- argument checks ---------------------------------------------------------------------------------------


def _number(name: str, value: Any, *, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    value = float(value)
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{name} must be finite and {'≥' if allow_zero else '>'} 0, got {value!r}")
    return value


def _vector(name: str, value: Any, size: int) -> tuple[float, ...]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a sequence of {size} numbers, got {value!r}") from exc
    if arr.shape != (size,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be {size} finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


def _track_path(path: Any, times: Any, m: int) -> tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]:
    """Validate a polyline Track reference: 2–8 vertices of m finite values and as many positive time shares."""
    if len(path) == 0 and len(times) == 0:
        return (), ()
    vertices = np.asarray(path, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != m or not 2 <= len(vertices) <= fk.PATH_VERTICES:
        raise ValueError(
            f"track_path must hold 2 to {fk.PATH_VERTICES} vertices of {m} values, got shape {vertices.shape}"
        )
    shares = np.asarray(times, dtype=np.float64)
    if shares.shape != (len(vertices),) or not np.all(np.isfinite(shares)) or not np.all(shares > 0):
        raise ValueError(
            f"track_path_times must be {len(vertices)} positive shares (one per segment), got {tuple(np.ravel(times))}"
        )
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"track_path must be finite, got {vertices.tolist()}")
    return tuple(tuple(map(float, v)) for v in vertices), tuple(map(float, shares))


def derived_defaults(robot: DistanceConstraintMechanism) -> dict[str, Any]:
    """Bounds, task box, stroke limits and Track amplitudes of a robot, scaled by its size around its home pose.

    The reach ρ is half the mean distance of the base anchors from their centroid. Pose bounds span ±ρ in
    position (planar: φ ±0.6 rad; spatial: ±0.8 ρ in x, y, ±0.9 ρ in z, tilts ±0.6 rad and yaw ±1.9 rad) and the
    task box 0.6 (spatial: 0.4) of that in position, tilts ±0.2 rad and yaw ±0.5 rad. Legs get strokes from
    0.5 (spatial: 0.75) of the shortest to 1.6 (spatial: 1.3) of the longest leg at home; cranks ±1 rad and
    sliders ±0.2 m around their values at home.

    Args:
        robot: The mechanism.

    Returns:
        Keyword arguments of ``FamilyParams`` (a caller's own values take precedence).
    """
    home = robot.home_pose()
    reach = 0.5 * float(np.mean(np.linalg.norm(robot.base - robot.base.mean(axis=0), axis=1)))
    space = robot.pose_space.name
    if space == "spatial":
        half = np.array([0.8 * reach, 0.8 * reach, 0.9 * reach, 0.6, 0.6, 1.9])
        box = np.array([0.4 * reach, 0.4 * reach, 0.4 * reach, 0.2, 0.2, 0.5])
        amplitude = (0.2 * reach, 0.0, 0.16 * reach, 0.0, 0.1, 0.0)
        leg_band = (0.75, 1.3)
    else:
        half = np.array([reach, reach, 0.6 if space == "planar" else reach])
        box = 0.6 * half
        amplitude = (0.3 * reach, 0.3 * reach, 0.2)
        leg_band = (0.5, 1.6)
    at_home = robot.inverse_kinematics(home)
    if all(kind == "leg" for kind in robot.actuator_kinds):
        strokes = (leg_band[0] * float(at_home.min()), leg_band[1] * float(at_home.max()))
    else:  # cranks [rad] or sliders [m]: a band around the home pose's values
        band = 1.0 if "crank" in robot.actuator_kinds else 0.2
        strokes = (float(at_home.min()) - band, float(at_home.max()) + band)
    return {
        "pose_low": tuple(home - half),
        "pose_high": tuple(home + half),
        "sample_low": tuple(home - box),
        "sample_high": tuple(home + box),
        "track_amplitude": amplitude,
        "stroke_limits": strokes,
    }


def build_family_params(robot: DistanceConstraintMechanism | None = None, **kwargs: Any) -> FamilyParams:
    """Validate constructor arguments into ``FamilyParams``; a robot without bounds gets ones around its home pose.

    Args:
        robot: The mechanism, or the name of one with its default geometry (a key of ``ROBOTS``); default
            ``StewartGough()``.
        **kwargs: Fields of ``FamilyParams``.

    Returns:
        The validated parameters.

    Raises:
        TypeError: On a robot that is not a ``DistanceConstraintMechanism`` or an argument of the wrong type.
        ValueError: On an argument out of its range, naming the expected and the actual value.
    """
    if robot is None:
        robot = "stewart_gough"
    if isinstance(robot, str):
        if robot in ROBOT_PRESETS:  # a preset: its documented settings, under the caller's own
            preset = dict(ROBOT_PRESETS[robot])
            name = preset.pop("robot")
            kwargs = {**preset, **kwargs}
            robot = name
        if robot not in ROBOTS:
            raise ValueError(
                f"robot must be a DistanceConstraintMechanism or one of {sorted(set(ROBOTS) | set(ROBOT_PRESETS))}, "
                f"got {robot!r}"
            )
        robot = ROBOTS[robot]()
    if not isinstance(robot, DistanceConstraintMechanism):
        raise TypeError(f"robot must be a kinematics.DistanceConstraintMechanism, got {type(robot).__name__}")
    m = robot.n_pose
    defaults = FamilyParams.__dataclass_fields__
    for name, value in derived_defaults(robot).items():
        kwargs.setdefault(name, value)
    unknown = set(kwargs) - set(defaults)
    if unknown:
        raise TypeError(f"unknown argument(s) {sorted(unknown)}")
    values: dict[str, Any] = {}
    for name in ("pose_low", "pose_high", "sample_low", "sample_high", "track_amplitude"):
        values[name] = _vector(name, kwargs.get(name, defaults[name].default), m)
    lo, hi = _vector("stroke_limits", kwargs.get("stroke_limits", defaults["stroke_limits"].default), 2)
    has_legs = "leg" in robot.actuator_kinds
    if not (0 < lo < hi if has_legs else lo < hi):
        bound = "0 < q_min < q_max (leg lengths)" if has_legs else "q_min < q_max"
        raise ValueError(f"stroke_limits must satisfy {bound}, got {(lo, hi)}")
    for a, b in (("pose_low", "pose_high"), ("sample_low", "sample_high")):
        if not all(u < v for u, v in zip(values[a], values[b])):
            raise ValueError(f"{a} must be < {b} componentwise, got {values[a]} and {values[b]}")
    if not all(
        pl <= sl and sh <= ph
        for pl, sl, sh, ph in zip(values["pose_low"], values["sample_low"], values["sample_high"], values["pose_high"])
    ):
        raise ValueError(
            f"the sampling box {values['sample_low']}–{values['sample_high']} must lie inside the pose bounds "
            f"{values['pose_low']}–{values['pose_high']}"
        )
    if robot.pose_space.name == "spatial" and max(map(abs, values["pose_low"][3:] + values["pose_high"][3:])) >= 2.5:
        raise ValueError("rotation-vector bounds must stay within ±2.5 rad, away from the wrap at |r| = π")
    values["track_path"], values["track_path_times"] = _track_path(
        kwargs.get("track_path", ()), kwargs.get("track_path_times", ()), m
    )
    options = {}
    for name, valid in (("hard_kind", _HARD_KINDS), ("task_region", _TASK_REGIONS), ("track_shape", _TRACK_SHAPES)):
        options[name] = kwargs.get(name, defaults[name].default)
        if options[name] not in valid:
            raise ValueError(f"{name} must be one of {valid}, got {options[name]!r}")
    if options["task_region"] == "grid" and m != 3:
        raise ValueError(f"task_region='grid' needs a robot with 3 pose coordinates, got {m} ({robot.pose_space.name})")
    if options["hard_kind"] == "crossing" and options["task_region"] != "grid":
        raise ValueError(f"hard_kind='crossing' needs task_region='grid', got {options['task_region']!r}")
    if options["track_shape"] == "circle" and (options["task_region"] != "grid" or values["track_path"]):
        raise ValueError("track_shape='circle' needs task_region='grid' and no track_path")
    values["grid_cell"] = _vector("grid_cell", kwargs.get("grid_cell", defaults["grid_cell"].default), 3)
    if not all(v > 0 for v in values["grid_cell"]):
        raise ValueError(f"grid_cell must be 3 positive spacings, got {values['grid_cell']}")
    for name in ("track_radius_range", "track_angle_range"):
        values[name] = _vector(name, kwargs.get(name, defaults[name].default), 2)
        if not 0 <= values[name][0] <= values[name][1]:
            raise ValueError(f"{name} must satisfy 0 ≤ low ≤ high, got {values[name]}")
    integrator = kwargs.get("integrator", "euler")
    if integrator not in _INTEGRATORS:
        raise ValueError(f"integrator must be one of {_INTEGRATORS}, got {integrator!r}")
    safe = _number("safe_threshold", kwargs.get("safe_threshold", defaults["safe_threshold"].default))
    hard = _number("hard_threshold", kwargs.get("hard_threshold", defaults["hard_threshold"].default))
    if not 0 < hard < safe < 1:
        raise ValueError(f"thresholds must satisfy 0 < hard_threshold < safe_threshold < 1, got {hard} and {safe}")
    hard1 = _number(
        "actuator_hard_threshold",
        kwargs.get("actuator_hard_threshold", defaults["actuator_hard_threshold"].default),
        allow_zero=True,
    )
    safe1 = _number(
        "actuator_safe_threshold", kwargs.get("actuator_safe_threshold", defaults["actuator_safe_threshold"].default)
    )
    if not hard1 < safe1 < 1:
        raise ValueError(
            f"thresholds must satisfy actuator_hard_threshold < actuator_safe_threshold < 1, got {hard1} and {safe1}"
        )
    iterations = kwargs.get("newton_max_iterations", defaults["newton_max_iterations"].default)
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ValueError(f"newton_max_iterations must be an int ≥ 1, got {iterations!r}")
    substeps = kwargs.get("max_substeps", defaults["max_substeps"].default)
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ValueError(f"max_substeps must be an int ≥ 1, got {substeps!r}")
    scalars = {}
    for name in (
        "dt",
        "max_rate",
        "success_position_tolerance",
        "success_orientation_tolerance",
        "newton_tolerance",
        "jump_tolerance",
        "max_substep",
        "track_period",
        "segment_spacing",
    ):
        scalars[name] = _number(name, kwargs.get(name, defaults[name].default))
    for name in (
        "position_weight",
        "orientation_weight",
        "singularity_weight",
        "action_weight",
        "termination_penalty",
        "actuator_singularity_weight",
        "stroke_margin",
        "min_distance",
    ):
        scalars[name] = _number(name, kwargs.get(name, defaults[name].default), allow_zero=True)
    return FamilyParams(
        robot=robot,
        stroke_limits=(lo, hi),
        integrator=integrator,
        **options,
        safe_threshold=safe,
        hard_threshold=hard,
        actuator_hard_threshold=hard1,
        actuator_safe_threshold=safe1,
        newton_max_iterations=int(iterations),
        max_substeps=int(substeps),
        **values,
        **scalars,
    )


# -- the environments ----------------------------------------------------------------------------------------


#: The scalar entries of a single env's ``info``, in order; "is_success" becomes a bool, then come
#: "termination_reason", "pose" and "target", then the Type I entries (``_TYPE_I_INFO``).
_INFO_SCALARS = (
    "reward_tracking",
    "reward_singularity",
    "reward_action",
    "reward_termination",
    "position_error",
    "orientation_error",
    "inverse_condition_number",
    "constraint_residual",
    "is_success",
    "cost",
    "reward_actuator_singularity",
    "actuator_condition_number",
    "cost_actuator_singularity",
)
_TYPE_I_INFO = ("reward_actuator_singularity", "actuator_condition_number", "cost_actuator_singularity")


class FamilyEnvBase(gym.Env[np.ndarray, np.ndarray]):
    """Shared machinery of the single-robot family environments; see ``FamilyReachEnv`` for the documentation."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}
    with_velocity = False
    reset_options: tuple[str, ...] = ()

    def _setup(self, render_mode: str | None, params: FamilyParams) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.params = params
        self.metadata = {**type(self).metadata, "render_fps": 1.0 / params.dt}
        n = params.robot.n_actuators
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        low, high = observation_bounds(params, self.with_velocity)
        self.observation_space = spaces.Box(low.copy(), high.copy(), dtype=np.float32)
        self._state: FamilyState | None = None
        self._buffers = (StepBuffers(params, 1, self.with_velocity), StepBuffers(params, 1, self.with_velocity))
        self._next = 0
        self._terminated = False
        self._trail: deque[np.ndarray] = deque(maxlen=TRAIL_LENGTH)
        rows = params.evaluation_rows
        self._reward_row = rows["reward"]
        self._info_rows = tuple((name, rows[name]) for name in _INFO_SCALARS)
        self._pose_rows, self._target_rows = rows["pose"], rows["target"]
        self._window: HumanWindow | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start a new episode (see the class docstring, Starting State)."""
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        unknown = set(options) - set(self.reset_options)
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid options are {list(self.reset_options)}")
        start, reference = self.sample_tasks((self.np_random,), options)
        self._state = initial_state(self.params, start, reference)
        self._terminated = False
        self._trail.clear()
        if self.render_mode is not None:  # the trail is drawn only
            self._trail.append(self.params.robot.pose_space.position(self._state.x[0]).copy())
        n = self.params.robot.n_actuators
        evaluation, observations = evaluate(
            self.params, self._state, np.zeros((1, n)), np.zeros(1, dtype=np.int64), self.with_velocity
        )
        if self.render_mode == "human":
            self.render()
        return observations[0], self._info(evaluation[:, 0], 0)

    def step(self, action: Any):
        """Apply normalised stroke rates for one period dt (see the class docstring)."""
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        if self._terminated:
            raise gym.error.ResetNeeded("The episode has terminated; call reset() before step()")
        n = self.params.robot.n_actuators
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"action must be an array of {n} real numbers, got {action!r}") from exc
        if a.shape != (n,):
            raise ValueError(f"action must have shape ({n},), got shape {a.shape}")
        out = self._buffers[self._next]
        state, outcome, evaluation, observations = step(
            self.params, self._state, a.reshape(1, n), self.with_velocity, out
        )
        self._next ^= 1
        self._state = state
        reason = int(outcome.reason[0])
        self._terminated = reason != 0
        row = evaluation[:, 0]
        info = self._info(row, reason)
        if self.render_mode is not None:
            self._trail.append(self.params.robot.pose_space.position(info["pose"]).copy())
        if self.render_mode == "human":
            self.render()
        return observations[0].copy(), float(row[self._reward_row]), self._terminated, False, info

    def render(self):
        """An RGB frame (``rgb_array``, headless), or a window update (``human``); None without a render mode."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call render() before reset()")
        frame = self._frame()
        if self.render_mode == "rgb_array":
            return frame
        if self._window is None:
            self._window = HumanWindow(self.metadata["render_fps"])
        self._window.show(frame)
        return None

    def close(self) -> None:
        """Close the window of ``human`` rendering, if open."""
        if self._window is not None:
            self._window.close()
            self._window = None
        super().close()

    def _frame(self) -> np.ndarray:
        from envs.rendering_family import render_family_frame

        evaluation, _ = evaluate(
            self.params, self._state, np.zeros_like(self._state.q), np.zeros(1, dtype=np.int64), False
        )
        target = evaluation[self.params.evaluation_rows["target"], 0]
        return render_family_frame(
            self.params.robot,
            self._state.x[0],
            target,
            float(self._state.inverse_condition[0]),
            safe_threshold=self.params.safe_threshold,
            hard_threshold=self.params.hard_threshold,
            view_low=self.params.pose_low,
            view_high=self.params.pose_high,
            trail=list(self._trail),
            step=int(self._state.t[0]),
            q=self._state.q[0],
        )

    @property
    def workspace(self) -> WorkspaceMap | None:
        """The certified grid tasks are drawn from (``task_region="grid"``), else None."""
        return self.params.workspace

    @property
    def state(self) -> FamilyState | None:
        """A copy of the current batched state (N = 1), or None before the first reset."""
        return None if self._state is None else copy_state(self._state)

    def _info(self, row: np.ndarray, reason: int) -> dict[str, Any]:
        v = row.tolist()
        info = {name: v[index] for name, index in self._info_rows}
        info["is_success"] = info["is_success"] != 0.0
        info["termination_reason"] = TERMINATION_REASONS[reason]
        info["pose"] = row[self._pose_rows].copy()
        info["target"] = row[self._target_rows].copy()
        for name in _TYPE_I_INFO:
            info[name] = info.pop(name)
        return info

    def sample_tasks(
        self, generators: Sequence[np.random.Generator], options: dict[str, Any]
    ) -> tuple[np.ndarray, FamilyReference]:
        """Draw one task per generator in one compiled call (start poses (M, m) and references)."""
        raise NotImplementedError


_ARGUMENTS_DOC = """
    ## Arguments
    | Parameter | Type | Default | Description |
    |-----------|------|---------|-------------|
    | `render_mode` | str or None | `None` | "rgb_array" (headless) or "human" (a window) |
    | `robot` | mechanism, str or None | `None` | a mechanism, a preset or robot name; None: "stewart_gough" |
    | `stroke_limits` | (float, float) | `(0.45, 0.75)` | actuator limits: leg lengths [m], crank angles [rad] |
    | `dt` | float | `0.05` | control period [s] |
    | `max_rate` | float | `0.1` | stroke rate of a unit action [m/s] |
    | `integrator` | str | `"euler"` | "euler" or "rk4" |
    | `pose_low` | sequence of m floats | `(-0.2, -0.2, 0.3, -0.6, -0.6, -1.9)` | pose bounds [m, rad] |
    | `pose_high` | sequence of m floats | `(0.2, 0.2, 0.75, 0.6, 0.6, 1.9)` | pose bounds [m, rad] |
    | `sample_low` | sequence of m floats | `(-0.1, -0.1, 0.4, -0.2, -0.2, -0.5)` | task box [m, rad] |
    | `sample_high` | sequence of m floats | `(0.1, 0.1, 0.6, 0.2, 0.2, 0.5)` | task box [m, rad] |
    | `safe_threshold` | float | `0.1` | k below which the penalty and the cost start |
    | `hard_threshold` | float | `0.03` | k below which the episode terminates |
    | `actuator_safe_threshold` | float | `0.1` | k_I (cranks, sliders) below which its penalty and the cost start |
    | `actuator_hard_threshold` | float | `0.02` | k_I (cranks, sliders) below which the episode terminates |
    | `actuator_singularity_weight` | float | `1.0` | w_s1, the Type I penalty's weight |
    | `position_weight` | float | `1.0` | w_p [1/m] |
    | `orientation_weight` | float | `1.0` | w_o [1/m] |
    | `singularity_weight` | float | `1.0` | w_s |
    | `action_weight` | float | `0.01` | w_a |
    | `termination_penalty` | float | `50.0` | P |
    | `success_position_tolerance` | float | `0.01` | [m] |
    | `success_orientation_tolerance` | float | `0.05` | [rad] |
    | `track_period` | float | `8.0` | Track reference period [s] |
    | `track_amplitude` | sequence of m floats | `(0.05, 0.0, 0.04, 0.0, 0.1, 0.0)` | largest amplitudes [m, rad] |
    | `track_path` | sequence of m-tuples | `()` | vertices of a polyline Track reference (units of the amplitudes) |
    | `track_path_times` | sequence of floats | `()` | share of the period of each segment of the path |
    | `hard_kind` | str | `"detour"` | "detour", "ill_conditioned" or "crossing" (grid only) hard targets |
    | `task_region` | str | `"box"` | "box" (the sampling box) or "grid" (regions of a certified grid; m = 3) |
    | `grid_cell` | (float, float, float) | `(0.025, 0.025, 0.05)` | spacing of the certified grid [m, rad] |
    | `track_shape` | str | `"sinusoid"` | "sinusoid" (or the `track_path`) or "circle" (grid only) |
    | `track_radius_range` | (float, float) | `(0.05, 0.15)` | radius of a circle reference [m] |
    | `track_angle_range` | (float, float) | `(0.0, 0.4)` | amplitude of a circle's third coordinate [rad] |
    | `**kwargs` | | | any other field of `FamilyParams` (Newton, substeps, margins) |

    `robot` may name a preset of `ROBOT_PRESETS` (its settings apply under the caller's own); a mechanism gets
    bounds, task box, strokes and amplitudes scaled by its size around its `home_pose()` (`derived_defaults`)
    unless given.
"""


class FamilyReachEnv(FamilyEnvBase):
    r"""Reach a target pose with any parallel robot of the distance-constraint family, away from singularities.

    ## Description
    Leg i of the robot (``kinematics.DistanceConstraintMechanism``, by default the Stewart–Gough hexapod
    ``kinematics.StewartGough()``) keeps the platform point P_i at the distance q_i from the base anchor B_i:
    Φ_i = ‖p + R P_i − B_i‖² − q_i² = 0. Each step the leg lengths q move at the commanded rates; the pose
    follows through the twist J_f q̇, J_f = −J_x⁻¹ J_q (Euler or RK4 on the rotation group: R ← exp([ω h]×) R),
    and is corrected onto Φ = 0 by Newton's method (residual ≤ 1e-10, in substeps of ≤ 1 cm of predicted
    motion). Near a Type II singularity (J_x singular; for the hexapod, Fichter's: centred and turned by
    ±90° about the vertical) small stroke rates give huge platform motion.

    Cranks and sliders (the Delta ``DeltaReach-v0``, the planar 3-RRR ``Planar3RRRReach-v0``, the 3-PRR
    ``Planar3PRRReach-v0``; ``robot=`` takes a mechanism or a name of ``ROBOTS``) move their link's end
    A_i(q_i) = B_i + a_i (cos q_i u_i + sin q_i v_i) + q_i e_i, Φ_i = ‖p + R P_i − A_i‖² − l_i², and bring Type I
    singularities (J_q singular: a link in line with its crank or square to its rail), measured by the actuator
    condition number k_I.

    ```
        ___P___      {P}: platform frame; pose x = (p [m], rotation vector r [rad]) of {P} in {B}
       /  / \\  \\     six legs B_i → P_i, lengths q_i actuated
      B__B   B__B    {B}: base frame, z up
    ```

    ## Action Space
    `Box(-1, 1, (n,), float32)`: actuator rates q̇_i / max_rate (m/s for legs and sliders, rad/s for cranks);
    actuators stop at `stroke_limits` (the joint limits).

    ## Observation Space
    `Box(low, high, (D,), float32)` with finite bounds; spatial robots (D = 33, or 39 with Track's velocity):

    | Num | Observation | Unit |
    |-----|-------------|------|
    | 0-2 | platform position p | m |
    | 3-6 | orientation quaternion (w, x, y, z), w ≥ 0 | 1 |
    | 7-9 | target position p* | m |
    | 10-13 | target quaternion, w ≥ 0 | 1 |
    | 14-16 | position error p* − p | m |
    | 17-19 | orientation error: rotation vector of R* Rᵀ (in {B}) | rad |
    | 20-25 | leg lengths normalised to [−1, 1] over the stroke limits | 1 |
    | 26-31 | stroke error (q(x*) − q) / (q_max − q_min) | 1 |
    | 32 | inverse condition number k | 1 |
    | 33-38 | (Track) target velocity ẋ* = (ṗ*, ṙ*) | m/s, rad/s |

    Planar robots: (x, y, cos φ, sin φ), the target likewise, (x* − x, y* − y, wrap(φ* − φ)), strokes,
    stroke errors, k (D = 18). Translational robots (the Delta): p, p*, p* − p, strokes, stroke errors, k (D = 16;
    19 with Track's velocity).

    ## Rewards
    r = −(w_p ‖p* − p‖ + w_o ℓ_c θ_err) − w_s ((k_safe − k)/k_safe)² [k < k_safe] − w_a ‖a‖² − P [terminated],
    − w_s1 ((k_I,safe − k_I)/k_I,safe)² [k_I < k_I,safe], with θ_err the angle of R* Rᵀ (the last term, Type I, is 0
    for legs). Each term is in `info` and the reward is their sum; `info["cost"]` = 1 while k < k_safe or
    k_I < k_I,safe, and `info["cost_actuator_singularity"]` = 1 while k_I < k_I,safe (the Type I part alone).

    ## Starting State
    Tasks are certified, not guessed (a 6-D pose space cannot be gridded): start and target are drawn
    uniformly in the task box (`sample_low`–`sample_high`, rotation-vector coordinates), each *safe* (strokes
    within the limits less 2 cm, k ≥ k_safe), at least `min_distance` apart in (δp, ℓ_c δθ). A *standard*
    target is kept only when the geodesic from the start (p linear, R along one rotation) is safe at points
    at most `segment_spacing` (1 cm) apart, so a singularity-free path is known. A *hard* target is kept
    only when that geodesic dips below `safe_threshold` (staying inside the box and the stroke limits) and a
    waypoint is found whose two geodesics
    start → waypoint → target are safe at the same spacing: a detour is known, the straight line is not safe.
    With `hard_kind="ill_conditioned"` (the hexapod's `StewartGoughReachHard-v0` and the Delta's
    `DeltaReachHard-v0`, whose workspaces have no detour tasks) a hard target lies in the ill-conditioned band
    2 `hard_threshold` ≤ k < `safe_threshold` (toward Fichter's singularity; for the Delta, at the outer, lower edge
    of its workspace), on a geodesic from a safe start that keeps k ≥ 2 `hard_threshold`. For cranks and sliders
    "safe" and the path's k are min(k, k_I k_safe / k_I,safe), both kinds of singularity (the band is on k).
    With `task_region="grid"` (the 3-RPR ids), start and target are instead drawn in one connected safe region
    of the certified grid (``envs.workspace``), at least `min_distance` apart; its hard targets
    (`hard_kind="crossing"`) are those whose straight line from the start dips below `hard_threshold`, while the
    region certifies a detour. `reset(options={"targets": "hard"})` switches for one episode; with the grid,
    `options` may also give a `"start"` and/or a `"target"` pose (safe, in one region).

    ## Episode End
    Termination (penalty P), first applicable: `newton_failed`, `assembly_mode_change` (prediction and
    correction more than `jump_tolerance` apart), `singularity_crossed` (sign(det J_x) flipped),
    `singular` (k < `hard_threshold`), `out_of_bounds`, and for cranks and sliders `actuator_singular` (the Type I
    measure below `actuator_hard_threshold`). Truncation after the registered 200 steps.
    `info["is_success"]`: position error ≤ `success_position_tolerance` and orientation error ≤
    `success_orientation_tolerance`.
    {arguments}
    | `targets` | str | `"standard"` | "standard", "hard" or "mixed" (hard with probability 1/2 per episode) |

    ## Version History
    * v0: Initial version.
    """

    reset_options = ("targets", "start", "target")
    target_modes = _TARGET_MODES

    def __init__(
        self, render_mode: str | None = None, targets: str = "standard", robot: Any = None, **kwargs: Any
    ) -> None:
        if targets not in _TARGET_MODES:
            raise ValueError(f"targets must be one of {_TARGET_MODES}, got {targets!r}")
        self.targets = targets
        self._setup(render_mode, build_family_params(robot, **kwargs))

    def sample_tasks(
        self, generators: Sequence[np.random.Generator], options: dict[str, Any]
    ) -> tuple[np.ndarray, FamilyReference]:
        """Certified start/target pairs, one per generator (see the class docstring, Starting State).

        "mixed" draws each episode's kind first (hard with probability 1/2, from its own generator).
        """
        mode = options.get("targets", self.targets)
        if mode not in _TARGET_MODES:
            raise ValueError(f"options['targets'] must be one of {_TARGET_MODES}, got {mode!r}")
        params = self.params
        n, m = len(generators), params.robot.n_pose
        start = self._fixed_pose("start", options["start"]) if "start" in options else None
        target = self._fixed_pose("target", options["target"]) if "target" in options else None
        if start is not None and target is not None:
            if params.workspace is not None and params.workspace.component_of(start) != params.workspace.component_of(
                target
            ):
                raise ValueError(
                    f"start {start.tolist()} and target {target.tolist()} lie in different safe regions "
                    "(different working modes): no singularity-free path joins them"
                )
            self.last_waypoints = np.tile(target, (n, 1))
            return np.tile(start, (n, 1)), FamilyReference(np.tile(target, (n, 1)), np.zeros((n, m)), np.zeros((n, m)))
        hard = np.array([g.random() < 0.5 for g in generators]) if mode == "mixed" else np.full(n, mode == "hard")
        starts, targets, waypoints = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
        for kind in (False, True):
            rows = np.flatnonzero(hard == kind)
            if rows.size == 0:
                continue
            streams = fk.random_streams([generators[i] for i in rows])
            if params.workspace is not None:
                fixed_kind, fixed = (
                    (1, start) if start is not None else ((2, target) if target is not None else (0, None))
                )
                found = workspace_kernels.sample_reach_batch(
                    params.packed,
                    params.workspace.packed,
                    streams,
                    rows.size,
                    kind,
                    params.min_distance,
                    fixed_kind,
                    fixed,
                )
                if found is not None:
                    found = (*found, found[1])
            elif start is not None or target is not None:
                raise ValueError("reset options 'start' and 'target' alone need task_region='grid'; give both")
            else:
                found = fk.sample_reach_batch(params.packed, streams, rows.size, m, kind, params.min_distance)
            if found is None:
                what = "hard" if kind else "standard"
                if start is not None or target is not None:
                    raise ValueError(f"no {what} task exists for the given pose")
                raise RuntimeError(f"no certified {what} task found in the task box after {fk.SAMPLER_TRIES} tries")
            starts[rows], targets[rows], waypoints[rows] = found
        self.last_waypoints = waypoints
        return starts, FamilyReference(targets, np.zeros((n, m)), np.zeros((n, m)))

    def _fixed_pose(self, name: str, value: Any) -> np.ndarray:
        """A start or target pose given in ``reset`` options, checked to be finite and safe."""
        m = self.params.robot.n_pose
        try:
            pose = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"options[{name!r}] must be a pose of {m} numbers, got {value!r}") from exc
        if pose.shape != (m,) or not np.isfinite(pose).all():
            raise ValueError(f"options[{name!r}] must be {m} finite numbers, got {value!r}")
        safe = fk.safe_batch(self.params.packed, pose[None])[0]
        if safe and self.params.workspace is not None:
            safe = bool(np.isin(self.params.workspace.component_of(pose), self.params.workspace.component_ids))
        if not safe:
            raise ValueError(
                f"options[{name!r}] = {pose.tolist()} is not in the certified safe set (the task box, strokes "
                f"within the limits less {self.params.stroke_margin}, k ≥ {self.params.safe_threshold})"
            )
        return pose


class FamilyTrackEnv(FamilyEnvBase):
    """Follow a moving target with any robot of the distance-constraint family (a motion-simulator reference).

    ## Description
    As ``FamilyReachEnv``, but the target moves: x*_j(t) = c_j + a_j sin(2π t / track_period + θ_j) for each
    pose coordinate, or, with a `track_path`, along a closed polyline once per `track_period`, at rest at each
    vertex (the Delta's `DeltaTrack-v0`: the adept cycle ``ADEPT_CYCLE``, 25 mm up, 305 mm across, 25 mm down
    and back, in a random horizontal direction, every 4 s). With the hexapod's defaults the reference combines
    surge (x, ≤ 5 cm), heave (z, ≤ 4 cm)
    and pitch (rotation about y, ≤ 0.1 rad): a motion-simulator cue. The centre, amplitudes (½–1 of
    `track_amplitude`) and phases are drawn so that the whole period stays in the safe set (checked at points
    ≤ 1 cm apart). The observation ends with the target velocity. Truncation after the registered 400 steps.

    ## Action Space
    As ``FamilyReachEnv``.

    ## Observation Space
    As ``FamilyReachEnv``, plus the target velocity (m values).

    ## Rewards
    As ``FamilyReachEnv``.

    ## Starting State
    The platform starts on the reference at t = 0.

    ## Episode End
    As ``FamilyReachEnv`` (400 steps).
    {arguments}

    ## Version History
    * v0: Initial version.
    """

    with_velocity = True

    def __init__(self, render_mode: str | None = None, robot: Any = None, **kwargs: Any) -> None:
        self._setup(render_mode, build_family_params(robot, **kwargs))

    def sample_tasks(
        self, generators: Sequence[np.random.Generator], options: dict[str, Any]
    ) -> tuple[np.ndarray, FamilyReference]:
        """References whose whole period is safe, one per generator; the start is the reference at t = 0."""
        n, m = len(generators), self.params.robot.n_pose
        streams = fk.random_streams(generators)
        if self.params.track_shape == "circle":
            found = workspace_kernels.sample_circle_batch(
                self.params.packed,
                self.params.workspace.packed,
                streams,
                n,
                self.params.track_radius_range,
                self.params.track_angle_range,
                int(np.ceil(self.params.track_period / self.params.dt)),
            )
        else:
            found = fk.sample_track_batch(self.params.packed, streams, n, m, self.params.track_amplitude, 64)
        if found is None:
            raise RuntimeError(f"no safe reference found in the task box after {fk.SAMPLER_TRIES} tries")
        center, amplitude, phase = found
        start, _ = fk.reference_batch(self.params.packed, np.zeros(n, dtype=np.int64), center, amplitude, phase)
        return start, FamilyReference(center, amplitude, phase)


FamilyReachEnv.__doc__ = FamilyReachEnv.__doc__.replace("{arguments}", _ARGUMENTS_DOC)
FamilyTrackEnv.__doc__ = FamilyTrackEnv.__doc__.replace("{arguments}", _ARGUMENTS_DOC)
