"""Hyperparameter files and overrides: the shipped YAML loads, and every malformed input is a precise ConfigError."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import pytest
import torch
import yaml
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

from envs import ENV_IDS
from training.config import (
    ALGORITHMS,
    EVAL_DEFAULTS,
    NOISE_KEYS,
    NOISE_TYPES,
    RUN_KEYS,
    ConfigError,
    algorithm_class,
    default_config_path,
    load_hyperparams,
    parse_overrides,
    resolve_action_noise,
    resolve_policy_kwargs,
    resolve_schedules,
    valid_keys,
)

REACH = "Planar3RPRReach-v0"


def _write(tmp_path: Path, text: str, name: str = "hyper.yml") -> Path:
    """Write ``text`` to a YAML file under ``tmp_path`` and return its path."""
    path = tmp_path / name
    path.write_text(text)
    return path


# -- the shipped files -----------------------------------------------------------------------------


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_shipped_file_has_one_entry_per_env_id(algo):
    """training/<algo>.yml has exactly one entry for each registered env id, no stale ones."""
    data = yaml.safe_load(default_config_path(algo).read_text())
    assert set(data) == set(ENV_IDS)


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_shipped_hyperparams_load(algo, env_id):
    """Every algo × env id entry loads, holds only valid keys and sane run settings."""
    config = load_hyperparams(algo, env_id)
    assert set(config) <= valid_keys(algo)
    assert config["policy"] == "MlpPolicy"
    for key in ("n_envs", "n_timesteps"):
        assert isinstance(config[key], int) and config[key] >= 1, (key, config[key])
    assert not {"eval_freq", "n_eval_episodes"} & set(config), "run settings are flags, as in the RL Zoo"
    freq, episodes = EVAL_DEFAULTS[algo]
    assert freq >= 1 and episodes >= 1
    learning_rate = resolve_schedules(config)["learning_rate"]
    initial = learning_rate(1.0) if callable(learning_rate) else learning_rate
    assert 0.0 < initial < 1.0
    assert 0.0 < config["gamma"] <= 1.0


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_shipped_hyperparams_construct_the_algorithm(algo, env_id):
    """The algorithm arguments of every entry are accepted by the SB3 constructor (types, not just names)."""
    config = load_hyperparams(algo, env_id)
    hyper = {k: v for k, v in config.items() if k not in RUN_KEYS + NOISE_KEYS}
    hyper["policy_kwargs"] = resolve_policy_kwargs(hyper.get("policy_kwargs"))
    hyper = resolve_schedules(hyper)
    env = gym.make(env_id)
    noise = resolve_action_noise(config.get("noise_type"), config.get("noise_std"), env.action_space.shape[0])
    if noise is not None:
        hyper["action_noise"] = noise
    try:
        model = algorithm_class(algo)(config["policy"], env, device="cpu", seed=0, **hyper)
    finally:
        env.close()
    assert model.gamma == pytest.approx(config["gamma"])


def test_load_returns_a_fresh_dict():
    """Mutating a loaded config (nested values included) does not leak into the next load."""
    first = load_hyperparams("ppo", REACH)
    first["policy_kwargs"]["net_arch"].append(999)
    first["gamma"] = -1.0
    second = load_hyperparams("ppo", REACH)
    assert 999 not in second["policy_kwargs"]["net_arch"]
    assert second["gamma"] != -1.0


def test_overrides_replace_file_values():
    """Overrides win over the file and leave the other keys as the file has them."""
    base = load_hyperparams("sac", REACH)
    config = load_hyperparams("sac", REACH, overrides={"learning_rate": 1e-3, "buffer_size": 1000})
    assert config["learning_rate"] == 1e-3
    assert config["buffer_size"] == 1000
    assert config["gamma"] == base["gamma"]


# -- malformed files, entries and overrides --------------------------------------------------------


def test_unknown_key_in_file_lists_valid_keys(tmp_path):
    """An entry key the algorithm does not take is named, and the valid keys are listed."""
    path = _write(tmp_path, f"{REACH}:\n  n_envs: 1\n  learning_rat: 0.001\n")
    with pytest.raises(
        ConfigError, match=r"unknown hyperparameter\(s\) \['learning_rat'\].*valid keys: .*learning_rate"
    ):
        load_hyperparams("ppo", REACH, path)


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_unknown_override_lists_valid_keys(algo):
    """An override key the algorithm does not take is named, and the valid keys are listed."""
    with pytest.raises(ConfigError, match=r"\['bogus_key'\].*valid keys: .*'gamma'.*'n_envs'"):
        load_hyperparams(algo, REACH, overrides={"bogus_key": 1})


def test_key_of_another_algorithm_is_rejected():
    """PPO's gae_lambda is not a SAC argument: keys are checked against the algorithm's own constructor."""
    assert "gae_lambda" in valid_keys("ppo")
    with pytest.raises(ConfigError, match=r"\['gae_lambda'\] for SAC"):
        load_hyperparams("sac", REACH, overrides={"gae_lambda": 0.9})


@pytest.mark.parametrize("reserved", ["seed", "env", "device", "verbose"])
def test_keys_set_by_the_script_are_rejected(reserved):
    """seed, env, device and verbose belong to the training script, never to a config."""
    with pytest.raises(ConfigError, match=reserved):
        load_hyperparams("ppo", REACH, overrides={reserved: 0})


def test_unknown_env_entry_lists_entries(tmp_path):
    """A file without an entry for the env id names it and lists the entries it has."""
    with pytest.raises(ConfigError, match=r"no entry for env 'Nope-v0'; entries: \[.*'Planar3RPRReach-v0'"):
        load_hyperparams("ppo", "Nope-v0")
    path = _write(tmp_path, "A-v0: {n_envs: 1}\nB-v0: {n_envs: 2}\n")
    with pytest.raises(ConfigError, match=r"entries: \['A-v0', 'B-v0'\]"):
        load_hyperparams("ppo", REACH, path)


def test_missing_file(tmp_path):
    """A file that does not exist is a ConfigError naming the path."""
    path = tmp_path / "missing.yml"
    with pytest.raises(ConfigError, match=r"missing\.yml.* does not exist"):
        load_hyperparams("ppo", REACH, path)


@pytest.mark.parametrize("text", [f"{REACH}: {{n_envs: [1, 2\n", f"{REACH}:\n  n_envs: 1\n n_steps: 64\n\t: x\n"])
def test_invalid_yaml(tmp_path, text):
    """Unparsable YAML is a ConfigError saying so, not a yaml exception."""
    with pytest.raises(ConfigError, match="is not valid YAML"):
        load_hyperparams("ppo", REACH, _write(tmp_path, text))


@pytest.mark.parametrize(("text", "kind"), [("- a\n- b\n", "list"), ("42\n", "int"), ("", "NoneType")])
def test_non_mapping_file(tmp_path, text, kind):
    """A file whose content is not a mapping of env ids is a ConfigError naming what it holds."""
    with pytest.raises(ConfigError, match=f"must map env ids to settings, got {kind}"):
        load_hyperparams("ppo", REACH, _write(tmp_path, text))


def test_non_mapping_entry(tmp_path):
    """An env entry that is not a mapping is a ConfigError naming the entry."""
    with pytest.raises(ConfigError, match=f"entry '{REACH}' .* must be a mapping, got list"):
        load_hyperparams("ppo", REACH, _write(tmp_path, f"{REACH}: [1, 2]\n"))


@pytest.mark.parametrize("bad", ["A2C", "dqn", "", "pp0"])
def test_unknown_algorithm_lists_choices(bad):
    """An unknown algorithm is a ConfigError listing ppo, sac, td3 and tqc."""
    with pytest.raises(ConfigError, match=r"unknown algorithm .*valid choices: \['ppo', 'sac', 'td3', 'tqc'\]"):
        load_hyperparams(bad, REACH)
    with pytest.raises(ConfigError, match=r"\['ppo', 'sac', 'td3', 'tqc'\]"):
        algorithm_class(bad)


@pytest.mark.parametrize("algo", ["PPO", "Sac", "td3"])
def test_algorithm_names_are_case_insensitive(algo):
    """Algorithm names resolve regardless of case."""
    assert algorithm_class(algo) is ALGORITHMS[algo.lower()]


@pytest.mark.parametrize("key", ["n_envs", "n_timesteps"])
@pytest.mark.parametrize("value", [0, -3, 2.5, True, "4", None])
def test_counts_must_be_positive_integers(key, value):
    """n_envs and n_timesteps must be positive integers (0, negatives, floats, bools, strings rejected)."""
    with pytest.raises(ConfigError, match=f"{key} must be a positive integer"):
        load_hyperparams("ppo", REACH, overrides={key: value})


def test_zero_n_envs_in_file_rejected(tmp_path):
    """n_envs: 0 written in a YAML file is rejected like the override."""
    with pytest.raises(ConfigError, match="n_envs must be a positive integer, got 0"):
        load_hyperparams("td3", REACH, _write(tmp_path, f"{REACH}:\n  n_envs: 0\n"))


# -- safe loading ----------------------------------------------------------------------------------


def test_python_tags_in_file_are_rejected_not_executed(tmp_path):
    """A !!python tag in a hyperparameter file is a ConfigError and the code it names never runs."""
    trace = tmp_path / "executed"
    text = f"{REACH}:\n  n_envs: !!python/object/apply:builtins.open [{str(trace)!r}, 'w']\n"
    with pytest.raises(ConfigError, match="is not valid YAML"):
        load_hyperparams("ppo", REACH, _write(tmp_path, text))
    assert not trace.exists()
    with pytest.raises(ConfigError, match="is not valid YAML"):
        load_hyperparams("ppo", REACH, _write(tmp_path, f"{REACH}:\n  policy: !!python/object:object {{}}\n"))


def test_python_tags_in_overrides_are_rejected_not_executed(tmp_path):
    """A !!python tag in a --hyperparams value is a ConfigError and the code it names never runs."""
    trace = tmp_path / "executed"
    item = f"n_envs=!!python/object/apply:builtins.open [{str(trace)!r}, 'w']"
    with pytest.raises(ConfigError, match="not valid YAML"):
        parse_overrides([item])
    assert not trace.exists()


# -- parse_overrides -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("item", "key", "value"),
    [
        ("learning_rate=1e-3", "learning_rate", 1e-3),
        ("ent_coef=5e-3", "ent_coef", 5e-3),
        ("learning_rate=3.0e-4", "learning_rate", 3.0e-4),
        ("learning_rate=0.001", "learning_rate", 0.001),
        ("n_envs=4", "n_envs", 4),
        ("normalize=false", "normalize", False),
        ("policy=MlpPolicy", "policy", "MlpPolicy"),
        ("policy_kwargs={net_arch: [64, 64]}", "policy_kwargs", {"net_arch": [64, 64]}),
        ("normalize={norm_obs: true, norm_reward: false}", "normalize", {"norm_obs": True, "norm_reward": False}),
        (" gamma =0.9", "gamma", 0.9),
    ],
)
def test_parse_overrides_values(item, key, value):
    """Values are YAML: floats (1e-3 included), ints, booleans, strings and flow mappings."""
    parsed = parse_overrides([item])
    assert parsed == {key: value}
    assert type(parsed[key]) is type(value)


def test_exponent_float_in_file_is_a_float(tmp_path):
    """learning_rate: 1e-3 in a hyperparameter file loads as the float 0.001, as any YAML reader of 1.2 does."""
    config = load_hyperparams("ppo", REACH, _write(tmp_path, f"{REACH}:\n  learning_rate: 1e-3\n"))
    assert config["learning_rate"] == 1e-3
    assert isinstance(config["learning_rate"], float)


def test_parse_overrides_several_and_none():
    """Several items give one dict; None or an empty list give an empty dict."""
    assert parse_overrides(["gamma=0.9", "n_epochs=3"]) == {"gamma": 0.9, "n_epochs": 3}
    assert parse_overrides(None) == {}
    assert parse_overrides([]) == {}


@pytest.mark.parametrize("item", ["novalue", "=5", "  =1", ""])
def test_parse_overrides_rejects_items_without_key_and_value(item):
    """An item without '=' or without a key is a ConfigError showing the expected form."""
    with pytest.raises(ConfigError, match="must look like key=value"):
        parse_overrides([item])


@pytest.mark.parametrize("item", ["policy_kwargs={net_arch: [64, 64]", "gamma=[1, 2", "x=a: b: c"])
def test_parse_overrides_rejects_unparsable_values(item):
    """A value that is not valid YAML is a ConfigError naming the item."""
    with pytest.raises(ConfigError, match="not valid YAML"):
        parse_overrides([item])


# -- policy_kwargs ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["ReLU", "Tanh", "ELU", "LeakyReLU", "GELU", "SiLU"])
def test_activation_name_becomes_torch_class(name):
    """policy_kwargs.activation_fn given by name becomes the torch.nn class; other keys are kept."""
    given = {"net_arch": [64, 64], "activation_fn": name}
    resolved = resolve_policy_kwargs(given)
    assert resolved["activation_fn"] is getattr(torch.nn, name)
    assert resolved["net_arch"] == [64, 64]
    assert given["activation_fn"] == name, "the YAML form must not be mutated"


@pytest.mark.parametrize("name", ["Sigmoid", "relu", "torch.nn.ReLU", "nn.Tanh", "__import__('os')"])
def test_unknown_activation_rejected(name):
    """An activation name outside the allowed list is a ConfigError listing the allowed ones."""
    with pytest.raises(ConfigError, match=r"activation_fn .* is not one of \['ReLU', 'Tanh'"):
        resolve_policy_kwargs({"activation_fn": name})


def test_policy_kwargs_without_activation():
    """No policy_kwargs gives an empty dict; without activation_fn the dict is returned as a copy."""
    assert resolve_policy_kwargs(None) == {}
    given = {"net_arch": [32]}
    resolved = resolve_policy_kwargs(given)
    assert resolved == given and resolved is not given


# -- exploration noise (RL Zoo keys noise_type / noise_std) ---------------------------------------


@pytest.mark.parametrize(
    ("name", "cls"), [("normal", NormalActionNoise), ("ornstein-uhlenbeck", OrnsteinUhlenbeckActionNoise)]
)
def test_noise_keys_become_sb3_noise(name, cls):
    """noise_type / noise_std give SB3's noise with zero mean and σ in every action dimension."""
    noise = resolve_action_noise(name, 0.2, 3)
    assert isinstance(noise, cls)
    assert noise._mu.tolist() == [0.0, 0.0, 0.0]
    assert noise._sigma.tolist() == [0.2, 0.2, 0.2]


