"""The distance-constraint family: Φ_i = ‖p + R P_i − A_i(q_i)‖² − ℓ_i(q_i)², one class for every member.

Almost every parallel robot in use keeps, for each leg i, a platform point P_i at a distance ℓ_i(q_i) from
an anchor A_i(q_i) that its actuator positions. A member of the family is *data*: its pose space, the kind
of its actuators and its geometry. This module holds the math once for all of them:

Pose spaces (``POSE_SPACES``)
    ``planar``   x = (x [m], y [m], φ [rad]); points are 2-D; R(φ) the rotation by φ; the velocity is ẋ.
    ``translational``  x = p = (p_x, p_y, p_z) [m], R = I (the Delta's travelling plate); points are 3-D.
    ``spatial``  x = (p_x, p_y, p_z [m], r_x, r_y, r_z [rad]) with r the rotation vector, R = exp([r]×)
                 (SciPy's ``Rotation.from_rotvec`` convention); points are 3-D. The velocity is the platform
                 twist (v, ω) in {B}: v the velocity of the origin of {P}, ω the angular velocity with
                 Ṙ = [ω]× R. J_x, J_f and J_i refer to the twist, not to ṙ, and a pose is updated on the
                 rotation group, R ← exp([δθ]×) R (``retract``), never through Euler angles.

Actuator kinds (``ACTUATOR_KINDS``), leg by leg
    ``leg``      A_i = B_i, ℓ_i = q_i [m]: an extensible leg (3-RPR, 6-UPS Stewart–Gough).
    ``crank``    A_i = B_i + a_i (cos q_i u_i + sin q_i v_i), ℓ_i = l_i: a motor at B_i turns an arm of length
                 a_i in the plane of the orthonormal u_i, v_i, and a link of length l_i joins its tip (the
                 elbow) to P_i; q_i [rad] (3-RRR, Delta's 3-RUS, 6-RUS).
    ``slider``   A_i = B_i + q_i e_i, ℓ_i = l_i: a carriage at q_i [m] along a rail of unit direction e_i,
                 and a link of length l_i to P_i (3-PRR, linear Delta, Hexaglide).

With d_i = p + R P_i − A_i(q_i) (the link vector, from the anchor to the platform point):

    Φ_i = d_iᵀ d_i − ℓ_i²,   J_q = −2 diag(d_iᵀ A_i′ + ℓ_i ℓ_i′),   row i of J_x = 2 (d_iᵀ, ((R P_i) × d_i)ᵀ)

(planar: the cross product is its z component, so row i = 2 (d_ix, d_iy, (R P_i)_x d_iy − (R P_i)_y d_ix),
the lesson's §5.2; translational: row i = 2 d_iᵀ). For a leg, A_i′ = 0 and ℓ_i′ = 1, so J_q = −2 diag(q).
Two singularities (Gosselin & Angeles 1990), each with a homogeneous measure in [0, 1]:

* Type II (J_x singular): ``inverse_condition_number``, σ_min/σ_max of the *link Jacobian*, whose rows are
  the links' unit Plücker lines (u_i, (R P_i) × u_i / ℓ_c), u_i = d_i / ℓ_i; for legs it is J_i diag(pose_scale).
* Type I (J_q singular: a crank's link in line with its arm, a slider's link square to its rail):
  ``actuator_condition_number``, min_i |d_iᵀ A_i′ + ℓ_i ℓ_i′| / (ℓ_i ‖(A_i′, ℓ_i′)‖), the cosine of the angle
  between the link and the direction the actuator moves its anchor; 1 for a leg.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics._validation import FloatArray, check_distinct, point_set, positive_scalar
from kinematics.actuation import ACTUATOR_KINDS, leg_actuation
from kinematics.family_singularities import FamilySingularities
from kinematics.pose_space import POSE_SPACES, PoseSpace, _cross

__all__ = ["ACTUATOR_KINDS", "POSE_SPACES", "DistanceConstraintMechanism", "PoseSpace"]


def load_mechanism(path: Any) -> DistanceConstraintMechanism:
    """A mechanism from a JSON file of its geometry (``DistanceConstraintMechanism.from_dict``'s keys).

    Raises:
        FileNotFoundError: If there is no such file.
        ValueError: If the file is not JSON or its data is refused (the message names the file).
    """
    import json
    from pathlib import Path

    file = Path(path)
    try:
        data = json.loads(file.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{file}: not a JSON file ({exc})") from None
    try:
        return DistanceConstraintMechanism.from_dict(data)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{file}: {exc}") from None


class DistanceConstraintMechanism(FamilySingularities):
    """A fully parallel robot of the distance-constraint family, given by its data alone.

    Φ_i(q, x) = ‖p + R(x) P_i − A_i(q_i)‖² − ℓ_i(q_i)², i = 1..n, with n = m actuators (see the module
    docstring for the pose spaces and actuator kinds). Every method of ``ParallelMechanism`` (J_f, J_i,
    forward kinematics on the rotation group, DOF, mobility, statics, conditioning) works unchanged; the
    family adds the Type I measures (``actuator_condition_number``, ``actuator_mobility``).

    Args:
        base: Anchors B_i in {B} [m], shape (n, d) with d = 2 (planar) or 3 (spatial, translational); pairwise
            distinct. For a crank the motor's axis point, for a slider the rail's origin (q_i = 0).
        platform: Platform points P_i in {P} [m], shape (n, d); pairwise distinct.
        pose_space: "planar" (n = 3), "spatial" (n = 6) or "translational" (n = 3).
        actuators: Actuator kind of every leg, "leg", "crank" or "slider", or a sequence of n kinds.
        link_lengths: l_i [m] of the crank and slider legs, a number or shape (n,) (ignored for legs).
        crank_radii: a_i [m] of the crank legs, a number or shape (n,) (ignored for other kinds).
        crank_axes: (u_i, v_i) of the crank legs, orthonormal, shape (2, d) or (n, 2, d); the arm points
            along u_i at q_i = 0 and turns towards v_i. Default for planar robots: u = x̂, v = ŷ.
        rails: e_i of the slider legs, unit, shape (d,) or (n, d).
        branches: +1 or −1 for each crank or slider leg, the branch of the closed-form inverse kinematics
            (a crank's elbow on one side of the line from its motor to P_i or the other; the larger or
            smaller of a slider's two positions). Default +1.
        home: The pose ``home_pose`` returns, shape (m,) (default: centred over the base, see there).
        characteristic_length: ℓ_c [m] that divides the rotation columns of J_i to make them dimensionless.
            Default: the largest distance from the platform origin to a P_i.
        singular_tolerance: Hadamard ratio of the homogenised J_x below which inverting it raises
            ``SingularConfigurationError``; the same bound on the Type I measure for J_i. Default 1e-12.
        check_architecture: Refuse an architecture-singular design (J_x singular at every pose), detected
            by the conditioning at random poses around the home pose. Default True.
    """

    def __init__(
        self,
        base: Any,
        platform: Any,
        *,
        pose_space: str = "spatial",
        actuators: Any = "leg",
        link_lengths: Any = None,
        crank_radii: Any = None,
        crank_axes: Any = None,
        rails: Any = None,
        branches: Any = None,
        home: Any = None,
        characteristic_length: float | None = None,
        singular_tolerance: float = 1e-12,
        check_architecture: bool = True,
    ) -> None:
        """Validate and store the geometry (see the class docstring for the arguments)."""
        if pose_space not in POSE_SPACES:
            raise ValueError(f"pose_space must be one of {sorted(POSE_SPACES)}, got {pose_space!r}")
        space = POSE_SPACES[pose_space]
        n, d = space.n_pose, space.point_dim
        kinds = (actuators,) * n if isinstance(actuators, str) else tuple(actuators)
        if len(kinds) != n or any(kind not in ACTUATOR_KINDS for kind in kinds):
            raise ValueError(
                f"actuators must be one of {list(ACTUATOR_KINDS)} or a sequence of {n} of them, got {actuators!r}"
            )
        B = point_set("base anchors", base, n, d)
        P = point_set("platform points", platform, n, d)
        check_distinct("base anchors", B)
        check_distinct("platform points", P)
        if characteristic_length is None:
            characteristic_length = float(np.max(np.linalg.norm(P, axis=1))) if space.rotation_columns else 1.0
            if characteristic_length <= 0:  # pragma: no cover - excluded by distinct points
                raise ValueError("platform points are all at the origin; give characteristic_length")
        l_c = positive_scalar("characteristic_length", characteristic_length)
        tol = positive_scalar("singular_tolerance", singular_tolerance)
        super().__init__(pose_scale=space.pose_scale(l_c), singular_tolerance=tol)
        self._space = space
        self._kinds = kinds
        self._actuators = kinds[0] if len(set(kinds)) == 1 else kinds
        self._all_legs = all(kind == "leg" for kind in kinds)
        self._B = B
        self._P = P
        self._l_c = l_c
        self.n_actuators = n
        self.n_pose = n
        self.n_constraints = n
        self.x_description = space.x_description
        actuation = leg_actuation(kinds, d, link_lengths, crank_radii, crank_axes, rails, branches)
        self._a, self._U, self._V, self._E = actuation.crank_radii, actuation.u, actuation.v, actuation.rails
        self._lam, self._ell, self._branch = actuation.length_rate, actuation.link_lengths, actuation.branches
        self.q_description = actuation.q_description
        self._home = None if home is None else self._x(np.array(home, dtype=np.float64), "home")
        if self._home is not None:
            self._home.setflags(write=False)
        if check_architecture:
            self._check_architecture()

    # -- geometry ---------------------------------------------------------------------------------

    @property
    def pose_space(self) -> PoseSpace:
        """The pose space (planar, spatial or translational)."""
        return self._space

    @property
    def actuators(self) -> Any:
        """The actuator kind of every leg ("leg", "crank" or "slider"), or the tuple of kinds if they differ."""
        return self._actuators

    @property
    def actuator_kinds(self) -> tuple[str, ...]:
        """The actuator kind of each leg, length n."""
        return self._kinds

    @property
    def base(self) -> FloatArray:
        """Anchors B_i in {B} [m], shape (n, d), read-only."""
        return self._B

    @property
    def platform(self) -> FloatArray:
        """Platform points P_i in {P} [m], shape (n, d), read-only."""
        return self._P

    @property
    def link_lengths(self) -> FloatArray:
        """l_i [m] of the crank and slider legs (0 for legs), shape (n,), read-only."""
        return self._ell

    @property
    def crank_radii(self) -> FloatArray:
        """a_i [m] of the crank legs (0 for other kinds), shape (n,), read-only."""
        return self._a

    @property
    def crank_axes(self) -> FloatArray:
        """(u_i, v_i) of the crank legs (zero for other kinds), shape (n, 2, d)."""
        return np.stack([self._U, self._V], axis=1)

    @property
    def rails(self) -> FloatArray:
        """e_i of the slider legs (zero for other kinds), shape (n, d), read-only."""
        return self._E

    @property
    def branches(self) -> FloatArray:
        """The inverse-kinematics branch (+1 or −1) of each leg, shape (n,), read-only."""
        return self._branch

    @property
    def characteristic_length(self) -> float:
        """ℓ_c [m], the length that makes rotations commensurate with translations."""
        return self._l_c

    def home_pose(self) -> FloatArray:
        """A pose at the centre of the workspace, shape (m,).

        The ``home`` given to the constructor if any; else, planar: the centroid of the base anchors, φ = 0;
        spatial: above the anchors' centroid at a height equal to the base's mean radius, r = 0;
        translational: below the anchors' centroid by the base's mean radius.
        """
        if self._home is not None:
            return self._home.copy()
        centre = self._B.mean(axis=0)
        if self._space.name == "planar":
            return np.array([centre[0], centre[1], 0.0])
        radius = float(np.mean(np.linalg.norm(self._B - centre, axis=1)))
        if self._space.name == "translational":
            return np.array([centre[0], centre[1], centre[2] - radius])
        return np.array([centre[0], centre[1], centre[2] + radius, 0.0, 0.0, 0.0])

    def to_mjcf(self, inertia: Any = None, **options: Any) -> str:
        """An MJCF model of the robot for MuJoCo: ``kinematics.mjcf.to_mjcf(self, inertia, **options)``."""
        from kinematics.mjcf import to_mjcf

        return to_mjcf(self, inertia, **options)

    def __repr__(self) -> str:
        """Geometry in a form that can be pasted back."""
        extra = ""
        if not self._all_legs:
            extra = f", actuators={self._actuators!r}, link_lengths={self._ell.tolist()}"
            if "crank" in self._kinds:
                extra += f", crank_radii={self._a.tolist()}, crank_axes={self.crank_axes.tolist()}"
            if "slider" in self._kinds:
                extra += f", rails={self._E.tolist()}"
            extra += f", branches={self._branch.tolist()}"
        if self._home is not None:
            extra += f", home={self._home.tolist()}"
        return (
            f"{type(self).__name__}(base={self._B.tolist()}, platform={self._P.tolist()}, "
            f"pose_space={self._space.name!r}{extra}, characteristic_length={self._l_c!r}, "
            f"singular_tolerance={self.singular_tolerance!r})"
        )

    def to_dict(self) -> dict[str, Any]:
        """The geometry as plain data (lists, numbers, strings): ``from_dict`` and JSON read it back.

        Only what the kind of each leg needs is written (link lengths for cranks and sliders, radii and axes for
        cranks, rails for sliders, branches for both).
        """
        data: dict[str, Any] = {
            "pose_space": self._space.name,
            "base": self._B.tolist(),
            "platform": self._P.tolist(),
            "actuators": list(self._kinds),
        }
        if not self._all_legs:
            data["link_lengths"] = self._ell.tolist()
            data["branches"] = self._branch.tolist()
        if "crank" in self._kinds:
            data["crank_radii"] = self._a.tolist()
            data["crank_axes"] = self.crank_axes.tolist()
        if "slider" in self._kinds:
            data["rails"] = self._E.tolist()
        if self._home is not None:
            data["home"] = self._home.tolist()
        data["characteristic_length"] = self._l_c
        return data

    @classmethod
    def from_dict(cls, data: Any) -> DistanceConstraintMechanism:
        """A mechanism from plain data (a ``to_dict`` output, or a JSON object with the constructor's arguments).

        Raises:
            TypeError: If ``data`` is not a mapping.
            ValueError: On an unknown key (naming the valid ones) or a value the constructor refuses.
        """
        if not isinstance(data, dict):
            raise TypeError(f"a robot's data must be a mapping of constructor arguments, got {type(data).__name__}")
        valid = (
            "base", "platform", "pose_space", "actuators", "link_lengths", "crank_radii", "crank_axes", "rails",
            "branches", "home", "characteristic_length", "singular_tolerance",
        )  # fmt: skip
        unknown = sorted(set(data) - set(valid))
        if unknown:
            raise ValueError(f"unknown key(s) {unknown} in a robot's data; valid keys are {list(valid)}")
        missing = [key for key in ("base", "platform") if key not in data]
        if missing:
            raise ValueError(f"a robot's data needs {missing}")
        args = dict(data)
        return DistanceConstraintMechanism(args.pop("base"), args.pop("platform"), **args)

    def _key(self) -> tuple[Any, ...]:
        arrays = (self._B, self._P, self._a, self._U, self._V, self._E, self._ell, self._branch)
        home = None if self._home is None else self._home.tobytes()
        return (self._space.name, self._kinds, *(a.tobytes() for a in arrays), home, self._l_c, self.singular_tolerance)

    def __eq__(self, other: object) -> bool:
        """Mechanisms are equal when their kind, geometry, actuation and tolerances are."""
        if not isinstance(other, DistanceConstraintMechanism):
            return NotImplemented
        return type(self) is type(other) and self._key() == other._key()

    def __hash__(self) -> int:
        """Hash of the geometry, consistent with ``__eq__``."""
        return hash(self._key())

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

    def anchors(self, q: Any, *, validate: bool = True) -> FloatArray:
        """Anchors A_i(q_i) in {B} [m]: B_i for a leg, the elbow for a crank, the carriage for a slider.

        Args:
            q: Actuator coordinates, shape (..., n).
            validate: Check shape and values.

        Returns:
            A [m], shape (..., n, d); row i is leg i's anchor.
        """
        if validate:
            q = self._q(q)
        return self._anchor_terms(q)[0]

    def link_vectors(self, q: Any, x: Any, *, validate: bool = True) -> FloatArray:
        """Link vectors d_i = p + R P_i − A_i(q_i) in {B} (for legs, ``leg_vectors``).

        Args:
            q: Actuator coordinates, shape (..., n).
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check inputs.

        Returns:
            d [m], shape (..., n, d); row i is link i.
        """
        q, x = self._qx(q, x, validate)
        return self._link_terms(q, x)[0]

    # -- the constraint-level math ----------------------------------------------------------------

    def _check_actuators(self, q: FloatArray) -> None:
        legs = q[..., self._lam == 1.0]
        if legs.size and not legs.min() > 0:
            raise ValueError(f"leg lengths q must be > 0 [m], got minimum {float(np.min(legs))!r}")

    def _retract(self, x: FloatArray, step: FloatArray) -> FloatArray:
        return self._space.retract(x, step)

    def _anchor_terms(self, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(A, A′, ℓ) at q: anchors and their derivatives dA_i/dq_i, shape (..., n, d); lengths ℓ_i, shape (..., n)."""
        c, s = np.cos(q)[..., None], np.sin(q)[..., None]
        a = self._a[:, None]
        A = self._B + a * (c * self._U + s * self._V) + q[..., None] * self._E
        dA = a * (c * self._V - s * self._U) + self._E
        return A, dA, self._lam * q + self._ell

    def _link_terms(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(d, A′, ℓ): link vectors d_i = p + R P_i − A_i(q_i), anchor derivatives and lengths."""
        A, dA, ell = self._anchor_terms(q)
        return self.platform_points_in_base(x, validate=False) - A, dA, ell

    def _constraints(self, q: FloatArray, x: FloatArray) -> FloatArray:
        if self._all_legs:
            d = self.leg_vectors(x, validate=False)
            return np.einsum("...ij,...ij->...i", d, d) - q * q
        d, _, ell = self._link_terms(q, x)
        return np.einsum("...ij,...ij->...i", d, d) - ell * ell

    def _rows_x(self, x: FloatArray, d: FloatArray) -> FloatArray:
        """J_x, shape (..., n, m), from the link vectors d: row i = 2 (d_iᵀ, ((R P_i) × d_i)ᵀ), translational 2 d_iᵀ."""
        if self._space.name == "translational":
            return 2.0 * d
        moment = _cross(self._rotated_platform(x), d)
        if moment.ndim == d.ndim - 1:
            moment = moment[..., None]
        return 2.0 * np.concatenate([d, moment], axis=-1)

    def _jacobian_x(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(J_x, d) of a leg-actuated robot (d = p + R P_i − B_i does not depend on q)."""
        RP = self._rotated_platform(x)
        d = self._space.position(x)[..., None, :] + RP - self._B
        return self._rows_x(x, d), d

    def _newton_terms(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self._all_legs:
            J_x, d = self._jacobian_x(x)
            return np.einsum("...ij,...ij->...i", d, d) - q * q, J_x
        d, _, ell = self._link_terms(q, x)
        return np.einsum("...ij,...ij->...i", d, d) - ell * ell, self._rows_x(x, d)

    def _jacobians(self, q: FloatArray, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        n = self.n_actuators
        if self._all_legs:
            J_x, _ = self._jacobian_x(x)
            diagonal = -2.0 * q  # J_q = −2 diag(q)
        else:
            d, dA, ell = self._link_terms(q, x)
            J_x = self._rows_x(x, d)
            diagonal = -2.0 * (np.einsum("...ij,...ij->...i", d, dA) + ell * self._lam)
        shape = np.broadcast_shapes(q.shape[:-1], x.shape[:-1]) + (n, n)
        J_q = np.zeros(shape)
        np.einsum("...ii->...i", J_q)[...] = diagonal
        return J_q, np.broadcast_to(J_x, shape[:-1] + (self.n_pose,))

    def _inverse_kinematics(self, x: FloatArray) -> FloatArray:
        """Closed-form q(x) leg by leg on the chosen branches; NaN for a leg that cannot reach its point."""
        w = self.leg_vectors(x, validate=False)  # P_w − B_i
        if self._all_legs:
            return np.linalg.norm(w, axis=-1)
        ww = np.einsum("...ij,...ij->...i", w, w)
        q = np.sqrt(ww)  # legs
        with np.errstate(invalid="ignore", divide="ignore"):
            # slider: ‖w − q e‖² = l²  ⇒  q = (w·e) ± √((w·e)² − ‖w‖² + l²)
            we = np.einsum("...ij,ij->...i", w, self._E)
            disc = we * we - ww + self._ell**2  # ≥ 0 where the link reaches the rail's line; 0 at a Type I pose
            disc = np.where(disc < 0.0, np.where(disc >= -1e-12 * (ww + self._ell**2), 0.0, np.nan), disc)
            slider_q = we + self._branch * np.sqrt(disc)
            # crank: (w·u) cos q + (w·v) sin q = (‖w‖² + a² − l²) / 2a  ⇒  q = atan2(w·v, w·u) ± acos(K / ρ)
            wu = np.einsum("...ij,ij->...i", w, self._U)
            wv = np.einsum("...ij,ij->...i", w, self._V)
            a = np.where(self._a > 0, self._a, 1.0)
            ratio = (ww + self._a**2 - self._ell**2) / (2.0 * a * np.hypot(wu, wv))
            # |ratio| = 1: crank and link in line (a Type I pose at the reach's edge), let rounding not lose it
            ratio = np.where(np.abs(ratio) <= 1.0 + 1e-12, np.clip(ratio, -1.0, 1.0), np.nan)
            crank_q = np.arctan2(wv, wu) + self._branch * np.arccos(ratio)
            crank_q = np.mod(crank_q + np.pi, 2.0 * np.pi) - np.pi  # in [−π, π)
        kinds = np.array(self._kinds)
        return np.where(kinds == "crank", crank_q, np.where(kinds == "slider", slider_q, q))

    def inverse_kinematics(self, x: Any, *, validate: bool = True) -> FloatArray:
        """Closed-form inverse kinematics q(x), leg by leg, on each crank's and slider's chosen ``branches``.

        Args:
            x: Platform pose of {P} in {B}, shape (..., m).
            validate: Check the pose and raise where a leg cannot reach it (else that q_i is NaN).

        Returns:
            q, shape (..., n) (crank angles in [−π, π)).

        Raises:
            ValueError: If ``validate`` and a crank or slider leg cannot reach its platform point.
        """
        if validate:
            x = self._x(x)
        q = self._inverse_kinematics(x)
        if validate and not np.isfinite(q).all():
            index = tuple(int(i) for i in np.argwhere(~np.isfinite(q))[0])
            leg = index[-1]
            raise ValueError(
                f"pose out of reach: leg {leg + 1} ({self._kinds[leg]}, link {float(self._ell[leg])!r} m) cannot "
                f"reach its platform point at pose {np.asarray(x)[index[:-1]].tolist()}"
            )
        return q
