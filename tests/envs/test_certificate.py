"""The certificate against the kinematics library (three actuators; the hexapod's walk); its two row paths agree."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from envs.kernels import generic as fk
from envs.kernels.packing import THREE, WORK_ARRAYS
from envs.tasks import certificate

#: Robots whose certificate runs in scalars (three actuators on three pose coordinates): legs, cranks, sliders.
THREE_ACTUATORS = ["Planar3RPRReach-v0", "Planar3RRRReach-v0", "Planar3PRRReach-v0", "DeltaReach-v0"]


def _oracle(params, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(inside the stroke margin, safety, sign(det J_x)) of poses x (N, 3) by the kinematics library.

    Safety is min(k, k_I k_safe / k_I,safe) (k alone for legs) where every stroke keeps the margin, else NaN; the
    sign is NaN where the inverse kinematics has no solution.
    """
    robot = params.robot
    q = robot.inverse_kinematics(x, validate=False)  # NaN where a pose is out of reach
    lo, hi = params.stroke_limits
    with np.errstate(invalid="ignore"):
        inside = np.all((q >= lo + params.stroke_margin) & (q <= hi - params.stroke_margin), axis=-1)
    reached = np.all(np.isfinite(q), axis=-1)
    sign = np.full(len(x), np.nan)
    _, j_x = robot.jacobians(q[reached], x[reached], validate=False)
    sign[reached] = np.sign(np.linalg.det(j_x))
    safety = np.full(len(x), np.nan)
    k = robot.inverse_condition_number(q[inside], x[inside])
    if "leg" not in robot.actuator_kinds:
        k1 = robot.actuator_condition_number(q[inside], x[inside])
        k = np.minimum(k, k1 * params.safe_threshold / params.actuator_safe_threshold)
    safety[inside] = k
    return inside, safety, sign


def _poses(params, n: int, seed: int) -> np.ndarray:
    """Poses drawn uniformly in the pose bounds (wider than the sampling box: some leave the stroke margin), (n, 3)."""
    lo, hi = np.array(params.pose_low), np.array(params.pose_high)
    return lo + np.random.default_rng(seed).random((n, len(lo))) * (hi - lo)


@pytest.mark.parametrize("env_id", THREE_ACTUATORS)
def test_the_certificate_of_a_pose_matches_the_kinematics_library(env_id):
    """safety_batch: −1 exactly where a stroke leaves the margin, else the library's safety; the sign of det J_x."""
    params = gym.make(env_id).unwrapped.params
    x = _poses(params, 400, seed=3)
    inside, expected, sign = _oracle(params, x)
    assert 20 <= inside.sum() <= len(x) - 20, "the poses should lie both inside and outside the stroke margin"
    safety, o_sign = fk.safety_batch(params.packed, x)
    np.testing.assert_array_equal(safety[~inside], -1.0)
    np.testing.assert_allclose(safety[inside], expected[inside], rtol=1e-7, atol=1e-10)
    defined = np.isfinite(sign)
    np.testing.assert_array_equal(o_sign[defined], sign[defined])
    np.testing.assert_array_equal(o_sign[~defined], 0.0)


