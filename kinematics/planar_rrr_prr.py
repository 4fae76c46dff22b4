"""The planar 3-RRR and 3-PRR: the planar crank- and slider-actuated members of the distance-constraint family."""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics._validation import positive_scalar
from kinematics.family import DistanceConstraintMechanism

__all__ = ["Planar3PRR", "Planar3RRR"]


def _triangle(radius: float) -> np.ndarray:
    """The vertices of an equilateral triangle of circumradius ``radius`` at 90°, 210° and 330°, shape (3, 2)."""
    angles = np.radians([90.0, 210.0, 330.0])
    return radius * np.stack([np.cos(angles), np.sin(angles)], axis=-1)


def _branches(name: str, value: Any) -> tuple[float, float, float]:
    signs = (value,) * 3 if isinstance(value, (int, float)) else tuple(value)
    if len(signs) != 3 or any(s not in (1, -1) for s in signs):
        raise ValueError(f"{name} must be +1 or −1, or three of them, got {value!r}")
    return tuple(float(s) for s in signs)


class Planar3RRR(DistanceConstraintMechanism):
    """Symmetric planar 3-RRR with actuated base joints: three crank arms, three distal links, pose (x, y, φ).

    Motor i sits at B_i, a vertex of an equilateral triangle of circumradius R_b (at 90°, 210°, 330°); its crank
    of length a makes the angle q_i [rad] with the line from B_i to the base's centre, counter-clockwise
    positive: A_i = B_i + a (cos q_i u_i + sin q_i v_i) with u_i = −B_i / R_b and v_i = u_i turned by +90°
    (so a symmetric pose has the same q_i on every leg, and one pair of joint limits serves all); a distal link of
    length l joins the elbow A_i to the platform point P_i, a vertex of an equilateral triangle of circumradius
    r_p in {P} (same angles). Φ_i = ‖p + R(φ) P_i − A_i(q_i)‖² − l²: the crank legs of
    ``DistanceConstraintMechanism`` in the planar pose space.

    Each leg reaches its platform point with its elbow on either side of the line B_i P_i, so a pose has up
    to 2³ = 8 inverse kinematics solutions; ``elbows`` chooses one (+1: the elbow to the left of B_i → P_i,
    counter-clockwise; −1: to the right). Type I singularities: a leg stretched or folded (crank and link in
    line); Type II: the three distal links' lines meeting in one point (or all parallel).

    Args:
        base_radius: R_b [m]. Default 0.25.
        platform_radius: r_p [m]. Default 0.05.
        crank: a [m]. Default 0.14.
        link: l [m]. Default 0.14.
        elbows: +1 or −1 for every leg, or three of them. Default −1 (all to the right: the symmetric "−−−"
            working mode, whose home pose is well conditioned).
        singular_tolerance: See ``DistanceConstraintMechanism``. Default 1e-12.

    The default is a lab-bench size of our own choosing (the platform reaches about ±0.1 m around the centre).
    """

    def __init__(
        self,
        base_radius: float = 0.25,
        platform_radius: float = 0.05,
        crank: float = 0.14,
        link: float = 0.14,
        *,
        elbows: Any = -1,
        singular_tolerance: float = 1e-12,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        R_b = positive_scalar("base_radius", base_radius)
        r_p = positive_scalar("platform_radius", platform_radius)
        a = positive_scalar("crank", crank)
        l = positive_scalar("link", link)  # noqa: E741 - the literature's name
        signs = _branches("elbows", elbows)
        if not abs(a - l) < R_b - r_p < a + l:
            raise ValueError(
                f"the home pose (centred, φ = 0) must be reachable: need |crank − link| < base_radius − "
                f"platform_radius < crank + link, got {abs(a - l)!r} < {R_b - r_p!r} < {a + l!r}"
            )
        self._dims = (R_b, r_p, a, l)
        base = _triangle(R_b)
        inward = -base / R_b
        axes = np.stack([inward, np.stack([-inward[:, 1], inward[:, 0]], axis=-1)], axis=1)
        # IK branch +1 puts the elbow at atan2(w) + acos(·): counter-clockwise of B_i → P_i, i.e. to the left.
        super().__init__(
            base,
            _triangle(r_p),
            pose_space="planar",
            actuators="crank",
            link_lengths=l,
            crank_radii=a,
            crank_axes=axes,
            branches=signs,
            home=np.zeros(3),
            singular_tolerance=singular_tolerance,
        )

    @property
    def dimensions(self) -> tuple[float, float, float, float]:
        """(base_radius, platform_radius, crank, link) [m]."""
        return self._dims

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        R_b, r_p, a, l = self._dims  # noqa: E741
        return (
            f"Planar3RRR(base_radius={R_b!r}, platform_radius={r_p!r}, crank={a!r}, link={l!r}, "
            f"elbows={tuple(int(s) for s in self.branches)!r}, singular_tolerance={self.singular_tolerance!r})"
        )


class Planar3PRR(DistanceConstraintMechanism):
    """Planar 3-PRR: three carriages on fixed rails, each with a link to the platform, pose (x, y, φ).

    Rail i runs along side i of an equilateral base triangle of circumradius R_b: from its vertex B_i (at 90°,
    210°, 330°) towards the next one, e_i = (B_{i+1} − B_i)/‖·‖; the carriage is at A_i = B_i + q_i e_i, q_i [m]
    along the rail. A link of length l joins it to P_i, a vertex of the platform triangle of circumradius r_p.
    Φ_i = ‖p + R(φ) P_i − A_i(q_i)‖² − l²: the slider legs of ``DistanceConstraintMechanism``.

    Each leg reaches its platform point from two carriage positions; ``branches`` chooses (+1: the one
    further along the rail). Type I: a link square to its rail; Type II: the three links' lines concurrent.

    Args:
        base_radius: R_b [m]. Default 0.3.
        platform_radius: r_p [m]. Default 0.05.
        link: l [m]. Default 0.2.
        branches: +1 or −1 for every leg, or three of them. Default +1.
        singular_tolerance: See ``DistanceConstraintMechanism``. Default 1e-12.

    The default is a lab-bench size of our own choosing (rails 0.52 m long).
    """

    def __init__(
        self,
        base_radius: float = 0.3,
        platform_radius: float = 0.05,
        link: float = 0.2,
        *,
        branches: Any = 1,
        singular_tolerance: float = 1e-12,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        R_b = positive_scalar("base_radius", base_radius)
        r_p = positive_scalar("platform_radius", platform_radius)
        l = positive_scalar("link", link)  # noqa: E741
        signs = _branches("branches", branches)
        B = _triangle(R_b)
        rails = np.roll(B, -1, axis=0) - B
        rails /= np.linalg.norm(rails, axis=-1, keepdims=True)
        # the home pose needs each platform point within l of its rail's line
        offset = _triangle(r_p)[0] - B[0]
        gap = abs(float(rails[0, 0] * offset[1] - rails[0, 1] * offset[0]))
        if not gap < l:
            raise ValueError(f"link must be longer than the home pose's distance to a rail, {gap!r} m, got {l!r}")
        self._dims = (R_b, r_p, l)
        super().__init__(
            B,
            _triangle(r_p),
            pose_space="planar",
            actuators="slider",
            link_lengths=l,
            rails=rails,
            branches=signs,
            home=np.zeros(3),
            singular_tolerance=singular_tolerance,
        )

    @property
    def dimensions(self) -> tuple[float, float, float]:
        """(base_radius, platform_radius, link) [m]."""
        return self._dims

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        R_b, r_p, l = self._dims  # noqa: E741
        return (
            f"Planar3PRR(base_radius={R_b!r}, platform_radius={r_p!r}, link={l!r}, "
            f"branches={tuple(int(s) for s in self.branches)!r}, singular_tolerance={self.singular_tolerance!r})"
        )