def test_no_noise_type_means_no_noise():
    """Without the keys there is no noise object (SAC and TQC explore through their entropy)."""
    assert resolve_action_noise(None, None, 3) is None


@pytest.mark.parametrize(
    ("noise_type", "noise_std", "message"),
    [
        ("gaussian", 0.1, "noise_type 'gaussian' is not one of ['normal', 'ornstein-uhlenbeck']"),
        ("normal", None, "noise_std must be a positive number with noise_type 'normal', got None"),
        ("normal", 0.0, "noise_std must be a positive number with noise_type 'normal', got 0.0"),
        ("normal", -0.1, "noise_std must be a positive number"),
        ("normal", float("nan"), "noise_std must be a positive number"),
        ("normal", "0.1", "noise_std must be a positive number"),
        ("normal", True, "noise_std must be a positive number"),
        (None, 0.1, "noise_std 0.1 needs a noise_type, one of ['normal', 'ornstein-uhlenbeck']"),
    ],
)
def test_bad_noise_entries_are_refused(noise_type, noise_std, message):
    """Every malformed noise entry is a ConfigError naming the expected and the actual value."""
    with pytest.raises(ConfigError, match=re.escape(message)):
        resolve_action_noise(noise_type, noise_std, 3)


@pytest.mark.parametrize("algo", ["sac", "td3", "tqc"])
def test_off_policy_algorithms_take_noise_keys_not_action_noise(algo):
    """action_noise (an object) is replaced by the two YAML keys for the algorithms that take it."""
    keys = valid_keys(algo)
    assert set(NOISE_KEYS) <= keys and "action_noise" not in keys
    config = load_hyperparams(algo, REACH, overrides={"noise_type": "normal", "noise_std": 0.1})
    assert config["noise_type"] == "normal" and config["noise_std"] == 0.1


