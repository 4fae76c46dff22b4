"""Certified workspace of a planar parallel robot: a conditioning grid and its connected safe regions.

A pose is *safe* when every stroke lies inside its limits with a margin and the homogeneous inverse
condition number is at least the safe threshold. The safe set is sampled on a regular grid over the
pose bounds; face-adjacent safe nodes are joined, and the connected components of that graph are the
regions within which a start and a target may be paired: every component has a single sign of
det J_x (one working mode), and neighbouring nodes lie a fraction of a cell apart, so a path along safe
nodes never meets a Type II singularity (checked by ``tests/envs/test_workspace.py``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from envs.kernels import pack_workspace
from kinematics import Planar3RPR
from kinematics.linalg import determinant

__all__ = ["WorkspaceMap", "WorkspaceSpec", "certify_workspace"]


@dataclass(frozen=True)
class WorkspaceSpec:
    """What a workspace certification depends on (hashable, so results are cached per geometry).

    Attributes:
        robot: The mechanism.
        stroke_limits: (L_min, L_max) [m].
        pose_low: Lower pose bounds (x [m], y [m], φ [rad]).
        pose_high: Upper pose bounds (x [m], y [m], φ [rad]).
        safe_threshold: Inverse condition number a safe pose must reach.
        stroke_margin: Distance [m] a safe pose keeps from both stroke limits.
        bounds_margin: Distance (Δx [m], Δy [m], Δφ [rad]) a sampled pose keeps from the pose bounds.
        cell: Grid spacing (Δx [m], Δy [m], Δφ [rad]).
        min_component_fraction: Components smaller than this share of safe nodes are not sampled.
    """

    robot: Planar3RPR
    stroke_limits: tuple[float, float]
    pose_low: tuple[float, float, float]
    pose_high: tuple[float, float, float]
    safe_threshold: float
    stroke_margin: float = 0.02
    bounds_margin: tuple[float, float, float] = (0.05, 0.05, 0.1)
    cell: tuple[float, float, float] = (0.025, 0.025, 0.05)
    min_component_fraction: float = 0.02


@dataclass(frozen=True)
class WorkspaceMap:
    """The certified grid (read-only arrays).

    Attributes:
        spec: What it was computed from.
        axes: Grid coordinates along x [m], y [m], φ [rad]; shapes (n_x,), (n_y,), (n_φ,).
        inverse_condition: Homogeneous inverse condition number at every node, shape (n_x, n_y, n_φ).
        reachable: Strokes within limits (with margin) at every node, shape (n_x, n_y, n_φ).
        labels: Component id of every safe node (0 for unsafe ones), shape (n_x, n_y, n_φ).
        det_sign: sign(det J_x) at every node, shape (n_x, n_y, n_φ).
        component_ids: The ids of the components large enough to sample from, shape (c,).
        component_weights: Sampling probability of each of them (proportional to size), shape (c,).
    """

    spec: WorkspaceSpec
    axes: tuple[np.ndarray, np.ndarray, np.ndarray]
    inverse_condition: np.ndarray
    reachable: np.ndarray
    labels: np.ndarray
    det_sign: np.ndarray
    component_ids: np.ndarray
    component_weights: np.ndarray

    @property
    def nodes(self) -> np.ndarray:
        """Pose of every node, shape (n_x, n_y, n_φ, 3)."""
        return np.stack(np.meshgrid(*self.axes, indexing="ij"), axis=-1)

    @functools.cached_property
    def packed(self) -> tuple[np.ndarray, ...]:
        """The grid as the compiled sampling kernels read it (``envs.kernels.pack_workspace``)."""
        return pack_workspace(self)

    @functools.cached_property
    def component_nodes(self) -> dict[int, np.ndarray]:
        """Flat indices (into ``labels``) of the nodes of each sampled component."""
        flat = self.labels.ravel()
        return {int(c): np.flatnonzero(flat == c) for c in self.component_ids}

    def node_index(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Index of the grid node nearest to each pose (clipped to the grid).

        Args:
            x: Poses (x [m], y [m], φ [rad]), shape (..., 3).

        Returns:
            Three integer arrays of shape (...), one per axis.
        """
        idx = []
        for axis, values in enumerate(self.axes):
            step = values[1] - values[0]
            i = np.rint((x[..., axis] - values[0]) / step).astype(np.int64)
            idx.append(np.clip(i, 0, len(values) - 1))
        return idx[0], idx[1], idx[2]

    def component_of(self, x: np.ndarray) -> np.ndarray:
        """Component id of the node nearest to each pose (0: not in a safe region).

        Args:
            x: Poses (x [m], y [m], φ [rad]), shape (..., 3).

        Returns:
            Integer ids, shape (...).
        """
        return self.labels[self.node_index(x)]


@functools.lru_cache(maxsize=16)
def certify_workspace(spec: WorkspaceSpec) -> WorkspaceMap:
    """Grid the pose bounds, mark safe nodes and label their connected components (cached per spec).

    Args:
        spec: Geometry, limits, thresholds and grid spacing.

    Returns:
        The certified ``WorkspaceMap``.

    Raises:
        ValueError: If no safe region is large enough to sample starts and targets from.
    """
    robot = spec.robot
    axes = tuple(
        np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)
        for lo, hi, step in zip(spec.pose_low, spec.pose_high, spec.cell)
    )
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    q = robot.inverse_kinematics(nodes, validate=False)
    lo, hi = spec.stroke_limits
    reachable = (q.min(axis=-1) >= lo + spec.stroke_margin) & (q.max(axis=-1) <= hi - spec.stroke_margin)
    q_safe = np.maximum(q, 1e-9)  # a zero-length leg (Type I) is never reachable; keep J_q regular
    inverse_condition = robot.inverse_condition_number(q_safe, nodes, validate=False)
    _, J_x = robot.jacobians(q_safe, nodes, validate=False)
    det_sign = np.sign(determinant(J_x)).astype(np.int8)
    safe = reachable & (inverse_condition >= spec.safe_threshold)
    labels, count = ndimage.label(safe)  # face adjacency (6-connectivity)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    keep = np.flatnonzero(sizes >= spec.min_component_fraction * max(int(safe.sum()), 1)) + 1
    if keep.size == 0:
        raise ValueError(
            "no safe region to sample from: no pose within the bounds keeps every stroke in "
            f"{spec.stroke_limits} m and an inverse condition number ≥ {spec.safe_threshold}"
        )
    weights = sizes[keep - 1] / sizes[keep - 1].sum()
    for arr in (inverse_condition, reachable, labels, det_sign, keep, weights, *axes):
        arr.setflags(write=False)
    return WorkspaceMap(
        spec=spec,
        axes=axes,
        inverse_condition=inverse_condition,
        reachable=reachable,
        labels=labels,
        det_sign=det_sign,
        component_ids=keep,
        component_weights=weights,
    )
