"""The certificate of a segment and the OMPL planner, checked against the kinematics library densely.

The oracle walks each segment at many more points than the certificate checks, with the kinematics library
alone (inverse kinematics, the inverse condition number, sign(det) of the link Jacobian, the actuator measure of
cranks and sliders): no kernel code.
"""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs.kernels import generic as fk
from robot_control.planner import SafePlanner, make_planner

#: One robot per pose space and actuator kind, with the task kind that exercises the planner most.
CASES = {
    "planar legs": ("ParallelRobotReachHard-v0", {"robot": "planar_3rpr", "task_region": "box", "hard_kind": "detour",
                                                  "track_shape": "sinusoid"}),
    "planar cranks": ("Planar3RRRReach-v0", {}),
    "planar sliders": ("Planar3PRRReach-v0", {}),
    "spatial legs": ("StewartGoughReachHard-v0", {}),
    "translational cranks": ("DeltaReachHard-v0", {}),
}  # fmt: skip


def _oracle_min(params, waypoints: np.ndarray, points_per_segment: int = 400) -> tuple[float, float, bool]:
    """(min k, min Type I measure, whether sign(det) stays one) densely along a polyline of geodesics."""
    robot = params.robot
    poses = []
    for a, b in itertools.pairwise(waypoints):
        step = robot.pose_difference(b, a)
        f = np.linspace(0.0, 1.0, points_per_segment)[:, None]
        poses.append(robot.retract(np.repeat(a[None], len(f), axis=0), f * step))
    x = np.concatenate(poses)
    q = robot.inverse_kinematics(x)
    lo, hi = params.stroke_limits
    assert np.all(q >= lo + params.stroke_margin - 1e-9) and np.all(q <= hi - params.stroke_margin + 1e-9)
    k = robot.inverse_condition_number(q, x)
    k1 = robot.actuator_condition_number(q, x) if "leg" not in robot.actuator_kinds else np.ones_like(k)
    sign = np.sign(np.linalg.det(robot.link_jacobian(q, x)))
    return float(k.min()), float(k1.min()), bool(np.all(sign == sign[0]))


def _make(case: str):
    env_id, kwargs = CASES[case]
    return gym.make(env_id, **kwargs)


def test_a_segment_that_steps_over_a_singularity_is_not_certified():
    """The 3-RRR crosses its Type II band between two checked points 1 cm apart: the sign check rejects it.

    The oracle finds k < 1e-3 inside the segment and sign(det) flipping; before the sign check (and with the
    coarse spacing) the certificate reported the segment safe (its ends have k ≈ 0.10 and 0.125).
    """
    params = gym.make("Planar3RRRReach-v0").unwrapped.params
    a, b = np.array([0.036, -0.015, 0.63]), np.array([0.039, -0.017, 0.48])
    k, _, same_sign = _oracle_min(params, np.stack([a, b]))
    assert k < 1e-3 and not same_sign
    for spacing in (0.01, params.segment_spacing):
        assert fk.segment_min_safety_batch(params.packed, a[None], b[None], spacing)[0] < params.hard_threshold


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_certificate_spacing_keeps_certified_segments_above_the_hard_threshold(case):
    """Segments the certificate passes at the env's spacing stay, densely, above the hard threshold on one side."""
    env = _make(case)
    params = env.unwrapped.params
    rng = np.random.default_rng(3)
    lo, hi = np.array(params.sample_low), np.array(params.sample_high)
    a = lo + rng.random((400, len(lo))) * (hi - lo)
    b = np.clip(a + rng.normal(scale=0.1, size=a.shape) / params.pose_metric, lo, hi)  # about 10 cm away in z
    k = fk.segment_min_safety_batch(params.packed, a, b, params.segment_spacing)
    passed = np.flatnonzero(k >= params.safe_threshold)[:40]
    assert len(passed) >= 5
    for i in passed:
        k_min, k1_min, same_sign = _oracle_min(params, np.stack([a[i], b[i]]))
        assert same_sign and k_min > params.hard_threshold and k1_min > params.actuator_hard_threshold


