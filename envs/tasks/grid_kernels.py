"""Compiled task sampling on a certified grid (``envs.tasks.grid``): starts, targets and circles in one safe region.

A robot with three pose coordinates (planar or translational) may draw its tasks from the connected safe
regions of a grid over its pose bounds (``task_region="grid"``): start and target lie in one region, so a
singularity-free path between them is known without checking one. Each pose is a random node of a region
(regions drawn in proportion to their size) jittered within its cell, kept if it is safe (the family's
``_safe``: inside the sampling box, strokes within the limits less the margin, k ≥ k_safe and, for cranks and
sliders, k_I ≥ k_I,safe) and still in that region. Every draw comes from NumPy generators through
``envs.kernels.setup.random_streams``, so a generator's stream is the same whether NumPy or a kernel draws.

The packed grid (``pack_workspace``) is a tuple: (cell (3,), labels (n_0, n_1, n_2), sampled-label lookup,
component ids (c,), cumulative sampling weights (c,), the sampled components' node indices, their offsets
(c + 1,), axis 0, axis 1, axis 2).
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels import three
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _work
from envs.kernels.layout import C_DT, C_HARD, C_LC, C_LEGS, C_OMEGA, C_TRANSLATIONAL
from envs.kernels.packing import THREE
from envs.kernels.setup import _next_double, borrow, jit, keep_alive
from envs.tasks.certificate import _safe

__all__ = ["SAMPLER_TRIES", "SEGMENT_POINTS", "pack_workspace", "sample_circle_batch", "sample_reach_batch"]

drop_stale_caches(__file__)

#: Candidates a sampler may reject (per pose or pair) before it reports failure.
SAMPLER_TRIES = 6400
#: Points checked along the straight start → target segment of a crossing pair (ends included).
SEGMENT_POINTS = 33

_TWO_PI = 2.0 * math.pi


def pack_workspace(workspace) -> tuple:
    """A certified ``envs.tasks.grid.WorkspaceMap`` as the tuple of arrays the sampling kernels read (module doc)."""
    labels = np.ascontiguousarray(workspace.labels, dtype=np.int64)
    ids = np.asarray(workspace.component_ids, dtype=np.int64)
    sampled = np.zeros(int(labels.max()) + 1, dtype=np.bool_)
    sampled[ids] = True
    cumulative = np.cumsum(np.asarray(workspace.component_weights, dtype=np.float64))
    nodes = [np.asarray(workspace.component_nodes[int(i)], dtype=np.int64) for i in ids]
    offsets = np.concatenate([[0], np.cumsum([len(n) for n in nodes])]).astype(np.int64)
    axes = tuple(np.ascontiguousarray(a, dtype=np.float64) for a in workspace.axes)
    cell = np.asarray(workspace.spec.cell, dtype=np.float64)
    packed = (cell, labels, sampled, ids, cumulative, np.concatenate(nodes), offsets, *axes)
    for array in packed:
        array.setflags(write=False)
    return packed


@jit
def _node_index(values, v):
    """Index of the grid value nearest to v along one axis, clipped to the axis (``WorkspaceMap.node_index``)."""
    i = np.rint((v - values[0]) / (values[1] - values[0]))
    if not i > 0.0:  # also NaN
        return 0
    last = values.shape[0] - 1
    if i > last:
        return last
    return int(i)


@jit
def _label(ws, x):
    """Component id of the grid node nearest to the pose x (0: not in a safe region)."""
    return ws[1][_node_index(ws[7], x[0]), _node_index(ws[8], x[1]), _node_index(ws[9], x[2])]


@jit
def _grid_safe(c, ws, x, w, strokes):
    """Whether x is safe (the family's ``_safe``, in scalars) and its node lies in a sampled region."""
    if not _safe(THREE, c, x, w, strokes):
        return False
    return ws[2][_label(ws, x)]


@jit
def _pose_in_component(c, ws, fn, st, j, w, strokes, out):
    """A safe pose of sampled component j into out: a random node of it jittered within its cell; found?"""
    cell, labels, comp = ws[0], ws[1], ws[3][j]
    nodes, offsets = ws[5], ws[6]
    size = offsets[j + 1] - offsets[j]
    n1, n2 = labels.shape[1], labels.shape[2]
    for _ in range(SAMPLER_TRIES):
        flat = nodes[offsets[j] + min(int(_next_double(fn, st) * size), size - 1)]
        i0, rest = divmod(flat, n1 * n2)
        i1, i2 = divmod(rest, n2)
        out[0] = ws[7][i0] + (_next_double(fn, st) - 0.5) * cell[0]
        out[1] = ws[8][i1] + (_next_double(fn, st) - 0.5) * cell[1]
        out[2] = ws[9][i2] + (_next_double(fn, st) - 0.5) * cell[2]
        if _grid_safe(c, ws, out, w, strokes) and _label(ws, out) == comp:
            return True
    return False


@jit
def _choose_component(ws, fn, st):
    """Index of a sampled component, drawn with probability proportional to its size."""
    cumulative = ws[4]
    u = _next_double(fn, st) * cumulative[-1]
    for j in range(cumulative.shape[0] - 1):
        if u < cumulative[j]:
            return j
    return cumulative.shape[0] - 1


@jit
def _component_index(ws, x):
    """Index (into the sampled components) of the region of a pose, −1 if it is in none."""
    label = _label(ws, x)
    ids = ws[3]
    for j in range(ids.shape[0]):
        if ids[j] == label:
            return j
    return -1


@jit
def _straight_dips_below(c, start, target, n, threshold):
    """Whether k (Type II) < ``threshold`` at one of n points of the straight line start → target in pose space.

    Ends included; False where k is NaN at a point (a pose out of reach). k is proven ≥ ``threshold`` where it can
    be (``three.singularity``'s ``at_least``) and computed where not: the same answer as comparing the smallest k
    with the threshold. In scalars (``envs.kernels.three``): the grid holds robots with three pose coordinates only.
    """
    dips = False
    legs = c[C_LEGS] != 0.0
    for s in range(n):
        f = s / (n - 1)
        x0 = start[0] + f * (target[0] - start[0])
        x1 = start[1] + f * (target[1] - start[1])
        x2 = start[2] + f * (target[2] - start[2])
        q0, q1, q2 = three.inverse_kinematics(c, x0, x1, x2)
        if legs:  # a zero-length leg (Type I) keeps J_q regular, as the grid's certification does
            q0, q1, q2 = max(q0, 1e-9), max(q1, 1e-9), max(q2, 1e-9)
            anchors = three.leg_anchors(c, q0, q1, q2)
        else:
            anchors = three.anchors(c, q0, q1, q2)
        k, _, _ = three.singularity(c, anchors, three.rows(c, anchors, x0, x1, x2), threshold)
        if k != k:
            return False
        dips = dips or k < threshold
    return dips


@jit
def _distance(c, start, target):
    """‖(δp, ℓ_c δφ)‖ between two poses of three coordinates [m] (translational: ‖δp‖)."""
    d0, d1, d2 = target[0] - start[0], target[1] - start[1], target[2] - start[2]
    if c[C_TRANSLATIONAL] == 0.0:
        d2 = c[C_LC] * d2
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@jit
def _sample_reach(c, ws, streams, hard, min_distance, fixed_kind, fixed, o_start, o_target):
    """Fill o_start / o_target (M, 3) with pairs in one region; fixed_kind 1 (2) keeps the start (target) fixed.

    Standard pairs are at least ``min_distance`` apart; hard ("crossing") pairs also have a straight line
    between them that dips below hard_threshold. Pair i draws from ``streams[i]`` (or from ``streams[0]`` for
    every pair when there is one stream).

    Returns:
        −1 on success, else the index of the first pair for which ``SAMPLER_TRIES`` candidates were rejected.
    """
    work = (_work(), np.empty(6), np.empty(3), np.empty(3), np.empty(3))
    w, strokes, start, target, other = borrow(work)  # borrowed (``borrow``), kept to the end
    c, ws, streams, o_start, o_target = borrow((c, ws, streams, o_start, o_target))
    fixed_j = -1
    if fixed_kind != 0:
        fixed_j = _component_index(ws, fixed)
        if fixed_j < 0:
            return 0
    shared = streams.shape[0] == 1
    for i in range(o_start.shape[0]):
        s = 0 if shared else i
        fn, st = streams[s, 0], streams[s, 1]
        done = False
        for _ in range(SAMPLER_TRIES):
            if fixed_kind == 0:
                j = _choose_component(ws, fn, st)
                ok = _pose_in_component(c, ws, fn, st, j, w, strokes, start)
                ok2 = _pose_in_component(c, ws, fn, st, j, w, strokes, target)
                if not (ok and ok2):
                    return i
            else:
                if not _pose_in_component(c, ws, fn, st, fixed_j, w, strokes, other):
                    return i
                for k in range(3):
                    start[k] = fixed[k] if fixed_kind == 1 else other[k]
                    target[k] = other[k] if fixed_kind == 1 else fixed[k]
            if not _distance(c, start, target) >= min_distance:
                continue
            if hard and not _straight_dips_below(c, start, target, SEGMENT_POINTS, c[C_HARD]):
                continue
            for k in range(3):
                o_start[i, k], o_target[i, k] = start[k], target[k]
            done = True
            break
        if not done:
            return i
    keep_alive(work)
    return -1


def sample_reach_batch(c, ws, streams, n, hard, min_distance, fixed_kind=0, fixed=None):
    """Draw n start/target pairs in one safe region each (``_sample_reach``), or None if one could not be found.

    Args:
        c: The family's packed constants (``envs.kernels.packing.pack_family``).
        ws: The packed grid (``pack_workspace``).
        streams: ``random_streams`` of one generator (shape (1, 2)) or of n generators (shape (n, 2)).
        n: Number of pairs.
        hard: Whether the straight line must dip below the hard threshold.
        min_distance: Smallest ‖(δp, ℓ_c δφ)‖ between start and target [m].
        fixed_kind: 0 (none), 1 (``fixed`` is the start) or 2 (``fixed`` is the target).
        fixed: The fixed pose, shape (3,) (ignored when fixed_kind is 0).

    Returns:
        (starts (n, 3), targets (n, 3)), or None.
    """
    o_start, o_target = np.empty((n, 3)), np.empty((n, 3))
    pose = np.zeros(3) if fixed is None else np.ascontiguousarray(fixed, dtype=np.float64)
    if _sample_reach(c, ws, streams, bool(hard), float(min_distance), int(fixed_kind), pose, o_start, o_target) >= 0:
        return None
    return o_start, o_target


@jit
def _sample_circle(c, ws, streams, r_lo, r_hi, a_lo, a_hi, n_check, o_center, o_amplitude, o_phase):
    """Fill circle references whose every step pose of a period is safe and in the region of their centre.

    Reference i: p*(t) = c + r (cos(ωt + θ), sin(ωt + θ)), third coordinate c_2 + a sin(ωt), with r uniform in
    [r_lo, r_hi], θ in [−π, π) and a in [a_lo, a_hi]; stored as the family's sinusoids, amplitudes (r, r, a)
    and phases (θ + π/2, θ, 0).

    Returns:
        −1 on success, else the index of the first reference that could not be drawn.
    """
    work = (_work(), np.empty(6), np.empty(3), np.empty(3))
    w, strokes, center, point = borrow(work)  # borrowed (``borrow``), kept to the end
    c, ws, streams = borrow((c, ws, streams))
    o_center, o_amplitude, o_phase = borrow((o_center, o_amplitude, o_phase))
    omega_dt = c[C_OMEGA] * c[C_DT]
    shared = streams.shape[0] == 1
    for i in range(o_center.shape[0]):
        s = 0 if shared else i
        fn, st = streams[s, 0], streams[s, 1]
        done = False
        for _ in range(SAMPLER_TRIES):
            j = _choose_component(ws, fn, st)
            if not _pose_in_component(c, ws, fn, st, j, w, strokes, center):
                return i
            r = r_lo + _next_double(fn, st) * (r_hi - r_lo)
            th = -math.pi + _next_double(fn, st) * _TWO_PI
            a = a_lo + _next_double(fn, st) * (a_hi - a_lo)
            comp = ws[3][j]
            good = True
            for step in range(n_check):
                wt = omega_dt * step
                point[0] = center[0] + r * math.cos(wt + th)
                point[1] = center[1] + r * math.sin(wt + th)
                point[2] = center[2] + a * math.sin(wt)
                if not (_grid_safe(c, ws, point, w, strokes) and _label(ws, point) == comp):
                    good = False
                    break
            if good:
                for k in range(3):
                    o_center[i, k] = center[k]
                o_amplitude[i, 0], o_amplitude[i, 1], o_amplitude[i, 2] = r, r, a
                o_phase[i, 0], o_phase[i, 1], o_phase[i, 2] = th + 0.5 * math.pi, th, 0.0
                done = True
                break
        if not done:
            return i
    keep_alive(work)
    return -1


def sample_circle_batch(c, ws, streams, n, radius_range, angle_range, n_check):
    """Draw n circle references (``_sample_circle``): (centres, amplitudes, phases), each (n, 3), or None.

    Args:
        c: The family's packed constants.
        ws: The packed grid.
        streams: ``random_streams`` of one generator (shape (1, 2)) or of n generators (shape (n, 2)).
        n: Number of references.
        radius_range: (r_min, r_max) of the circle [m].
        angle_range: (a_min, a_max) of the third coordinate's amplitude [rad, or m when translational].
        n_check: Control steps of one period checked.
    """
    center, amplitude, phase = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    r_lo, r_hi = (float(v) for v in radius_range)
    a_lo, a_hi = (float(v) for v in angle_range)
    if _sample_circle(c, ws, streams, r_lo, r_hi, a_lo, a_hi, int(n_check), center, amplitude, phase) >= 0:
        return None
    return center, amplitude, phase
