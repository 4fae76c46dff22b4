"""Clavel's Delta robot (3-RUS): the translational, crank-actuated member of the distance-constraint family."""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics._validation import FloatArray, positive_scalar
from kinematics.family import DistanceConstraintMechanism
from kinematics.mechanism import _scalarize

__all__ = ["DEFAULT_DELTA", "Delta"]

#: The default geometry [m]: the ABB FlexPicker IRB 360 of R. L. Williams II, "The Delta Parallel Robot: Kinematics
#: Solutions" (Ohio University, 2015): base triangle side s_B = 0.567, plate triangle side s_P = 0.076, upper arm
#: L = 0.524, forearm (parallelogram) l = 1.244. The motor axes lie on the sides of the base triangle, so the base
#: radius (centre to motor axis) is w_B = s_B √3 / 6; the forearms end at the vertices of the plate triangle, so the
#: plate radius (centre to forearm joint) is u_P = s_P / √3. His arm 1 points along −y, our arm 0 along +x, so his
#: point (x, y, z) is our (−y, x, z), turned by +90° about z; his θ_1, θ_2, θ_3 are our q_0, q_1, q_2, and both
#: turn an arm downwards for positive angles.
DEFAULT_DELTA = {
    "base_radius": 0.567 * np.sqrt(3.0) / 6.0,
    "platform_radius": 0.076 / np.sqrt(3.0),
    "upper_arm": 0.524,
    "forearm": 1.244,
}


