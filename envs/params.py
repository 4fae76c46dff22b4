"""The constants of an environment: one frozen dataclass for every robot and task (``FamilyParams``).

Every keyword argument of the envs is described once, here: each field of ``FamilyParams`` carries its
``envs.arguments.Parameter`` (type text, description, unit, the check of its values, whether the robot's preset
gives its default), which validates it (``check_fields``), writes ``FamilyParams``' Attributes and the envs'
Arguments table (``arguments_table``). The per-robot values themselves are data: ``envs.presets.ROBOT_PRESETS``.
"""

from __future__ import annotations

import functools
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from envs.arguments import (
    CONDITION,
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    Choice,
    Parameter,
    Range,
    Vector,
    attributes,
    documented,
    parameters,
    table,
)
from envs.hardware import OBSERVATION_SOURCES
from envs.kernels import generic as fk
from envs.kernels.dynamics_layout import pack_inertia
from envs.tasks.grid import WorkspaceMap, WorkspaceSpec, certify_workspace, restore_read_only
from kinematics import DistanceConstraintMechanism, StewartGough
from kinematics.dynamics import RobotDynamics, default_inertia

__all__ = [
    "CONTROLS",
    "HARD_KINDS",
    "INTEGRATORS",
    "RENDER_MODE",
    "REWARD_FIELDS",
    "ROBOT",
    "TARGETS",
    "TARGET_MODES",
    "TASK_REGIONS",
    "TRACK_SHAPES",
    "FamilyParams",
    "Parameter",
    "arguments_table",
    "check_fields",
    "field_parameters",
]

TARGET_MODES = ("standard", "hard", "mixed")
HARD_KINDS = ("detour", "ill_conditioned", "crossing")
TASK_REGIONS = ("box", "grid")
TRACK_SHAPES = ("sinusoid", "circle")
INTEGRATORS = ("euler", "rk4")
CONTROLS = ("rate", "force")
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


#: The constructor arguments of the envs that are not fields of ``FamilyParams``, and the env's form of ``robot``.
RENDER_MODE = Parameter("render_mode", None, '"rgb_array" (headless) or "human" (a window)', type="str or None")
TARGETS = Parameter(
    "targets", "standard", '"standard", "hard" or "mixed" (hard with probability 1/2 per episode)',
    check=Choice(TARGET_MODES),
)  # fmt: skip
ROBOT = Parameter(
    "robot", None, 'a mechanism, its data or JSON file, a preset or robot name; None: "stewart_gough"',
    type="mechanism, dict, str or None",
)  # fmt: skip
#: Checks of a pose vector (m values) and of an inverse condition number's threshold, in (0, 1).
M = Vector("m")
K = CONDITION


