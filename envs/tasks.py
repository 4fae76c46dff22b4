"""Batched sampling of fair starts, targets and reference trajectories from the certified workspace."""

from __future__ import annotations

import numpy as np

from envs.core import EnvParams, Reference
from envs.workspace import WorkspaceMap

__all__ = ["is_safe", "sample_reach", "sample_track", "segment_min_condition"]

#: Candidates drawn per rejection round (vectorised).
_BATCH = 256
#: Rejection rounds before giving up (each round draws ``_BATCH`` candidates per missing sample).
_MAX_ROUNDS = 200


def is_safe(params: EnvParams, workspace: WorkspaceMap, x: np.ndarray) -> np.ndarray:
    """Whether poses are in a sampled safe region (bounds and strokes with margins, k ≥ k_safe).

    Inside the pose bounds and the stroke limits, each with its margin, k ≥ k_safe, and in a component
    large enough to sample from.

    Args:
        params: Environment constants.
        workspace: The certified grid.
        x: Poses (x [m], y [m], φ [rad]), shape (M, 3).

    Returns:
        Boolean array, shape (M,).
    """
    spec = workspace.spec
    margin = np.asarray(spec.bounds_margin)
    inside = np.all((x >= np.asarray(spec.pose_low) + margin) & (x <= np.asarray(spec.pose_high) - margin), axis=-1)
    q = params.robot.inverse_kinematics(x, validate=False)
    lo, hi = spec.stroke_limits
    strokes_ok = (q.min(axis=-1) >= lo + spec.stroke_margin) & (q.max(axis=-1) <= hi - spec.stroke_margin)
    k = params.robot.inverse_condition_number(np.maximum(q, 1e-9), x, validate=False)
    in_region = np.isin(workspace.component_of(x), workspace.component_ids)
    return inside & strokes_ok & (k >= spec.safe_threshold) & in_region


def _sample_in_components(
    params: EnvParams, workspace: WorkspaceMap, rng: np.random.Generator, components: np.ndarray
) -> np.ndarray:
    """One safe pose in each given component: a random node jittered within its cell, shape (M, 3)."""
    out = np.empty((len(components), 3))
    todo = np.arange(len(components))
    cell = np.array(workspace.spec.cell)
    for _ in range(_MAX_ROUNDS):
        if todo.size == 0:
            return out
        comp = components[todo]
        nodes = np.empty((todo.size, 3))
        for c in np.unique(comp):
            flat = workspace.component_nodes[int(c)]
            pick = flat[rng.integers(0, flat.size, size=int(np.sum(comp == c)))]
            ijk = np.unravel_index(pick, workspace.labels.shape)
            nodes[comp == c] = np.stack([workspace.axes[a][ijk[a]] for a in range(3)], axis=-1)
        cand = nodes + rng.uniform(-0.5, 0.5, size=nodes.shape) * cell
        ok = is_safe(params, workspace, cand) & (workspace.component_of(cand) == comp)
        out[todo[ok]] = cand[ok]
        todo = todo[~ok]
    raise RuntimeError("could not sample safe poses; the safe regions are too thin for the grid")


def segment_min_condition(params: EnvParams, start: np.ndarray, target: np.ndarray, n: int = 33) -> np.ndarray:
    """Smallest inverse condition number along the straight line start → target in pose space.

    Args:
        params: Environment constants (the robot).
        start: Poses, shape (M, 3).
        target: Poses, shape (M, 3).
        n: Points sampled along each segment, ends included.

    Returns:
        min k along each segment, shape (M,).
    """
    s = np.linspace(0.0, 1.0, n)[None, :, None]
    points = start[:, None, :] + s * (target - start)[:, None, :]
    q = np.maximum(params.robot.inverse_kinematics(points, validate=False), 1e-9)
    return params.robot.inverse_condition_number(q, points, validate=False).min(axis=-1)


