"""Inertial data of the distance-constraint family: the bodies of a robot, their masses and inertias, and gravity.

For each leg i with link vector d_i = p + R P_i − A_i(q_i), ℓ_i = ‖d_i‖ and u_i = d_i / ℓ_i
(``kinematics.dynamics`` writes the equations of motion from these):

    platform     mass m, centre of mass c in {P}, inertia tensor I_c about c in {P} axes (planar: I_zz).
    actuator     ``leg``: the cylinder, turning about its base joint B_i, with its centre of mass at B_i + c u_i;
                 ``crank``: rotor, gearbox and arm turning about the motor axis (moment of inertia J about the
                 axis; mass and centre of mass at distance c from the axis along the arm, for its weight);
                 ``slider``: the carriage at A_i (mass).
    distal body  ``leg``: the rod sliding in the cylinder; ``crank``, ``slider``: the link from A_i to P_i. A rod
                 along u_i with its centre of mass at P_i − c u_i (c measured from the platform end), mass and
                 transverse moment of inertia about its centre of mass (spin about its own axis is neglected).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinematics._validation import FloatArray, as_float_array, check_finite, per_leg
from kinematics.delta import Delta
from kinematics.family import DistanceConstraintMechanism
from kinematics.planar_3rpr import Planar3RPR
from kinematics.planar_rrr_prr import Planar3PRR, Planar3RRR
from kinematics.stewart_gough import StewartGough

__all__ = [
    "STANDARD_GRAVITY",
    "InertialParameters",
    "default_inertia",
    "rod_from_end_masses",
    "uniform_rod",
]

#: Standard gravity g_n [m/s²] (CGPM 1901).
STANDARD_GRAVITY = 9.80665

_PER_LEG = (
    "actuator_mass",
    "actuator_com",
    "actuator_inertia",
    "distal_mass",
    "distal_com",
    "distal_inertia",
    "actuator_damping",
    "joint_damping",
)


def _non_negative(name: str, arr: FloatArray, unit: str) -> None:
    bad = np.flatnonzero(arr < 0)
    if bad.size:
        raise ValueError(f"{name} must be ≥ 0 {unit}, got {float(arr[bad[0]])!r} for leg {bad[0] + 1}")


@dataclass(frozen=True, eq=False)
class InertialParameters:
    """The masses and inertias of a distance-constraint robot and the gravity acting on it (read-only arrays).

    The number of legs n is the length of the per-leg arrays; the point dimension d (2 planar, 3 otherwise)
    is that of ``platform_com``. Numbers given for a per-leg field broadcast to every leg.

    Attributes:
        platform_mass: m [kg] of the platform (with its payload), > 0.
        platform_com: Centre of mass c of the platform in {P} [m], shape (d,).
        platform_inertia: Inertia tensor of the platform about c, in {P} axes [kg·m²]: shape (3, 3), symmetric
            positive definite, for d = 3 (unused by a translational robot, whose plate does not turn); I_zz, a
            number or shape (1, 1), > 0, for d = 2. Stored with shape (3, 3) or (1, 1).
        actuator_mass: Mass of each actuator's moving body [kg], shape (n,): a leg's cylinder, a crank's arm
            (for its weight), a slider's carriage.
        actuator_com: Centre of mass of that body [m], shape (n,): a leg's cylinder, its distance from the base
            joint B_i along the leg; a crank's arm, its distance from the motor axis along the arm; unused for
            a slider.
        actuator_inertia: Shape (n,) [kg·m²]: a leg's cylinder, its transverse moment of inertia about its
            centre of mass; a crank, the moment of inertia of rotor, gearbox and arm about the motor axis (it
            carries the arm's kinetic energy); unused for a slider.
        distal_mass: Mass of each distal rod [kg], shape (n,): a leg's sliding rod, a crank's or slider's
            link from A_i to P_i.
        distal_com: Distance of the rod's centre of mass from the platform point P_i, along the rod [m],
            shape (n,).
        distal_inertia: Transverse moment of inertia of the rod about its centre of mass [kg·m²], shape (n,).
        gravity: Gravitational acceleration g in {B} [m/s²], shape (d,).
        actuator_damping: Viscous friction b of each actuated joint, shape (n,), ≥ 0 [N·s/m for legs and sliders,
            N·m·s/rad for cranks]: the drive loses the effort b_i q̇_i (default 0: none). A friction that stops
            the drive faster than an integration substep (b_i above its moving inertia / substep) is too stiff
            for the explicit integrators.
        joint_damping: Viscous friction of each chain's passive joint at its actuator [N·m·s/rad], shape (n,),
            ≥ 0: a leg's base joint, a crank's or slider's elbow. The joint loses the moment b ω of the relative
            angular velocity ω of the two bodies it joins (the rod's u × u̇ less the crank arm's; spin about the
            rod's own axis is neglected, as in the inertia). Default 0; the joints at the platform are frictionless.
    """

    platform_mass: float
    platform_com: FloatArray
    platform_inertia: FloatArray
    actuator_mass: FloatArray
    actuator_com: FloatArray
    actuator_inertia: FloatArray
    distal_mass: FloatArray
    distal_com: FloatArray
    distal_inertia: FloatArray
    gravity: FloatArray
    actuator_damping: FloatArray = 0.0  # type: ignore[assignment]  (a number broadcasts to every leg)
    joint_damping: FloatArray = 0.0  # type: ignore[assignment]

    def __post_init__(self) -> None:
        """Validate and freeze the arrays (see the class docstring); raise ``ValueError`` naming a bad value."""
        mass = as_float_array("platform_mass", self.platform_mass)
        if mass.ndim != 0 or not math.isfinite(float(mass)) or not float(mass) > 0:
            raise ValueError(f"platform_mass must be a finite number > 0 [kg], got {self.platform_mass!r}")
        com = as_float_array("platform_com", self.platform_com)
        if com.shape not in ((2,), (3,)):
            raise ValueError(f"platform_com must have shape (2,) (planar) or (3,), got shape {com.shape}")
        check_finite("platform_com", com)
        d = com.shape[0]
        r = 1 if d == 2 else 3
        inertia = as_float_array("platform_inertia", self.platform_inertia)
        if d == 2 and inertia.ndim == 0:
            inertia = inertia.reshape(1, 1)
        if inertia.shape != (r, r):
            expected = "a number or shape (1, 1)" if r == 1 else "shape (3, 3)"
            raise ValueError(f"platform_inertia must be {expected} for {d}-D points, got shape {inertia.shape}")
        check_finite("platform_inertia", inertia)
        if not np.allclose(inertia, inertia.T, rtol=1e-12, atol=1e-12 * float(np.abs(inertia).max())):
            raise ValueError(f"platform_inertia must be symmetric, got {inertia.tolist()}")
        inertia = 0.5 * (inertia + inertia.T)
        eigenvalues = np.linalg.eigvalsh(inertia)
        if not eigenvalues.min() > 0:
            raise ValueError(
                f"platform_inertia must be positive definite, got eigenvalues {eigenvalues.tolist()} [kg·m²]"
            )
        n = np.size(self.actuator_mass) if np.ndim(self.actuator_mass) else None
        if n is None:
            raise ValueError("actuator_mass must have shape (n,), one mass per leg, got a number")
        legs = {name: per_leg(name, getattr(self, name), n) for name in _PER_LEG}
        _non_negative("actuator_mass", legs["actuator_mass"], "[kg]")
        _non_negative("actuator_inertia", legs["actuator_inertia"], "[kg·m²]")
        _non_negative("distal_mass", legs["distal_mass"], "[kg]")
        _non_negative("distal_inertia", legs["distal_inertia"], "[kg·m²]")
        check_finite("actuator_damping", legs["actuator_damping"])
        _non_negative("actuator_damping", legs["actuator_damping"], "[N·s/m or N·m·s/rad]")
        check_finite("joint_damping", legs["joint_damping"])
        _non_negative("joint_damping", legs["joint_damping"], "[N·m·s/rad]")
        gravity = as_float_array("gravity", self.gravity)
        if gravity.shape != (d,):
            raise ValueError(f"gravity must have shape ({d},) like platform_com, got shape {gravity.shape}")
        check_finite("gravity", gravity)
        arrays = {"platform_com": com, "platform_inertia": inertia, "gravity": gravity, **legs}
        for name, value in arrays.items():
            value = np.array(value, dtype=np.float64)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "platform_mass", float(mass))

    @property
    def n_legs(self) -> int:
        """Number of legs n."""
        return int(self.actuator_mass.shape[0])

    @property
    def point_dim(self) -> int:
        """Dimension d of the points (2 or 3)."""
        return int(self.platform_com.shape[0])

    def replace(self, **changes: Any) -> InertialParameters:
        """A copy with some fields changed (validated again), e.g. ``replace(gravity=(0.0, -STANDARD_GRAVITY))``."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The parameters as plain data (numbers and lists): ``from_dict`` and JSON read them back."""
        data: dict[str, Any] = {"platform_mass": self.platform_mass}
        for field in dataclasses.fields(self)[1:]:
            data[field.name] = getattr(self, field.name).tolist()
        return data

    @classmethod
    def from_dict(cls, data: Any) -> InertialParameters:
        """Parameters from plain data (a ``to_dict`` output or a JSON object with the same keys).

        Raises:
            TypeError: If ``data`` is not a mapping.
            ValueError: On an unknown or missing key (naming them) or a value the constructor refuses.
        """
        if not isinstance(data, dict):
            raise TypeError(f"inertial data must be a mapping, got {type(data).__name__}")
        names = [field.name for field in dataclasses.fields(cls)]
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise ValueError(f"unknown key(s) {unknown} in inertial data; valid keys are {names}")
        optional = {field.name for field in dataclasses.fields(cls) if field.default is not dataclasses.MISSING}
        missing = [name for name in names if name not in data and name not in optional]
        if missing:
            raise ValueError(f"inertial data needs {missing}")
        return cls(**data)

    def __eq__(self, other: object) -> bool:
        """Equal when every field is."""
        if not isinstance(other, InertialParameters):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        """Hash of the plain data, consistent with ``__eq__``."""
        return hash(repr(self.to_dict()))

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickle with the arrays read-only again, as the constructor leaves them."""
        for value in state.values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
        self.__dict__.update(state)


def uniform_rod(mass: float, length: float) -> tuple[float, float, float]:
    """A uniform slender rod as a distal body: (mass [kg], centre of mass from the platform end [m], I [kg·m²]).

    Args:
        mass: m [kg].
        length: l [m].

    Returns:
        (m, l / 2, m l² / 12).
    """
    return float(mass), 0.5 * float(length), float(mass) * float(length) ** 2 / 12.0


def rod_from_end_masses(anchor_mass: float, platform_mass: float, length: float) -> tuple[float, float, float]:
    """A distal rod made of two point masses at its ends (Codourey's simplification of the Delta's forearms).

    Two point masses m_A at the anchor A_i and m_P at the platform point P_i, a distance l apart, have the
    kinetic energy of one rod of mass m = m_A + m_P, centre of mass at m_A l / m from P_i and transverse
    moment of inertia m_A m_P l² / m about it, which is what this returns.

    Args:
        anchor_mass: m_A [kg] at the anchor (a crank's elbow, a slider's carriage joint).
        platform_mass: m_P [kg] at the platform point.
        length: l [m].

    Returns:
        (mass [kg], centre of mass from the platform end [m], transverse inertia [kg·m²]).

    Raises:
        ValueError: If a mass is negative or both are zero.
    """
    m_A, m_P, l = float(anchor_mass), float(platform_mass), float(length)  # noqa: E741
    if not (m_A >= 0 and m_P >= 0 and m_A + m_P > 0):
        raise ValueError(f"end masses must be ≥ 0 [kg] and not both 0, got {m_A!r} and {m_P!r}")
    m = m_A + m_P
    return m, m_A * l / m, m_A * m_P * l * l / m


def _platform_disc(mass: float, radius: float, d: int, com: Any = None) -> dict[str, Any]:
    """A platform as a uniform disc of a radius (planar: I_zz = m r²/2; 3-D: diag(m r²/4, m r²/4, m r²/2))."""
    if d == 2:
        inertia: Any = mass * radius**2 / 2.0
    else:
        inertia = np.diag([mass * radius**2 / 4.0, mass * radius**2 / 4.0, mass * radius**2 / 2.0])
    return {
        "platform_mass": mass,
        "platform_com": np.zeros(d) if com is None else com,
        "platform_inertia": inertia,
    }


def _inertia_3rpr(robot: DistanceConstraintMechanism) -> InertialParameters:
    P = robot.platform
    centroid = P.mean(axis=0)
    radius = float(np.max(np.linalg.norm(P - centroid, axis=1)))
    return InertialParameters(
        **_platform_disc(2.0, radius, 2, centroid),
        actuator_mass=np.full(3, 1.0),
        actuator_com=np.full(3, 0.15),
        actuator_inertia=np.full(3, 1.0 * 0.3**2 / 12.0),
        distal_mass=np.full(3, 0.5),
        distal_com=np.full(3, 0.15),
        distal_inertia=np.full(3, 0.5 * 0.3**2 / 12.0),
        gravity=np.zeros(2),
    )


def _inertia_hexapod(robot: DistanceConstraintMechanism) -> InertialParameters:
    radius = float(np.max(np.linalg.norm(robot.platform, axis=1)))
    return InertialParameters(
        **_platform_disc(10.0, radius, 3),
        actuator_mass=np.full(6, 2.0),
        actuator_com=np.full(6, 0.15),
        actuator_inertia=np.full(6, 2.0 * 0.4**2 / 12.0),
        distal_mass=np.full(6, 1.0),
        distal_com=np.full(6, 0.15),
        distal_inertia=np.full(6, 1.0 * 0.4**2 / 12.0),
        gravity=np.array([0.0, 0.0, -STANDARD_GRAVITY]),
    )


def _inertia_delta(robot: DistanceConstraintMechanism) -> InertialParameters:
    a, l = float(robot.crank_radii[0]), float(robot.link_lengths[0])  # noqa: E741
    arm_mass, rotor = 1.0, 0.01
    forearm = rod_from_end_masses(0.15, 0.15, l)
    radius = float(np.max(np.linalg.norm(robot.platform, axis=1)))
    return InertialParameters(
        **_platform_disc(0.5, radius, 3),
        actuator_mass=np.full(3, arm_mass),
        actuator_com=np.full(3, a / 2.0),
        actuator_inertia=np.full(3, rotor + arm_mass * a * a / 3.0),
        distal_mass=np.full(3, forearm[0]),
        distal_com=np.full(3, forearm[1]),
        distal_inertia=np.full(3, forearm[2]),
        gravity=np.array([0.0, 0.0, -STANDARD_GRAVITY]),
    )


def _inertia_planar_distal(robot: DistanceConstraintMechanism, crank: bool) -> InertialParameters:
    P = robot.platform
    l = float(robot.link_lengths[0])  # noqa: E741
    link = uniform_rod(0.1, l)
    if crank:
        a = float(robot.crank_radii[0])
        actuator = {"actuator_mass": 0.2, "actuator_com": a / 2.0, "actuator_inertia": 1e-4 + 0.2 * a * a / 3.0}
    else:
        actuator = {"actuator_mass": 0.3, "actuator_com": 0.0, "actuator_inertia": 0.0}
    return InertialParameters(
        **_platform_disc(0.5, float(np.max(np.linalg.norm(P, axis=1))), 2),
        actuator_mass=np.full(3, actuator["actuator_mass"]),
        actuator_com=np.full(3, actuator["actuator_com"]),
        actuator_inertia=np.full(3, actuator["actuator_inertia"]),
        distal_mass=np.full(3, link[0]),
        distal_com=np.full(3, link[1]),
        distal_inertia=np.full(3, link[2]),
        gravity=np.zeros(2),
    )


_DEFAULTS = (
    (Planar3RPR, _inertia_3rpr),
    (StewartGough, _inertia_hexapod),
    (Delta, _inertia_delta),
    (Planar3RRR, lambda robot: _inertia_planar_distal(robot, crank=True)),
    (Planar3PRR, lambda robot: _inertia_planar_distal(robot, crank=False)),
)


def default_inertia(mechanism: DistanceConstraintMechanism) -> InertialParameters:
    """Illustrative inertial parameters for a preset, scaled to its geometry.

    No preset comes with measured masses; these numbers are of our own choosing, of the right order for the
    robot's size, for simulation and tests (give measured ones with ``InertialParameters`` for anything else).

    * ``Planar3RPR``: platform 2 kg, a disc about the centroid of the P_i; cylinders 1 kg (centre of mass
      0.15 m from the base joint, a 0.3 m tube), rods 0.5 kg (0.15 m from the platform end, 0.3 m long).
    * ``StewartGough``: platform 10 kg, a disc of the platform's radius; cylinders 2 kg, rods 1 kg (centres
      of mass 0.15 m from their ends, 0.4 m tubes).
    * ``Delta``: plate 0.5 kg; arms 1 kg uniform (centre of mass at a/2; rotor 0.01 kg·m² plus m a²/3 about
      the motor axis); forearms 0.3 kg, Codourey's model (M.-A. Codourey, "Dynamic modeling of parallel
      robots for computed-torque control implementation", IJRR 17(12), 1998): point masses at the elbow and
      at the plate (``rod_from_end_masses``), here half at each end.
    * ``Planar3RRR``: platform 0.5 kg; cranks 0.2 kg uniform plus a 1e-4 kg·m² rotor; links 0.1 kg uniform.
    * ``Planar3PRR``: platform 0.5 kg; carriages 0.3 kg; links 0.1 kg uniform.

    Planar robots lie in a horizontal plane: gravity (0, 0); stand one up with
    ``default_inertia(robot).replace(gravity=(0.0, -STANDARD_GRAVITY))``. Spatial and translational robots have
    g = (0, 0, −g_n) in {B} (z up).

    Args:
        mechanism: A preset (``Planar3RPR``, ``StewartGough``, ``Delta``, ``Planar3RRR``, ``Planar3PRR``).

    Returns:
        The parameters.

    Raises:
        ValueError: For a mechanism that is not one of the presets.
    """
    for kind, build in _DEFAULTS:
        if isinstance(mechanism, kind):
            return build(mechanism)
    names = [kind.__name__ for kind, _ in _DEFAULTS]
    raise ValueError(f"default inertia exists for the presets {names}, got a {type(mechanism).__name__}")
