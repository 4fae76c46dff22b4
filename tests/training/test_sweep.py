"""training.sweep: the trial plan, a tiny two-trial sweep on a local Ray, resuming, and the rliable report."""

from __future__ import annotations

import json
import os

import pytest

from training import sweep
from training.config import ConfigError


def test_plan_is_the_product_of_algorithms_envs_grid_and_seeds():
    """Every combination appears once, with a unique, file-safe name."""
    trials = sweep.plan_trials(["ppo", "sac"], ["Planar3RPRReach-v0"], [0, 1], {"gamma": [0.98, 0.99]})
    assert len(trials) == 2 * 1 * 2 * 2
    names = [t["name"] for t in trials]
    assert len(set(names)) == len(names)
    assert "ppo-Planar3RPRReach-v0-gamma=0.98-s1" in names
    assert {t["overrides"]["gamma"] for t in trials} == {0.98, 0.99}


@pytest.mark.parametrize(
    ("algos", "env_ids", "match"),
    [(["a2c"], ["Planar3RPRReach-v0"], "unknown algorithm 'a2c'"), (["ppo"], ["CartPole-v1"], "unknown env id")],
)
def test_plan_refuses_unknown_names(algos, env_ids, match):
    """Unknown algorithms and env ids are refused with the valid choices."""
    with pytest.raises(ConfigError, match=match):
        sweep.plan_trials(algos, env_ids, [0], {})


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray session, started by the sweep's own ``connect_ray``, for every sweep of this module.

    (Under xdist the module's tests run on one worker: ``ONE_WORKER_MODULES`` in ``tests/conftest.py``.) Its
    workers run at normal priority: Ray starts them at nice 15, which next to the other xdist worker gives a
    trial a few per cent of a core (a 10 s sweep then took minutes).
    """
    import ray

    niceness = os.environ.get("RAY_worker_niceness")
    os.environ["RAY_worker_niceness"] = "0"
    try:
        assert sweep.connect_ray(None)  # no session was open: started here
    finally:
        if niceness is None:
            del os.environ["RAY_worker_niceness"]
        else:
            os.environ["RAY_worker_niceness"] = niceness
    yield
    ray.shutdown()


@pytest.mark.slow
def test_tiny_sweep_on_local_ray_resumes_without_rerunning(tmp_path, capsys, local_ray):
    """Two trials on a local Ray; the report aggregates them; --resume re-runs nothing; a name is not reused.

    The trials run one after the other in one reused worker; the caller's Ray session is left running.
    """
    import ray

    argv = ["--root", str(tmp_path), "--name", "tiny", "--algos", "ppo", "--envs", "Planar3RPRReach-v0"]
    argv += ["--seeds", "0", "1", "--timesteps", "128", "--episodes", "2", "--max-concurrent", "1"]
    assert sweep.main(argv) == 0
    assert ray.is_initialized()
    out = tmp_path / "tiny"
    results = json.loads((out / "sweep_results.json").read_text())
    assert results["trials"] == 2
    (group,) = results["groups"].values()
    assert group["seeds"] == [0, 1]
    assert set(group["tasks"]) == {"standard", "standard+shield", "hard", "hard+shield"}
    for task in group["tasks"].values():
        lo, hi = task["ci95"]
        assert 0.0 <= lo <= task["mean"] <= hi <= 1.0
    assert group["tasks"]["hard+shield"]["singularity_terminations"] == 0
    assert "| ppo @ Planar3RPRReach-v0 | standard | 2 |" in (out / "report.md").read_text()
    assert (out / "performance_profile.png").is_file()
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("trials/*/result.json")}
    assert len(stamps) == 2
    assert sweep.main(["--root", str(tmp_path), "--name", "tiny", "--resume"]) == 0
    assert {p: p.stat().st_mtime_ns for p in out.glob("trials/*/result.json")} == stamps
    with pytest.raises(SystemExit):
        sweep.main(argv)
    assert "exists" in capsys.readouterr().err
    # --report-only aggregates what has finished and runs nothing
    unfinished = next(iter(stamps))
    unfinished.unlink()
    assert sweep.main(["--root", str(tmp_path), "--name", "tiny", "--report-only"]) == 0
    assert not unfinished.exists()
    assert json.loads((out / "sweep_results.json").read_text())["trials"] == 1
    assert f"1 of 2 trials finished (unfinished: {unfinished.parent.name})" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        sweep.main(["--root", str(tmp_path), "--name", "none", "--report-only"])
    assert "--report-only: no sweep named 'none'" in capsys.readouterr().err


@pytest.mark.slow
def test_a_failing_trial_is_reported_and_left_for_resume(tmp_path, capsys, local_ray):
    """A trial that raises is reported by name with the resume command; the sweep exits 1 and keeps the others."""
    argv = ["--root", str(tmp_path), "--name", "bad", "--algos", "ppo", "--envs", "Planar3RPRReach-v0"]
    argv += ["--seeds", "0", "--grid", "n_epochs=1,0", "--timesteps", "64", "--episodes", "1"]
    argv += ["--max-concurrent", "1"]
    assert sweep.main(argv) == 1
    printed = capsys.readouterr().out
    assert "trial ppo-Planar3RPRReach-v0-n_epochs=0-s0 failed" in printed and "--resume" in printed
    assert (tmp_path / "bad" / "trials" / "ppo-Planar3RPRReach-v0-n_epochs=1-s0" / "result.json").is_file()
    assert not (tmp_path / "bad" / "trials" / "ppo-Planar3RPRReach-v0-n_epochs=0-s0" / "result.json").exists()
