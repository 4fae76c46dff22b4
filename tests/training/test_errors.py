"""Bad input to the train and evaluate CLIs is one clear line on stderr and exit status 2, never a traceback."""

from __future__ import annotations

import re

import pytest

from envs import ENV_IDS
from tests.training.conftest import REACH
from training import evaluate, train
from training.config import ConfigError

ENV_CHOICES = re.escape(str(list(ENV_IDS)))


def _exit_message(main, argv: list[str], capsys) -> str:
    """Run a CLI main, assert it exits with status 2 (argparse's usage error) and return its stderr."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert captured.err.startswith("usage: "), captured.err
    return captured.err


# -- evaluate --------------------------------------------------------------------------------------


def test_evaluate_missing_run_folder(tmp_path, capsys):
    """A run folder that does not exist is named."""
    err = _exit_message(evaluate.main, ["--run", str(tmp_path / "nope"), "--out", str(tmp_path / "o")], capsys)
    assert re.search(r"error: run folder '.*nope' does not exist", err), err


def test_evaluate_folder_without_config(tmp_path, capsys):
    """A folder without config.yml is not a run folder, and the message lists what it holds."""
    folder = tmp_path / "not-a-run"
    folder.mkdir()
    (folder / "model.zip").write_bytes(b"")
    err = _exit_message(evaluate.main, ["--run", str(folder), "--out", str(tmp_path / "o")], capsys)
    assert "is not a run folder: no config.yml (it holds ['model.zip'])" in err


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("algo: [ppo\nenv_id: x\n", "is corrupt"),
        ("just some text\n", "is corrupt: it must name 'algo' and 'env_id'"),
        ("algo: ppo\n", "is corrupt: it must name 'algo' and 'env_id'"),
        ("- algo\n- env_id\n", "is corrupt: it must name 'algo' and 'env_id'"),
    ],
)
def test_evaluate_corrupt_config(tmp_path, capsys, text, expected):
    """An unparsable or incomplete config.yml is reported as corrupt, naming the file."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yml").write_text(text)
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert "config.yml' " + expected in err, err


def test_evaluate_config_with_unknown_algorithm(make_run_folder, tmp_path, capsys):
    """A config.yml naming an algorithm the project does not train lists the valid ones."""
    run = make_run_folder("ppo")
    (run / "config.yml").write_text((run / "config.yml").read_text().replace("algo: ppo", "algo: a2c"))
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert "unknown algorithm 'a2c'; valid choices: ['ppo', 'sac', 'td3', 'tqc']" in err


def test_evaluate_config_with_unknown_env(make_run_folder, tmp_path, capsys):
    """A config.yml naming an unregistered env id lists the valid ids."""
    run = make_run_folder("ppo")
    (run / "config.yml").write_text((run / "config.yml").read_text().replace(REACH, "Planar3RPRReach-v9"))
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert re.search(f"unknown env id 'Planar3RPRReach-v9'; valid choices: {ENV_CHOICES}", err), err


@pytest.mark.parametrize("content", [b"", b"garbage bytes, not a zip archive" * 10, b"PK\x03\x04 truncated"])
def test_evaluate_corrupt_model(make_run_folder, tmp_path, capsys, content):
    """A damaged model.zip is reported as unloadable, naming the file."""
    run = make_run_folder("ppo")
    (run / "model.zip").write_bytes(content)
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert re.search(r"error: cannot load '.*model\.zip'", err), err


def test_evaluate_missing_model(make_run_folder, tmp_path, capsys):
    """A run folder without model.zip (or best_model.zip for --model best) names the missing file."""
    run = make_run_folder("sac")
    err = _exit_message(evaluate.main, ["--run", str(run), "--model", "best", "--out", str(tmp_path / "o")], capsys)
    assert "has no best_model.zip" in err
    (run / "model.zip").unlink()
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert "has no model.zip" in err


def test_evaluate_unknown_model_choice(make_run_folder, tmp_path, capsys):
    """--model other than final or best lists the two choices."""
    run = make_run_folder("ppo")
    err = _exit_message(evaluate.main, ["--run", str(run), "--model", "last", "--out", str(tmp_path / "o")], capsys)
    assert "--model must be one of ['best', 'final'], got 'last'" in err