def sample_reach(
    params: EnvParams,
    workspace: WorkspaceMap,
    rng: np.random.Generator,
    n: int,
    hard: bool,
    min_distance: float = 0.1,
    start: np.ndarray | None = None,
    target: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Starts and targets in the same safe region (so a singularity-free path joins them).

    Standard pairs are at least ``min_distance`` apart in (x, y, ℓ_c φ). Hard pairs are also such that
    the straight line between them in pose space dips below ``hard_threshold``: a straight-line
    controller meets the ill-conditioned zone, a detour inside the region does not. A given ``start``
    (or ``target``) is kept and the other end is drawn from its region under the same conditions.

    Args:
        params: Environment constants.
        workspace: The certified grid.
        rng: Random generator (the env's ``np_random``).
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
    starts, targets = np.empty((n, 3)), np.empty((n, 3))
    fixed = start if start is not None else target
    todo = np.arange(n)
    for _ in range(_MAX_ROUNDS):
        if todo.size == 0:
            return starts, targets
        m = todo.size * (_BATCH // 8 if hard else 1)
        if fixed is None:
            comp = rng.choice(workspace.component_ids, size=m, p=workspace.component_weights)
            s = _sample_in_components(params, workspace, rng, comp)
            t = _sample_in_components(params, workspace, rng, comp)
        else:
            comp = np.full(m, workspace.component_of(np.asarray(fixed)))
            other = _sample_in_components(params, workspace, rng, comp)
            ends = np.broadcast_to(fixed, other.shape)
            s, t = (ends, other) if start is not None else (other, ends)
        ok = np.linalg.norm((t - s) * params.pose_metric, axis=-1) >= min_distance
        if hard:
            ok &= segment_min_condition(params, s, t) < params.hard_threshold
        good = np.flatnonzero(ok)[: todo.size]
        starts[todo[: good.size]] = s[good]
        targets[todo[: good.size]] = t[good]
        todo = todo[good.size :]
    kind = "hard " if hard else ""
    raise RuntimeError(f"could not sample {kind}start/target pairs for this geometry, thresholds and poses")


def sample_track(
    params: EnvParams,
    workspace: WorkspaceMap,
    rng: np.random.Generator,
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
        rng: Random generator.
        n: Number of references.
        radius_range: Range of r [m].
        amplitude_range: Range of a [rad].

    Returns:
        The references (its values at t = 0 are the starting poses).
    """
    center, radius = np.empty((n, 3)), np.empty(n)
    phase, amplitude = np.empty(n), np.empty(n)
    todo = np.arange(n)
    n_check = int(np.ceil(params.track_period / params.dt))
    omega_t = 2.0 * np.pi / params.track_period * params.dt * np.arange(n_check)
    for _ in range(_MAX_ROUNDS):
        if todo.size == 0:
            return Reference(center=center, radius=radius, phase=phase, amplitude=amplitude)
        m = todo.size * 8
        comp = rng.choice(workspace.component_ids, size=m, p=workspace.component_weights)
        c = _sample_in_components(params, workspace, rng, comp)
        r = rng.uniform(*radius_range, size=m)
        th = rng.uniform(-np.pi, np.pi, size=m)
        a = rng.uniform(*amplitude_range, size=m)
        angle = omega_t[None, :] + th[:, None]
        points = c[:, None, :] + np.stack(
            [r[:, None] * np.cos(angle), r[:, None] * np.sin(angle), a[:, None] * np.sin(omega_t)[None, :]],
            axis=-1,
        )
        ok = is_safe(params, workspace, points.reshape(-1, 3)).reshape(m, n_check).all(axis=-1)
        ok &= np.all(workspace.component_of(points) == comp[:, None], axis=-1)
        good = np.flatnonzero(ok)[: todo.size]
        dst = todo[: good.size]
        center[dst], radius[dst], phase[dst], amplitude[dst] = c[good], r[good], th[good], a[good]
        todo = todo[good.size :]
    raise RuntimeError("could not sample reference trajectories inside one safe region")
