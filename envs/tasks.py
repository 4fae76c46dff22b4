"""Batched sampling of fair starts, targets and reference trajectories from the certified workspace."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from envs import kernels
from envs.core import EnvParams, Reference, batch3
from envs.workspace import WorkspaceMap

__all__ = ["is_safe", "sample_reach", "sample_track", "segment_min_condition"]

#: Points checked along a straight start → target segment for hard pairs (ends included).
SEGMENT_POINTS = 33


def is_safe(params: EnvParams, workspace: WorkspaceMap, x: np.ndarray) -> np.ndarray:
    """Whether poses are in a sampled safe region (bounds and strokes with margins, k ≥ k_safe).

    Inside the pose bounds and the stroke limits, each with its margin, k ≥ k_safe, and in a component
    large enough to sample from. Computed by the compiled kernel ``envs.kernels.safe_batch``.

    Args:
        params: Environment constants.
        workspace: The certified grid.
        x: Poses (x [m], y [m], φ [rad]), shape (M, 3).

    Returns:
        Boolean array, shape (M,); False for a non-finite pose.
    """
    return kernels.safe_batch(params.packed, workspace.packed, batch3(x))


def segment_min_condition(
    params: EnvParams, start: np.ndarray, target: np.ndarray, n: int = SEGMENT_POINTS
) -> np.ndarray:
    """Smallest inverse condition number along the straight line start → target in pose space.

    Args:
        params: Environment constants (the robot).
        start: Poses, shape (M, 3).
        target: Poses, shape (M, 3).
        n: Points sampled along each segment, ends included (≥ 2).

    Returns:
        min k along each segment, shape (M,).
    """
    start, target = batch3(start), batch3(target)
    if start.shape != target.shape:
        raise ValueError(f"start and target must have the same shape, got {start.shape} and {target.shape}")
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n must be an integer ≥ 2, got {n!r}")
    return kernels.segment_batch(params.packed, start, target, int(n))


def sample_reach(
    params: EnvParams,
    workspace: WorkspaceMap,
    rng: np.random.Generator | Sequence[np.random.Generator],
    n: int,
    hard: bool,
    min_distance: float = 0.1,
    start: np.ndarray | None = None,
    target: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Starts and targets in the same safe region (so a singularity-free path joins them).

    Each pose is a random node of a region (regions drawn in proportion to their size) jittered within
    its grid cell, kept if it is safe (``is_safe``) and still in that region. Standard pairs are at
    least ``min_distance`` apart in (x, y, ℓ_c φ). Hard pairs are also such that the straight line
    between them in pose space dips below ``hard_threshold``: a straight-line controller meets the
    ill-conditioned zone, a detour inside the region does not. A given ``start`` (or ``target``) is
    kept and the other end is drawn from its region under the same conditions. The rejection loop is
    the compiled kernel ``envs.kernels.sample_reach_batch``, drawing from ``rng`` exactly the numbers
    ``rng.random()`` would.

    Args:
        params: Environment constants.
        workspace: The certified grid.
        rng: Random generator (the env's ``np_random``) that draws every pair in turn, or a sequence of
            n generators, pair i drawn from the i-th (a vector env's sub-environments, in one call).
        n: Number of pairs.
        hard: Whether to sample hard pairs.
        min_distance: Smallest start–target distance [m].
        start: A fixed safe start pose, shape (3,), or None.
        target: A fixed safe target pose, shape (3,), or None (not both given).

    Returns:
        (starts (n, 3), targets (n, 3)) [m, m, rad].

    Raises:
        RuntimeError: If no such pair is found (for example no hard target for a given start).
    """
    if start is not None and target is not None:
        raise ValueError("give a start or a target to keep, not both")
    kind, fixed = (1, start) if start is not None else ((2, target) if target is not None else (0, (0.0, 0.0, 0.0)))
    streams = _streams(rng, n)
    pairs = kernels.sample_reach_batch(
        params.packed, workspace.packed, streams, int(n), bool(hard), float(min_distance), kind, fixed, SEGMENT_POINTS
    )
    if pairs is None:
        what = "hard " if hard else ""
        raise RuntimeError(f"could not sample {what}start/target pairs for this geometry, thresholds and poses")
    return pairs


def sample_track(
    params: EnvParams,
    workspace: WorkspaceMap,
    rng: np.random.Generator | Sequence[np.random.Generator],
    n: int,
    radius_range: tuple[float, float] = (0.05, 0.15),
    amplitude_range: tuple[float, float] = (0.0, 0.4),
) -> Reference:
    """Reference trajectories that lie entirely in one safe region.

    Each reference is a circle of radius r in (x, y) travelled once per ``track_period`` with φ
    oscillating by ±a around c_φ; its pose at every control step of a period (the poses the
    environment visits) is safe and in the same region as its centre.

    Args:
        params: Environment constants.
        workspace: The certified grid.
        rng: Random generator that draws every reference in turn, or a sequence of n generators
            (reference i drawn from the i-th).
        n: Number of references.
        radius_range: Range of r [m].
        amplitude_range: Range of a [rad].

    Returns:
        The references (its values at t = 0 are the starting poses).
    """
    n_check = int(np.ceil(params.track_period / params.dt))
    found = kernels.sample_track_batch(
        params.packed, workspace.packed, _streams(rng, n), int(n), radius_range, amplitude_range, n_check
    )
    if found is None:
        raise RuntimeError("could not sample reference trajectories inside one safe region")
    center, radius, phase, amplitude = found
    return Reference(center=center, radius=radius, phase=phase, amplitude=amplitude)


def _streams(rng: np.random.Generator | Sequence[np.random.Generator], n: int) -> np.ndarray:
    """The kernels' random streams (``kernels.random_streams``) of one generator or of n of them."""
    if isinstance(rng, np.random.Generator):
        return kernels.random_streams((rng,))
    if isinstance(rng, Sequence) and not isinstance(rng, (str, bytes)):
        if len(rng) != n:
            raise ValueError(f"rng must be a Generator or a sequence of n={n} Generators, got {len(rng)}")
        return kernels.random_streams(rng)
    raise TypeError(f"rng must be a numpy.random.Generator or a sequence of them, got {type(rng).__name__}")
