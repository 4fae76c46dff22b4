"""The family's one certificate in compiled code: the safety of a pose and the smallest safety along a segment.

Every safety decision (the task samplers, the certified grid, the planner's edges) goes through
``_pose_safety``: k, or with cranks and sliders min(k, k_I · k_safe / k_I,safe), or −1 where an actuator leaves
its limits less the margin. Segments are checked at points a spacing apart along the geodesic
(``_segment_min_k``); a change of sign(det J_x) between two of them counts as safety 0.
"""

from __future__ import annotations

import math

import numpy as np

from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _actuator_condition, _inverse_kinematics, _singularity, _solve, _work
from envs.kernels.layout import (
    C_LEGS,
    C_LMAX,
    C_LMIN,
    C_MARGIN,
    C_N,
    C_SAFE,
    C_SAFE1,
    C_SHIGH,
    C_SLOW,
    C_SPACING,
    W_A,
    W_RHS,
    W_SEG,
    W_SEG_D,
    W_SOL,
)
from envs.kernels.pose import _difference, _metric, _retract
from envs.kernels.setup import jit

__all__ = ["SEGMENT_MAX_POINTS", "safe_batch", "safety_batch", "segment_batch", "segment_min_safety_batch"]

drop_stale_caches(__file__)


#: Most points checked along one segment.
SEGMENT_MAX_POINTS = 2000


@jit
def _safety(c, strokes, w):
    """The measure tasks are certified on, on k's scale: k, or with cranks and sliders min(k, k_I · s / s_I).

    So a configuration has safety ≥ safe_threshold (s) exactly when k ≥ s and k_I ≥ actuator_safe_threshold
    (s_I): both kinds of singularity are kept at bay. Needs the rows of A at (strokes, x) in w.
    """
    k, _ = _singularity(c, strokes, w, W_A)
    if c[C_LEGS] != 0.0:
        return k
    return min(k, _actuator_condition(c, w) * c[C_SAFE] / c[C_SAFE1])


@jit
def _pose_safety(c, x, w, strokes):
    """The certificate of one pose: its ``_safety``, or −1 where an actuator leaves its limits less the margin.

    Every safety decision (the task samplers, the certified grid, the planner's edges) goes through here. The
    strokes of x (inverse kinematics) are left in ``strokes`` and the rows of A there in w. The sampling box is
    not checked.
    """
    _inverse_kinematics(c, x, w, strokes)
    lo, hi = c[C_LMIN] + c[C_MARGIN], c[C_LMAX] - c[C_MARGIN]
    for j in range(int(c[C_N])):
        if not (lo <= strokes[j] <= hi):
            return -1.0
    return _safety(c, strokes, w)


@jit
def _in_box(c, x):
    """Whether the pose x lies in the sampling box."""
    for j in range(int(c[C_N])):
        if not (c[C_SLOW + j] <= x[j] <= c[C_SHIGH + j]):
            return False
    return True


@jit
def _safe(c, x, w, strokes):
    """Whether x is in the sampling box and its ``_pose_safety`` (strokes with margin, safety) ≥ safe_threshold."""
    if not _in_box(c, x):
        return False
    return _pose_safety(c, x, w, strokes) >= c[C_SAFE]


@jit
def _segment_min_k(c, start, target, w, strokes, stop_below, spacing, box):
    """Smallest ``_pose_safety`` along the geodesic start → target (p linear, R along exp).

    Checked points are at most ``spacing`` apart in ‖(δp, ℓ_c δθ)‖ (ends included; at most
    ``SEGMENT_MAX_POINTS`` intervals). A point whose strokes leave the limits less the margin (or, with ``box``,
    that leaves the sampling box) makes the segment −1; a point where sign(det J_x) differs from the start's
    counts as safety 0 (the segment crossed a Type II singularity between checked points). Stops early once
    below ``stop_below``.
    """
    direction, point = w[W_SEG_D], w[W_SEG]
    _difference(c, target, start, direction)
    count = int(min(max(math.ceil(_metric(c, direction) / spacing), 1), SEGMENT_MAX_POINTS))
    worst = np.inf
    first_sign = 0.0
    for s in range(count + 1):
        _retract(c, start, direction, s / count, point)
        if box and not _in_box(c, point):
            return -1.0
        safety = _pose_safety(c, point, w, strokes)
        if safety < 0.0:
            return -1.0
        det = _solve(w, int(c[C_N]), W_A, w[W_RHS], w[W_SOL])
        sign = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)
        if s == 0:
            first_sign = sign
        elif sign != first_sign:
            safety = 0.0
        worst = min(worst, safety)
        if worst < stop_below:
            return worst
    return worst


@jit
def safe_batch(c, x):
    """Whether each pose (N, m) is in the safe set (sampling box, strokes with margin, k ≥ safe_threshold)."""
    out = np.empty(x.shape[0], dtype=np.bool_)
    w = _work()
    strokes = np.empty(6)
    for i in range(x.shape[0]):
        out[i] = _safe(c, x[i], w, strokes)
    return out


@jit
def _segment_loop(c, start, target, spacing, box, out):
    w = _work()
    strokes = np.empty(6)
    for i in range(start.shape[0]):
        out[i] = _segment_min_k(c, start[i], target[i], w, strokes, -np.inf, spacing, box)
    return out


def segment_batch(c, start, target):
    """Smallest safety along each geodesic start → target as the samplers check it, shape (N,).

    Points ``segment_spacing`` apart; −1 if one leaves the sampling box or the stroke limits less the margin.
    """
    out = np.empty(start.shape[0])
    _segment_loop(c, start, target, c[C_SPACING], True, out)
    return out


@jit
def _safety_loop(c, x, o_safety, o_sign):
    w = _work()
    strokes = np.empty(6)
    m = int(c[C_N])
    for i in range(x.shape[0]):
        o_safety[i] = _pose_safety(c, x[i], w, strokes)
        det = _solve(w, m, W_A, w[W_RHS], w[W_SOL])
        o_sign[i] = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)


def safety_batch(c, x):
    """The certificate at N poses (N, m), ignoring the sampling box: (safety, sign(det J_x)), each shape (N,).

    Safety is ``_pose_safety``: k (with cranks and sliders min(k, k_I · k_safe / k_I,safe)), or −1 where an
    actuator leaves its limits less the margin; a pose is safe when it is ≥ safe_threshold. The sign is 0 where
    the inverse kinematics has no solution.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    o_safety, o_sign = np.empty(x.shape[0]), np.empty(x.shape[0])
    _safety_loop(c, x, o_safety, o_sign)
    return o_safety, o_sign


def segment_min_safety_batch(c, start, target, spacing):
    """Smallest safety (``safety_batch``) along each geodesic start → target, ignoring the sampling box, shape (M,).

    Args:
        c: Packed constants (``pack_family`` or ``pack_certificate``).
        start: Poses, shape (M, m).
        target: Poses, shape (M, m).
        spacing: Largest gap between checked points (ends included) in ‖(δp, ℓ_c δθ)‖ [m].

    Returns:
        The smallest safety at the checked points of each segment; −1 where one leaves the stroke limits less
        the margin.
    """
    start = np.ascontiguousarray(start, dtype=np.float64)
    target = np.ascontiguousarray(target, dtype=np.float64)
    out = np.empty(start.shape[0])
    _segment_loop(c, start, target, float(spacing), False, out)
    return out
