"""The distance-constraint family: Φ_i = ‖p + R P_i − A_i(q_i)‖² − ℓ_i(q_i)², one class for every member.

Almost every parallel robot in use keeps, for each leg i, a platform point P_i at a distance ℓ_i(q_i) from
an anchor A_i(q_i) that its actuator positions. A member of the family is *data*: its pose space, the kind
of its actuators and its geometry. This module holds the math once for all of them:

Pose spaces (``POSE_SPACES``)
    ``planar``   x = (x [m], y [m], φ [rad]); points are 2-D; R(φ) the rotation by φ; the velocity is ẋ.
    ``spatial``  x = (p_x, p_y, p_z [m], r_x, r_y, r_z [rad]) with r the rotation vector, R = exp([r]×)
                 (SciPy's ``Rotation.from_rotvec`` convention); points are 3-D. The velocity is the platform
                 twist (v, ω) in {B}: v the velocity of the origin of {P}, ω the angular velocity with
                 Ṙ = [ω]× R. J_x, J_f and J_i refer to the twist, not to ṙ, and a pose is updated on the
                 rotation group, R ← exp([δθ]×) R (``retract``), never through Euler angles.

Actuator kinds (``ACTUATOR_KINDS``)
    ``leg``      A_i = B_i, ℓ_i = q_i: an extensible leg (3-RPR, 6-UPS Stewart–Gough). Crank and slider
                 kinds follow the same formula with other A_i and ℓ_i.

For the leg kind, with d_i = p + R P_i − B_i:

    Φ_i = d_iᵀ d_i − q_i²,   J_q = −2 diag(q),   row i of J_x = 2 (d_iᵀ, ((R P_i) × d_i)ᵀ)

(planar: the cross product is its z component, so row i = 2 (d_ix, d_iy, (R P_i)_x d_iy − (R P_i)_y d_ix),
the lesson's §5.2). The rows of J_i = −J_q⁻¹ J_x are the legs' unit Plücker lines (u_i, (R P_i) × u_i).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics._validation import FloatArray, point_set, positive_scalar
from kinematics.mechanism import ParallelMechanism

__all__ = ["ACTUATOR_KINDS", "POSE_SPACES", "DistanceConstraintMechanism", "PoseSpace"]

#: Actuator kinds this version implements (crank and slider come with the rotary and linear robots).
ACTUATOR_KINDS = ("leg",)


class PoseSpace:
    """How a pose x parametrises the platform's position p and rotation R, and how it moves.

    Attributes:
        name: "planar" or "spatial".
        point_dim: Dimension d of the anchor and platform points (2 or 3).
        n_pose: Number m of pose coordinates (3 or 6).
        rotation_columns: Indices of the pose (and twist) coordinates that are rotations.
        x_description: Human-readable description of x, for error messages.
    """

    def __init__(self, name: str, point_dim: int, n_pose: int, rotation_columns: tuple[int, ...], description: str):
        self.name = name
        self.point_dim = point_dim
        self.n_pose = n_pose
        self.rotation_columns = rotation_columns
        self.x_description = description

    def __repr__(self) -> str:
        return f"PoseSpace({self.name!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (_pose_space, (self.name,))

    def pose_scale(self, characteristic_length: float) -> FloatArray:
        """Column scaling (1 for translations, 1/ℓ_c for rotations) that homogenises J_i, shape (m,)."""
        scale = np.ones(self.n_pose)
        scale[list(self.rotation_columns)] = 1.0 / characteristic_length
        return scale

    # -- the pose ↔ (p, R) map and the motion on the group -------------------------------------------

    def position(self, x: FloatArray) -> FloatArray:
        """Position p of the origin of {P} in {B} [m], shape (..., d)."""
        return x[..., : self.point_dim]

    def rotation(self, x: FloatArray) -> FloatArray:
        """Rotation R of {P} in {B}, shape (..., d, d)."""
        if self.name == "planar":
            c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
            return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)
        r = x[..., 3:6]
        return _rotations(r).as_matrix().reshape(r.shape[:-1] + (3, 3))

    def retract(self, x: FloatArray, step: FloatArray) -> FloatArray:
        """The pose reached from x by a twist step (δp, δθ): p + δp and R ← exp([δθ]×) R.

        Args:
            x: Poses, shape (..., m).
            step: Steps in twist coordinates (planar: (δx, δy, δφ); spatial: (δp [m], δθ [rad]) in {B}),
                shape (..., m).

        Returns:
            Poses, shape (..., m); spatial rotation vectors in the ball |r| ≤ π.
        """
        if self.name == "planar":
            return x + step
        shape = np.broadcast_shapes(x.shape, step.shape)
        x, step = np.broadcast_to(x, shape), np.broadcast_to(step, shape)
        out = np.empty(shape)
        out[..., :3] = x[..., :3] + step[..., :3]
        rotation = _rotations(step[..., 3:]) * _rotations(x[..., 3:])
        out[..., 3:] = rotation.as_rotvec().reshape(shape[:-1] + (3,))
        return out

    def difference(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """The twist step from y to x: (p_x − p_y, δθ) with exp([δθ]×) R_y = R_x (planar: x − y).

        Args:
            x: Poses, shape (..., m).
            y: Poses, shape (..., m).

        Returns:
            Steps in twist coordinates, shape (..., m); ``retract(y, difference(x, y)) == x``.
        """
        if self.name == "planar":
            return x - y
        shape = np.broadcast_shapes(x.shape, y.shape)
        x, y = np.broadcast_to(x, shape), np.broadcast_to(y, shape)
        out = np.empty(shape)
        out[..., :3] = x[..., :3] - y[..., :3]
        relative = _rotations(x[..., 3:]) * _rotations(y[..., 3:]).inv()
        out[..., 3:] = relative.as_rotvec().reshape(shape[:-1] + (3,))
        return out


#: The pose spaces, by name.
POSE_SPACES = {
    "planar": PoseSpace("planar", 2, 3, (2,), "a pose (x [m], y [m], φ [rad])"),
    "spatial": PoseSpace("spatial", 3, 6, (3, 4, 5), "a pose (p_x, p_y, p_z [m], rotation vector r_x, r_y, r_z [rad])"),
}


def _pose_space(name: str) -> PoseSpace:
    return POSE_SPACES[name]


def _rotations(r: FloatArray) -> Any:
    """SciPy rotations (``scipy.spatial.transform.Rotation``) from rotation vectors of shape (..., 3), as a stack.

    SciPy is imported here, on first use by a spatial pose, so that planar robots load NumPy alone.
    """
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.array(r, dtype=np.float64).reshape(-1, 3))


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """A × b over the last axis: the z component for 2-D vectors (shape (...)), the vector for 3-D."""
    if a.shape[-1] == 2:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return np.cross(a, b)


def check_distinct(name: str, points: FloatArray) -> None:
    """Raise a ``ValueError`` naming the first pair of coincident points of a set, shape (n, d) [m]."""
    extent = max(1.0, float(np.max(np.abs(points))))
    for i in range(len(points)):
        for j in range(i + 1, len(points)):
            gap = float(np.linalg.norm(points[i] - points[j]))
            if gap <= 1e-9 * extent:
                raise ValueError(
                    f"{name} must be pairwise distinct: points {i + 1} and {j + 1} are {gap:.3g} m "
                    f"apart ({points[i].tolist()} and {points[j].tolist()})"
                )


class DistanceConstraintMechanism(ParallelMechanism):
    """A fully parallel robot of the distance-constraint family, given by its data alone.

    Φ_i(q, x) = ‖p + R(x) P_i − A_i(q_i)‖² − ℓ_i(q_i)², i = 1..n, with n = m actuators (see the module
    docstring for the pose spaces and actuator kinds). Every method of ``ParallelMechanism`` (J_f, J_i,
    forward kinematics on the rotation group, DOF, mobility, statics, conditioning) works unchanged.

    Args:
        base: Anchors B_i in {B} [m], shape (n, d) with d = 2 (planar) or 3 (spatial); pairwise distinct.
        platform: Platform points P_i in {P} [m], shape (n, d); pairwise distinct.
        pose_space: "planar" (n = 3) or "spatial" (n = 6).
        actuators: Actuator kind of every leg; "leg" (A_i = B_i, ℓ_i = q_i).
        characteristic_length: ℓ_c [m] that divides the rotation columns of J_i to make them dimensionless.
            Default: the largest distance from the platform origin to a P_i.
        singular_tolerance: Hadamard ratio of the homogenised J_x below which inverting it raises
            ``SingularConfigurationError``. Default 1e-12.
        check_architecture: Refuse an architecture-singular design (J_x singular at every pose), detected
            by the conditioning at random poses around the platform's home. Default True.
    """

    def __init__(
        self,
        base: Any,
        platform: Any,
        *,
        pose_space: str = "spatial",
        actuators: str = "leg",
        characteristic_length: float | None = None,
        singular_tolerance: float = 1e-12,
        check_architecture: bool = True,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        if pose_space not in POSE_SPACES:
            raise ValueError(f"pose_space must be one of {sorted(POSE_SPACES)}, got {pose_space!r}")
        if actuators not in ACTUATOR_KINDS:
            raise ValueError(f"actuators must be one of {list(ACTUATOR_KINDS)}, got {actuators!r}")
        space = POSE_SPACES[pose_space]
        n, d = space.n_pose, space.point_dim
        B = point_set("base anchors", base, n, d)
        P = point_set("platform points", platform, n, d)
        check_distinct("base anchors", B)
        check_distinct("platform points", P)
        if characteristic_length is None:
            characteristic_length = float(np.max(np.linalg.norm(P, axis=1)))
            if characteristic_length <= 0:  # pragma: no cover - excluded by distinct points
                raise ValueError("platform points are all at the origin; give characteristic_length")
        l_c = positive_scalar("characteristic_length", characteristic_length)
        tol = positive_scalar("singular_tolerance", singular_tolerance)
        super().__init__(pose_scale=space.pose_scale(l_c), singular_tolerance=tol)
        self._space = space
        self._actuators = actuators
        self._B = B
        self._P = P
        self._l_c = l_c
        self.n_actuators = n
        self.n_pose = n
        self.n_constraints = n
        self.x_description = space.x_description
        self.q_description = f"leg lengths (q_1, …, q_{n}) [m]"
        if check_architecture:
            self._check_architecture()

    # -- geometry ---------------------------------------------------------------------------------

    @property
    def pose_space(self) -> PoseSpace:
        """The pose space (planar or spatial)."""
        return self._space

    @property
    def actuators(self) -> str:
        """The actuator kind of every leg ("leg")."""
        return self._actuators

    @property
    def base(self) -> FloatArray:
        """Anchors B_i in {B} [m], shape (n, d), read-only."""
        return self._B

    @property
    def platform(self) -> FloatArray:
        """Platform points P_i in {P} [m], shape (n, d), read-only."""
        return self._P

    @property
    def characteristic_length(self) -> float:
        """ℓ_c [m], the length that makes rotations commensurate with translations."""
        return self._l_c

    def home_pose(self) -> FloatArray:
        """A pose where the platform is centred over the base anchors, unrotated, shape (m,).

        Planar: the centroid of the base anchors, φ = 0. Spatial: above the anchors' centroid at a height
        equal to the base's mean radius, r = 0.
        """
        centre = self._B.mean(axis=0)
        if self._space.name == "planar":
            return np.array([centre[0], centre[1], 0.0])
        radius = float(np.mean(np.linalg.norm(self._B - centre, axis=1)))
        return np.array([centre[0], centre[1], centre[2] + radius, 0.0, 0.0, 0.0])

    def _check_architecture(self) -> None:
        """Refuse a design whose J_x is singular at every pose (an *architecture singularity*)."""
        rng = np.random.default_rng(0)
        home = self.home_pose()
        spread = np.full(self.n_pose, 0.1 * self._l_c)  # [m] for translations
        spread[list(self._space.rotation_columns)] = 0.3  # [rad] for rotations
        x = home + rng.uniform(-1.0, 1.0, size=(32, self.n_pose)) * spread
        q = self._inverse_kinematics(x)
        if not np.all(q > 0):  # pragma: no cover - a leg of zero length at the home pose
            return
        k = self.inverse_condition_number(q, x, validate=False)
        if float(np.max(k)) < 1e-9:
            raise ValueError(
                "architecture-singular design: J_x is singular at every one of 32 random poses around the home "
                f"pose {home.tolist()} (largest inverse condition number {float(np.max(k)):.3g}); "
                "for example, similar base and platform hexagons with legs joining corresponding vertices"
            )

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        return (
            f"{type(self).__name__}(base={self._B.tolist()}, platform={self._P.tolist()}, "
            f"pose_space={self._space.name!r}, characteristic_length={self._l_c!r}, "
            f"singular_tolerance={self.singular_tolerance!r})"
        )

    def __eq__(self, other: object) -> bool:
        """Mechanisms are equal when their kind, geometry and tolerances are."""
        if not isinstance(other, DistanceConstraintMechanism):
            return NotImplemented
        return (
            type(self) is type(other)
            and self._space.name == other._space.name
            and self._actuators == other._actuators
            and np.array_equal(self._B, other._B)
            and np.array_equal(self._P, other._P)
            and self._l_c == other._l_c
            and self.singular_tolerance == other.singular_tolerance
        )

    def __hash__(self) -> int:
        """Hash of the geometry, consistent with ``__eq__``."""
        return hash((self._space.name, self._B.tobytes(), self._P.tobytes(), self._l_c, self.singular_tolerance))

    def rotation_matrix(self, x: Any, *, validate: bool = True) -> FloatArray:
        """Rotation R of {P} in {B}.

        Args:
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check shape and values.

        Returns:
            R, shape (..., d, d).
        """
        if validate:
            x = self._x(x)
        return self._space.rotation(x)

    def _rotated_platform(self, x: FloatArray) -> FloatArray:
        """R P_i in {B} axes, shape (..., n, d)."""
        return np.einsum("...jk,ik->...ij", self._space.rotation(x), self._P)

    def platform_points_in_base(self, x: Any, *, validate: bool = True) -> FloatArray:
        """Platform points in {B}: p + R P_i.

        Args:
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check shape and values.

        Returns:
            Points [m] in {B}, shape (..., n, d); row i is platform point i.
        """
        if validate:
            x = self._x(x)
        return self._space.position(x)[..., None, :] + self._rotated_platform(x)

    def leg_vectors(self, x: Any, *, validate: bool = True) -> FloatArray:
        """Leg vectors d_i = p + R P_i − B_i in {B}.

        Args:
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check shape and values.

        Returns:
            d [m], shape (..., n, d); row i is leg i.
        """
        return self.platform_points_in_base(x, validate=validate) - self._B

    def retract(self, x: Any, step: Any, *, validate: bool = True) -> FloatArray:
        """Move poses by twist steps on the pose space's group (see ``PoseSpace.retract``).

        Args:
            x: Poses, shape (..., m).
            step: Steps (δp [m], δθ [rad]) in twist coordinates, shape (..., m).
            validate: Check shapes and values.

        Returns:
            Poses, shape (..., m).
        """
        if validate:
            x, step = self._x(x), self._x(step, "step")
        return self._space.retract(x, step)

    def pose_difference(self, x: Any, y: Any, *, validate: bool = True) -> FloatArray:
        """The twist step from y to x (see ``PoseSpace.difference``).

        Args:
            x: Poses, shape (..., m).
            y: Poses, shape (..., m).
            validate: Check shapes and values.

        Returns:
            Steps (δp [m], δθ [rad]), shape (..., m).
        """
        if validate:
            x, y = self._x(x), self._x(y, "y")
        return self._space.difference(x, y)

    # -- the constraint-level math ----------------------------------------------------------------

    def _check_actuators(self, q: FloatArray) -> None:
        if q.size and not q.min() > 0:
            raise ValueError(f"leg lengths q must be > 0 [m], got minimum {float(np.min(q))!r}")

    def _retract(self, x: FloatArray, step: FloatArray) -> FloatArray:
        return self._space.retract(x, step)

    def _constraints(self, q: FloatArray, x: FloatArray) -> FloatArray:
        d = self.leg_vectors(x, validate=False)
        return np.einsum("...ij,...ij->...i", d, d) - q * q

    def _jacobian_x(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(J_x, d): J_x of shape (..., n, m) with row i = 2 (d_iᵀ, ((R P_i) × d_i)ᵀ); d of shape (..., n, d)."""
        RP = self._rotated_platform(x)
        d = self._space.position(x)[..., None, :] + RP - self._B
        moment = _cross(RP, d)
        if moment.ndim == d.ndim - 1:
            moment = moment[..., None]
        return 2.0 * np.concatenate([d, moment], axis=-1), d

    def _newton_terms(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        J_x, d = self._jacobian_x(x)
        return np.einsum("...ij,...ij->...i", d, d) - q * q, J_x

    def _jacobians(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        J_x, _ = self._jacobian_x(x)
        n = self.n_actuators
        shape = np.broadcast_shapes(q.shape[:-1], x.shape[:-1]) + (n, n)
        J_q = np.zeros(shape)
        np.einsum("...ii->...i", J_q)[...] = -2.0 * q  # J_q = −2 diag(q)
        return J_q, np.broadcast_to(J_x, shape)

    def _inverse_kinematics(self, x: FloatArray) -> FloatArray:
        return np.linalg.norm(self.leg_vectors(x, validate=False), axis=-1)
