"""training.policies.PlanFreeMlpPolicy: the plain network's mean through the damping of k and the in-position hold.

The oracle is SB3's own ``MlpPolicy`` holding the same weights, with the damping factor and the hold computed here
in NumPy from the raw (un-normalised) observation.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.policies import ActorCriticPolicy

from training.policies import PlanFreeMlpPolicy

D, K_INDEX, K_D = 18, 17, 0.1
POSITION, ORIENTATION = [8, 9], [10]  # a planar observation's error block: (x* − x, y* − y, wrap(φ* − φ))
RAW_MEAN = np.linspace(-0.3, 0.4, D)
RAW_SCALE = np.linspace(0.05, 0.2, D)


def _model(seed: int = 0, **overrides) -> PPO:
    torch.manual_seed(seed)
    kwargs = {
        "net_arch": [32, 32],
        "raw_mean": RAW_MEAN.tolist(),
        "raw_scale": RAW_SCALE.tolist(),
        "k_index": K_INDEX,
        "position_columns": POSITION,
        "orientation_columns": ORIENTATION,
    }
    use_sde = overrides.pop("use_sde", False)
    env = gym.make("Planar3RRRReach-v0")
    return PPO(PlanFreeMlpPolicy, env, device="cpu", use_sde=use_sde, policy_kwargs={**kwargs, **overrides})


def _observations(k: np.ndarray, error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(raw, normalised) observation batches (B, D): random entries, k and the error block (B, 3) as given."""
    raw = RAW_MEAN + RAW_SCALE * np.random.default_rng(1).normal(size=(len(k), D))
    raw[:, K_INDEX] = k
    raw[:, 8:11] = error
    return raw, ((raw - RAW_MEAN) / RAW_SCALE).astype(np.float32)


def _means(model: PPO, normalised: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the policy's mean, SB3's plain MlpPolicy's mean with the same weights) at ``normalised`` (B, D)."""
    plain = ActorCriticPolicy(model.observation_space, model.action_space, lambda _: 0.0, net_arch=[32, 32])
    plain.load_state_dict(model.policy.state_dict())
    obs = torch.as_tensor(normalised)
    with torch.no_grad():
        return (
            model.policy.get_distribution(obs).distribution.mean.numpy(),
            plain.get_distribution(obs).distribution.mean.numpy(),
        )


def test_without_a_layer_the_mean_is_the_plain_networks():
    """Neither damping nor hold: the mean is SB3's MlpPolicy's with the same weights."""
    _, obs = _observations(np.full(4, 0.01), np.zeros((4, 3)))
    gated, plain = _means(_model(), obs)
    np.testing.assert_allclose(gated, plain, rtol=1e-6)


def test_the_damped_mean_is_the_plain_networks_output_times_the_damping_of_the_raw_k():
    """The factor is clip((k / k_d)², 0.05, 1) of the un-normalised k; both clips are exercised."""
    k = np.array([0.0, 0.01, 0.03, 0.05, 0.0999, 0.1, 0.4])
    _, obs = _observations(k, np.full((len(k), 3), 0.05))
    model = _model(damping_threshold=K_D)
    gated, plain = _means(model, obs)
    factor = np.array([max(0.05, min(1.0, (value / K_D) ** 2)) for value in k])
    np.testing.assert_allclose(gated, plain * factor[:, None], rtol=1e-5, atol=1e-7)
    # the action PPO samples and its log-likelihood use the same gated mean
    with torch.no_grad():
        actions, _, log_prob = model.policy(torch.as_tensor(obs), deterministic=True)
        _, log_prob_again, _ = model.policy.evaluate_actions(torch.as_tensor(obs), actions)
    np.testing.assert_allclose(actions.numpy(), gated, rtol=1e-6)
    np.testing.assert_allclose(log_prob.numpy(), log_prob_again.numpy(), rtol=1e-6)


def test_the_hold_zeroes_the_mean_exactly_where_both_raw_errors_are_within_its_tolerances():
    """Inside: ‖(δx, δy)‖ ≤ 1 mm and |δφ| ≤ 0.005 rad, both; elsewhere the (damped) plain output."""
    error = np.array(
        [
            [0.0, 0.0, 0.0],
            [0.0006, -0.0007, 0.004],  # 0.92 mm, inside
            [0.0008, 0.0007, 0.0],  # 1.06 mm: outside
            [0.0, 0.0, -0.006],  # orientation outside
            [0.02, 0.0, 0.0],
        ]
    )
    k = np.array([0.05, 0.05, 0.05, 0.2, 0.3])
    _, obs = _observations(k, error)
    gated, plain = _means(_model(damping_threshold=K_D, hold_position=0.001, hold_orientation=0.005), obs)
    inside = np.array([np.hypot(e[0], e[1]) <= 0.001 and abs(e[2]) <= 0.005 for e in error])
    np.testing.assert_array_equal(inside, [True, True, False, False, False])
    factor = np.array([max(0.05, min(1.0, (value / K_D) ** 2)) for value in k])
    np.testing.assert_array_equal(gated[inside], 0.0)
    np.testing.assert_allclose(gated[~inside], (plain * factor[:, None])[~inside], rtol=1e-5, atol=1e-7)


def test_the_error_gain_is_the_heads_matrix_times_the_scaled_raw_error():
    """The mean is the head's 3 × 3 matrix times the raw error over the normaliser's scale; about 0 at the target.

    Oracle: the actor's MLP and head evaluated in NumPy from the state dict. At the target the raw error the policy
    recovers from the float32 normalised observation is 0 up to rounding, and so is the action.
    """
    error = np.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.3], [-0.05, 0.01, -0.1]])
    _, obs = _observations(np.array([0.3, 0.3, 0.05]), error)
    model = _model(seed=5, error_gain=True, damping_threshold=K_D)
    state = {name: value.numpy().astype(np.float64) for name, value in model.policy.state_dict().items()}
    hidden = obs.astype(np.float64)
    for layer in (0, 2):
        weight, bias = (
            state[f"mlp_extractor.policy_net.{layer}.weight"],
            state[f"mlp_extractor.policy_net.{layer}.bias"],
        )
        hidden = np.tanh(hidden @ weight.T + bias)
    gain = (hidden @ state["action_net.weight"].T + state["action_net.bias"]).reshape(3, 3, 3)
    scaled = error / RAW_SCALE[[8, 9, 10]]
    factor = np.array([1.0, 1.0, (0.05 / K_D) ** 2])
    expected = np.einsum("bij,bj->bi", gain, scaled) * factor[:, None]
    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(obs)).distribution.mean.numpy()
    np.testing.assert_allclose(mean, expected, rtol=1e-4, atol=1e-7)
    assert np.max(np.abs(mean[0])) < 1e-8
    assert np.all(np.abs(mean[1:]) > 0.0)


