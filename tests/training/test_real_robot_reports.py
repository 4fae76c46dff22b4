"""The real-robot reports (``experiments.mismatch_report``, ``geometry_report``) and runs trained with env kwargs."""

from __future__ import annotations

import csv
import json

import gymnasium as gym
import numpy as np
import yaml

from experiments import geometry_report, mismatch_report
from tests.training.conftest import REACH, write_run_folder
from training import evaluate

FAMILY = "Planar3RPRReachFamily-v0"


def _final_errors(folder) -> list[float]:
    with open(folder / "episodes.csv") as fh:
        return [float(row["final_position_error_mm"]) for row in csv.DictReader(fh)]


def test_mismatch_report_scores_every_agent_at_every_tolerance_from_its_metrics(tmp_path):
    """One row per agent and tolerance, each the figures of its metrics.json; the tolerance reaches the robot."""
    run = write_run_folder(tmp_path / "ppo-run", "ppo")
    out = tmp_path / "report"
    argv = ["--env", REACH, "--run", str(run), "--tolerances", "0", "3", "--episodes", "2", "--out", str(out)]
    assert mismatch_report.main(argv) == 0
    table = (out / "table.md").read_text()
    rows = [line for line in table.splitlines() if line.startswith("| ") and not line.startswith("| agent")]
    assert len(rows) == 3 * 2
    for agent in ("resolved-rate", "singularity-aware", "ppo-run"):
        for mm in (0, 3):
            metrics = json.loads((out / f"{agent}-{mm}mm" / "metrics.json").read_text())
            row = next(r for r in rows if r.startswith(f"| {agent} | {mm} |"))
            assert f"| {100 * metrics['success_rate']:.0f} % |" in row
            assert f"{metrics['final_position_error_mm']['median']:.2f} /" in row
    assert (out / "mismatch.png").stat().st_size > 10_000
    # the same tasks, a robot built 3 mm off: resolved-rate on the nominal model no longer ends where it did
    assert _final_errors(out / "resolved-rate-0mm") != _final_errors(out / "resolved-rate-3mm")


def test_geometry_report_scores_family_and_nominal_runs_on_the_same_robots(tmp_path):
    """The nominal run sees the family's observation without the codes; the table has its six rows."""
    family = write_run_folder(tmp_path / "family", "ppo", env_id=FAMILY)
    nominal = write_run_folder(tmp_path / "nominal", "ppo", env_id=REACH)  # 18 observations, as a nominal run
    out = tmp_path / "geometry"
    argv = ["--family", str(family), "--nominal", str(nominal), "--episodes", "2", "--out", str(out)]
    assert geometry_report.main(argv) == 0
    table = (out / "table.md").read_text()
    assert table.count("| nominal policy") == 4 and table.count("| family policy") == 2
    env = geometry_report.without_codes(gym.make(FAMILY))
    obs, _ = env.reset(seed=0)
    full, _ = gym.make(FAMILY).reset(seed=0)
    assert obs.shape == (18,) and env.observation_space.shape == (18,)
    np.testing.assert_array_equal(obs, full[:18])


def test_a_run_trained_with_env_kwargs_is_loaded_and_scored_with_them(tmp_path):
    """``training.evaluate --run`` builds the run's env with the kwargs it was trained with (else shapes differ)."""
    run = write_run_folder(tmp_path / "run", "ppo", env_id=REACH)
    config = yaml.safe_load((run / "config.yml").read_text())
    config["env_id"] = FAMILY
    config["hyperparams"]["env_kwargs"] = {"geometry_variation": 0.0}  # the family's tasks on the nominal robot
    (run / "config.yml").write_text(yaml.safe_dump(config))
    assert evaluate.run_env_kwargs(config) == {"geometry_variation": 0.0}
    agent, _ = evaluate.load_run(run)
    out = tmp_path / "eval"
    assert evaluate.main(["--run", str(run), "--episodes", "1", "--out", str(out)]) == 0
    assert json.loads((out / "metrics.json").read_text())["env_id"] == FAMILY
    assert agent(np.zeros((1, 18), dtype=np.float32)).shape == (1, 3)
