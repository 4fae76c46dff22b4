"""The certificate of robots with three actuators against the kinematics library, and its two row paths agree."""

from __future__ import annotations

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


def _checked_points(params, start: np.ndarray, target: np.ndarray, spacing: float) -> np.ndarray:
    """The points the certificate checks on the segment start → target: at most ``spacing`` apart, ends included."""
    planar = params.robot.pose_space.name == "planar"
    scale = np.array([1.0, 1.0, params.robot.characteristic_length if planar else 1.0])
    length = np.linalg.norm((target - start) * scale)
    count = int(min(max(np.ceil(length / spacing), 1), fk.SEGMENT_MAX_POINTS))
    return start + (np.arange(count + 1) / count)[:, None] * (target - start)


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
        ok, safety, sign = _oracle(params, _checked_points(params, start[i], target[i], spacing))
        expected[i] = -1.0 if not ok.all() else np.where(sign != sign[0], 0.0, safety).min()
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
    threshold; the segment is certified when the result is ≥ threshold.
    """
    planar = params.robot.pose_space.name == "planar"
    scale = np.array([1.0, 1.0, params.robot.characteristic_length if planar else 1.0])
    length = np.linalg.norm((target - start) * scale)
    spacing, limit = params.segment_spacing, certificate.ADAPTIVE_STEP_LIMIT
    margin, u, points, first, worst = _spacing_margin(params), 0.0, [], None, np.inf
    while True:
        points.append(start + u * (target - start))
        inside, safety, sign = _oracle(params, points[-1][None])
        first = sign[0] if first is None else first
        if not inside[0]:
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
    threshold (a step or a stop may differ); on every certified segment the safety at points a twentieth of the
    spacing apart stays ≥ safe − margin / 2, the bound that points ``segment_spacing`` apart give.
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
        if abs(got[i] - worst) > 1e-7 * max(1.0, abs(worst)):
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
