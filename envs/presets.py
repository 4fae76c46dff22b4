"""Named robots and their documented settings, and the construction of an env's parameters from them.

``ROBOT_PRESETS`` holds the defaults of the robots with registered ids; ``build_family_params`` validates an
env's keyword arguments into ``FamilyParams``, from a preset's name or from any
``kinematics.DistanceConstraintMechanism`` (whose bounds, task box, strokes, rates and lengths are then derived
from its size and home pose, ``derived_defaults``).
"""

from __future__ import annotations

import dataclasses
from pathlib import PurePath
from typing import Any

import numpy as np

from envs import hardware
from envs.kernels import generic as fk
from envs.params import FamilyParams, check_fields
from kinematics import (
    Delta,
    DistanceConstraintMechanism,
    Planar3PRR,
    Planar3RPR,
    Planar3RRR,
    StewartGough,
    load_mechanism,
)
from kinematics.dynamics import InertialParameters, RobotDynamics

__all__ = [
    "ADEPT_CYCLE",
    "FORCE_ACCELERATION",
    "REFERENCE_REACH",
    "ROBOTS",
    "ROBOT_PRESETS",
    "build_family_params",
    "derived_defaults",
    "force_limits",
    "reach",
]

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
    # Type II singularities (the links' lines concurrent) lies near φ ≈ 0.3–0.6 rad. The band separates the two
    # signs of det J_x, so a pair across it has no safe path at all, and a pair on one side whose straight path
    # dips below k_safe is rare (``docs/results/detour_survey``): hard targets are ill-conditioned ones.
    "robot": "planar_3rrr",
    "stroke_limits": (-2.2, 0.6),
    "max_rate": 0.5,
    "pose_low": (-0.125, -0.125, -0.9),
    "pose_high": (0.125, 0.125, 0.9),
    "sample_low": (-0.1, -0.1, -0.7),
    "sample_high": (0.1, 0.1, 0.7),
    "stroke_margin": 0.05,
    "hard_kind": "ill_conditioned",
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
    # A family of 3-RPRs (``envs.hardware.varied_plants``): each episode's base and platform scaled and sheared by up
    # to ±15 %, the robot known to the policy (its codes end the observation). Tasks in the task box, certified on
    # each robot's own geometry (the grid certifies one geometry only). Hard targets are ill-conditioned ones
    # (2 k_hard ≤ k < k_safe): detour tasks are rare on the 3-RPR (1.9 % of safe pairs) and some robots have none.
    "planar_3rpr_family": {
        **_PLANAR_3RPR,
        "task_region": "box",
        "hard_kind": "ill_conditioned",
        "track_shape": "sinusoid",
        "geometry_variation": 0.15,
    },
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


#: The reach ρ [m] of the default hexapod ``StewartGough()``, whose sizes ``FamilyParams``' lengths are.
REFERENCE_REACH = 0.25
#: Lengths of ``FamilyParams`` per reach ρ (the default hexapod's values at ρ = ``REFERENCE_REACH``).
_LENGTHS_PER_REACH = {
    "segment_spacing": 0.04,
    "min_distance": 0.2,
    "success_position_tolerance": 0.04,
    "jump_tolerance": 0.08,
    "max_substep": 0.04,
}
#: The keys of ``derived_defaults`` that a preset's robot (given by name) also takes: its shape, not its lengths.
_SHAPE_KEYS = ("pose_low", "pose_high", "sample_low", "sample_high", "track_amplitude", "stroke_limits")
#: Poses of the task box checked for safety, and the safe share of them a derived task box must reach.
_BOX_CHECKS = 512
#: Poses of the task box at which the certificate's slope is estimated (``certificate_spacing``).
_SLOPE_CHECKS = 4096
_BOX_SAFE_FRACTION = 0.5
#: Factor by which a derived task box shrinks around the home pose while it is not safe enough, and how often.
_BOX_SHRINK = 0.8
_BOX_SHRINKS = 12


