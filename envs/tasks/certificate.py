"""The family's one certificate in compiled code: the safety of a pose and the smallest safety along a segment.

Every safety decision (the task samplers, the certified grid, the planner's edges) goes through
``_pose_safety``: k, or with cranks and sliders min(k, k_I · k_safe / k_I,safe), or −1 where an actuator leaves
its limits less the margin. Segments are checked at points a spacing apart along the geodesic
(``_segment_min_k``); a change of sign(det J_x) between two of them counts as safety 0. A check that only compares
the safety with a threshold (the samplers', ``safe_batch``) proves k ≥ the threshold where it can
(``constraints._singularity_at_least``: a factorisation of JᵀJ − t² U I instead of the Jacobi SVD or the closed
form) and reports the threshold there: the same decisions, in a third of the time on the hexapod.

The measures at a pose (``_measures``) are chosen at compile time by the row path (``envs.kernels.packing``): a
robot with three actuators and three pose coordinates (planar or translational; legs, cranks or sliders) computes
its inverse kinematics, k, k_I and sign(det J_x) in scalars with ``envs.kernels.three``'s primitives, every other
robot over the work arrays of ``envs.kernels.constraints``; both give the same floating-point results. The entry
kernels are compiled per path (``certificate_kernels``), so a planar robot never compiles the 6 × 6 algebra.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba.extending import overload

from envs.kernels import three
from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _actuator_condition, _inverse_kinematics, _singularity_at_least, _work
from envs.kernels.layout import (
    C_HARD,
    C_HARD1,
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
    C_TRANSLATIONAL,
    W_A,
    W_SEG,
    W_SEG_D,
)
from envs.kernels.packing import _OVERLOAD_OPTIONS, THREE, WORK_ARRAYS, _literal_path, row_path
from envs.kernels.pose import _difference, _metric, _retract
from envs.kernels.setup import borrow, jit, jit_inline, keep_alive

__all__ = [
    "ADAPTIVE_STEP_LIMIT",
    "SEGMENT_MAX_POINTS",
    "CertificateKernels",
    "certificate_kernels",
    "certificate_path",
    "certified_segment_batch",
    "safe_batch",
    "safety_batch",
    "segment_batch",
    "segment_min_safety_batch",
]

drop_stale_caches(__file__)


#: Most points checked along one segment.
SEGMENT_MAX_POINTS = 2000
#: Longest step [m] between the checked points of the samplers' segments (the default ``segment_spacing``); robots
#: whose spacing is at least this are checked at fixed points.
ADAPTIVE_STEP_LIMIT = 0.01


@jit
def _measures_three(c, x0, x1, x2, always, at_least):
    """(inside, k, sign(det J_x), k_I) of the pose (x0, x1, x2) of a robot with three actuators, in scalars.

    ``inside`` says whether every actuator coordinate (the closed-form inverse kinematics) lies within its
    limits less the margin; where one does not, k, the sign and k_I are NaN, 0 and NaN unless ``always``. k is
    ``at_least`` where ``at_least`` > 0 and k ≥ ``at_least`` is proven. The operations are those of
    ``_measures_work`` (``constraints._inverse_kinematics``, ``_singularity_at_least``, ``_actuator_condition``)
    in the same order, so both give the same results.
    """
    if c[C_TRANSLATIONAL] != 0.0:  # ``pose._frame``: p = x, R = I
        cs, sn, z = 1.0, 0.0, x2
    else:  # p = (x0, x1, 0), R = R_z(x2)
        cs, sn, z = math.cos(x2), math.sin(x2), 0.0
    lo, hi = c[C_LMIN] + c[C_MARGIN], c[C_LMAX] - c[C_MARGIN]
    if c[C_LEGS] != 0.0:  # the anchors are the B_i, and q_i = ‖d_i‖ from the rows (``_inverse_kinematics``)
        a = three.rows(c, three.leg_anchors(c, 0.0, 0.0, 0.0), x0, x1, x2)  # ℓ_i enters −J_q / 2 only, unused for legs
        q0, q1, q2 = math.sqrt(a[9]), math.sqrt(a[10]), math.sqrt(a[11])
        inside = lo <= q0 <= hi and lo <= q1 <= hi and lo <= q2 <= hi
        if not (inside or always):
            return False, np.nan, 0.0, np.nan
        anc = three.leg_anchors(c, q0, q1, q2)
    else:
        # The indices as int64, not as constants (one compiled ``three.ik_leg``, as ``three.anchors``).
        q0 = three._ik_one(c, np.int64(0), cs, sn, x0, x1, z)
        inside = lo <= q0 <= hi
        if not (inside or always):
            return False, np.nan, 0.0, np.nan
        q1 = three._ik_one(c, np.int64(1), cs, sn, x0, x1, z)
        inside = inside and lo <= q1 <= hi
        if not (inside or always):
            return False, np.nan, 0.0, np.nan
        q2 = three._ik_one(c, np.int64(2), cs, sn, x0, x1, z)
        inside = inside and lo <= q2 <= hi
        if not (inside or always):
            return False, np.nan, 0.0, np.nan
        anc = three.anchors(c, q0, q1, q2)
        a = three.rows(c, anc, x0, x1, x2)
    k, sign, k1 = three.singularity(c, anc, a, at_least)
    return inside, k, sign, k1


@jit
def _measures_work(c, x, w, strokes, always, at_least):
    """``_measures_three`` of any robot over the work array w: the strokes of x go to ``strokes``, A's rows to w.

    Where ``at_least`` > 0, k is ``at_least`` where k ≥ ``at_least`` is proven (``constraints._singularity_at_least``).
    """
    _inverse_kinematics(c, x, w, strokes)
    lo, hi = c[C_LMIN] + c[C_MARGIN], c[C_LMAX] - c[C_MARGIN]
    inside = True
    for j in range(int(c[C_N])):
        if not (lo <= strokes[j] <= hi):
            inside = False
    if not (inside or always):
        return False, np.nan, 0.0, np.nan
    k, sign = _singularity_at_least(c, strokes, w, W_A, at_least)
    return inside, k, sign, _actuator_condition(c, w)


def _measures(path, c, x, w, strokes, always, at_least):
    """(inside, k, sign(det J_x), k_I) of the pose x: whether its strokes keep the margin, and the two measures.

    Where a stroke leaves them, k, the sign and k_I are NaN, 0 and NaN unless ``always``; the sign is 0 where
    the inverse kinematics has no solution. ``path`` is the row path (``envs.kernels.packing.row_path``), a
    compile-time constant: three actuators on three pose coordinates compute in scalars (``_measures_three``),
    the rest over the work array w (``_measures_work``), the only code the overload below compiles. A caller
    that only compares k with a threshold passes it as ``at_least`` (else 0): k is then the threshold itself where it
    is proven to be at least that, a tenth of the 6 × 6 SVD's cost (``constraints._singularity_at_least``).
    """
    raise NotImplementedError("compiled only (see its overload)")


@overload(_measures, prefer_literal=True, jit_options=_OVERLOAD_OPTIONS)
def _measures_of_path(path, c, x, w, strokes, always, at_least):
    if _literal_path(path) == WORK_ARRAYS:

        def work(path, c, x, w, strokes, always, at_least):
            return _measures_work(c, x, w, strokes, always, at_least)

        return work

    def scalars(path, c, x, w, strokes, always, at_least):
        return _measures_three(c, x[0], x[1], x[2], always, at_least)

    return scalars


@jit_inline
def _safety(c, inside, k, k1):
    """Safety from ``_measures``: −1 outside the stroke margin, else k (legs) or min(k, k_I · s / s_I).

    The measure tasks are certified on, on k's scale: a configuration has safety ≥ safe_threshold (s) exactly
    when k ≥ s and k_I ≥ actuator_safe_threshold (s_I), both kinds of singularity kept at bay.
    """
    if not inside:
        return -1.0
    if c[C_LEGS] != 0.0:
        return k
    return min(k, k1 * c[C_SAFE] / c[C_SAFE1])


@jit_inline
def _pose_safety(path, c, x, w, strokes, at_least):
    """The certificate of one pose: (``_safety``, sign(det J_x)), the sign 0 where a stroke leaves its margin.

    Every safety decision (the task samplers, the certified grid, the planner's edges) goes through here. The
    sampling box is not checked. A caller that compares the safety with a threshold alone passes it as
    ``at_least`` (else 0): k may then be the threshold where it is proven to be at least that (``_measures``).
    """
    # ``always`` a bool, not the constant False: one compiled ``_measures`` for every caller (a literal bool would
    # be a second specialisation of it).
    inside, k, sign, k1 = _measures(path, c, x, w, strokes, np.bool_(False), at_least)
    return _safety(c, inside, k, k1), sign


@jit
def _in_box(c, x):
    """Whether the pose x lies in the sampling box."""
    for j in range(int(c[C_N])):
        if not (c[C_SLOW + j] <= x[j] <= c[C_SHIGH + j]):
            return False
    return True


@jit
def _safe(path, c, x, w, strokes):
    """Whether x is in the sampling box and its ``_pose_safety`` (strokes with margin, safety) ≥ safe_threshold."""
    if not _in_box(c, x):
        return False
    safety, _ = _pose_safety(path, c, x, w, strokes, c[C_SAFE])
    return safety >= c[C_SAFE]


@jit_inline
def _spacing_margin(c):
    """The safety a certified segment may lose between checked points ``segment_spacing`` apart, on k's scale.

    min(safe − hard, (safe_I − hard_I) · safe / safe_I): the margin ``envs.presets.certificate_spacing`` derives
    the spacing from (the spacing is margin / L for the safety's largest slope L, so the safety falls by at most
    margin / 2 between two checked points).
    """
    return min(c[C_SAFE] - c[C_HARD], (c[C_SAFE1] - c[C_HARD1]) * c[C_SAFE] / c[C_SAFE1])


@jit
def _segment_min_k(path, c, start, target, w, strokes, stop_below, spacing, box, margin):
    """Smallest ``_pose_safety`` along the geodesic start → target (p linear, R along exp).

    Checked points are at most ``spacing`` apart in ‖(δp, ℓ_c δθ)‖ (ends included; at most
    ``SEGMENT_MAX_POINTS`` intervals). A point whose strokes leave the limits less the margin (or, with ``box``,
    that leaves the sampling box) makes the segment −1; a point where sign(det J_x) differs from the start's
    counts as safety 0 (the segment crossed a Type II singularity between checked points). Stops early once
    below ``stop_below``.

    With ``margin`` > 0, a finite ``stop_below`` = T and ``spacing`` < ``ADAPTIVE_STEP_LIMIT``, the steps follow the
    safety met instead. Points ``spacing`` apart suppose that the safety's slope along z is at most
    L = margin / spacing (``envs.presets.certificate_spacing``), so that between two checked points ≥ T it stays
    ≥ T − margin / 2. After a point of safety s ≥ T the next is h_s = spacing · (1 + (s − T) / margin) further: by
    the same slope, between points a, b at most h_{s_a} apart with s_a, s_b ≥ T the safety stays
    ≥ (s_a + s_b − L h_{s_a}) / 2 ≥ T − margin / 2, the same bound from fewer points. Steps are at most
    ``ADAPTIVE_STEP_LIMIT`` (the default spacing, which bounds what the strokes and the box may do between points)
    and at least the fixed walk's (longer than ``spacing`` only past ``SEGMENT_MAX_POINTS`` spacings). The result
    is then only compared with T: above it, it is the smallest safety at the checked points. The fixed walk with a
    threshold T > 0 passes T to ``_pose_safety``, which may report T for a point whose k is proven to be ≥ T: its
    result is then a lower bound ≥ T (the same decision).

    Points go one at a time, the hexapod's k by the plain Jacobi SVD. Its SIMD form (``inverse_condition6_lanes``,
    16 points at once) walks the hexapod's segments 1.5× faster with the same results, but Numba optimises a
    callee's code again in every function that calls it: walking in lanes doubled the CPU of the hexapod's first
    step on a cold cache (``benchmarks.bench_cold_start``).
    """
    direction, point = w[W_SEG_D], w[W_SEG]
    _difference(c, target, start, direction)
    length = _metric(c, direction)
    count = int(min(max(math.ceil(length / spacing), 1), SEGMENT_MAX_POINTS))
    adaptive = margin > 0.0 and stop_below > -np.inf and spacing < ADAPTIVE_STEP_LIMIT and length > 0.0
    worst = np.inf
    first_sign = 0.0
    u = 0.0
    s = 0
    # Where only the comparison with stop_below counts (the fixed walk: no step length from the safety met), k may
    # be proven ≥ stop_below instead of computed.
    at_least = stop_below if not adaptive and stop_below > 0.0 else 0.0
    while True:
        _retract(c, start, direction, u, point)
        if box and not _in_box(c, point):
            return -1.0
        safety, sign = _pose_safety(path, c, point, w, strokes, at_least)
        if safety < 0.0:
            return -1.0
        if s == 0:
            first_sign = sign
        elif sign != first_sign:
            safety = 0.0
        worst = min(worst, safety)
        if worst < stop_below:
            return worst
        s += 1
        if adaptive:
            if u >= 1.0:
                return worst
            step = max(min(spacing * (1.0 + (safety - stop_below) / margin), ADAPTIVE_STEP_LIMIT), length / count)
            u = min(1.0, u + step / length)
        elif s > count:
            return worst
        else:
            u = s / count


def certificate_path(c) -> int:
    """The code the certificate of the robot of ``c`` compiles: ``THREE`` (scalars) or ``WORK_ARRAYS``.

    Three actuators on three pose coordinates (the row paths ``PLANAR_LEGS`` and ``THREE``) share the scalar code.

    Args:
        c: Packed constants, shape (C_SIZE,) or (N, C_SIZE) (the first row is read).
    """
    return WORK_ARRAYS if row_path(c) == WORK_ARRAYS else THREE


class CertificateKernels(NamedTuple):
    """The certificate's entry kernels of one path (see ``_certificate_kernels``)."""

    safe: Any
    segment: Any
    safety: Any
    certified: Any