class Delta(DistanceConstraintMechanism):
    """Delta robot: three motors on the base turn upper arms; parallelogram forearms carry a translating plate.

    Arm i (i = 0, 1, 2) lies in the vertical plane at azimuth θ_i = 120°·i about the base's z axis (z up). Its
    motor axis is at B_i = R_b (cos θ_i, sin θ_i, 0), tangent to the base circle; the arm of length a points
    radially outwards at q_i = 0 and turns downwards for q_i > 0, so the elbow is

        A_i(q_i) = B_i + a (cos q_i u_i + sin q_i v_i),   u_i = (cos θ_i, sin θ_i, 0),  v_i = (0, 0, −1).

    Each parallelogram forearm keeps the midpoint of its lower bar, the plate point P_i = r_p (cos θ_i, sin θ_i,
    0) in {P}, at the distance l from the elbow; the plate does not turn (R = I), so the pose is its centre
    p = (x, y, z) [m] (z < 0 below the base) and Φ_i = ‖p + P_i − A_i(q_i)‖² − l². These are the crank legs
    of ``DistanceConstraintMechanism`` with a translational pose space; everything else comes from there.

    Singularities: Type I where an arm and its forearm are in line (stretched or folded, at the workspace's
    edge); Type II where the forearms lose rank, for example all parallel to one plane.

    Args:
        base_radius: R_b [m], base centre to the motor axes (Williams' w_B).
        platform_radius: r_p [m], plate centre to the forearms' lower joints (Williams' u_P).
        upper_arm: a [m].
        forearm: l [m].
        elbows: "out" (the usual posture: each elbow outside the line from its motor to the plate) or "in";
            the branch of the closed-form inverse kinematics.
        singular_tolerance: See ``DistanceConstraintMechanism``. Default 1e-12.

    Defaults: ``DEFAULT_DELTA`` (Williams' ABB IRB 360, about 1.1 m across the working range). With them, the
    inverse kinematics of (0, 0, −0.9) m is −20.5° on every arm and the forward kinematics of q = 0 is
    z = −1.065 m, his worked examples.
    """

    def __init__(
        self,
        base_radius: float = DEFAULT_DELTA["base_radius"],
        platform_radius: float = DEFAULT_DELTA["platform_radius"],
        upper_arm: float = DEFAULT_DELTA["upper_arm"],
        forearm: float = DEFAULT_DELTA["forearm"],
        *,
        elbows: str = "out",
        singular_tolerance: float = 1e-12,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        R_b = positive_scalar("base_radius", base_radius)
        r_p = positive_scalar("platform_radius", platform_radius)
        a = positive_scalar("upper_arm", upper_arm)
        l = positive_scalar("forearm", forearm)  # noqa: E741 - the literature's name
        if elbows not in ("out", "in"):
            raise ValueError(f"elbows must be 'out' or 'in', got {elbows!r}")
        if l <= a + abs(R_b - r_p):
            raise ValueError(
                f"forearm must be longer than upper_arm + |base_radius − platform_radius| = {a + abs(R_b - r_p)!r} m "
                f"for the plate to hang below the base, got {l!r}"
            )
        theta = np.radians([0.0, 120.0, 240.0])
        radial = np.stack([np.cos(theta), np.sin(theta), np.zeros(3)], axis=-1)
        down = np.broadcast_to([0.0, 0.0, -1.0], (3, 3))
        self._dims = (R_b, r_p, a, l)
        self._elbows = elbows
        # The home: the plate centred with every arm 30° below horizontal (the middle of the usual range).
        reach = R_b + a * np.cos(np.radians(30.0)) - r_p
        home = np.array([0.0, 0.0, -a * np.sin(np.radians(30.0)) - np.sqrt(l * l - reach * reach)])
        super().__init__(
            R_b * radial,
            r_p * radial,
            pose_space="translational",
            actuators="crank",
            link_lengths=l,
            crank_radii=a,
            crank_axes=np.stack([radial, down], axis=1),
            branches=-1.0 if elbows == "out" else 1.0,
            home=home,
            singular_tolerance=singular_tolerance,
        )

    @property
    def dimensions(self) -> tuple[float, float, float, float]:
        """(base_radius, platform_radius, upper_arm, forearm) [m]."""
        return self._dims

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        R_b, r_p, a, l = self._dims  # noqa: E741
        return (
            f"Delta(base_radius={R_b!r}, platform_radius={r_p!r}, upper_arm={a!r}, forearm={l!r}, "
            f"elbows={self._elbows!r}, singular_tolerance={self.singular_tolerance!r})"
        )

    def sphere_intersections(self, q: Any, *, validate: bool = True) -> FloatArray:
        """Both closed-form forward kinematics solutions: the points at distance l from the three A_i − P_i.

        Subtracting the sphere equations pairwise leaves two planes, whose line meets the first sphere in two
        points (Clavel's construction; Williams 2015, §"Forward position kinematics").

        Args:
            q: Motor angles [rad], shape (..., 3).
            validate: Check inputs.

        Returns:
            (lower, upper) plate centres [m], shape (..., 2, 3), lower (smaller z) first; NaN where the three
            spheres do not meet (the motors' angles are not assembled).
        """
        if validate:
            q = self._q(q)
        centres = self._anchor_terms(q)[0] - self._P  # sphere i: ‖p − c_i‖ = l
        l = self._dims[3]  # noqa: E741
        c1, c2, c3 = centres[..., 0, :], centres[..., 1, :], centres[..., 2, :]
        # ‖p − c_i‖² − ‖p − c_1‖² = 0  ⇒  2 (c_1 − c_i)·p = ‖c_1‖² − ‖c_i‖²   (i = 2, 3)
        n1, n2 = c1 - c2, c1 - c3
        axis = np.cross(n1, n2)  # the line's direction
        s1 = 0.5 * (np.einsum("...i,...i->...", c1, c1) - np.einsum("...i,...i->...", c2, c2))
        s2 = 0.5 * (np.einsum("...i,...i->...", c1, c1) - np.einsum("...i,...i->...", c3, c3))
        aa = np.einsum("...i,...i->...", axis, axis)
        # the point of the line nearest the origin: p0 = (s1 (n2 × axis) + s2 (axis × n1)) / |axis|²
        p0 = (s1[..., None] * np.cross(n2, axis) + s2[..., None] * np.cross(axis, n1)) / aa[..., None]
        u = axis / np.sqrt(aa)[..., None]
        # ‖p0 + t u − c_1‖² = l²
        w = p0 - c1
        b = np.einsum("...i,...i->...", w, u)
        disc = b * b - (np.einsum("...i,...i->...", w, w) - l * l)
        with np.errstate(invalid="ignore"):
            root = np.sqrt(disc)
        first = p0 + (-b - root)[..., None] * u
        second = p0 + (-b + root)[..., None] * u
        lower_first = first[..., 2] <= second[..., 2]
        lower = np.where(lower_first[..., None], first, second)
        upper = np.where(lower_first[..., None], second, first)
        return np.stack([lower, upper], axis=-2)

    def forward_kinematics_closed_form(self, q: Any, *, upper: bool = False, validate: bool = True) -> Any:
        """The plate centre from the motor angles in closed form (``sphere_intersections``), lower by default.

        Args:
            q: Motor angles [rad], shape (..., 3).
            upper: Return the upper solution (plate above the elbows) instead.
            validate: Check inputs.

        Returns:
            p [m], shape (..., 3); NaN where the angles cannot be assembled.
        """
        return _scalarize_rows(self.sphere_intersections(q, validate=validate)[..., 1 if upper else 0, :])


def _scalarize_rows(arr: FloatArray) -> FloatArray:
    return arr if arr.ndim > 1 else _scalarize(arr)