def reach(robot: DistanceConstraintMechanism) -> float:
    """ρ [m]: half the mean distance of the base anchors from their centroid (the default hexapod: 0.25 m)."""
    return 0.5 * float(np.mean(np.linalg.norm(robot.base - robot.base.mean(axis=0), axis=1)))


def derived_defaults(robot: DistanceConstraintMechanism) -> dict[str, Any]:
    """Bounds, task box, strokes, rates and lengths of a robot, scaled by its size around its home pose.

    With the reach ρ (``reach``): pose bounds span ±ρ in position (planar: φ ±0.6 rad; spatial: ±0.8 ρ in x,
    y, ±0.9 ρ in z, tilts ±0.6 rad and yaw ±1.9 rad) and the task box 0.6 (spatial: 0.4) of that in position,
    tilts ±0.2 rad and yaw ±0.5 rad. Legs get strokes from 0.5 (spatial: 0.75) of the shortest to 1.6
    (spatial: 1.3) of the longest leg at home; cranks ±1 rad and sliders ±0.2 m around their values at home.
    Lengths are the default hexapod's in proportion to ρ / ``REFERENCE_REACH`` (s): the certification spacing,
    the smallest task distance, the success tolerance, the Newton jump and substep lengths, and for legs and
    sliders the stroke margin (0.02 s m) and the stroke rate (0.1 s m/s); the Newton residual tolerance is
    1e-12 s² m². ``build_family_params`` then shrinks a derived task box around the home pose until at least
    half of it is safe.

    Args:
        robot: The mechanism.

    Returns:
        Keyword arguments of ``FamilyParams`` (a caller's own values take precedence).
    """
    home = robot.home_pose()
    rho = reach(robot)
    scale = rho / REFERENCE_REACH
    space = robot.pose_space.name
    if space == "spatial":
        half = np.array([0.8 * rho, 0.8 * rho, 0.9 * rho, 0.6, 0.6, 1.9])
        box = np.array([0.4 * rho, 0.4 * rho, 0.4 * rho, 0.2, 0.2, 0.5])
        amplitude = (0.2 * rho, 0.0, 0.16 * rho, 0.0, 0.1, 0.0)
        leg_band = (0.75, 1.3)
    else:
        half = np.array([rho, rho, 0.6 if space == "planar" else rho])
        box = 0.6 * half
        amplitude = (0.3 * rho, 0.3 * rho, 0.2)
        leg_band = (0.5, 1.6)
    at_home = robot.inverse_kinematics(home)
    if all(kind == "leg" for kind in robot.actuator_kinds):
        strokes = (leg_band[0] * float(at_home.min()), leg_band[1] * float(at_home.max()))
    else:  # cranks [rad] or sliders [m]: a band around the home pose's values
        band = 1.0 if "crank" in robot.actuator_kinds else 0.2
        strokes = (float(at_home.min()) - band, float(at_home.max()) + band)
    lengths = {name: per_reach * rho for name, per_reach in _LENGTHS_PER_REACH.items()}
    lengths["newton_tolerance"] = 1e-12 * scale**2
    if "crank" not in robot.actuator_kinds:  # strokes in metres
        lengths["stroke_margin"] = 0.02 * scale
        lengths["max_rate"] = 0.1 * scale
    return {
        "pose_low": tuple(home - half),
        "pose_high": tuple(home + half),
        "sample_low": tuple(home - box),
        "sample_high": tuple(home + box),
        "track_amplitude": amplitude,
        "stroke_limits": strokes,
        **lengths,
    }


