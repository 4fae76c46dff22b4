"""experiments.detour_survey: a tiny run's files, and its straight-path certificate against a NumPy oracle."""

from __future__ import annotations

import json

import numpy as np
import pytest

from envs.kernels import generic as fk
from experiments import detour_survey
from experiments.detour_survey import SURVEY_BOXES, SurveyBox, draw_pairs, render_markdown


def _oracle_safety(params, x: np.ndarray) -> np.ndarray:
    """The certificate at poses x (N, m) from ``kinematics`` alone: −1 outside the strokes less the margin."""
    robot = params.robot
    q = robot.inverse_kinematics(x, validate=False)
    low, high = params.stroke_limits[0] + params.stroke_margin, params.stroke_limits[1] - params.stroke_margin
    inside = np.all((q >= low) & (q <= high), axis=-1)
    q = np.where(inside[:, None], q, robot.inverse_kinematics(robot.home_pose()))
    k = robot.inverse_condition_number(q, x, validate=False)
    if any(kind != "leg" for kind in robot.actuator_kinds):
        k_i = robot.actuator_condition_number(q, x, validate=False)
        k = np.minimum(k, k_i * params.safe_threshold / params.actuator_safe_threshold)
    return np.where(inside, k, -1.0)


def _oracle_straight_min(params, start: np.ndarray, target: np.ndarray) -> float:
    """Smallest safety along the geodesic start → target at points ≤ segment_spacing apart (ends included)."""
    robot = params.robot
    step = robot.pose_difference(target, start)
    length = float(np.linalg.norm(step * params.pose_metric))
    count = int(min(max(np.ceil(length / params.segment_spacing), 1), fk.SEGMENT_MAX_POINTS))
    points = robot.retract(np.tile(start, (count + 1, 1)), np.arange(count + 1)[:, None] / count * step)
    safety = _oracle_safety(params, points)
    if np.any(safety < 0.0):
        return -1.0
    # a change of sign(det J_x) between checked points is a crossed singularity: safety 0 there
    q = params.robot.inverse_kinematics(points, validate=False)
    sign = np.sign(np.linalg.det(params.robot.link_jacobian(q, points, validate=False)))
    return float(np.where(sign != sign[0], 0.0, safety).min())


@pytest.mark.parametrize("robot", ["planar_3rrr", "planar_3prr", "stewart_gough", "delta"])
def test_pairs_and_straight_paths_match_a_numpy_oracle(robot):
    """Drawn pairs are safe and far enough apart; the compiled straight-path minimum is the oracle's."""
    box = next(b for b in SURVEY_BOXES if b.robot == robot)
    params = box.params()
    starts, targets, _ = draw_pairs(params, 12, np.random.default_rng(3))
    for poses in (starts, targets):
        assert np.all(_oracle_safety(params, poses) >= params.safe_threshold)
        assert np.all((poses >= params.sample_low) & (poses <= params.sample_high))
    gap = np.linalg.norm(params.robot.pose_difference(targets, starts) * params.pose_metric, axis=-1)
    assert np.all(gap >= params.min_distance)
    compiled = fk.segment_min_safety_batch(params.packed, starts, targets, params.segment_spacing)
    oracle = [_oracle_straight_min(params, s, t) for s, t in zip(starts, targets)]
    np.testing.assert_allclose(compiled, oracle, rtol=1e-6, atol=1e-9)


def test_a_certified_detour_is_safe_by_the_oracle():
    """A detour the survey finds has a dipping straight path and two safe legs by the oracle."""
    box = SurveyBox("planar_3rpr", "t", "", detour_survey._BOX_TASKS)
    params = box.params()
    rng = np.random.default_rng(0)
    starts, targets, _ = draw_pairs(params, 400, rng)
    found = detour_survey.classify_pairs(params, starts, targets, 64, rng)
    rows = np.flatnonzero(found["detour"] >= 0)
    assert rows.size > 0
    for i in rows[:3]:
        waypoint = found["waypoint"][i]
        assert 0.0 <= _oracle_straight_min(params, starts[i], targets[i]) < params.safe_threshold
        assert _oracle_straight_min(params, starts[i], waypoint) >= params.safe_threshold
        assert _oracle_straight_min(params, waypoint, targets[i]) >= params.safe_threshold


def test_tiny_run_writes_consistent_counts_and_a_table_generated_from_them(tmp_path):
    """The kinds partition the pairs; the Markdown is the JSON rendered; the reset check finds detour tasks."""
    argv = ["--pairs", "60", "--waypoints", "16", "--resets", "3", "--min-share", "0.0", "--robots", "planar_3rrr"]
    assert detour_survey.main([*argv, "--out", str(tmp_path)]) == 0
    survey = json.loads((tmp_path / "detour_survey.json").read_text())
    assert [r["robot"] for r in survey["boxes"]] == [b.robot for b in SURVEY_BOXES if b.robot == "planar_3rrr"]
    for r in survey["boxes"]:
        c = r["counts"]
        assert c["straight_safe"] + c["leaves"] + c["dips"] == c["pairs"] == 60
        assert c["detour"] + c["no_detour"] == c["dips"]
        assert c["leaves_strokes"] + c["leaves_box"] == c["leaves"]
        assert c["detour_env"] <= c["detour"] and c["dips_below_hard"] <= c["dips"]
    checked = [r["reset"] for r in survey["boxes"] if r["reset"] is not None]
    assert checked and all(t["not_detour"] == 0 for t in checked)
    assert (tmp_path / "detour_survey.md").read_text() == render_markdown(survey)


def test_unknown_robot_is_refused(tmp_path):
    """--robots that matches no box is a usage error naming the surveyed presets."""
    with pytest.raises(SystemExit):
        detour_survey.main(["--robots", "scara", "--out", str(tmp_path)])
