"""MJCF export of a distance-constraint robot: the same bodies, masses and inertias for the MuJoCo simulator.

``to_mjcf`` writes an MJCF model (a string MuJoCo's ``MjModel.from_xml_string`` reads) of any member of the
family with the bodies of ``kinematics.inertia.InertialParameters``, assembled at a pose (q, x). Every body
frame is placed at its assembled position and every actuated joint has ``ref`` = q_i, so at MuJoCo's reference
configuration ``qpos0`` the model is closed and the actuated joints read q. Names, leg i = 0..n−1:

    platform     body ``platform`` (frame {P}); spatial: a free joint ``platform``; translational: slide joints
                 ``platform_x``, ``platform_y``, ``platform_z`` (the plate does not turn: the Delta's
                 parallelograms keep it level, so each is modelled as one rod and the slides hold the plate's
                 orientation); planar: slides ``platform_x``, ``platform_y`` and a hinge ``platform_phi`` about z,
                 so that the motion stays in the plane z = 0.
    actuator     body ``actuator{i}``: a leg's cylinder on joint ``base{i}`` at B_i (ball; planar: hinge about z),
                 a crank's rotor and arm on hinge ``actuator{i}`` at B_i about w_i = u_i × v_i, a slider's
                 carriage on slide ``actuator{i}`` along e_i.
    distal       body ``distal{i}``: a leg's rod on slide ``actuator{i}`` along the cylinder (its frame at P_i);
                 a crank's or slider's link on joint ``elbow{i}`` at A_i (ball; planar: hinge about z).
    closure      equality ``closure{i}``: a ``connect`` of the platform point P_i to the distal body's end
                 (planar: its z row is identically satisfied, so it acts as a hinge in the plane).
    motor        actuator ``motor{i}`` on joint ``actuator{i}``, gear 1, no control limits: ``data.ctrl`` is
                 τ (N for legs and sliders, N·m for cranks), the effort dual to q of ``kinematics.dynamics``; the
                 joint's ``damping`` is the drive's viscous friction b_i (``actuator_damping``), that of
                 ``base{i}`` or ``elbow{i}`` the passive joint's (``joint_damping``; a rod's spin, which the
                 friction of a ball joint also slows, stays decoupled from the platform).

The platform's joints come first in ``qpos`` (``platform_pose`` reads x from them). The inertial data map to
MuJoCo's bodies as follows (every ``<inertial>`` explicit, geoms for display only, contacts disabled):

    platform     mass m at c, inertia I_c in {P} axes (planar: I_zz on every axis; only z turns).
    leg          cylinder: mass at c along the leg from B_i, transverse moment I about its centre of mass;
                 rod: mass at c from P_i, transverse moment I.
    crank        rotor and arm: mass at c along the arm, moment J − m c² about its centre of mass on every
                 axis, so J about the motor axis; link: mass at ℓ − c from A_i, transverse moment I.
    slider       carriage: mass at A_i (it only translates); link as for a crank.

Rods and cylinders get a moment of inertia about their own axis, ``axial_inertia`` times the transverse one,
which ``InertialParameters`` neglects: a ball joint lets a leg (or a link) spin about its axis, and since every
such body is axisymmetric and its closure acts on the axis, that spin is decoupled from the platform's motion
whatever its inertia. A mass or moment of zero becomes 1e-9 (kg or kg·m²), as MuJoCo refuses massless moving
bodies.
"""

from __future__ import annotations

import math
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np

from kinematics._validation import FloatArray
from kinematics.family import DistanceConstraintMechanism
from kinematics.inertia import InertialParameters, default_inertia

__all__ = ["ASSEMBLY_TOLERANCE", "INTEGRATORS", "platform_pose", "to_mjcf"]

#: MuJoCo's integrators ``to_mjcf`` accepts.
INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")

#: Largest gap [m] between a link's length and the distance of its ends that ``to_mjcf`` assembles.
ASSEMBLY_TOLERANCE = 1e-9

#: Smallest mass [kg] and moment of inertia [kg·m²] given to a moving body: MuJoCo refuses massless ones.
_FLOOR = 1e-9


