"""Certified tasks drawn in the sampling box (compiled): Reach pairs (with detours) and Track references.

Every draw comes from NumPy generators through ``envs.kernels.setup.random_streams`` and every candidate is
checked by the certificate (``envs.tasks.certificate``); many pairs with one stream per robot run on every core.
The entry kernels are compiled per certificate path (``sampler_kernels``), a compile-time constant of the
certificate's code: a robot compiles its own path only.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from envs.kernels.cache import drop_stale_caches
from envs.kernels.constraints import _work
from envs.kernels.evaluation import _reference_at
from envs.kernels.layout import (
    C_HARD,
    C_HARD_KIND,
    C_N,
    C_PATH,
    C_SAFE,
    C_SHIGH,
    C_SLOW,
    C_SPACING,
)
from envs.kernels.packing import THREE, WORK_ARRAYS, read_only
from envs.kernels.pose import _TWO_PI, _difference, _metric
from envs.kernels.setup import ONE_THREAD, _next_double, borrow, claim, jit, jit_inline, keep_alive, on_every_core
from envs.tasks.certificate import _measures, _safe, _segment_min_k, _spacing_margin, certificate_path

__all__ = [
    "PARALLEL_MIN_SAMPLES",
    "SAMPLER_TRIES",
    "WAYPOINT_TRIES",
    "SamplerKernels",
    "sample_reach_batch",
    "sample_track_batch",
    "sampler_kernels",
]

drop_stale_caches(__file__)


#: Candidates a sampler may reject before it reports failure.
SAMPLER_TRIES = 2000
#: Pairs from which the Reach sampler runs on every core (one generator per robot; a pair costs 3–12 µs, waking
#: the other threads about 40 µs: measured on two cores, 32 pairs took 3.2 µs each on both and 3.6 µs on one for the
#: 3-PRR, 7.3 and 12.1 µs for the 3-RRR).
PARALLEL_MIN_SAMPLES = 32
#: Waypoints tried per hard pair to certify a detour.
WAYPOINT_TRIES = 64


@jit
def _draw_safe(path, c, fn, st, w, strokes, out):
    """A pose drawn uniformly in the sampling box until it is safe; False after ``SAMPLER_TRIES`` rejections."""
    m = int(c[C_N])
    for _ in range(SAMPLER_TRIES):
        for j in range(m):
            lo, hi = c[C_SLOW + j], c[C_SHIGH + j]
            out[j] = lo + (hi - lo) * _next_double(fn, st)
        if _safe(path, c, out, w, strokes):
            return True
    return False


@jit
def _draw_band(path, c, fn, st, w, strokes, low, high, out):
    """A pose of the sampling box with strokes within the margin and low ≤ k < high; False after the tries."""
    m = int(c[C_N])
    for _ in range(SAMPLER_TRIES):
        for j in range(m):
            out[j] = c[C_SLOW + j] + (c[C_SHIGH + j] - c[C_SLOW + j]) * _next_double(fn, st)
        # k ≥ high may be proven instead of computed (k is then high: rejected); a bool (see ``_pose_safety``)
        inside, k, _, _ = _measures(path, c, out, w, strokes, np.bool_(False), high)
        if inside and low <= k < high:
            return True
    return False


@jit_inline
def _sample_reach_one(path, c, fn, st, hard, min_distance, w, strokes, start, target, waypoint, step):
    """One certified pair from the stream (fn, st) into start, target, waypoint (see ``_sample_reach``); success."""
    safe = c[C_SAFE]
    margin = _spacing_margin(c)
    box = np.bool_(True)  # a bool, not the constant True: one compiled _segment_min_k for every caller
    band = hard and c[C_HARD_KIND] != 0.0
    floor = 2.0 * c[C_HARD]
    for _ in range(SAMPLER_TRIES):
        if not _draw_safe(path, c, fn, st, w, strokes, start):
            return False
        if band:
            if not _draw_band(path, c, fn, st, w, strokes, floor, safe, target):
                return False
        elif not _draw_safe(path, c, fn, st, w, strokes, target):
            return False
        _difference(c, target, start, step)
        if not _metric(c, step) >= min_distance:
            continue
        if not hard:
            if _segment_min_k(path, c, start, target, w, strokes, safe, c[C_SPACING], box, margin) >= safe:
                return True
        elif band:
            if _segment_min_k(path, c, start, target, w, strokes, floor, c[C_SPACING], box, margin) >= floor:
                return True
        elif 0.0 <= _segment_min_k(path, c, start, target, w, strokes, -np.inf, c[C_SPACING], box, 0.0) < safe:
            for _ in range(WAYPOINT_TRIES):
                if not _draw_safe(path, c, fn, st, w, strokes, waypoint):
                    return False
                if (
                    _segment_min_k(path, c, start, waypoint, w, strokes, safe, c[C_SPACING], box, margin) >= safe
                    and _segment_min_k(path, c, waypoint, target, w, strokes, safe, c[C_SPACING], box, margin) >= safe
                ):
                    return True
    return False


@jit_inline
def _put_pair(c, hard, start, target, waypoint, i, o_start, o_target, o_waypoint):
    band = hard and c[C_HARD_KIND] != 0.0
    for j in range(int(c[C_N])):
        o_start[i, j] = start[j]
        o_target[i, j] = target[j]
        o_waypoint[i, j] = waypoint[j] if hard and not band else target[j]


class SamplerKernels(NamedTuple):
    """The samplers' entry kernels of one certificate path (see ``_sampler_kernels``).

    ``reach(c, streams, hard, min_distance, o_start, o_target, o_waypoint, ok, counter)`` fills o_start, o_target,
    o_waypoint (M, m) with certified pairs and returns −1 on success, else the failing pair. Standard pair: the
    geodesic start → target has safety ≥ safe_threshold at every checked point. Hard pair (``hard_kind`` "detour"): that
    geodesic dips below safe_threshold (it stays inside the box and stroke limits), and the two geodesics
    start → waypoint → target are safe. Hard pair ("ill_conditioned"): a safe start and a target in the
    ill-conditioned band 2 hard_threshold ≤ k < safe_threshold, joined by a geodesic that keeps
    safety ≥ 2 hard_threshold. ``streams`` holds one stream for all pairs or one per pair.

    ``ok`` (M,) bool marks the pairs found. ``counter``: an empty int64 array (``ONE_THREAD``), the pairs in turn,
    up to the first failure; or the counter of ``on_every_core``, one thread's share of the pairs, for one stream
    per robot (each robot's pair depends on its stream only): it draws those it claims and returns −1.

    ``track(c, streams, max_amplitude, n_check, o_center, o_amplitude, o_phase)`` fills references (centre,
    amplitude, phase) whose poses at ``n_check`` times of a period, and the segments between them, are all safe.
    Sinusoids: a_j uniform in [½, 1] of ``max_amplitude`` and θ_j uniform. A path: a = ``max_amplitude``,
    θ_0 = 0 (the start at the first vertex) and the heading θ_1 = ψ uniform in [0, 2π) (see ``_reference_at``).
    """

    reach: Any
    track: Any


def _sampler_kernels(path: int) -> SamplerKernels:
    """The samplers' entry kernels for the certificate path ``path`` (``certificate_path``), a compile-time constant.

    Each gets a name of its own per path, hence its own Numba cache index (see ``envs.kernels.step._path_kernels``).
    """

    def reach(c, streams, hard, min_distance, o_start, o_target, o_waypoint, ok, counter):
        n = o_start.shape[0]
        one_thread, shared = counter.shape[0] == 0, streams.shape[0] == 1
        work = (_work(), np.empty(6), np.empty(6), np.empty(6), np.empty(6), np.empty(6))
        w, strokes, start, target, waypoint, step = borrow(work)  # arrays borrowed (``borrow``), kept to the end
        c, streams, o_start, o_target, o_waypoint = borrow((c, streams, o_start, o_target, o_waypoint))
        failed = -1
        i = 0 if one_thread else claim(counter)
        while i < n:
            s = 0 if shared else i
            ok[i] = _sample_reach_one(
                path, c, streams[s, 0], streams[s, 1], hard, min_distance, w, strokes, start, target, waypoint, step
            )
            if ok[i]:
                _put_pair(c, hard, start, target, waypoint, i, o_start, o_target, o_waypoint)
            elif one_thread:  # the caller gives up: draw no further
                failed = i
                break
            i = i + 1 if one_thread else claim(counter)
        keep_alive(work)
        return failed

    def track(c, streams, max_amplitude, n_check, o_center, o_amplitude, o_phase):
        m = int(c[C_N])
        safe = c[C_SAFE]
        margin = _spacing_margin(c)
        box = np.bool_(True)  # a bool, not the constant True (see ``_sample_reach_one``)
        path_kind = c[C_PATH] != 0.0
        shared = streams.shape[0] == 1
        work = (_work(), np.empty(6), np.empty(6), np.empty(6), np.empty(6))
        w, strokes, point, previous, rate = borrow(work)
        c, streams, max_amplitude = borrow((c, streams, max_amplitude))
        o_center, o_amplitude, o_phase = borrow((o_center, o_amplitude, o_phase))
        for i in range(o_center.shape[0]):
            s = 0 if shared else i
            fn, st = streams[s, 0], streams[s, 1]
            done = False
            for _ in range(SAMPLER_TRIES):
                if not _draw_safe(path, c, fn, st, w, strokes, o_center[i]):
                    return i
                for j in range(m):
                    if path_kind:
                        o_amplitude[i, j] = max_amplitude[j]
                        o_phase[i, j] = 0.0
                    else:
                        o_amplitude[i, j] = max_amplitude[j] * (0.5 + 0.5 * _next_double(fn, st))
                        o_phase[i, j] = _TWO_PI * _next_double(fn, st)
                if path_kind:
                    o_phase[i, 1] = _TWO_PI * _next_double(fn, st)
                ok = True
                for step in range(n_check + 1):
                    _reference_at(c, _TWO_PI * step / n_check, o_center, o_amplitude, o_phase, i, point, rate)
                    if (
                        step > 0
                        and _segment_min_k(path, c, previous, point, w, strokes, safe, c[C_SPACING], box, margin) < safe
                    ):
                        ok = False
                        break
                    for j in range(m):
                        previous[j] = point[j]
                if ok:
                    done = True
                    break
            if not done:
                return i
        keep_alive(work)
        return -1

    kernels = (reach, track)
    for kernel in kernels:
        kernel.__qualname__ = kernel.__name__ = f"sample_{kernel.__name__}_path{path}"
    return SamplerKernels(jit(reach), jit(track))


#: The samplers' entry kernels by ``certificate_path``.
_SAMPLER_KERNELS = {path: _sampler_kernels(path) for path in (THREE, WORK_ARRAYS)}


def sampler_kernels(c) -> SamplerKernels:
    """The samplers' entry kernels of the robot of packed constants ``c`` (its ``certificate_path``'s)."""
    return _SAMPLER_KERNELS[certificate_path(c)]


def sample_reach_batch(c, streams, n, m, hard, min_distance):
    """Draw n certified start/target pairs (``FamilyReachEnv.sample_tasks``), or None if one could not be found.

    Args:
        c: Packed constants.
        streams: ``random_streams`` of one generator (shared) or of n generators, shape (1, 2) or (n, 2).
        n: Number of pairs.
        m: Pose coordinates.
        hard: Whether the straight path must dip below the safe threshold (with a certified detour).
        min_distance: Smallest ‖(δp, ℓ_c δθ)‖ between start and target [m].

    Returns:
        (starts (n, m), targets (n, m), waypoints (n, m): the detour's waypoint, or the target), or None.
    """
    c = read_only(c)
    o_start, o_target, o_waypoint = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    reach, ok = sampler_kernels(c).reach, np.empty(n, dtype=np.bool_)
    if streams.shape[0] > 1 and n >= PARALLEL_MIN_SAMPLES:
        on_every_core(reach, c, streams, hard, min_distance, o_start, o_target, o_waypoint, ok)
        if not ok.all():
            return None
    elif reach(c, streams, hard, min_distance, o_start, o_target, o_waypoint, ok, ONE_THREAD) >= 0:
        return None
    return o_start, o_target, o_waypoint


def sample_track_batch(c, streams, n, m, max_amplitude, n_check):
    """Draw n references whose whole period stays in the safe set (checked between ``n_check`` points), or None."""
    o_center, o_amplitude, o_phase = np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    c = read_only(c)
    max_amplitude = np.asarray(max_amplitude, dtype=np.float64)
    if sampler_kernels(c).track(c, streams, max_amplitude, n_check, o_center, o_amplitude, o_phase) >= 0:
        return None
    return o_center, o_amplitude, o_phase