def _certificate_kernels(path: int) -> CertificateKernels:
    """The certificate's entry kernels for the path ``path`` (``certificate_path``), a compile-time constant.

    A closure over an int is cached by Numba under its value, so each path's kernels compile (and load from the
    on-disk cache) on their own; each gets a name of its own, hence its own cache index (see
    ``envs.kernels.step._path_kernels``).
    """

    # The arrays borrowed (``borrow``): the caller holds the arguments, and the work arrays are kept to the end.
    def safe(c, x, out):
        work = (_work(), np.empty(6))
        (w, strokes), c, x, out = borrow((work, c, x, out))
        for i in range(x.shape[0]):
            out[i] = _safe(path, c, x[i], w, strokes)
        keep_alive(work)

    def segment(c, start, target, spacing, box, out):
        work = (_work(), np.empty(6))
        (w, strokes), c, start, target, out = borrow((work, c, start, target, out))
        for i in range(start.shape[0]):
            out[i] = _segment_min_k(path, c, start[i], target[i], w, strokes, -np.inf, spacing, box, 0.0)
        keep_alive(work)

    def safety(c, x, o_safety, o_sign):
        work = (_work(), np.empty(6))
        (w, strokes), c, x, o_safety, o_sign = borrow((work, c, x, o_safety, o_sign))
        for i in range(x.shape[0]):
            inside, k, o_sign[i], k1 = _measures(path, c, x[i], w, strokes, np.bool_(True), 0.0)
            o_safety[i] = _safety(c, inside, k, k1)
        keep_alive(work)

    def certified(c, start, target, threshold, box, out):
        work = (_work(), np.empty(6))
        (w, strokes), c, start, target, out = borrow((work, c, start, target, out))
        margin = _spacing_margin(c)
        for i in range(start.shape[0]):
            out[i] = _segment_min_k(path, c, start[i], target[i], w, strokes, threshold, c[C_SPACING], box, margin)
        keep_alive(work)

    kernels = (safe, segment, safety, certified)
    for kernel in kernels:
        kernel.__qualname__ = kernel.__name__ = f"certificate_{kernel.__name__}_path{path}"
    return CertificateKernels(*(jit(kernel) for kernel in kernels))