def _numbers(values: Any) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _world_inertia(transverse: float, axial: float, axis: FloatArray) -> FloatArray:
    """Inertia of an axisymmetric body about its centre of mass in world axes, shape (3, 3)."""
    outer = np.outer(axis, axis)
    return transverse * (np.eye(3) - outer) + axial * outer


def _full(inertia: FloatArray) -> str:
    I = np.asarray(inertia)  # noqa: E741
    return _numbers([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def _quaternion(r: FloatArray) -> FloatArray:
    """Unit quaternion (w, x, y, z) of the rotation vector r."""
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[math.cos(angle / 2.0)], math.sin(angle / 2.0) * np.asarray(r) / angle])


def _lift(points: FloatArray) -> FloatArray:
    """Points of shape (..., 2) or (..., 3) as 3-D points (planar robots lie in the plane z = 0)."""
    points = np.asarray(points, dtype=np.float64)
    if points.shape[-1] == 3:
        return points
    return np.concatenate([points, np.zeros(points.shape[:-1] + (1,))], axis=-1)


def _check_number(name: str, value: Any, low: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > low):
        raise ValueError(f"{name} must be a finite number > {low}, got {value!r}")
    return float(value)


def _check_pair(name: str, value: Any, size: int) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (size,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be {size} finite numbers, got {value!r}")
    return arr


def _assembly(mechanism: DistanceConstraintMechanism, q: Any, x: Any) -> tuple[FloatArray, FloatArray]:
    """The pose (q, x) to assemble at: the home pose by default, q from the inverse kinematics if not given."""
    x = mechanism.home_pose() if x is None else mechanism._x(np.array(x, dtype=np.float64))
    if x.ndim != 1:
        raise ValueError(f"x must be one pose of shape ({mechanism.n_pose},), got shape {x.shape}")
    q = mechanism.inverse_kinematics(x) if q is None else mechanism._q(np.array(q, dtype=np.float64))
    if q.ndim != 1 or not np.isfinite(q).all():
        raise ValueError(f"q must be finite actuator coordinates of shape ({mechanism.n_actuators},), got {q!r}")
    lengths = np.where(np.array(mechanism.actuator_kinds) == "leg", q, mechanism.link_lengths)
    residual = float(np.max(np.abs(np.linalg.norm(mechanism.link_vectors(q, x), axis=-1) - lengths)))
    if not residual < ASSEMBLY_TOLERANCE:
        raise ValueError(
            f"(q, x) must be an assembled pose (every |‖d_i‖ − ℓ_i| < {ASSEMBLY_TOLERANCE} m), got {residual:.3g} m"
        )
    return q, x


def to_mjcf(
    mechanism: DistanceConstraintMechanism,
    inertia: InertialParameters | None = None,
    *,
    q: Any = None,
    x: Any = None,
    timestep: float = 0.00025,
    integrator: str = "RK4",
    solref: Any = (0.0005, 1.0),
    solimp: Any = (0.9999, 0.9999, 0.001, 0.5, 2.0),
    axial_inertia: float = 1e-3,
    model_name: str | None = None,
) -> str:
    """An MJCF model of the robot with the bodies, masses and inertias of ``inertia`` (see the module docstring).

    Args:
        mechanism: The robot.
        inertia: Its inertial parameters; default ``default_inertia(mechanism)`` (presets only). Gravity is
            ``inertia.gravity`` in {B} (planar robots: in the plane z = 0).
        q: Actuator coordinates of the assembly, shape (n,); default the inverse kinematics of ``x``.
        x: Platform pose of the assembly, shape (m,); default ``mechanism.home_pose()``.
        timestep: MuJoCo's time step [s], > 0. Default 0.25 ms.
        integrator: One of ``INTEGRATORS``. Default "RK4".
        solref: (time constant [s], damping ratio) of the closures' constraint dynamics (MuJoCo's soft
            constraints; a time constant of at least two time steps keeps them stable). Default (0.5 ms, 1).
        solimp: MuJoCo's impedance (d_0, d_width, width [m], midpoint, power) of the closures; d near 1 makes
            them stiff. Default (0.9999, 0.9999, 0.001, 0.5, 2).
        axial_inertia: Moment of inertia of every rod and cylinder about its own axis, as a fraction of its
            transverse one, > 0 (our model neglects it; the spin it weighs is decoupled). Default 1e-3; at least
            2 b × ``timestep`` on a ball joint with friction b (``joint_damping``).
        model_name: The model's name; default the mechanism's class name.

    Returns:
        The MJCF document, a string.

    Raises:
        ValueError: If the inertia does not fit the mechanism, (q, x) is not assembled (``ASSEMBLY_TOLERANCE``),
            a crank's moment of inertia about its axis is not above m c² (its arm's own share), or an option is
            out of range (naming it).
    """
    if not isinstance(mechanism, DistanceConstraintMechanism):
        raise TypeError(f"mechanism must be a DistanceConstraintMechanism, got {type(mechanism).__name__}")
    ine = default_inertia(mechanism) if inertia is None else inertia
    space = mechanism.pose_space
    n, d = mechanism.n_actuators, space.point_dim
    if ine.n_legs != n or ine.point_dim != d:
        raise ValueError(
            f"inertial parameters for {ine.n_legs} legs with {ine.point_dim}-D points do not fit a robot with "
            f"{n} legs and {d}-D points"
        )
    _check_number("timestep", timestep, 0.0)
    _check_number("axial_inertia", axial_inertia, 0.0)
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {list(INTEGRATORS)}, got {integrator!r}")
    solref = _check_pair("solref", solref, 2)
    solimp = _check_pair("solimp", solimp, 5)
    q, x = _assembly(mechanism, q, x)
    kinds = mechanism.actuator_kinds
    crank = np.array([kind == "crank" for kind in kinds])
    shortfall = ine.actuator_inertia - ine.actuator_mass * ine.actuator_com**2
    if np.any(crank & (shortfall <= 0)):
        i = int(np.flatnonzero(crank & (shortfall <= 0))[0])
        raise ValueError(
            f"actuator_inertia of crank {i} must exceed actuator_mass · actuator_com² = "
            f"{ine.actuator_mass[i] * ine.actuator_com[i] ** 2!r} [kg·m²] (the arm's own share), "
            f"got {ine.actuator_inertia[i]!r}"
        )

    R = _lift3(mechanism.rotation_matrix(x).reshape(d, d))
    p = _lift(x[:d])
    P = _lift(mechanism.platform_points_in_base(x))  # (n, 3) in {B}
    B = _lift(mechanism.base)
    A = _lift(mechanism.anchors(q))
    link = P - A
    u = link / np.linalg.norm(link, axis=-1, keepdims=True)
    scale = float(np.max(np.linalg.norm(P - p, axis=1)))
    radius = repr(0.04 * scale)

    root = ET.Element("mujoco", model=model_name or type(mechanism).__name__)
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    option = ET.SubElement(
        root, "option", timestep=repr(float(timestep)), integrator=integrator, gravity=_numbers(_lift(ine.gravity))
    )
    ET.SubElement(option, "flag", contact="disable")
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "geom", contype="0", conaffinity="0", group="1", rgba="0.6 0.6 0.7 1")
    ET.SubElement(default, "equality", solref=_numbers(solref), solimp=_numbers(solimp))
    world = ET.SubElement(root, "worldbody")

    # The platform: frame {P} (spatial: rotated by R; otherwise world-aligned, its geometry in {B} axes).
    spatial = space.name == "spatial"
    R_body = R if spatial else np.eye(3)
    local = (R_body.T @ (P - p).T).T  # P_i in the platform body's frame
    com = R_body.T @ (R @ _lift(ine.platform_com))
    I_platform = _platform_inertia(ine)
    body_attrs = {"name": "platform", "pos": _numbers(p)}
    if spatial:
        body_attrs["quat"] = _numbers(_quaternion(x[3:6]))
    platform = ET.SubElement(world, "body", **body_attrs)
    if spatial:
        ET.SubElement(platform, "freejoint", name="platform")
    else:
        axes = ("x", "y") if space.name == "planar" else ("x", "y", "z")
        for k, axis in enumerate(axes):
            unit = np.eye(3)[k]
            ET.SubElement(
                platform, "joint", name=f"platform_{axis}", type="slide", axis=_numbers(unit), ref=repr(float(p[k]))
            )
        if space.name == "planar":
            ET.SubElement(platform, "joint", name="platform_phi", type="hinge", axis="0 0 1", ref=repr(float(x[2])))
    ET.SubElement(
        platform,
        "inertial",
        pos=_numbers(com),
        mass=repr(ine.platform_mass),
        fullinertia=_full(I_platform),
    )
    for i in range(n):
        ET.SubElement(platform, "geom", type="capsule", size=radius, fromto=_numbers([*local[i - 1], *local[i]]))

    joint_kind = "ball" if d == 3 else "hinge"

    def actuated_joint(body: ET.Element, i: int, joint_type: str, axis: FloatArray) -> None:
        """Joint ``actuator{i}`` at q_i, with the drive's viscous friction (none: MuJoCo's default)."""
        b = float(ine.actuator_damping[i])
        extra = {"damping": repr(b)} if b > 0.0 else {}
        ref = repr(float(q[i]))
        ET.SubElement(body, "joint", name=f"actuator{i}", type=joint_type, axis=_numbers(axis), ref=ref, **extra)

    for i, kind in enumerate(kinds):
        # a ball joint's friction also slows the spin of the rod it carries: an axial moment of at least 2 b dt keeps
        # that mode (time constant I / b) stable under MuJoCo's explicit integrators
        spin = 2.0 * float(ine.joint_damping[i]) * timestep if joint_kind == "ball" else 0.0
        t_i = max(float(ine.distal_inertia[i]), _FLOOR)
        rod_inertia = _world_inertia(t_i, max(axial_inertia * t_i, spin), u[i])
        rod_mass = repr(max(float(ine.distal_mass[i]), _FLOOR))
        if kind == "leg":
            cylinder = ET.SubElement(world, "body", name=f"actuator{i}", pos=_numbers(B[i]))
            _pivot(cylinder, f"base{i}", joint_kind, float(ine.joint_damping[i]))
            c_i = max(float(ine.actuator_inertia[i]), _FLOOR)
            ET.SubElement(
                cylinder,
                "inertial",
                pos=_numbers(ine.actuator_com[i] * u[i]),
                mass=repr(max(float(ine.actuator_mass[i]), _FLOOR)),
                fullinertia=_full(_world_inertia(c_i, max(axial_inertia * c_i, spin), u[i])),
            )
            ET.SubElement(
                cylinder,
                "geom",
                type="cylinder",
                size=repr(0.06 * scale),
                fromto=_numbers([0, 0, 0, *(0.5 * q[i] * u[i])]),
            )
            distal = ET.SubElement(cylinder, "body", name=f"distal{i}", pos=_numbers(P[i] - B[i]))
            actuated_joint(distal, i, "slide", u[i])
            rod_com = -ine.distal_com[i] * u[i]
            rod_geom = [*(-0.5 * q[i] * u[i]), 0, 0, 0]
        else:
            if kind == "crank":
                U, V = (_lift(axis) for axis in mechanism.crank_axes[i])
                w = np.cross(U, V)
                arm = ET.SubElement(world, "body", name=f"actuator{i}", pos=_numbers(B[i]))
                actuated_joint(arm, i, "hinge", w)
                radial = (A[i] - B[i]) / mechanism.crank_radii[i]
                own = max(float(shortfall[i]), _FLOOR)
                ET.SubElement(
                    arm,
                    "inertial",
                    pos=_numbers(ine.actuator_com[i] * radial),
                    mass=repr(max(float(ine.actuator_mass[i]), _FLOOR)),
                    fullinertia=_full(own * np.eye(3)),
                )
                ET.SubElement(arm, "geom", type="capsule", size=radius, fromto=_numbers([0, 0, 0, *(A[i] - B[i])]))
                offset = A[i] - B[i]
            else:
                e = _lift(mechanism.rails[i])
                arm = ET.SubElement(world, "body", name=f"actuator{i}", pos=_numbers(A[i]))
                actuated_joint(arm, i, "slide", e)
                ET.SubElement(
                    arm,
                    "inertial",
                    pos="0 0 0",
                    mass=repr(max(float(ine.actuator_mass[i]), _FLOOR)),
                    diaginertia=_numbers([_FLOOR] * 3),
                )
                ET.SubElement(arm, "geom", type="sphere", size=repr(2 * float(radius)))
                offset = np.zeros(3)
            distal = ET.SubElement(arm, "body", name=f"distal{i}", pos=_numbers(offset))
            _pivot(distal, f"elbow{i}", joint_kind, float(ine.joint_damping[i]))
            ell = float(np.linalg.norm(link[i]))
            rod_com = (ell - ine.distal_com[i]) * u[i]
            rod_geom = [0, 0, 0, *link[i]]
        ET.SubElement(distal, "inertial", pos=_numbers(rod_com), mass=rod_mass, fullinertia=_full(rod_inertia))
        ET.SubElement(distal, "geom", type="capsule", size=repr(0.5 * float(radius)), fromto=_numbers(rod_geom))

    equality = ET.SubElement(root, "equality")
    for i in range(n):
        ET.SubElement(
            equality, "connect", name=f"closure{i}", body1="platform", body2=f"distal{i}", anchor=_numbers(local[i])
        )
    actuators = ET.SubElement(root, "actuator")
    for i in range(n):
        ET.SubElement(actuators, "motor", name=f"motor{i}", joint=f"actuator{i}", gear="1", ctrllimited="false")
    ET.indent(root)
    return ET.tostring(root, encoding="unicode")