def _fit_task_box(
    robot: DistanceConstraintMechanism,
    low: tuple[float, ...],
    high: tuple[float, ...],
    stroke_limits: tuple[float, float],
    stroke_margin: float,
    safe_threshold: float,
    actuator_safe_threshold: float,
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A derived task box shrunk around the home pose until ``_BOX_SAFE_FRACTION`` of it is safe.

    The share is measured on ``_BOX_CHECKS`` fixed random poses of the box with the family's certificate
    (``envs.tasks.certificate.safety_batch``); the box shrinks by ``_BOX_SHRINK`` at most ``_BOX_SHRINKS``
    times, and the safest box tried is returned if none reaches the share (a home pose near a singularity).
    """
    c = fk.pack_certificate(robot, stroke_limits, stroke_margin, safe_threshold, actuator_safe_threshold)
    home = robot.home_pose()
    lo, hi = np.array(low), np.array(high)
    unit = np.random.default_rng(0).uniform(size=(_BOX_CHECKS, len(lo)))
    best, best_fraction = (lo, hi), -1.0
    for _ in range(_BOX_SHRINKS + 1):
        safety, _ = fk.safety_batch(c, lo + unit * (hi - lo))
        fraction = float(np.mean(safety >= safe_threshold))
        if fraction > best_fraction:
            best, best_fraction = (lo, hi), fraction
        if fraction >= _BOX_SAFE_FRACTION:
            break
        lo, hi = home + _BOX_SHRINK * (lo - home), home + _BOX_SHRINK * (hi - home)
    return tuple(map(float, best[0])), tuple(map(float, best[1]))


def certificate_spacing(
    certificate: np.ndarray,
    robot: DistanceConstraintMechanism,
    low: tuple[float, ...],
    high: tuple[float, ...],
    margin: float,
) -> float:
    """The spacing [m] of checked points at which a certified segment cannot dip by ``margin`` between two of them.

    Between checked points h apart (in z = (p, ℓ_c θ)) the safety can fall by at most L h / 2, with L its
    largest slope in z. L is estimated as the 99th percentile of ‖∇_z safety‖ (central differences, 10⁻⁴ m)
    at ``_SLOPE_CHECKS`` fixed random poses of the task box where the safety is defined on both sides, and the
    spacing is ``margin`` / L: half the margin between the safe and the hard thresholds, for the steepest 1 %
    of the box. Small planar robots with cranks or sliders, whose safety changes by about 1.5 per radian of
    platform rotation on ℓ_c = 5 cm, need about 1 mm; the hexapod and the 3-RPR keep their 1 cm.

    Args:
        certificate: Packed constants of the certificate (``envs.kernels.packing.pack_certificate``).
        robot: The mechanism (its ``pose_scale`` gives ℓ_c).
        low: Task box lower corner, shape (m,).
        high: Task box upper corner, shape (m,).
        margin: Safety the segment may lose between checked points.
    """
    key = (certificate.tobytes(), np.asarray(robot.pose_scale).tobytes(), tuple(low), tuple(high), float(margin))
    if key not in _SPACINGS:  # every gym.make asks; the hexapod's answer costs about 70 ms
        if len(_SPACINGS) >= 256:
            _SPACINGS.clear()
        _SPACINGS[key] = _slope_spacing(certificate, robot, low, high, margin)
    return _SPACINGS[key]


#: ``certificate_spacing``'s answers by their arguments' values.
_SPACINGS: dict[tuple, float] = {}


def _slope_spacing(certificate, robot, low, high, margin) -> float:
    """``certificate_spacing``, computed."""
    lo, hi = np.asarray(low), np.asarray(high)
    x = lo + np.random.default_rng(1).uniform(size=(_SLOPE_CHECKS, len(lo))) * (hi - lo)
    step = 1e-4
    gradient = np.zeros_like(x)
    defined = np.ones(len(x), dtype=bool)
    for j in range(len(lo)):
        dx = np.zeros(len(lo))
        dx[j] = step * robot.pose_scale[j]
        up, _ = fk.safety_batch(certificate, x + dx)
        down, _ = fk.safety_batch(certificate, x - dx)
        defined &= (up >= 0.0) & (down >= 0.0)
        gradient[:, j] = (up - down) / (2.0 * step)
    if not defined.any():
        return np.inf
    slope = float(np.quantile(np.linalg.norm(gradient[defined], axis=-1), 0.99))
    return margin / slope if slope > 0.0 else np.inf


#: The platform acceleration [m/s² along each position coordinate, /ℓ_c rad/s² about each angle] the derived drive
#: limits of force control afford on top of holding the platform (``force_limits``).
FORCE_ACCELERATION = 2.0


def _round_up(value: float) -> float:
    """``value`` > 0 rounded up to two significant digits."""
    unit = 10.0 ** (np.floor(np.log10(value)) - 1)
    return float(np.ceil(value / unit - 1e-9) * unit)


def force_limits(dynamics: RobotDynamics) -> tuple[float, ...]:
    """Drive limits of force control derived from the robot's dynamics at its home pose.

    Per actuator, 2 |τ_h,i| + Σ_k |(J_fᵀ M e_k)_i| a_k at ``home_pose()``: twice the holding force against gravity,
    plus enough to accelerate the platform by ``FORCE_ACCELERATION`` along every pose coordinate at once
    (a_k = 2 m/s², or 2/ℓ_c rad/s² about an angle); rounded up to two significant digits. Near a Type II
    singularity the holding forces grow as 1/k and pass these limits: the drives saturate.

    Args:
        dynamics: The robot's equations of motion.

    Returns:
        τ_max, n values > 0 [N for legs and sliders, N·m for cranks].
    """
    robot = dynamics.mechanism
    x = robot.home_pose()
    q = robot.inverse_kinematics(x)
    hold = dynamics.holding_forces(q, x)
    M = dynamics.mass_matrix(q, x)
    accelerate = np.zeros_like(hold)
    for k, scale in enumerate(np.asarray(robot.pose_scale, dtype=np.float64) * FORCE_ACCELERATION):
        accelerate += np.abs(robot.actuator_forces(q, x, M[:, k] * scale))
    return tuple(_round_up(float(v)) for v in 2.0 * np.abs(hold) + accelerate)


def build_family_params(robot: DistanceConstraintMechanism | None = None, **kwargs: Any) -> FamilyParams:
    """Validate constructor arguments into ``FamilyParams``; a robot without bounds gets ones around its home pose.

    A mechanism takes every ``derived_defaults`` the caller does not give; a robot given by name takes its
    preset's settings, then the derived bounds, task box, strokes and Track amplitudes (its lengths and rates
    are the preset's or ``FamilyParams``'). A derived task box shrinks around the home pose until at least half
    of it is safe.

    Args:
        robot: The mechanism, the name of one with its default geometry (a key of ``ROBOTS``), its data (a dict,
            ``DistanceConstraintMechanism.from_dict``) or the path of a JSON file of it (``*.json``,
            ``kinematics.load_mechanism``); default ``StewartGough()``.
        **kwargs: Fields of ``FamilyParams``.

    Returns:
        The validated parameters.

    Raises:
        TypeError: On a robot that is not a ``DistanceConstraintMechanism`` or an argument of the wrong type.
        ValueError: On an argument out of its range, naming the expected and the actual value.
    """
    caller_keys = set(kwargs)
    if robot is None:
        robot = "stewart_gough"
    if isinstance(robot, dict):  # a robot given as data (``DistanceConstraintMechanism.from_dict``)
        robot = DistanceConstraintMechanism.from_dict(robot)
    elif isinstance(robot, (str, PurePath)) and str(robot).endswith(".json"):  # ... or as a file of it
        robot = load_mechanism(robot)
    named = isinstance(robot, str)
    if named:
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
    derived = derived_defaults(robot)
    box_derived = "sample_low" not in kwargs and "sample_high" not in kwargs
    for name, value in derived.items():
        if not named or name in _SHAPE_KEYS:
            kwargs.setdefault(name, value)
    unknown = set(kwargs) - set(defaults)
    if unknown:
        raise TypeError(f"unknown argument(s) {sorted(unknown)}")
    args = {name: spec.default for name, spec in defaults.items()} | kwargs  # the given values, else the defaults
    sizes = {"m": m, "n": robot.n_actuators, "d": robot.pose_space.point_dim}
    values = check_fields(args, sizes)  # each value in its range (``FamilyParams`` docs)
    lo, hi = values["stroke_limits"]
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
    values["track_path"], values["track_path_times"] = _track_path(args["track_path"], args["track_path_times"], m)
    if values["task_region"] == "grid" and m != 3:
        raise ValueError(f"task_region='grid' needs a robot with 3 pose coordinates, got {m} ({robot.pose_space.name})")
    if values["hard_kind"] == "crossing" and values["task_region"] != "grid":
        raise ValueError(f"hard_kind='crossing' needs task_region='grid', got {values['task_region']!r}")
    if values["track_shape"] == "circle" and (values["task_region"] != "grid" or values["track_path"]):
        raise ValueError("track_shape='circle' needs task_region='grid' and no track_path")
    for name in ("track_radius_range", "track_angle_range"):
        if not values[name][0] <= values[name][1]:
            raise ValueError(f"{name} must satisfy 0 ≤ low ≤ high, got {values[name]}")
    safe, hard = values["safe_threshold"], values["hard_threshold"]
    if not hard < safe:
        raise ValueError(f"thresholds must satisfy 0 < hard_threshold < safe_threshold < 1, got {hard} and {safe}")
    safe1, hard1 = values["actuator_safe_threshold"], values["actuator_hard_threshold"]
    if not hard1 < safe1:
        raise ValueError(
            f"thresholds must satisfy actuator_hard_threshold < actuator_safe_threshold < 1, got {hard1} and {safe1}"
        )
    if values["geometry_variation"] and (values["task_region"] != "box" or values["geometry_tolerance"]):
        raise ValueError(
            "geometry_variation needs task_region='box' (tasks certified on each robot's own geometry) and no "
            f"geometry_tolerance, got task_region={values['task_region']!r}, "
            f"geometry_tolerance={values['geometry_tolerance']}"
        )
    if box_derived:
        values["sample_low"], values["sample_high"] = _fit_task_box(
            robot, values["sample_low"], values["sample_high"], (lo, hi), values["stroke_margin"], safe, safe1
        )
    if "segment_spacing" not in caller_keys:
        certificate = fk.pack_certificate(robot, (lo, hi), values["stroke_margin"], safe, safe1)
        margin = min(safe - hard, (safe1 - hard1) * safe / safe1)
        values["segment_spacing"] = min(
            values["segment_spacing"],
            certificate_spacing(certificate, robot, values["sample_low"], values["sample_high"], margin),
        )
    _check_force_control(robot, values)
    params = FamilyParams(robot=robot, **values)
    hardware.check_tolerance(params)
    if params.control == "force" and not params.force_limits:
        limits = force_limits(params.dynamics)
        params = dataclasses.replace(params, force_limits=limits)
    return params


def _check_force_control(robot: DistanceConstraintMechanism, values: dict[str, Any]) -> None:
    """Make ``values["inertia"]`` (a dict) ``InertialParameters`` fitting ``robot``; refuse what force control lacks."""
    inertia = values["inertia"]
    if isinstance(inertia, dict):
        inertia = InertialParameters.from_dict(inertia)
    if inertia is not None:
        if not isinstance(inertia, InertialParameters):
            raise TypeError(f"inertia must be a kinematics.InertialParameters, its dict or None, got {inertia!r}")
        RobotDynamics(robot, inertia)  # raises if the data do not fit the robot
    values["inertia"] = inertia
    if values["control"] == "force" and values["max_acceleration"]:
        raise ValueError(
            "control='force' has no max_acceleration (a limit on the stroke rates the actions command), got "
            f"max_acceleration={values['max_acceleration']}"
        )