def test_ppo_refuses_noise_keys():
    """PPO's policy is stochastic and takes no action noise: the keys are unknown there."""
    with pytest.raises(ConfigError, match=r"unknown hyperparameter\(s\) \['noise_type'\] for PPO"):
        load_hyperparams("ppo", REACH, overrides={"noise_type": "normal"})


def test_noise_types_are_sb3_classes():
    """Every name in NOISE_TYPES is a class of SB3's noise module."""
    from stable_baselines3.common import noise

    for class_name in NOISE_TYPES.values():
        assert isinstance(getattr(noise, class_name), type)


def test_env_wrapper_with_arguments_in_the_rl_zoo_form():
    """{name: {keyword: value}} binds the wrapper's arguments; malformed or unknown entries are refused clearly."""
    import gymnasium as gym

    from training.config import resolve_env_wrapper

    wrapper = resolve_env_wrapper({"robot_control.PlannerWaypointWrapper": {"lookahead": 0.05}})
    env = wrapper(gym.make("Planar3RPRReach-v0"))
    assert env.follower.lookahead == 0.05
    assert resolve_env_wrapper({"envs.GoalReachWrapper": None}) is resolve_env_wrapper("envs.GoalReachWrapper")
    with pytest.raises(ConfigError, match=r"env_wrapper must be a name or \{name: \{keyword: value\}\}"):
        resolve_env_wrapper({"envs.GoalReachWrapper": {}, "robot_control.PlannerWaypointWrapper": {}})
    with pytest.raises(ConfigError, match=r"env_wrapper 'os.system' is not one of"):
        resolve_env_wrapper({"os.system": {"command": "true"}})