@pytest.mark.parametrize("case", sorted(CASES))
def test_planned_paths_are_safe_by_the_oracle(case):
    """Every plan of 8 tasks (hard where the id has them) is found and stays safe densely, on one side of det = 0."""
    env = _make(case)
    params = env.unwrapped.params
    planner = SafePlanner(params)
    targets = "hard" if "Hard" in CASES[case][0] else "standard"
    for seed in range(8):
        _, info = env.reset(seed=seed, options={"targets": targets})
        plan = planner.plan(info["pose"], info["target"])
        assert plan.found
        np.testing.assert_array_equal(plan.waypoints[0], info["pose"])
        np.testing.assert_array_equal(plan.waypoints[-1], info["target"])
        # an ill-conditioned target (below k_safe) lowers the floor of the last segment to 0.8 of its safety
        k_ends = fk.safety_batch(params.packed, plan.waypoints[[0, -1]])[0]
        floor = min(params.safe_threshold, 0.8 * k_ends.min())
        assert plan.length >= plan.straight - 1e-12 and plan.min_k >= floor
        k_min, k1_min, same_sign = _oracle_min(params, plan.waypoints)
        # between checked points the certificate allows at most half the safe-to-hard margin of dip
        assert same_sign and k_min >= floor - 0.5 * (params.safe_threshold - params.hard_threshold)
        assert k_min > params.hard_threshold and k1_min > params.actuator_hard_threshold


def test_detour_tasks_take_a_longer_path_than_the_straight_line():
    """On the 3-RPR's box detour tasks (the straight line dips below k_safe) the plan goes around."""
    env = _make("planar legs")
    planner = SafePlanner(env.unwrapped.params)
    ratios = []
    for seed in range(5):
        _, info = env.reset(seed=seed, options={"targets": "hard"})
        plan = planner.plan(info["pose"], info["target"])
        assert len(plan.waypoints) > 2
        ratios.append(plan.length / plan.straight)
    assert min(ratios) > 1.0


def test_a_plan_from_an_unsafe_start_leaves_it_keeping_most_of_its_safety():
    """A start below k_safe (a state a policy visited) still gets a plan; its first segment keeps 0.8 k_start."""
    env = _make("planar legs")
    params = env.unwrapped.params
    planner = SafePlanner(params)
    rng = np.random.default_rng(0)
    lo, hi = np.array(params.sample_low), np.array(params.sample_high)
    x = lo + rng.random((4000, 3)) * (hi - lo)
    safety, sign = fk.safety_batch(params.packed, x)
    unsafe = np.flatnonzero((safety > 0.5 * params.safe_threshold) & (safety < 0.9 * params.safe_threshold))
    found = 0
    for i in unsafe[:10]:
        start = x[i]
        # the nearest well-conditioned pose on the same side of det J_x = 0 (no path crosses it)
        safe = x[(safety >= 1.5 * params.safe_threshold) & (sign == sign[i])]
        target = safe[np.argmin(np.linalg.norm(safe - start, axis=1))]
        plan = planner.plan(start, target)
        if plan.found:
            found += 1
            k_start = float(fk.safety_batch(params.packed, start[None])[0][0])
            k_first, _, same_sign = _oracle_min(params, plan.waypoints[:2])
            assert same_sign and k_first >= 0.8 * k_start - 0.5 * (params.safe_threshold - params.hard_threshold)
    assert found >= 8


def test_plans_repeat_across_processes_and_bad_options_are_named(tmp_path):
    """OMPL's generator is seeded once per process: a fresh interpreter plans the same detour twice over.

    Unknown planner kinds and a negative time limit are refused with the value named.
    """
    import subprocess
    import sys

    script = (
        "import gymnasium as gym, numpy as np, envs\n"
        "from robot_control.planner import SafePlanner\n"
        "env = gym.make('ParallelRobotReachHard-v0', robot='planar_3rpr', task_region='box', hard_kind='detour',"
        " track_shape='sinusoid')\n"
        "_, info = env.reset(seed=2)\n"
        "plan = SafePlanner(env.unwrapped.params).plan(info['pose'], info['target'])\n"
        "print(repr(plan.waypoints.round(12).tolist()))\n"
    )
    runs = [
        subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
        for _ in range(2)
    ]
    assert runs[0] == runs[1] and runs[0].count("[") > 3  # the same detour, with waypoints
    params = _make("spatial legs").unwrapped.params
    with pytest.raises(ValueError, match=r"planner must be one of \('auto', 'ompl', 'grid'\), got 'prm'"):
        make_planner(params, "prm")
    with pytest.raises(ValueError, match=r"time_limit must be a positive time \[s\], got -1"):
        SafePlanner(params, time_limit=-1)