def test_evaluate_missing_or_corrupt_normalisation(make_run_folder, tmp_path, capsys):
    """A normalising run without (or with a damaged) vecnormalize.pkl (best_vecnormalize.pkl for best) names it."""
    run = make_run_folder("td3")
    (run / "vecnormalize.pkl").write_bytes(b"\x80\x04not a pickle")
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert re.search(r"cannot load '.*vecnormalize\.pkl'", err), err
    (run / "vecnormalize.pkl").unlink()
    err = _exit_message(evaluate.main, ["--run", str(run), "--out", str(tmp_path / "o")], capsys)
    assert "normalises observations but has no vecnormalize.pkl" in err
    (run / "best_model.zip").write_bytes((run / "model.zip").read_bytes())
    err = _exit_message(evaluate.main, ["--run", str(run), "--model", "best", "--out", str(tmp_path / "o")], capsys)
    assert "normalises observations but has no best_vecnormalize.pkl" in err


@pytest.mark.parametrize("name", ["pid", "resolved_rate", "Resolved-Rate", ""])
def test_evaluate_unknown_controller(tmp_path, capsys, name):
    """An unknown controller name lists the valid ones."""
    err = _exit_message(evaluate.main, ["--controller", name, "--episodes", "1", "--out", str(tmp_path)], capsys)
    valid = "['computed-torque', 'planner', 'planner-computed-torque', 'resolved-rate', 'singularity-aware']"
    assert f"unknown controller {name!r}; valid choices: {valid}" in err


@pytest.mark.parametrize("value", ["0", "1.5", "-0.1"])
def test_evaluate_bad_shield_guard(tmp_path, capsys, value):
    """A shield guard outside (0, 1) is refused with the expected range and the value given."""
    argv = ["--controller", "resolved-rate", "--shield", value, "--episodes", "1", "--out", str(tmp_path)]
    err = _exit_message(evaluate.main, argv, capsys)
    assert f"--shield: k_guard must be a number in (0, 1), got {float(value)!r}" in err, err


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v1", "CartPole-v1", "reach"])
def test_evaluate_unknown_env(tmp_path, capsys, env_id):
    """An env id outside ENV_IDS (even one Gymnasium knows) lists the valid ids."""
    argv = ["--controller", "resolved-rate", "--env", env_id, "--episodes", "1", "--out", str(tmp_path)]
    err = _exit_message(evaluate.main, argv, capsys)
    assert re.search(f"unknown env id {re.escape(repr(env_id))}; valid choices: {ENV_CHOICES}", err), err


def test_evaluate_hard_targets_on_track(tmp_path, capsys):
    """--targets hard on the Track env says --targets applies only to Reach."""
    argv = ["--controller", "resolved-rate", "--env", "Planar3RPRTrack-v0", "--targets", "hard", "--episodes", "1"]
    err = _exit_message(evaluate.main, [*argv, "--out", str(tmp_path)], capsys)
    assert "--targets applies only to the Reach environments, not Planar3RPRTrack-v0" in err


def test_evaluate_unknown_targets(tmp_path, capsys):
    """--targets other than standard or hard lists the two choices."""
    argv = ["--controller", "resolved-rate", "--targets", "medium", "--episodes", "1", "--out", str(tmp_path)]
    err = _exit_message(evaluate.main, argv, capsys)
    assert "--targets must be one of ['standard', 'hard'], got 'medium'" in err


@pytest.mark.parametrize("episodes", ["0", "-2"])
def test_evaluate_episodes_must_be_positive(tmp_path, capsys, episodes):
    """--episodes below 1 is rejected, quoting the value."""
    argv = ["--controller", "resolved-rate", "--episodes", episodes, "--out", str(tmp_path / "o")]
    err = _exit_message(evaluate.main, argv, capsys)
    assert f"--episodes must be ≥ 1, got {episodes}" in err
    assert not (tmp_path / "o").exists(), "nothing is written for rejected options"


def test_evaluate_needs_exactly_one_source(tmp_path, capsys):
    """Neither or both of --run and --controller is an argparse usage error."""
    err = _exit_message(evaluate.main, ["--episodes", "1"], capsys)
    assert "one of the arguments --run --controller is required" in err
    err = _exit_message(evaluate.main, ["--run", str(tmp_path), "--controller", "resolved-rate"], capsys)
    assert "not allowed with argument" in err


@pytest.mark.parametrize("normalize", [False, True])
def test_evaluate_run_on_incompatible_env(make_run_folder, tmp_path, capsys, normalize):
    """A Reach run evaluated with --env Planar3RPRTrack-v0 (other observation shape) is a clear error."""
    run = make_run_folder("ppo", normalize=normalize)
    argv = ["--run", str(run), "--env", "Planar3RPRTrack-v0", "--episodes", "1", "--out", str(tmp_path / "o")]
    err = _exit_message(evaluate.main, argv, capsys)
    assert "Planar3RPRTrack-v0" in err and "observation" in err


