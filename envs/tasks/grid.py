"""Certified workspace of a robot with three pose coordinates: a conditioning grid and its connected safe regions.

A pose is *safe* when every actuator coordinate lies inside its limits with a margin and the homogeneous
inverse condition number k is at least the safe threshold (for cranks and sliders, the actuator condition
number k_I also at least its own: safety = min(k, k_I · k_safe / k_I,safe) ≥ k_safe): the family's one
certificate, ``envs.tasks.certificate.safety_batch``, which the task samplers and the planner use too. The safe
set is sampled on a regular grid over the pose bounds (not the sampling box); face-adjacent safe nodes are joined,
and the connected components of that graph are the regions within which a start and a target may be paired
(``task_region="grid"`` of the family environments): every component has a single sign of det J_x (one working
mode), and neighbouring nodes lie a fraction of a cell apart, so a path along safe nodes never meets a singularity.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from envs.kernels import generic as fk
from envs.tasks.grid_kernels import pack_workspace
from kinematics import DistanceConstraintMechanism

__all__ = ["WorkspaceMap", "WorkspaceSpec", "certify_workspace", "restore_read_only"]


def restore_read_only(obj: object, state: dict[str, Any]) -> None:
    """Restore the pickled ``__dict__`` of a frozen dataclass of constants, its arrays read-only again.

    Unpickled arrays are writable, and the compiled kernels take read-only constants: a writable copy would be
    compiled anew (a second specialisation of every kernel it reaches, a minute of CPU on a cold cache).

    Args:
        obj: The instance being unpickled.
        state: Its pickled ``__dict__`` (fields and cached properties); arrays in tuples, lists and dicts too.
    """
    obj.__dict__.update(state)
    stack = list(state.values())
    while stack:
        value = stack.pop()
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
        elif isinstance(value, (tuple, list)):
            stack.extend(value)
        elif isinstance(value, dict):
            stack.extend(value.values())


@dataclass(frozen=True)
class WorkspaceSpec:
    """What a workspace certification depends on (hashable, so results are cached per geometry).

    Attributes:
        robot: The mechanism (three pose coordinates: planar (x, y, φ) or translational (x, y, z)).
        stroke_limits: (q_min, q_max) of every actuator [m, or rad for cranks].
        pose_low: Lower pose bounds, shape (3,) [m, rad].
        pose_high: Upper pose bounds, shape (3,) [m, rad].
        safe_threshold: k_safe, the inverse condition number a safe pose must reach.
        actuator_safe_threshold: k_I,safe, the actuator condition number a safe pose of cranks and sliders
            must reach (unused for legs).
        stroke_margin: Distance a safe pose keeps from both stroke limits [m, rad].
        cell: Grid spacing, shape (3,) [m, rad].
        min_component_fraction: Components smaller than this share of safe nodes are not sampled.
    """

    robot: DistanceConstraintMechanism
    stroke_limits: tuple[float, float]
    pose_low: tuple[float, float, float]
    pose_high: tuple[float, float, float]
    safe_threshold: float
    actuator_safe_threshold: float = 0.1
    stroke_margin: float = 0.02
    cell: tuple[float, float, float] = (0.025, 0.025, 0.05)
    min_component_fraction: float = 0.02

    def __setstate__(self, state: dict[str, Any]) -> None:
        restore_read_only(self, state)

    @functools.cached_property
    def constants(self) -> np.ndarray:
        """The certificate's packed constants (``envs.kernels.packing.pack_certificate``), read-only."""
        return fk.pack_certificate(
            self.robot, self.stroke_limits, self.stroke_margin, self.safe_threshold, self.actuator_safe_threshold
        )


@dataclass(frozen=True)
class WorkspaceMap:
    """The certified grid (read-only arrays).

    Attributes:
        spec: What it was computed from.
        axes: Grid coordinates along each pose coordinate; shapes (n_x,), (n_y,), (n_φ,).
        safety: The certificate at every node (``envs.tasks.certificate.safety_batch``: k, for cranks and sliders
            min(k, k_I k_safe / k_I,safe); −1 where a stroke leaves its limits less the margin), shape
            (n_x, n_y, n_φ).
        labels: Component id of every safe node (0 for unsafe ones), shape (n_x, n_y, n_φ).
        det_sign: sign(det J_x) at every node, shape (n_x, n_y, n_φ).
        component_ids: The ids of the components large enough to sample from, shape (c,).
        component_weights: Sampling probability of each of them (proportional to size), shape (c,).
    """

    spec: WorkspaceSpec
    axes: tuple[np.ndarray, np.ndarray, np.ndarray]
    safety: np.ndarray
    labels: np.ndarray
    det_sign: np.ndarray
    component_ids: np.ndarray
    component_weights: np.ndarray

    def __setstate__(self, state: dict[str, Any]) -> None:
        restore_read_only(self, state)

    @property
    def nodes(self) -> np.ndarray:
        """Pose of every node, shape (n_x, n_y, n_φ, 3)."""
        return np.stack(np.meshgrid(*self.axes, indexing="ij"), axis=-1)

    @functools.cached_property
    def packed(self) -> tuple[np.ndarray, ...]:
        """The grid as the compiled sampling kernels read it (``envs.tasks.grid_kernels.pack_workspace``)."""
        return pack_workspace(self)

    @functools.cached_property
    def component_nodes(self) -> dict[int, np.ndarray]:
        """Flat indices (into ``labels``) of the nodes of each sampled component."""
        flat = self.labels.ravel()
        nodes = {int(c): np.flatnonzero(flat == c) for c in self.component_ids}
        for arr in nodes.values():
            arr.setflags(write=False)
        return nodes

    def node_index(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Index of the grid node nearest to each pose (clipped to the grid).

        Args:
            x: Poses, shape (..., 3).

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
            x: Poses, shape (..., 3).

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
    if robot.n_pose != 3:
        raise ValueError(f"a certified grid needs a robot with 3 pose coordinates, got {robot.n_pose}")
    axes = tuple(
        np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)
        for lo, hi, step in zip(spec.pose_low, spec.pose_high, spec.cell)
    )
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    safety, sign = fk.safety_batch(spec.constants, nodes.reshape(-1, 3))
    safety = safety.reshape(nodes.shape[:-1])
    det_sign = sign.reshape(nodes.shape[:-1]).astype(np.int8)
    safe = safety >= spec.safe_threshold
    labels, count = ndimage.label(safe)  # face adjacency (6-connectivity)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    keep = np.flatnonzero(sizes >= spec.min_component_fraction * max(int(safe.sum()), 1)) + 1
    if keep.size == 0:
        raise ValueError(
            "no safe region to sample from: no pose within the bounds keeps every actuator in "
            f"{spec.stroke_limits} and an inverse condition number ≥ {spec.safe_threshold}"
        )
    weights = sizes[keep - 1] / sizes[keep - 1].sum()
    for arr in (safety, labels, det_sign, keep, weights, *axes):
        arr.setflags(write=False)
    return WorkspaceMap(
        spec=spec,
        axes=axes,
        safety=safety,
        labels=labels,
        det_sign=det_sign,
        component_ids=keep,
        component_weights=weights,
    )
