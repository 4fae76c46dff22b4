"""training.evaluate --env-kwargs: the RL Zoo's KEY:VALUE form reaches the env; bad items are named."""

from __future__ import annotations

import json

import pytest

from training import evaluate
from training.evaluate import EvaluationError, parse_env_kwargs


def test_values_are_read_as_yaml():
    """Numbers, lists, strings and booleans; a value may itself hold colons."""
    parsed = parse_env_kwargs(["safe_threshold:0.12", "sample_low:[-0.1, -0.1, -0.5]", "robot:planar_3rpr", "x:a:b"])
    assert parsed == {"safe_threshold": 0.12, "sample_low": [-0.1, -0.1, -0.5], "robot": "planar_3rpr", "x": "a:b"}


@pytest.mark.parametrize(
    ("items", "message"),
    [
        (["safe_threshold"], r"--env-kwargs takes KEY:VALUE items, got 'safe_threshold'"),
        ([":1"], r"--env-kwargs takes KEY:VALUE items, got ':1'"),
        (["a:1", "a:2"], r"--env-kwargs gives 'a' twice"),
        (["a:[1, 2"], r"--env-kwargs 'a:\[1, 2': the value is not YAML"),
    ],
)
def test_bad_items_are_named(items, message):
    """Each malformed item raises EvaluationError naming it."""
    with pytest.raises(EvaluationError, match=message):
        parse_env_kwargs(items)


def test_the_kwargs_reach_the_env(tmp_path, capsys):
    """The planner on the 3-RPR's box detour tasks, given on the command line; an unknown kwarg is refused."""
    out = tmp_path / "eval"
    kwargs = ["robot:planar_3rpr", "task_region:box", "hard_kind:detour", "track_shape:sinusoid"]
    evaluate.main(["--controller", "planner", "--env", "ParallelRobotReachHard-v0", "--episodes", "2",
                   "--env-kwargs", *kwargs, "--out", str(out)])  # fmt: skip
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["episodes"] == 2 and metrics["planner"]["path_found_rate"] == 1.0
    assert metrics["planner"]["planned_length_ratio"]["mean"] > 1.0  # detours go around
    with pytest.raises(SystemExit):
        evaluate.main(["--controller", "planner", "--env", "ParallelRobotReach-v0", "--env-kwargs", "colour:red"])
    assert "unknown argument(s) ['colour']" in capsys.readouterr().err
