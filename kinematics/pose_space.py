"""Pose spaces of the distance-constraint family: how a pose x places the platform (p, R) and moves."""

from __future__ import annotations

from typing import Any

import numpy as np

from kinematics._validation import FloatArray

__all__ = ["POSE_SPACES", "PoseSpace"]


class PoseSpace:
    """How a pose x parametrises the platform's position p and rotation R, and how it moves.

    Attributes:
        name: "planar", "spatial" or "translational".
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
        if self.name == "translational":
            return np.broadcast_to(np.eye(3), x.shape[:-1] + (3, 3))
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
        if self.name != "spatial":
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
        if self.name != "spatial":
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
    "translational": PoseSpace("translational", 3, 3, (), "a position (p_x, p_y, p_z) [m]"),
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
