"""The shipped pre-trained policy: its run folder, its recorded regression result, and the demo built on it."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from PIL import Image

from envs import PLANAR_3RPR_IDS
from experiments import demo
from experiments.demo import PRETRAINED_RUN
from training.evaluate import aggregate, evaluate_agent, load_run, run_env_kwargs, wrap_for_run

#: Keys of regression.json and their types.
REGRESSION_KEYS = {
    "env_id": str,
    "targets": str,
    "seed": int,
    "episodes": int,
    "success_rate": float,
    "singularity_terminations": int,
}


#: How far a re-run may drift from its record: success rate ±0.02 (one episode in 50), singularity terminations ±1.
SUCCESS_RATE_TOLERANCE = 0.02
SINGULARITY_TOLERANCE = 1


def assert_keeps_record(metrics: dict, record: dict) -> None:
    """Assert re-run metrics match a regression record on both sides (better is a change too: re-record it)."""
    assert metrics["episodes"] == record["episodes"], metrics
    assert abs(metrics["success_rate"] - record["success_rate"]) <= SUCCESS_RATE_TOLERANCE + 1e-12, (
        f"success rate {metrics['success_rate']} against the recorded {record['success_rate']}"
    )
    assert abs(metrics["singularity_terminations"] - record["singularity_terminations"]) <= SINGULARITY_TOLERANCE, (
        f"{metrics['singularity_terminations']} singularity terminations against the recorded "
        f"{record['singularity_terminations']}"
    )


@pytest.fixture(scope="module")
def pretrained_run() -> Path:
    """The shipped run folder; the tests that need it are skipped until it exists."""
    if not PRETRAINED_RUN.is_dir():
        pytest.skip("pre-trained policy not shipped yet")
    return PRETRAINED_RUN


@pytest.fixture(scope="module")
def regression(pretrained_run: Path) -> dict:
    """The recorded regression result, checked against its contract."""
    record = json.loads((pretrained_run / "regression.json").read_text())
    assert set(record) == set(REGRESSION_KEYS), sorted(record)
    for key, kind in REGRESSION_KEYS.items():
        value = record[key]
        ok = isinstance(value, kind) and not isinstance(value, bool)
        assert ok or (kind is float and type(value) is int), f"{key} = {value!r} is not {kind.__name__}"
    assert record["env_id"] in PLANAR_3RPR_IDS
    assert record["targets"] == "standard"
    assert record["episodes"] >= 1
    assert 0.0 <= record["success_rate"] <= 1.0
    assert 0 <= record["singularity_terminations"] <= record["episodes"]
    return record


def test_pretrained_folder_is_a_complete_run(pretrained_run, regression):
    """The folder holds model.zip, vecnormalize.pkl, config.yml, command.txt and regression.json."""
    for name in ("model.zip", "vecnormalize.pkl", "config.yml", "command.txt", "regression.json"):
        assert (pretrained_run / name).is_file(), f"{name} missing from {pretrained_run}"
    config = yaml.safe_load((pretrained_run / "config.yml").read_text())
    assert config["algo"] == "ppo"
    assert config["env_id"] == regression["env_id"] == "Planar3RPRReach-v0"
    assert "training.train" in (pretrained_run / "command.txt").read_text()


@pytest.mark.slow
def test_pretrained_policy_keeps_its_recorded_performance(pretrained_run, regression):
    """Re-running the recorded episodes gives the recorded success rate (±0.02) and singularity count (±1)."""
    agent, config = load_run(pretrained_run)
    assert config["env_id"] == regression["env_id"]
    env = gym.make(regression["env_id"])
    try:
        records = evaluate_agent(agent, env, regression["episodes"], regression["seed"], regression["targets"])
    finally:
        env.close()
    metrics = aggregate(records)
    assert metrics["episodes"] == regression["episodes"]
    assert_keeps_record(metrics, regression)


@pytest.mark.slow
def test_demo_writes_report(pretrained_run, tmp_path, capsys, monkeypatch):
    """experiments.demo.main writes the report, the metrics, the pictures and the policy's GIF.

    It asks each family robot for its section with the same folder, episodes, seed and shield; those sections are
    run here by name only (``run_family_demo`` is run for every robot by the tests below).
    """
    out = tmp_path / "demo"
    sections = []

    def family_section(name, folder, episodes, seed, shield):
        sections.append((name, folder, episodes, seed, shield))
        return {}

    monkeypatch.setattr(demo, "run_family_demo", family_section)
    assert demo.main(["--episodes", "2", "--out", str(out)]) == 0
    assert sections == [(name, out, 2, 1000, demo.DEMO_SHIELD) for name in demo.FAMILY_DEMOS]
    names = (
        "report.md",
        "metrics.json",
        "trajectories_hard.png",
        "trajectories_standard.png",
        "condition_number_hard.png",
        "policy_hard.gif",
    )
    for name in names:
        assert (out / name).is_file(), f"{name} missing from {sorted(p.name for p in out.iterdir())}"
    metrics = json.loads((out / "metrics.json").read_text())
    agents = ["PPO policy", "resolved-rate", "singularity-aware", "planner"]
    if demo.PRETRAINED_MIXED_RUN.is_dir():
        agents.append("PPO policy (mixed, residual over the planner)")
    elif demo.PRETRAINED_HARD_RUN.is_dir():
        agents.append("PPO policy (hard-trained)")
    if demo.PRETRAINED_PLAN_FREE_RUN.is_dir():
        agents.append("plan-free policy (distilled planner)")
    expected = {f"{agent} @ {targets}" for agent in agents for targets in ("standard", "hard")}
    shielded = {f"{agent} + shield @ {targets}" for agent in agents for targets in ("standard", "hard")}
    assert set(metrics) == expected | shielded
    assert all(metrics[label]["singularity_terminations"] == 0 for label in shielded)
    assert all(m["episodes"] == 2 for m in metrics.values())
    report = (out / "report.md").read_text()
    assert "| PPO policy + shield | hard |" in report
    assert "| PPO policy | hard |" in report and "| singularity-aware | standard |" in report
    for name in names[2:5]:
        with Image.open(out / name) as image:
            assert image.format == "PNG"
    with Image.open(out / "policy_hard.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames > 2
    printed = capsys.readouterr().out
    assert "report written to" in printed
    assert all(f"{name}.md" in printed for name in demo.FAMILY_DEMOS)
    if demo.PRETRAINED_TRACK_RUN.is_dir():
        track = json.loads((out / "track_metrics.json").read_text())
        assert set(track) == {"PPO policy @ track", "resolved-rate @ track"}
        assert "RMS position error [mm]" in (out / "track.md").read_text()


@pytest.mark.slow
def test_track_demo_reports_tracking_errors(tmp_path):
    """The Track section: the shipped Track policy and resolved-rate, with finite tracking metrics."""
    if not demo.PRETRAINED_TRACK_RUN.is_dir():
        pytest.skip("no shipped Track policy")
    metrics = demo.run_track_demo(demo.PRETRAINED_TRACK_RUN, tmp_path, episodes=2)
    for m in metrics.values():
        assert m["episodes"] == 2
        assert np.isfinite(m["tracking"]["rms_position_mm"]["mean"])
    table = (tmp_path / "track.md").read_text()
    assert "| resolved-rate |" in table and "| PPO policy |" in table


@pytest.mark.slow
def test_pretrained_hexapod_policy_keeps_its_recorded_performance():
    """The shipped hexapod policy keeps its recorded success (±0.02) and singularity count (±1)."""
    run = demo.PRETRAINED_HEXAPOD_RUN
    record = json.loads((run / "regression.json").read_text())
    assert set(record) == set(REGRESSION_KEYS)
    assert record["env_id"] == "StewartGoughReach-v0"
    agent, config = load_run(run)
    assert config["env_id"] == record["env_id"]
    env = gym.make(record["env_id"])
    try:
        metrics = aggregate(evaluate_agent(agent, env, record["episodes"], record["seed"], record["targets"]))
    finally:
        env.close()
    assert_keeps_record(metrics, record)


@pytest.mark.slow
def test_demo_reports_the_hexapod(pretrained_run, tmp_path):
    """The main job's report has the hexapod section: policy, resolved-rate and planner, standard and hard, a GIF."""
    out = tmp_path / "demo"
    metrics = demo.run_hexapod_demo(demo.PRETRAINED_HEXAPOD_RUN, out, episodes=2)
    _title, _ids, runs = demo.FAMILY_DEMOS["hexapod"]
    agents = ["resolved-rate", "planner"]
    agents += [demo.policy_label(load_run(run)[1], main=i == 0) for i, run in enumerate(runs) if run.is_dir()]
    assert agents[2] == "PPO policy"
    expected = {
        f"{agent}{shield} @ {targets}"
        for agent in agents
        for shield in ("", " + shield")
        for targets in ("standard", "hard")
    }
    assert set(metrics) == expected
    assert "StewartGoughReachHard-v0" in (out / "hexapod.md").read_text()
    with Image.open(out / "hexapod_policy.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames > 2


#: The shipped 3-RPR policies besides the standard one, each with its regression.json (the plan-free policy is
#: the planner distilled by ``training.distill``: no planner at run time).
OTHER_3RPR_RUNS = [
    demo.PRETRAINED_MIXED_RUN,
    demo.PRETRAINED_TRACK_RUN,
    demo.PRETRAINED_PLAN_FREE_RUN,
    demo._pretrained("ppo-Planar3RPRReachFamily-v0"),  # one policy for a family of geometries (docs/real_robot.md)
]


@pytest.mark.slow
@pytest.mark.parametrize("run", OTHER_3RPR_RUNS, ids=lambda r: r.name)
def test_other_shipped_3rpr_policies_keep_their_recorded_performance(run):
    """The mixed-target policies (on hard targets, with their wrappers) and the Track policy keep their record."""
    if not (run / "regression.json").is_file():
        pytest.skip(f"{run.name} not shipped")
    record = json.loads((run / "regression.json").read_text())
    assert set(record) == set(REGRESSION_KEYS)
    agent, config = load_run(run)
    assert config["env_id"] == record["env_id"] in PLANAR_3RPR_IDS
    env = wrap_for_run(gym.make(record["env_id"]), config)
    targets = None if record["targets"] == "track" else record["targets"]
    try:
        metrics = aggregate(evaluate_agent(agent, env, record["episodes"], record["seed"], targets))
    finally:
        env.close()
    assert_keeps_record(metrics, record)


#: The shipped policies of the crank- and slider-driven robots and of force control, each with its regression.json.
CRANK_RUNS = [
    demo._pretrained(name)
    for name in (
        "ppo-DeltaReach-v0",
        "ppo-DeltaTrack-v0",
        "ppo-Planar3RRRReach-v0",
        "ppo-Planar3PRRReach-v0",
        "ppo-DeltaForceReach-v0",
        "ppo-StewartGoughForceReach-v0",
    )
]


@pytest.mark.slow
@pytest.mark.parametrize("run", CRANK_RUNS, ids=lambda r: r.name)
def test_shipped_crank_policies_keep_their_recorded_performance(run):
    """A shipped policy per new robot (Delta Reach, Track, 3-RRR, 3-PRR) and force control keeps its record."""
    record = json.loads((run / "regression.json").read_text())
    assert set(record) == set(REGRESSION_KEYS)
    agent, config = load_run(run)
    assert config["env_id"] == record["env_id"] == run.name.removeprefix("ppo-")
    env = gym.make(record["env_id"])
    targets = None if record["targets"] == "track" else record["targets"]
    try:
        metrics = aggregate(evaluate_agent(agent, env, record["episodes"], record["seed"], targets))
    finally:
        env.close()
    assert record["success_rate"] >= 0.9
    assert_keeps_record(metrics, record)


#: The shipped plan-free (``training.distill``) and residual policies of the other robots, and the 3-RPR's
#: force-control policies (plan-free: distilled from computed torque along the planner's path; residual PPO over
#: computed torque), with their regression.json.
PLAN_FREE_RUNS = [
    demo._pretrained(f"{kind}-{env_id}")
    for env_id in ("Planar3RRRReach-v0", "StewartGoughReachHard-v0", "DeltaReachHard-v0")
    for kind in ("distill", "ppo-residual")
] + [demo._pretrained("distill-Planar3RPRForceReach-v0"), demo._pretrained("ppo-residual-Planar3RPRForceReach-v0")]


@pytest.mark.slow
@pytest.mark.parametrize("run", PLAN_FREE_RUNS, ids=lambda r: r.name)
def test_shipped_plan_free_policies_keep_their_recorded_performance(run):
    """A plan-free or residual policy keeps its record on its robot's targets (two-sided), with its wrapper."""
    if not (run / "regression.json").is_file():
        pytest.skip(f"{run.name} not shipped")
    record = json.loads((run / "regression.json").read_text())
    assert set(record) == set(REGRESSION_KEYS)
    agent, config = load_run(run)
    wrapper = str(config.get("hyperparams", {}).get("env_wrapper"))
    residual = ("PlannerResidualWrapper", "ComputedTorqueResidualWrapper")
    assert config.get("distilled_from") == "planner" or any(name in wrapper for name in residual)
    assert config["env_id"] == record["env_id"]
    env = wrap_for_run(gym.make(record["env_id"], **run_env_kwargs(config)), config)
    try:
        metrics = aggregate(evaluate_agent(agent, env, record["episodes"], record["seed"], record["targets"]))
    finally:
        env.close()
    assert_keeps_record(metrics, record)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["delta", "planar_3rrr", "planar_3prr"])
