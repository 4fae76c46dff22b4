"""experiments.paths_report and its slice of the safety map."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from experiments import paths_report
from training import plots


def test_safety_slice_is_the_kinematics_inverse_condition_number_where_the_legs_reach():
    """On the hexapod (legs: safety = k), the slice equals the kinematics library's k inside the stroke limits."""
    params = gym.make("StewartGoughReachHard-v0").unwrapped.params
    through = np.array([0.0, 0.0, 0.5, 0.1, -0.2, 0.7])
    xs, ys, safety = plots.safety_slice(params, through, resolution=15)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    poses = np.repeat(through[None], X.size, axis=0)
    poses[:, 0], poses[:, 1] = X.ravel(), Y.ravel()
    robot = params.robot
    q = robot.inverse_kinematics(poses, validate=False)
    k = robot.inverse_condition_number(q, poses, validate=False).reshape(X.shape)
    lo, hi = params.stroke_limits
    margin = params.stroke_margin if hasattr(params, "stroke_margin") else 0.0
    inside = ((q.min(axis=-1) >= lo + margin) & (q.max(axis=-1) <= hi - margin)).reshape(X.shape)
    assert inside.sum() > 20 and (~inside).sum() > 0  # both kinds of cell are on the slice
    np.testing.assert_allclose(safety[inside], k[inside], rtol=1e-9)
    assert np.isnan(safety[~inside]).all()


def test_paths_report_draws_the_episode_where_resolved_rate_comes_closest(tmp_path):
    """The report draws one picture per robot and tabulates the chosen episode of every agent."""
    assert paths_report.main(["--out", str(tmp_path), "--episodes", "3", "--robots", "delta"]) == 0
    assert (tmp_path / "delta.png").stat().st_size > 10_000
    text = (tmp_path / "paths.md").read_text()
    assert "| planner | reached |" in text and "| resolved-rate |" in text
    chosen, episode = paths_report.robot_paths("delta", tmp_path, 3, 5000)
    assert set(episode) >= {"planner", "resolved-rate"}
    assert episode["resolved-rate"].episode == chosen