#: The certificate's entry kernels by ``certificate_path``.
_CERTIFICATE_KERNELS = {path: _certificate_kernels(path) for path in (THREE, WORK_ARRAYS)}


def certificate_kernels(c) -> CertificateKernels:
    """The certificate's entry kernels of the robot of packed constants ``c`` (its ``certificate_path``'s)."""
    return _CERTIFICATE_KERNELS[certificate_path(c)]


def safe_batch(c, x):
    """Whether each pose (N, m) is in the safe set (sampling box, strokes with margin, safety ≥ safe_threshold).

    Args:
        c: Packed constants (``pack_family``).
        x: Poses, shape (N, m).

    Returns:
        bool array, shape (N,).
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty(x.shape[0], dtype=np.bool_)
    certificate_kernels(c).safe(c, x, out)
    return out


def segment_batch(c, start, target):
    """Smallest safety along each geodesic start → target at points ``segment_spacing`` apart, shape (N,).

    −1 if one leaves the sampling box or the stroke limits less the margin. The samplers' decision, whose points
    may be spaced by the safety, is ``certified_segment_batch``.
    """
    start = np.ascontiguousarray(start, dtype=np.float64)
    target = np.ascontiguousarray(target, dtype=np.float64)
    out = np.empty(start.shape[0])
    certificate_kernels(c).segment(c, start, target, c[C_SPACING], True, out)
    return out


def certified_segment_batch(c, start, target, threshold):
    """Each geodesic start → target checked at ``threshold`` as the samplers check it, shape (N,).

    A segment is certified where the result is ≥ ``threshold``: every checked point in the sampling box and the
    stroke margin, with one sign of det J_x and safety ≥ ``threshold``, the points spaced by ``_segment_min_k``
    (by the safety met where ``segment_spacing`` < ``ADAPTIVE_STEP_LIMIT``, else ``segment_spacing`` apart).

    Args:
        c: Packed constants (``pack_family``).
        start: Poses, shape (N, m).
        target: Poses, shape (N, m).
        threshold: The least safety, on k's scale (safe_threshold for standard tasks).

    Returns:
        Float64, shape (N,): where certified, a lower bound of the smallest safety at the points checked, at least
        ``threshold`` (``threshold`` where every point's k was proven to reach it; the values themselves:
        ``segment_min_safety_batch``); else the first checked point's safety below it (0 where
        the sign of det J_x changed, −1 where a point left the box or the stroke margin).
    """
    start = np.ascontiguousarray(start, dtype=np.float64)
    target = np.ascontiguousarray(target, dtype=np.float64)
    out = np.empty(start.shape[0])
    certificate_kernels(c).certified(c, start, target, float(threshold), True, out)
    return out


def safety_batch(c, x):
    """The certificate at N poses (N, m), ignoring the sampling box: (safety, sign(det J_x)), each shape (N,).

    Safety is ``_pose_safety``: k (with cranks and sliders min(k, k_I · k_safe / k_I,safe)), or −1 where an
    actuator leaves its limits less the margin; a pose is safe when it is ≥ safe_threshold. The sign is 0 where
    the inverse kinematics has no solution.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    o_safety, o_sign = np.empty(x.shape[0]), np.empty(x.shape[0])
    certificate_kernels(c).safety(c, x, o_safety, o_sign)
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
    certificate_kernels(c).segment(c, start, target, float(spacing), False, out)
    return out