def test_demo_reports_each_crank_robot(name, tmp_path):
    """The main job's section of each new robot: its policy, resolved-rate and the planner on its targets, a GIF."""
    metrics = demo.run_family_demo(name, tmp_path, episodes=2, shield=None)
    _title, ids, runs = demo.FAMILY_DEMOS[name]
    agents = ["resolved-rate", "planner"]
    agents += [demo.policy_label(load_run(run)[1], main=i == 0) for i, run in enumerate(runs) if run.is_dir()]
    assert "PPO policy" in agents
    assert set(metrics) == {f"{agent} @ {t}" for agent in agents for t in ids}
    text = (tmp_path / f"{name}.md").read_text()
    assert all(env_id in text for env_id in ids.values())
    with Image.open(tmp_path / f"{name}_policy.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames > 2


@pytest.mark.slow
def test_demo_reports_the_delta_on_the_adept_cycle(tmp_path):
    """The Delta's Track section: its policy and resolved-rate on the adept cycle, RMS and max errors in mm."""
    metrics = demo.run_track_demo(demo.FAMILY_TRACK_DEMOS["delta"], tmp_path, episodes=2, stem="track_delta")
    assert set(metrics) == {"PPO policy @ track", "resolved-rate @ track"}
    for m in metrics.values():
        assert 0.0 < m["tracking"]["max_position_mm"]["mean"] < 50.0
    assert "DeltaTrack-v0" in (tmp_path / "track_delta.md").read_text()


@pytest.mark.slow
def test_the_shipped_adept_policy_places_and_picks_within_a_millimetre():
    """The distilled ``DeltaForceTrack-v0`` policy keeps its adept-cycle record.

    At its recorded cycle time every place and pick error is ≤ 1 mm, the largest within 0.05 mm of the recorded one
    (two-sided).
    """
    from experiments.pick_and_place import policy_cycles

    run = demo._pretrained("distill-DeltaForceTrack-v0")
    record = json.loads((run / "regression.json").read_text())
    assert set(record) == {"env_id", "period_s", "episodes", "cycles", "max_error_mm"}
    agent, config = load_run(run)
    assert config["env_id"] == record["env_id"] == "DeltaForceTrack-v0"
    assert config["distilled_from"] == "computed-torque"
    row = policy_cycles(agent, run_env_kwargs(config), record["period_s"], record["episodes"], record["cycles"])
    worst = max(row["place_error_mm"]["max"], row["pick_error_mm"]["max"])
    assert row["ended"] == 0 and worst <= 1.0, row
    assert worst == pytest.approx(record["max_error_mm"], abs=0.05)