# -- train -----------------------------------------------------------------------------------------


def _train_argv(tmp_path, *extra: str, algo: str = "ppo", env_id: str = REACH) -> list[str]:
    """Arguments of train.main writing into tmp_path, with the given extras."""
    return ["--algo", algo, "--env", env_id, "--run-dir", str(tmp_path / "run"), "--no-progress-bar", *extra]


@pytest.mark.parametrize("algo", ["a2c", "dqn", "ppo2"])
def test_train_unknown_algorithm(tmp_path, capsys, algo):
    """--algo outside ppo/sac/td3 lists the valid algorithms and writes nothing."""
    err = _exit_message(train.main, _train_argv(tmp_path, algo=algo), capsys)
    assert f"unknown algorithm {algo!r}; valid choices: ['ppo', 'sac', 'td3', 'tqc']" in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v1", "Pendulum-v1"])
def test_train_unknown_env(tmp_path, capsys, env_id):
    """--env outside ENV_IDS lists the valid ids and writes nothing."""
    err = _exit_message(train.main, _train_argv(tmp_path, env_id=env_id), capsys)
    assert re.search(f"unknown env id {re.escape(repr(env_id))}; valid choices: {ENV_CHOICES}", err), err
    assert not (tmp_path / "run").exists()


def test_train_unknown_hyperparameter(tmp_path, capsys):
    """--hyperparams with a key the algorithm does not take names it and lists the valid keys."""
    err = _exit_message(train.main, _train_argv(tmp_path, "--hyperparams", "bogus_key=1"), capsys)
    assert "unknown hyperparameter(s) ['bogus_key'] for PPO" in err
    assert re.search(r"valid keys: \[.*'learning_rate'.*'n_steps'", err), err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("item", ["novalue", "policy_kwargs={net_arch: [64"])
def test_train_malformed_hyperparameter(tmp_path, capsys, item):
    """A --hyperparams item that is not key=<YAML value> is named."""
    err = _exit_message(train.main, _train_argv(tmp_path, "--hyperparams", item), capsys)
    assert f"override {item!r}" in err


@pytest.mark.parametrize(("flag", "value"), [("--timesteps", "0"), ("--timesteps", "-100"), ("--n-envs", "0")])
def test_train_counts_must_be_positive(tmp_path, capsys, flag, value):
    """--timesteps and --n-envs below 1 are rejected before anything is written."""
    err = _exit_message(train.main, _train_argv(tmp_path, flag, value), capsys)
    assert f"{flag} must be ≥ 1, got {value}" in err
    assert not (tmp_path / "run").exists()


def test_train_missing_config_file(tmp_path, capsys):
    """--config pointing to a missing file names it."""
    err = _exit_message(train.main, _train_argv(tmp_path, "--config", str(tmp_path / "missing.yml")), capsys)
    assert "missing.yml' does not exist" in err


def test_train_unknown_vectorisation(tmp_path, capsys):
    """--vec other than dummy or subproc lists the two choices."""
    err = _exit_message(train.main, _train_argv(tmp_path, "--vec", "threads", "--timesteps", "64"), capsys)
    assert {"dummy", "subproc"} <= set(train.VEC_KINDS)
    assert f"unknown vectorisation 'threads'; valid choices: {list(train.VEC_KINDS)}" in err


def test_train_unknown_vectorisation_writes_nothing(tmp_path, capsys):
    """A rejected --vec leaves no half-written run folder behind (one that evaluate would take for a run)."""
    _exit_message(train.main, _train_argv(tmp_path, "--vec", "threads", "--timesteps", "64"), capsys)
    assert not (tmp_path / "run").exists(), sorted(p.name for p in (tmp_path / "run").iterdir())


@pytest.mark.parametrize("kwargs", [{"n_envs": 0}, {"timesteps": 0}, {"timesteps": -5}, {"n_envs": -1}])
def test_train_function_validates_counts(tmp_path, kwargs):
    """train() itself (not only main) rejects non-positive timesteps and n_envs with a ConfigError."""
    overrides = {"n_steps": 64, "batch_size": 64}
    kwargs = {"timesteps": 64, "n_envs": 1, **kwargs}
    with pytest.raises(ConfigError, match=r"timesteps|n_envs"):
        train.train("ppo", REACH, run_dir=tmp_path / "run", overrides=overrides, progress_bar=False, **kwargs)
