"""The constants of an environment: one frozen dataclass for every robot and task (``FamilyParams``)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from envs.kernels import generic as fk
from envs.tasks.grid import WorkspaceMap, WorkspaceSpec, certify_workspace, restore_read_only
from kinematics import DistanceConstraintMechanism, StewartGough

__all__ = [
    "HARD_KINDS",
    "INTEGRATORS",
    "REWARD_FIELDS",
    "TARGET_MODES",
    "TASK_REGIONS",
    "TRACK_SHAPES",
    "FamilyParams",
]

TARGET_MODES = ("standard", "hard", "mixed")
HARD_KINDS = ("detour", "ill_conditioned", "crossing")
TASK_REGIONS = ("box", "grid")
TRACK_SHAPES = ("sinusoid", "circle")
INTEGRATORS = ("euler", "rk4")
#: The fields of ``FamilyParams`` that change the reward only (weights, termination penalty, success bonus).
REWARD_FIELDS = (
    "position_weight",
    "orientation_weight",
    "singularity_weight",
    "action_weight",
    "termination_penalty",
    "success_reward",
    "actuator_singularity_weight",
)


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
        success_reward: b: reward added at every step that ends within the success tolerances (not terminated).
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
        segment_spacing: Largest gap between checked points of a certified path [m]; unless given, capped per robot
            by ``envs.presets.certificate_spacing`` (the safety may not fall by more than half the safe-to-hard
            margin between two checked points).
        min_distance: Smallest ‖(δp, ℓ_c δθ)‖ between start and target [m].
        hard_kind: What makes a hard target: "detour" (the straight path dips below k_safe, a detour is
            certified), "ill_conditioned" (the target lies where 2 k_hard ≤ k < k_safe) or "crossing" (the
            straight line in pose space dips below k_hard; start and target in one region of the grid, which
            certifies a detour; needs ``task_region="grid"``).
        task_region: Where starts and targets are drawn: "box" (uniformly in the sampling box, paths certified
            segment by segment) or "grid" (three pose coordinates only: in one connected safe region of a
            certified grid over the pose bounds, ``envs.tasks.grid``).
        grid_cell: Grid spacing of ``task_region="grid"``, shape (3,) [m, rad].
        track_shape: The Track reference: "sinusoid" (x*_j = c_j + a_j sin(ω t + θ_j), or the ``track_path``) or
            "circle" (three pose coordinates, ``task_region="grid"``: a circle of radius r in the first two
            coordinates, the third oscillating by ±a, all of one period in one safe region).
        track_radius_range: (r_min, r_max) of a circle reference [m].
        track_angle_range: (a_min, a_max) of a circle reference's third coordinate [rad, or m if translational].
        observation_source: "pose" (the observation holds the true pose) or "encoders" (measured actuator
            coordinates and the pose estimated from them by the nominal forward kinematics: ``envs.hardware``).
        encoder_resolution: Count of each actuator's encoder [m, or rad for cranks], shape (n,); () for the
            defaults of ``envs.hardware.ENCODER_RESOLUTION`` (10 µm, 0.01°).
        encoder_noise: Standard deviation of each encoder's noise before quantisation, shape (n,) [m, rad]; ()
            for one count.
        estimator_iterations: Most Newton iterations of the pose estimate per step.
        geometry_tolerance: δ [m]: each episode's robot has its anchors, platform points and (cranks, sliders)
            link lengths and crank radii drawn within ±δ of the nominal ones, which every controller assumes.
        geometry_variation: ν: each episode's robot has its base and platform scaled and sheared by up to ±ν
            (``envs.hardware.varied_plants``), known to the controller and coded at the end of the observation.
        max_acceleration: Largest change of each actuator's rate per second [m/s², rad/s²], shape (n,); () for none.
        action_delay: Whole control steps between an action and its effect.
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
    success_reward: float = 0.0
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
    observation_source: str = "pose"
    encoder_resolution: tuple[float, ...] = ()
    encoder_noise: tuple[float, ...] = ()
    estimator_iterations: int = 20
    geometry_tolerance: float = 0.0
    geometry_variation: float = 0.0
    max_acceleration: tuple[float, ...] = ()
    action_delay: int = 0

    def __setstate__(self, state: dict) -> None:
        restore_read_only(self, state)  # the kernels' constants stay read-only: one compiled signature

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
        """The kernels' float64 constants (``generic.pack_family``), read-only."""
        return fk.pack_family(self)

    @functools.cached_property
    def packed_rows(self) -> np.ndarray:
        """``packed`` as one row of per-robot constants, shape (1, C_SIZE), read-only (one geometry for all)."""
        return self.packed[None]

    @property
    def random_hardware(self) -> bool:
        """Whether episodes draw the robot as built or steps draw encoder noise (the envs then pass streams)."""
        return self.geometry_tolerance > 0.0 or self.geometry_variation > 0.0 or self.observation_source == "encoders"

    @property
    def drive_shape(self) -> tuple[int, int] | None:
        """(1 + action_delay, n) of the drives' state (``envs.hardware.drive``), or None for ideal drives."""
        if self.action_delay == 0 and not self.max_acceleration:
            return None
        return 1 + self.action_delay, self.robot.n_actuators

    @functools.cached_property
    def evaluation_rows(self) -> dict[str, int | slice]:
        """Rows of ``evaluate`` / ``step``'s evaluation array."""
        return fk.evaluation_rows(self.robot.n_pose)

    @functools.cached_property
    def observation_bounds(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``observation_bounds`` without (index 0) and with (index 1) the target velocity."""
        return _observation_bounds(self, False), _observation_bounds(self, True)


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
    if params.geometry_variation:  # the codes of the robot's geometry (``envs.hardware.varied_plants``)
        d = params.robot.base.shape[1]
        low += [-1.0] * (2 * d * d)
        high += [1.0] * (2 * d * d)
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