@dataclass(frozen=True)
class FamilyParams:
    """Every constant of a family environment (see ``FamilyReachEnv`` for the tasks, the reward and the ends).

    Each field's ``metadata["doc"]`` (``envs.arguments.Parameter``) documents and checks it. Its default is the
    hexapod's (``StewartGough()``); where marked †, a robot's preset (``envs.presets.ROBOT_PRESETS``) or its size
    (``derived_defaults``) gives its own.

    Attributes:
        {attributes}
    """

    robot: DistanceConstraintMechanism = field(
        default_factory=StewartGough,
        metadata={"doc": Parameter("", None, "the mechanism (pose space, legs, geometry, ℓ_c)")},
    )
    stroke_limits: tuple[float, float] = documented(
        (0.45, 0.75),
        "hard stops q_min < q_max of every actuator (0 < q_min for legs)",
        "m, rad for cranks",
        Vector(2),
        per_robot=True,
    )
    dt: float = documented(0.05, "control period", "s", POSITIVE)
    max_rate: float = documented(0.1, "stroke rate of a unit action", "m/s, rad/s", POSITIVE, per_robot=True)
    integrator: str = documented("euler", '"euler" or "rk4" prediction of the twist J_f q̇', check=Choice(INTEGRATORS))
    pose_low: tuple[float, ...] = documented(
        (-0.2, -0.2, 0.3, -0.6, -0.6, -1.9), "lower pose bounds; leaving them terminates", "m, rad", M, per_robot=True
    )
    pose_high: tuple[float, ...] = documented(
        (0.2, 0.2, 0.75, 0.6, 0.6, 1.9), "upper pose bounds", "m, rad", M, per_robot=True
    )
    sample_low: tuple[float, ...] = documented(
        (-0.1, -0.1, 0.4, -0.2, -0.2, -0.5), "task box (starts, targets): lower corner", "m, rad", M, per_robot=True
    )
    sample_high: tuple[float, ...] = documented(
        (0.1, 0.1, 0.6, 0.2, 0.2, 0.5), "task box: upper corner", "m, rad", M, per_robot=True
    )
    safe_threshold: float = documented(0.1, "k below which the penalty and the cost start", check=K, per_robot=True)
    hard_threshold: float = documented(0.03, "k below which the episode terminates (< safe_threshold)", check=K)
    actuator_hard_threshold: float = documented(
        0.02, "k_I (cranks, sliders) below which the episode ends", check=Range(0.0, 1.0, high_open=True),
        note='k_I is the Type I measure, 1 for legs; the termination reason is "actuator_singular".',
    )  # fmt: skip
    actuator_safe_threshold: float = documented(0.1, "k_I (cranks, sliders) below which its penalty starts", check=K)
    actuator_singularity_weight: float = documented(1.0, "w_s1, the Type I penalty's weight", check=NON_NEGATIVE)
    position_weight: float = documented(1.0, "w_p", "1/m", NON_NEGATIVE)
    orientation_weight: float = documented(1.0, "w_o (multiplies ℓ_c θ_err)", "1/m", NON_NEGATIVE)
    singularity_weight: float = documented(1.0, "w_s", check=NON_NEGATIVE)
    action_weight: float = documented(0.01, "w_a", check=NON_NEGATIVE)
    termination_penalty: float = documented(50.0, "P, paid on termination", check=NON_NEGATIVE)
    success_reward: float = documented(
        0.0, "b, added at every step that ends within the success tolerances", check=NON_NEGATIVE
    )
    success_position_tolerance: float = documented(0.01, "success: position error", "m", POSITIVE, per_robot=True)
    success_orientation_tolerance: float = documented(
        0.05, "success: orientation error", "rad", POSITIVE, per_robot=True
    )
    newton_tolerance: float = documented(1e-12, "Newton residual max_i abs(Φ_i)", "m²", POSITIVE, per_robot=True)
    newton_max_iterations: int = documented(8, "Newton iterations per substep", check=POSITIVE_INT)
    jump_tolerance: float = documented(
        0.02, "largest ‖(δp, ℓ_c δθ)‖ from prediction to correction", "m", POSITIVE, per_robot=True,
        note='A larger jump terminates ("assembly_mode_change").',
    )  # fmt: skip
    max_substep: float = documented(0.01, "largest predicted motion per substep", "m", POSITIVE, per_robot=True)
    max_substeps: int = documented(16, "most substeps per period", check=POSITIVE_INT)
    track_period: float = documented(8.0, "Track reference period", "s", POSITIVE, per_robot=True)
    track_amplitude: tuple[float, ...] = documented(
        (0.05, 0.0, 0.04, 0.0, 0.1, 0.0), "largest amplitudes of a Track reference", "m, rad", M, per_robot=True,
        note="With a ``track_path``, a_j scales its coordinate j.",
    )  # fmt: skip
    track_path: tuple[tuple[float, ...], ...] = documented(
        (), "vertices of a polyline Track reference (units of the amplitudes)", per_robot=True,
        type="sequence of m-tuples",
        note="2 to 8 vertices W_k of m coordinates, x*_j = c_j + a_j W_kj, the first two turned by a random heading.",
    )  # fmt: skip
    track_path_times: tuple[float, ...] = documented(
        (), "share of the period of each segment of the path", per_robot=True, type="sequence of floats",
        note="One positive value per vertex W_k: the segment W_k → W_k+1 (mod K).",
    )  # fmt: skip
    stroke_margin: float = documented(
        0.02, "strokes of the safe set keep this far from the limits", "m, rad for cranks", NON_NEGATIVE, per_robot=True
    )
    segment_spacing: float = documented(
        0.01, "largest gap between the checked points of a certified path", "m", POSITIVE, per_robot=True,
        note="Unless given, capped per robot by ``envs.presets.certificate_spacing``.",
    )  # fmt: skip
    min_distance: float = documented(
        0.05, "smallest ‖(δp, ℓ_c δθ)‖ between start and target", "m", NON_NEGATIVE, per_robot=True
    )
    hard_kind: str = documented(
        "detour", '"detour", "ill_conditioned" or "crossing" (grid only) hard targets', check=Choice(HARD_KINDS),
        per_robot=True,
        note=(
            '"detour": the straight path dips below k_safe, a detour is certified; "ill_conditioned": '
            '2 k_hard ≤ k < k_safe at the target; "crossing": the straight line dips below k_hard, the grid region '
            "certifies a detour."
        ),
    )  # fmt: skip
    task_region: str = documented(
        "box", '"box" (the task box) or "grid" (regions of a certified grid; m = 3)', check=Choice(TASK_REGIONS),
        per_robot=True,
        note='"grid": start and target in one connected safe region of a certified grid (``envs.tasks.grid``).',
    )  # fmt: skip
    grid_cell: tuple[float, float, float] = documented(
        (0.025, 0.025, 0.05), "spacing of the certified grid", "m, rad", Vector(3, POSITIVE)
    )
    track_shape: str = documented(
        "sinusoid", '"sinusoid" (or the `track_path`) or "circle" (grid only)', check=Choice(TRACK_SHAPES),
        per_robot=True,
        note=(
            '"sinusoid": x*_j = c_j + a_j sin(ω t + θ_j); "circle": radius r in the first two coordinates, the third '
            "oscillating by ±a, all in one safe region."
        ),
    )  # fmt: skip
    track_radius_range: tuple[float, float] = documented(
        (0.05, 0.15), "radius of a circle reference", "m", Vector(2, NON_NEGATIVE)
    )
    track_angle_range: tuple[float, float] = documented(
        (0.0, 0.4), "amplitude of a circle's third coordinate", "rad, m if translational", Vector(2, NON_NEGATIVE)
    )
    observation_source: str = documented(
        "pose", '"pose" (the true pose) or "encoders" (strokes measured, pose estimated)',
        check=Choice(OBSERVATION_SOURCES),
        note="The pose is estimated by the nominal forward kinematics (``envs.hardware``).",
    )  # fmt: skip
    encoder_resolution: tuple[float, ...] = documented(
        (), "encoder count (() for 10 µm, 0.01°: `envs.hardware`)", "m, rad", Vector("n", POSITIVE, per_actuator=True)
    )
    encoder_noise: tuple[float, ...] = documented(
        (),
        "encoder noise, standard deviation (() for one count)",
        "m, rad",
        Vector("n", NON_NEGATIVE, per_actuator=True),
    )
    estimator_iterations: int = documented(20, "Newton iterations of the pose estimate per step", check=POSITIVE_INT)
    geometry_tolerance: float = documented(
        0.0, "the robot as built: anchors, points, lengths within ± this", "m", NON_NEGATIVE,
        note="Every controller assumes the nominal robot.",
    )  # fmt: skip
    geometry_variation: float = documented(
        0.0, "ν: each episode's robot scaled, sheared by up to ±ν, known (Reach, box)",
        check=Range(0.0, 0.5, high_open=True), per_robot=True,
        note="Its base and platform (``envs.hardware.varied_plants``); its codes end the observation.",
    )  # fmt: skip
    max_acceleration: tuple[float, ...] = documented(
        (),
        "largest change of an actuator's rate (() for none)",
        "m/s², rad/s²",
        Vector("n", POSITIVE, per_actuator=True),
    )
    action_delay: int = documented(0, "control steps between an action and its effect", check=NON_NEGATIVE_INT)
    control: str = documented(
        "rate", '"rate" (actions: stroke rates) or "force" (actions: efforts; rigid-body dynamics)',
        check=Choice(CONTROLS),
        note=(
            '"force": τ = clip(τ_h + a (τ_max + |τ_h|), ±τ_max), an offset a ∈ [−1, 1] from the holding forces τ_h '
            "at the period's start (``envs.kernels.force.efforts_of_actions``), held for dt; (x, ẋ) integrated by "
            "RKMK4 (``envs.kernels.force``); the observation adds ẋ and the actuator rates."
        ),
    )  # fmt: skip
    force_limits: tuple[float, ...] = documented(
        (), "drive limits τ_max of force control (() derived: ``envs.presets.force_limits``)", "N, N·m for cranks",
        Vector("n", POSITIVE, per_actuator=True),
    )  # fmt: skip
    dynamics_substeps: int = documented(
        2, "least RKMK4 steps per control period of force control", check=POSITIVE_INT,
        note="More at speed: each step moves at most ``max_substep`` (at most ``max_substeps`` steps).",
    )  # fmt: skip
    gravity: tuple[float, ...] = documented(
        (), "gravity g in {B} of force control (() the robot's: −z, 0 in a planar robot's plane)", "m/s²",
        Vector("d", per_actuator=True),
        note="A planar robot lies in a horizontal plane; ``gravity=(0, -9.80665)`` stands it up.",
    )  # fmt: skip
    inertia: Any = documented(  # noqa: RUF009 (an immutable InertialParameters or None, as every field's default)
        None, "masses and inertias (None: ``kinematics.default_inertia(robot)``)",
        type="InertialParameters, dict or None",
    )  # fmt: skip

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
        """The kernels' float64 constants (``packing.pack_family``), read-only."""
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
    def dynamics(self) -> RobotDynamics:
        """The robot's equations of motion (``kinematics.RobotDynamics``) with ``inertia`` and ``gravity``."""
        inertia = default_inertia(self.robot) if self.inertia is None else self.inertia
        if self.gravity:
            inertia = inertia.replace(gravity=self.gravity)
        return RobotDynamics(self.robot, inertia)

    @functools.cached_property
    def force_limit_array(self) -> np.ndarray:
        """``force_limits`` as a read-only float64 array, shape (n,) (empty under rate control without limits)."""
        return fk.read_only(np.asarray(self.force_limits, dtype=np.float64))

    @functools.cached_property
    def packed_inertia(self) -> np.ndarray | None:
        """The kernels' inertia and drive limits of force control (``pack_inertia``), (1, C_INERTIA_SIZE), or None."""
        if self.control != "force":
            return None
        packed = pack_inertia(self.robot, self.dynamics.inertia, self.force_limits, self.dynamics_substeps)
        return fk.read_only(packed[None])

    @functools.cached_property
    def evaluation_rows(self) -> dict[str, int | slice]:
        """Rows of ``evaluate`` / ``step``'s evaluation array."""
        return fk.evaluation_rows(self.robot.n_pose)

    @functools.cached_property
    def observation_bounds(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``observation_bounds`` without (index 0) and with (index 1) the target velocity."""
        return _observation_bounds(self, False), _observation_bounds(self, True)


#: Force control's observation clips ẋ_j to ± FAST (pose_high_j − pose_low_j) and the actuator rates to ± FAST times
#: the stroke range [1/s].
FAST = 4.0


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
    if params.control == "force":  # ẋ and the actuator rates, each clipped to ± its range crossed in 1 / FAST s
        twist = FAST * (high_p - low_p)
        rate = FAST * (params.stroke_limits[1] - params.stroke_limits[0])
        low += [*(-twist), *[-rate] * n]
        high += [*twist, *[rate] * n]
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


@functools.cache
def field_parameters() -> tuple[Parameter, ...]:
    """The ``Parameter`` of every field of ``FamilyParams`` but ``robot`` (an env's ``ROBOT``), in field order."""
    return parameters(FamilyParams, skip=("robot",))


def check_fields(args: dict[str, Any], sizes: dict[str, int]) -> dict[str, Any]:
    """Every field of ``args`` (all but ``robot``) checked by its ``Parameter.check``; those without one passed on.

    Args:
        args: A value for every field of ``FamilyParams`` but ``robot``.
        sizes: {"m": pose coordinates, "n": actuators} of the robot, the sizes of the ``Vector`` checks.

    Raises:
        TypeError: On a value of the wrong type, naming the field, the expected and the actual value.
        ValueError: On a value out of its range, naming the field, the range and the value.
    """
    return {
        p.name: args[p.name] if p.check is None else p.check(p.name, args[p.name], sizes) for p in field_parameters()
    }


#: What the † of the Arguments table means.
_DEFAULTS_NOTE = (
    "† The hexapod's default. A robot named by a preset of `ROBOT_PRESETS` takes the preset's settings (under the "
    "caller's own); a mechanism gets bounds, task box, strokes, amplitudes, rates and lengths scaled by its size "
    "around its `home_pose()` (`derived_defaults`; the task box shrunk until at least half of it is safe) unless "
    "given, and the certified `segment_spacing` is capped per robot unless given (`certificate_spacing`)."
)


def arguments_table(head: Sequence[Parameter]) -> str:
    """The ``## Arguments`` section of an env's docstring: its named arguments ``head``, then every field."""
    note = textwrap.fill(_DEFAULTS_NOTE, 116, initial_indent="    ", subsequent_indent="    ")
    return "\n".join(
        [
            "    ## Arguments",
            "    The named arguments, then every field of `FamilyParams` (given through `**kwargs`):",
            "",
            table((*head, *field_parameters())),
            "",
            note,
        ]
    )


if FamilyParams.__doc__:  # None under python -OO
    FamilyParams.__doc__ = FamilyParams.__doc__.replace("        {attributes}", attributes(FamilyParams))
