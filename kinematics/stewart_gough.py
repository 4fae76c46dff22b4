"""The Stewart–Gough platform (6-UPS): the spatial, leg-actuated member of the distance-constraint family."""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics.family import DistanceConstraintMechanism

__all__ = ["DEFAULT_HEXAPOD_BASE", "DEFAULT_HEXAPOD_PLATFORM", "StewartGough", "semi_regular_hexagon"]


def semi_regular_hexagon(radius: float, half_angle_deg: float, offset_deg: float = 0.0) -> np.ndarray:
    """Six points at ``radius`` in the plane z = 0, in pairs at angles 120°·k + offset ± half_angle.

    Ordered (120°·0 − a, 120°·0 + a, 120°·1 − a, 120°·1 + a, 120°·2 − a, 120°·2 + a) + offset.

    Args:
        radius: Distance of every point from the origin [m].
        half_angle_deg: Half the angle between the two points of a pair [deg].
        offset_deg: Rotation of the whole set about z [deg].

    Returns:
        Points, shape (6, 3) [m].
    """
    angles = []
    for k in range(3):
        centre = 120.0 * k + offset_deg
        angles += [centre - half_angle_deg, centre + half_angle_deg]
    theta = np.radians(angles)
    return np.stack([radius * np.cos(theta), radius * np.sin(theta), np.zeros(6)], axis=-1)


#: Base anchors B_i in {B} [m], shape (6, 3): radius 0.5 m, pairs at 120°·k ± 12° (a motion-simulator
#: or positioning hexapod about 1 m across; the proportions of Fichter's 1986 design).
DEFAULT_HEXAPOD_BASE = semi_regular_hexagon(0.5, 12.0)
#: Platform points P_i in {P} [m], shape (6, 3): radius 0.3 m, pairs at 120°·k ± 48°. Leg i joins B_i to P_i:
#: B at 120°·k ± 12° to P at 120°·k ± 48°, so the platform pairs sit 60° from the base pairs and the six legs
#: zigzag between them (the classical 6-6 architecture).
DEFAULT_HEXAPOD_PLATFORM = semi_regular_hexagon(0.3, 48.0)
DEFAULT_HEXAPOD_BASE.setflags(write=False)
DEFAULT_HEXAPOD_PLATFORM.setflags(write=False)


class StewartGough(DistanceConstraintMechanism):
    """Stewart–Gough platform (6-UPS / 6-SPS): six extensible legs B_i → P_i, spatial pose.

    Φ_i(q, x) = ‖p + R P_i − B_i‖² − q_i², with q = (q_1, …, q_6) the leg lengths [m] and
    x = (p [m], r [rad]) the pose of {P} in {B}, r the rotation vector (R = exp([r]×), SciPy's
    ``Rotation.from_rotvec``). J_q = −2 diag(q); row i of J_x = 2 (d_iᵀ, ((R P_i) × d_i)ᵀ) with respect to
    the platform twist (v, ω) in {B}. Everything else comes from ``DistanceConstraintMechanism``.

    The default geometry is a symmetric 6-6 hexapod: base anchors at radius 0.5 m in pairs 24° apart,
    platform points at radius 0.3 m in pairs 24° apart, centred 60° from the base pairs (legs zigzag); the
    home pose (``home_pose``) is p = (0, 0, 0.5) m, r = 0, with legs of 0.59 m. Turned by ±90° about the vertical axis
    while centred it is singular at every height (Fichter 1986).

    Args:
        base: Anchors B_i in {B} [m], shape (6, 3). Default ``DEFAULT_HEXAPOD_BASE``.
        platform: Platform points P_i in {P} [m], shape (6, 3). Default ``DEFAULT_HEXAPOD_PLATFORM``.
        characteristic_length: ℓ_c [m] for the homogeneous Jacobian. Default: the platform radius
            (largest ‖P_i‖).
        singular_tolerance: Hadamard ratio of the homogenised J_x below which inverting it raises
            ``SingularConfigurationError``. Default 1e-12.
    """

    def __init__(
        self,
        base: Any = None,
        platform: Any = None,
        *,
        characteristic_length: float | None = None,
        singular_tolerance: float = 1e-12,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        super().__init__(
            DEFAULT_HEXAPOD_BASE if base is None else base,
            DEFAULT_HEXAPOD_PLATFORM if platform is None else platform,
            pose_space="spatial",
            characteristic_length=characteristic_length,
            singular_tolerance=singular_tolerance,
        )

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        return (
            f"StewartGough(base={self._B.tolist()}, platform={self._P.tolist()}, "
            f"characteristic_length={self._l_c!r}, singular_tolerance={self.singular_tolerance!r})"
        )