def _segment(params, start: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    """The library's twist step start → target (``pose_space.difference``) and its length ‖(δp, ℓ_c δθ)‖ [m]."""
    step = params.robot.pose_space.difference(target, start)
    return step, float(np.linalg.norm(step / params.robot.pose_scale))


def _points_at(params, start: np.ndarray, step: np.ndarray, u: Any) -> np.ndarray:
    """Poses (len(u), m) at u ∈ [0, 1] of the geodesic from start along ``step`` (``pose_space.retract``)."""
    u = np.atleast_1d(np.asarray(u, dtype=np.float64))
    return params.robot.pose_space.retract(start, u[:, None] * step)


def _checked_points(params, start: np.ndarray, target: np.ndarray, spacing: float) -> np.ndarray:
    """The points the certificate checks on the segment start → target: at most ``spacing`` apart, ends included."""
    step, length = _segment(params, start, target)
    count = int(min(max(np.ceil(length / spacing), 1), fk.SEGMENT_MAX_POINTS))
    return _points_at(params, start, step, np.arange(count + 1) / count)


def _smallest_safety(params, start: np.ndarray, target: np.ndarray, spacing: float) -> float:
    """``segment_min_safety_batch`` by the library: −1 if a checked point leaves the margin, else the least safety.

    A point where sign(det J_x) differs from the start's counts as safety 0.
    """
    ok, safety, sign = _oracle(params, _checked_points(params, start, target, spacing))
    return -1.0 if not ok.all() else float(np.where(sign != sign[0], 0.0, safety).min())


@pytest.mark.parametrize("env_id", THREE_ACTUATORS)
def test_the_smallest_safety_along_a_segment_matches_the_kinematics_library(env_id):
    """segment_min_safety_batch: −1 if a checked point leaves the margin, else the least safety, the ends included.

    A point where sign(det J_x) differs from the start's counts as safety 0.
    """
    params = gym.make(env_id).unwrapped.params
    x = _poses(params, 2000, seed=5)
    inside, _, _ = _oracle(params, x)
    x = x[inside]
    start, target = x[:40], x[40:80]
    assert len(target) == 40
    spacing = 2.0 * params.segment_spacing
    expected = np.empty(len(start))
    for i in range(len(start)):
        expected[i] = _smallest_safety(params, start[i], target[i], spacing)
    assert np.count_nonzero(expected >= 0.0) >= 10, "too few segments keep the stroke margin"
    got = fk.segment_min_safety_batch(params.packed, start, target, spacing)
    np.testing.assert_allclose(got, expected, rtol=1e-7, atol=1e-10)


def _spacing_margin(params) -> float:
    """The safety a segment may lose between checked points: min(safe − hard, (safe_I − hard_I) safe / safe_I)."""
    safe, hard = params.safe_threshold, params.hard_threshold
    safe1, hard1 = params.actuator_safe_threshold, params.actuator_hard_threshold
    return min(safe - hard, (safe1 - hard1) * safe / safe1)


def _walk(params, start: np.ndarray, target: np.ndarray, threshold: float) -> tuple[float, np.ndarray]:
    """The samplers' check of one segment, by the kinematics library: (smallest safety met, the points checked).

    Points ``segment_spacing`` apart where the spacing is at least ``ADAPTIVE_STEP_LIMIT``; else each step after a
    point of safety s is spacing · (1 + (s − threshold) / margin), at most ``ADAPTIVE_STEP_LIMIT``. The walk stops
    at the first point that leaves the stroke margin (−1), changes the sign of det J_x (0) or falls below the
    threshold; the segment is certified when the result is ≥ threshold. A point out of the sampling box is −1 too.
    Points lie on the library's geodesic (``_points_at``).
    """
    step_to_target, length = _segment(params, start, target)
    spacing, limit = params.segment_spacing, certificate.ADAPTIVE_STEP_LIMIT
    margin, u, points, first, worst = _spacing_margin(params), 0.0, [], None, np.inf
    low, high = np.array(params.sample_low), np.array(params.sample_high)
    while True:
        points.append(_points_at(params, start, step_to_target, u)[0])
        inside, safety, sign = _oracle(params, points[-1][None])
        first = sign[0] if first is None else first
        if not inside[0] or not np.all((points[-1] >= low) & (points[-1] <= high)):
            return -1.0, np.array(points)
        worst = min(worst, 0.0 if sign[0] != first else safety[0])
        if worst < threshold or u >= 1.0:
            return worst, np.array(points)
        if spacing >= limit:
            count = int(min(max(np.ceil(length / spacing), 1), fk.SEGMENT_MAX_POINTS))
            u = min(1.0, (round(u * count) + 1) / count)
        else:
            step = spacing * (1.0 + (safety[0] - threshold) / margin)
            u = min(1.0, u + max(min(step, limit), length / fk.SEGMENT_MAX_POINTS) / length)


@pytest.mark.parametrize("env_id", THREE_ACTUATORS)
def test_sampled_pairs_are_safe_at_every_checked_point_by_the_kinematics_library(env_id):
    """Each standard pair's segment, at the points the samplers check, is safe with one sign of det J_x."""
    params = gym.make(env_id).unwrapped.params
    generators = [np.random.default_rng(40 + i) for i in range(12)]
    found = fk.sample_reach_batch(params.packed, fk.random_streams(generators), 12, 3, False, params.min_distance)
    assert found is not None
    for start, target in zip(found[0], found[1]):
        worst, points = _walk(params, start, target, params.safe_threshold * (1.0 - 1e-9))
        assert worst >= params.safe_threshold * (1.0 - 1e-9)
        _, _, sign = _oracle(params, points)
        assert sign[0] != 0.0


@pytest.mark.parametrize("env_id", ["Planar3RRRReach-v0", "Planar3PRRReach-v0", "DeltaReach-v0"])
def test_certified_segments_keep_the_spacing_bound_and_match_the_library_walk(env_id):
    """certified_segment_batch checks the library walk's points, and what it certifies keeps safe − margin / 2.

    Pairs of safe poses of the box (the 3-RRR's segments dip): the compiled result equals ``_walk``'s smallest
    safety at its points (the same points checked), except where a point's safety is within 1e-6 of the
    threshold (a step or a stop may differ) and where the walk is at fixed points (the Delta's) and certifies: its
    k is proven ≥ the threshold instead of computed (``linalg.condition_at_least3``), and the result is a lower
    bound, at least the threshold. On every certified segment the safety at points a twentieth of the spacing
    apart stays ≥ safe − margin / 2, the bound that points ``segment_spacing`` apart give.
    """
    params = gym.make(env_id).unwrapped.params
    safe, margin = params.safe_threshold, _spacing_margin(params)
    x = _poses(params, 3000, seed=11)
    x = x[fk.safe_batch(params.packed, x)]
    start, target = x[:150], x[150:300]
    assert len(target) == 150
    got = fk.certified_segment_batch(params.packed, start, target, safe)
    if env_id == "Planar3RRRReach-v0":  # the others' safe poses are joined by safe segments
        assert 0.3 < np.mean(got >= safe) < 1.0, "the pairs should hold segments that dip"
    for i in range(len(start)):
        worst, points = _walk(params, start[i], target[i], safe)
        if params.segment_spacing >= certificate.ADAPTIVE_STEP_LIMIT and worst >= safe:
            assert safe <= got[i] <= worst * (1 + 1e-7), f"pair {i}: compiled {got[i]}, library {worst}"
        elif abs(got[i] - worst) > 1e-7 * max(1.0, abs(worst)):
            _, safety, _ = _oracle(params, points)
            assert np.nanmin(np.abs(safety - safe)) < 1e-6, f"pair {i}: compiled {got[i]}, library {worst}"
    for i in np.flatnonzero(got >= safe):
        inside, safety, _ = _oracle(params, _checked_points(params, start[i], target[i], params.segment_spacing / 20))
        assert inside.all() and safety.min() >= safe - margin / 2


@pytest.mark.parametrize("env_id", THREE_ACTUATORS)
def test_the_scalar_certificate_equals_the_work_array_one(env_id):
    """Both row paths of the certificate give the same numbers, bit for bit (so the same tasks are drawn)."""
    params = gym.make(env_id).unwrapped.params
    c = params.packed
    assert certificate.certificate_path(c) == THREE
    x = _poses(params, 2000, seed=4)
    outputs = []
    for path in (THREE, WORK_ARRAYS):
        kernels = certificate._CERTIFICATE_KERNELS[path]
        o_safety, o_sign, o_safe, o_segment = np.empty(len(x)), np.empty(len(x)), np.empty(len(x), bool), np.empty(50)
        kernels.safety(c, x, o_safety, o_sign)
        kernels.safe(c, x, o_safe)
        kernels.segment(c, x[:50], x[50:100], 0.01, False, o_segment)
        outputs.append((o_safety, o_sign, o_safe, o_segment))
    for a, b in zip(*outputs):
        np.testing.assert_array_equal(a, b)


def test_the_walk_of_six_coordinates_matches_the_kinematics_library():
    """The hexapod's segments against the library's walk along its geodesic (``pose_space.retract``).

    Between poses of the sampling box (some leave the stroke margin) and to poses out of it, walked whole
    (``segment_min_safety_batch``, no box) and as the samplers walk them (``certified_segment_batch``: the box,
    stopping below a threshold; the median k of the box, so that some segments dip below it), with segments of a
    few points to some fifty. The samplers' walk gives a certified segment a lower bound of its safety, at least the
    threshold (``linalg.condition_at_least6`` proves k at the points instead of computing it).
    """
    params = gym.make("StewartGoughReach-v0").unwrapped.params
    low, high = np.array(params.sample_low), np.array(params.sample_high)
    x = low + (high - low) * np.random.default_rng(7).uniform(-0.1, 1.1, (400, 6))
    in_box = np.all((x >= low) & (x <= high), axis=1)
    start, target = x[in_box][:60], np.concatenate([x[in_box][60:100], x[~in_box][:20]])
    _, k, _ = _oracle(params, start)
    threshold = float(np.nanmedian(k))
    spacing = params.segment_spacing / 2
    free = fk.segment_min_safety_batch(params.packed, start, target, spacing)
    certified = fk.certified_segment_batch(params.packed, start, target, threshold)
    counts, kinds = [], set()
    for i in range(len(start)):
        counts.append(len(_checked_points(params, start[i], target[i], spacing)) - 1)
        expected = _smallest_safety(params, start[i], target[i], spacing)
        np.testing.assert_allclose(free[i], expected, rtol=1e-7, atol=1e-10, err_msg=f"pair {i}")
        expected, _ = _walk(params, start[i], target[i], threshold)
        if expected >= threshold:  # certified: the same decision, and a lower bound of the safety met (k proven)
            assert threshold <= certified[i] <= expected * (1 + 1e-7), (i, certified[i], expected)
        else:
            np.testing.assert_allclose(certified[i], expected, rtol=1e-7, atol=1e-10, err_msg=f"pair {i}")
        kinds.add("left" if expected < 0 else ("certified" if expected >= threshold else "dips"))
    assert kinds == {"left", "certified", "dips"}, kinds
    assert min(counts) < 16 and max(counts) > 48, (min(counts), max(counts))


def test_a_segment_of_the_hexapod_through_a_type_ii_singularity_is_zero():
    """A segment of the hexapod through a Type II singularity (within the stroke margin) is 0.

    The spacing puts the crossing between the 16th and the 17th checked points (where a walk in blocks of 16
    points would start its second): the 17th point's sign of det J_x is compared with the start's.
    """
    params = gym.make("StewartGoughReach-v0").unwrapped.params
    start = np.array([-0.09628838, 0.16443045, 0.47035076, 0.42813228, 0.47186144, 0.07706015])
    target = np.array([-0.14699781, 0.16349657, 0.41969325, 0.58241742, 0.57809131, 0.09865072])
    step, length = _segment(params, start, target)
    before, after = 0.0, 1.0  # u of the crossing, by bisection on the library's sign(det J_x)
    for _ in range(40):
        middle = 0.5 * (before + after)
        sign = _oracle(params, _points_at(params, start, step, middle))[2]
        before, after = (middle, after) if sign[0] == _oracle(params, start[None])[2][0] else (before, middle)
    count = int(16 / after)  # points s = 0 … count at u = s / count: s = 16 is the first past the crossing
    assert 15 / count < before and after < 16 / count
    spacing = length / (count - 0.5)
    assert len(_checked_points(params, start, target, spacing)) == count + 1
    assert _smallest_safety(params, start, target, spacing) == 0.0
    assert fk.segment_min_safety_batch(params.packed, start[None], target[None], spacing)[0] == 0.0