def _oracle_safety(params, x: np.ndarray) -> np.ndarray:
    """min(k, k_I k_safe / k_I,safe) by the kinematics library (k alone for legs), NaN off the strokes."""
    robot = params.robot
    out = np.full(len(x), np.nan)
    q = robot.inverse_kinematics(x, validate=False)  # NaN where a pose is out of reach
    lo, hi = params.stroke_limits
    inside = np.all((q >= lo + params.stroke_margin) & (q <= hi - params.stroke_margin), axis=-1)
    q, x = q[inside], x[inside]
    k = robot.inverse_condition_number(q, x)
    if "leg" not in robot.actuator_kinds:
        k1 = robot.actuator_condition_number(q, x)
        k = np.minimum(k, k1 * params.safe_threshold / params.actuator_safe_threshold)
    out[inside] = k
    return out


def test_a_remembered_certificate_spacing_is_the_one_computed_for_the_same_arguments():
    """``certificate_spacing`` answers from memory only for the same certificate, scale, box and margin."""
    from envs import presets

    robot = gym.make("Planar3RRRReach-v0").unwrapped.params.robot
    params = presets.build_family_params(robot)
    certificate = fk.pack_certificate(
        robot, params.stroke_limits, params.stroke_margin, params.safe_threshold,
        params.actuator_safe_threshold,
    )  # fmt: skip
    box = (params.sample_low, params.sample_high)
    for margin in (0.02, 0.04):
        for other_box in (box, (params.sample_low, tuple(0.5 * (np.array(box[0]) + np.array(box[1]))))):
            fresh = presets._slope_spacing(certificate, robot, *other_box, margin)
            assert presets.certificate_spacing(certificate, robot, *other_box, margin) == fresh
            assert presets.certificate_spacing(certificate, robot, *other_box, margin) == fresh
    assert presets._slope_spacing(certificate, robot, *box, 0.04) == pytest.approx(
        2.0 * presets._slope_spacing(certificate, robot, *box, 0.02)
    )


@pytest.mark.parametrize("env_id", ["Planar3RRRReach-v0", "Planar3PRRReach-v0", "StewartGoughReach-v0"])
def test_the_certificate_spacing_is_the_margin_over_the_steepest_slope(env_id):
    """The spacing is (k_safe − k_hard) / L99 where the preset's own spacing is larger; L99 from the kinematics library.

    The small crank and slider robots need about 1 mm (their safety changes by ~1.5 per radian of rotation on
    ℓ_c = 5 cm); the hexapod keeps its 1 cm.
    """
    params = gym.make(env_id).unwrapped.params
    rng = np.random.default_rng(11)
    lo, hi = np.array(params.sample_low), np.array(params.sample_high)
    x = lo + rng.random((20000, len(lo))) * (hi - lo)
    h = 1e-5
    steps = h * np.eye(len(lo)) / params.pose_metric
    grad = np.stack([(_oracle_safety(params, x + d) - _oracle_safety(params, x - d)) / (2 * h) for d in steps], axis=-1)
    slope = np.quantile(np.linalg.norm(grad[np.all(np.isfinite(grad), axis=-1)], axis=-1), 0.99)
    margin = min(
        params.safe_threshold - params.hard_threshold,
        (params.actuator_safe_threshold - params.actuator_hard_threshold)
        * params.safe_threshold
        / params.actuator_safe_threshold,
    )
    expected = min(margin / slope, 0.01)
    assert params.segment_spacing == pytest.approx(expected, rel=0.3)  # a tail quantile of 4096 samples
    if "Planar3" in env_id:
        assert params.segment_spacing < 0.002