def test_a_saved_policy_loads_and_exports_with_its_layers(tmp_path):
    """PPO.save / PPO.load keep the class and its layers; training.export's module gives the same actions."""
    from training.export import deployed_module

    model = _model(seed=3, damping_threshold=K_D, hold_position=0.001, hold_orientation=0.005, error_gain=True)
    model.save(tmp_path / "model.zip")
    loaded = PPO.load(tmp_path / "model.zip", device="cpu")
    assert type(loaded.policy) is PlanFreeMlpPolicy
    policy = loaded.policy
    assert (policy.damping_threshold, policy.hold_position, policy.error_gain) == (K_D, 0.001, True)
    _, obs = _observations(
        np.array([0.02, 0.06, 0.3, 0.05]), np.array([[0.01, 0, 0], [0, 0, 0.1], [0.1, 0, 0], [0] * 3])
    )
    expected, _ = model.predict(obs, deterministic=True)
    again, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_array_equal(again, expected)
    assert np.all(expected[3] == 0.0) and np.all(expected[:3] != 0.0)
    with torch.no_grad():
        exported = deployed_module(loaded, None)(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(exported, expected, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"k_index": 18}, r"k_index must be integer columns in \[0, 18\), got \[18\]"),
        ({"position_columns": [8, 1.5]}, r"position_columns must be integer columns in \[0, 18\), got \[8, 1.5\]"),
        ({"raw_mean": [0.0] * 17}, "raw_mean must hold 18 finite numbers, got 17"),
        ({"raw_scale": [1.0] * 17 + [0.0]}, "raw_scale must hold 18 finite numbers > 0, got 18"),
        ({"damping_threshold": 1.5}, r"damping_threshold must be None or in \(0, 1\], got 1.5"),
        ({"hold_position": 0.001}, r"must both be None or both > 0, got \(0.001, None\)"),
        ({"hold_position": -1.0, "hold_orientation": 0.1}, r"must both be None or both > 0, got \(-1.0, 0.1\)"),
        (
            {"hold_position": 0.001, "hold_orientation": 0.1, "position_columns": []},
            "an in-position hold needs position_columns, got none",
        ),
        ({"error_gain": True, "position_columns": []}, "an error gain needs position_columns, got none"),
        ({"use_sde": True}, "use_sde must be False, got True"),
    ],
)
def test_bad_arguments_are_refused(overrides, message):
    """Each bad argument is named with the value given."""
    with pytest.raises(ValueError, match=message):
        _model(**overrides)