def _lift3(R: FloatArray) -> FloatArray:
    """A rotation matrix of shape (2, 2) or (3, 3) as (3, 3) (planar: about z)."""
    if R.shape == (3, 3):
        return R
    out = np.eye(3)
    out[:2, :2] = R
    return out


def _platform_inertia(ine: InertialParameters) -> FloatArray:
    """The platform's inertia about its centre of mass in its body frame's axes, shape (3, 3).

    Spatial: I_c (the body frame is {P}). Translational: I_c, unused since the plate does not turn. Planar:
    I_zz about z, with I_xx = I_yy = I_zz for MuJoCo's checks (the hinge turns the platform about z only).
    """
    I_c = np.asarray(ine.platform_inertia)
    if I_c.shape == (1, 1):
        return float(I_c[0, 0]) * np.eye(3)
    return I_c


def _pivot(body: ET.Element, name: str, joint_kind: str, damping: float) -> None:
    extra = {"damping": repr(damping)} if damping > 0.0 else {}
    if joint_kind == "ball":
        ET.SubElement(body, "joint", name=name, type="ball", **extra)
    else:
        ET.SubElement(body, "joint", name=name, type="hinge", axis="0 0 1", **extra)


def platform_pose(mechanism: DistanceConstraintMechanism, qpos: Any) -> FloatArray:
    """The platform pose x from the positions of the platform's joints in a model of ``to_mjcf``.

    Args:
        mechanism: The robot the model was written for.
        qpos: The platform's joint positions, the first entries of MuJoCo's ``data.qpos``: spatial, the free
            joint's (p [m], quaternion (w, x, y, z)), shape (..., 7); translational (p_x, p_y, p_z) [m] and
            planar (x [m], y [m], φ [rad]), shape (..., 3). Longer arrays are cut to these.

    Returns:
        x, shape (..., m) (spatial: the rotation vector of the quaternion, angle in [0, π]).
    """
    qpos = np.asarray(qpos, dtype=np.float64)
    if mechanism.pose_space.name != "spatial":
        return qpos[..., :3].copy()
    quat = qpos[..., 3:7] * np.where(qpos[..., 3:4] < 0, -1.0, 1.0)
    vector = quat[..., 1:]
    sine = np.linalg.norm(vector, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sine, quat[..., :1])
    factor = np.where(sine > 1e-12, angle / np.where(sine > 1e-12, sine, 1.0), 2.0)
    return np.concatenate([qpos[..., :3], factor * vector], axis=-1)
