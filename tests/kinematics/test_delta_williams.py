"""The default Delta is R. L. Williams II's ABB IRB 360: his four worked examples, to his printed precision.

R. L. Williams II, "The Delta Parallel Robot: Kinematics Solutions" (Ohio University, 2015): s_B = 0.567 m,
s_P = 0.076 m, L = 0.524 m, l = 1.244 m, motor axes at w_B = s_B √3 / 6 from the base centre and forearm joints at
the plate triangle's vertices, u_P = s_P / √3. His arm 1 points along −y with arms 2 and 3 at 30° and 150°; our
arm 0 points along +x with 120° spacing, so his point (x, y, z) is our (−y, x, z) and his θ_i is our q_(i−1).
Both conventions turn an arm downwards for a positive angle. He prints angles to 0.1° and positions to 1 mm; a
result matches when it is within one unit of his last digit (his −1.065 m at θ = 0 is z = −1.06445 m, on the
rounding boundary). Joints at the mid-sides (plate radius s_P √3 / 6) miss each example, by 1.8° or 11 mm or
more on its worst coordinate.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinematics import Delta
from kinematics.delta import DEFAULT_DELTA

#: One unit of the last digit he prints: 0.1° for angles, 1 mm for positions.
ANGLE_TOLERANCE_DEG = 0.1
POSITION_TOLERANCE = 0.001

#: Inverse position kinematics: his plate centre [m] and his motor angles [deg].
IK_EXAMPLES = [
    ((0.0, 0.0, -0.9), (-20.5, -20.5, -20.5)),
    ((0.3, 0.5, -1.1), (47.5, -11.6, 21.4)),
]

#: Forward position kinematics: his motor angles [deg] and his plate centre [m] (the lower solution).
FK_EXAMPLES = [
    ((0.0, 0.0, 0.0), (0.0, 0.0, -1.065)),
    ((10.0, 20.0, 30.0), (0.108, -0.180, -1.244)),
]


def ours(point: tuple[float, float, float]) -> np.ndarray:
    """A point of Williams' base frame in ours: turned by +90° about z, (x, y, z) → (−y, x, z)."""
    x, y, z = point
    return np.array([-y, x, z])


def test_default_geometry_is_williams_irb360() -> None:
    """Base radius w_B = s_B √3 / 6 (motor axes on the base triangle's sides), plate radius u_P = s_P / √3."""
    s_B, s_P = 0.567, 0.076
    assert DEFAULT_DELTA["base_radius"] == pytest.approx(s_B * np.sqrt(3.0) / 6.0, rel=1e-15)
    assert DEFAULT_DELTA["platform_radius"] == pytest.approx(s_P / np.sqrt(3.0), rel=1e-15)
    assert (DEFAULT_DELTA["upper_arm"], DEFAULT_DELTA["forearm"]) == (0.524, 1.244)
    assert Delta().dimensions == tuple(
        DEFAULT_DELTA[k] for k in ("base_radius", "platform_radius", "upper_arm", "forearm")
    )
    np.testing.assert_allclose(np.linalg.norm(Delta().platform, axis=-1), 0.076 / np.sqrt(3.0), rtol=1e-15)


@pytest.mark.parametrize(("point", "theta_deg"), IK_EXAMPLES)
def test_inverse_kinematics_matches_williams(point: tuple, theta_deg: tuple) -> None:
    """The closed-form inverse kinematics (elbows out) gives his motor angles."""
    q = Delta().inverse_kinematics(ours(point))
    np.testing.assert_allclose(np.degrees(q), theta_deg, rtol=0, atol=ANGLE_TOLERANCE_DEG)


@pytest.mark.parametrize(("theta_deg", "point"), FK_EXAMPLES)
def test_forward_kinematics_matches_williams(theta_deg: tuple, point: tuple) -> None:
    """The closed form (sphere intersections) and Newton from the home pose both give his plate centre."""
    robot = Delta()
    q = np.radians(theta_deg)
    expected = ours(point)
    np.testing.assert_allclose(robot.forward_kinematics_closed_form(q), expected, rtol=0, atol=POSITION_TOLERANCE)
    result = robot.forward_kinematics(q, robot.home_pose())
    assert result.converged
    np.testing.assert_allclose(result.x, expected, rtol=0, atol=POSITION_TOLERANCE)
    np.testing.assert_allclose(result.x, robot.forward_kinematics_closed_form(q), rtol=0, atol=1e-12)


@pytest.mark.parametrize(("point", "theta_deg"), IK_EXAMPLES)
def test_williams_inverse_examples_round_trip(point: tuple, theta_deg: tuple) -> None:
    """FK of the computed angles returns his point exactly (the examples are one consistent geometry)."""
    robot = Delta()
    q = robot.inverse_kinematics(ours(point))
    np.testing.assert_allclose(robot.forward_kinematics_closed_form(q), ours(point), rtol=0, atol=1e-12)
