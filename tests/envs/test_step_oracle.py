"""Every pose space and actuator kind against the NumPy oracle of ``tests.envs.oracle``, reasons exactly.

Random rollouts compare everything a step returns (observation, reward, each reward term, the termination reason,
the new q and x) with the oracle. Boundary cases then put each threshold that decides a reason on both sides of a
value the oracle computed: an episode is recorded, a step is picked where the quantity reaches a new extreme, and
the episode is replayed in an env whose threshold sits a relative 1e-6 above and below that value; the reason at
that step must flip exactly as the oracle says. The replays use ``gym.make(id, **kwargs)`` and the same seed,
and check that the threshold did not change the episode's start.
"""

from __future__ import annotations

from collections.abc import Callable

import gymnasium as gym
import numpy as np
import pytest

from tests.envs import oracle

#: The 3-PRR with room to reach its Type II singularities: wider pose bounds, no Type I termination.
WIDE_3PRR = {"pose_low": (-0.3, -0.3, -1.4), "pose_high": (0.3, 0.3, 1.4), "actuator_hard_threshold": 0.0}
#: Per pose space and actuator kind: (id, keyword arguments, exploring policies) of its Reach id, and of a
#: sibling that brings k below k_safe (hard targets followed by "toward", or a wider workspace).
CASES = {
    "planar legs": (
        ("Planar3RPRReach-v0", {}, ("random", "drift")),
        ("Planar3RPRReachHard-v0", {}, ("toward", "random")),
    ),
    "spatial legs": (
        ("StewartGoughReach-v0", {}, ("random", "drift")),
        ("StewartGoughReachHard-v0", {}, ("toward", "random")),
    ),
    "translational cranks": (
        ("DeltaReach-v0", {}, ("random", "drift")),
        ("DeltaReachHard-v0", {}, ("toward", "random")),
    ),
    "planar cranks": (
        ("Planar3RRRReach-v0", {}, ("random", "drift")),
        ("Planar3RRRReachHard-v0", {}, ("toward", "random")),
    ),
    "planar sliders": (
        ("Planar3PRRReach-v0", {}, ("random", "drift")),
        ("Planar3PRRReach-v0", WIDE_3PRR, ("drift", "random")),
    ),
}
TYPE_ONE = ("translational cranks", "planar cranks", "planar sliders")
#: Weights unlike each other and unlike the defaults, so that a term read with another's weight shows.
WEIGHTS = {
    "position_weight": 0.8,
    "orientation_weight": 1.3,
    "singularity_weight": 1.7,
    "action_weight": 0.05,
    "termination_penalty": 37.0,
    "success_reward": 4.0,
}
TYPE_ONE_WEIGHTS = {"actuator_singularity_weight": 2.3}
#: The relative offset of a threshold from the value it brackets.
MARGIN = 1e-6


def make(env_id: str, **kwargs) -> gym.Env:
    """The unwrapped env of ``env_id`` with ``kwargs`` (no time limit: the tests end episodes themselves)."""
    return gym.make(env_id, **kwargs).unwrapped


def policy(name: str, seed: int) -> Callable[[gym.Env, oracle.Settings], np.ndarray]:
    """A deterministic exploring policy: "random" actions in [−1.5, 1.5], a noisy "drift" or "toward" the target.

    "toward" follows the straight line to the target (q̇ = J_i Δx, saturated at 1.2), which leads hard targets
    through the ill-conditioned zone; "drift" keeps one random direction, which meets the pose bounds and the
    stroke limits. Out-of-range actions exercise the clipping.
    """
    rng = np.random.default_rng(seed)
    direction: list[np.ndarray] = []

    def act(env: gym.Env, settings: oracle.Settings) -> np.ndarray:
        n = env.action_space.shape[0]
        if name == "random":
            return rng.uniform(-1.5, 1.5, n)
        if name == "drift":
            if not direction:
                direction.append(rng.uniform(-1.5, 1.5, n))
            return direction[0] + rng.normal(0.0, 0.5, n)
        state = oracle.state_of(env)
        robot = settings.robot
        error = robot.pose_difference(state.target, state.x, validate=False)
        with np.errstate(all="ignore"):
            rate = robot.inverse_jacobian(state.q, state.x, validate=False) @ error
        peak = float(np.max(np.abs(rate)))
        toward = rate / peak * 1.2 if np.isfinite(peak) and peak > 0 else np.zeros(n)
        return toward + rng.normal(0.0, 0.3, n)

    return act


def assert_step_matches(env: gym.Env, settings: oracle.Settings, result: tuple, expected: oracle.Outcome) -> bool:
    """Assert a step's results equal the oracle's; False (reason not compared) where a threshold is too close."""
    obs, reward, terminated, truncated, info = result
    state = env.state
    np.testing.assert_allclose(state.x[0], expected.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(state.q[0], expected.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(info["pose"], expected.x, rtol=0, atol=1e-9)
    assert info["inverse_condition_number"] == pytest.approx(expected.k, abs=1e-9)
    if oracle.near_threshold(settings, expected):
        return False
    assert info["termination_reason"] == expected.reason
    assert terminated == bool(expected.reason) and not truncated
    for key, value in expected.info.items():
        if isinstance(value, bool):
            assert info[key] is value, key
        else:
            assert info[key] == pytest.approx(value, abs=1e-9), key
    assert reward == pytest.approx(expected.reward, abs=1e-9)
    assert abs(info["constraint_residual"] - expected.residual) <= settings.newton_tolerance
    np.testing.assert_allclose(obs, expected.observation, rtol=0, atol=2e-6)
    return True


@pytest.mark.parametrize("integrator", ["euler", "rk4"])
@pytest.mark.parametrize("case", list(CASES))
def test_random_steps_match_the_oracle(case, integrator):
    """Random, drifting and target-seeking rollouts: every step as the oracle says, reasons exactly."""
    kwargs = {"integrator": integrator}
    if integrator == "euler":  # custom weights on one integrator, the defaults on the other
        kwargs.update(WEIGHTS, **(TYPE_ONE_WEIGHTS if case in TYPE_ONE else {}))
    compared = skipped = low_k = low_k1 = clamped = 0
    reasons: dict[str, int] = {}
    for env_id, extra, names in CASES[case]:
        env = make(env_id, **extra, **kwargs)
        settings = oracle.settings_of(env)
        lo, hi = settings.stroke_limits
        for episode in range(8):
            env.reset(seed=episode)
            act = policy(names[episode % 2], episode)
            for _ in range(60):
                action = act(env, settings)
                start = oracle.state_of(env)
                expected = oracle.step(settings, start, action, env.observation_space)
                result = env.step(action)
                if assert_step_matches(env, settings, result, expected):
                    compared += 1
                else:
                    skipped += 1
                reasons[expected.reason] = reasons.get(expected.reason, 0) + 1
                low_k += expected.k < settings.safe_threshold
                low_k1 += settings.type_one and expected.k1 < settings.actuator_safe_threshold
                command = start.q + np.clip(action, -1, 1) * settings.max_rate * settings.dt
                clamped += bool(np.any((command < lo) | (command > hi)))
                if expected.reason:
                    break
    assert skipped <= 0.01 * compared, f"{skipped} steps within 1e-9 of a threshold"
    assert compared >= 200
    assert low_k >= 5, "too few steps where the Type II penalty is active"
    if case in TYPE_ONE:
        assert low_k1 >= 3, "too few steps where the Type I penalty is active"
    assert sum(count for reason, count in reasons.items() if reason) >= 3, reasons
    if case not in ("planar cranks", "planar sliders"):  # these meet their pose bounds before their limits
        assert clamped >= 10, "too few steps at the stroke limits"


# -- boundary cases -------------------------------------------------------------------------------------------


def record(env_id: str, seed: int, name: str, steps: int = 120, **kwargs) -> tuple:
    """An episode of ``policy(name, seed)`` from ``reset(seed=seed)``: its start, actions and the oracle's outcomes."""
    env = make(env_id, **kwargs)
    settings = oracle.settings_of(env)
    env.reset(seed=seed)
    start = oracle.state_of(env)
    act = policy(name, seed)
    actions, outcomes = [], []
    for _ in range(steps):
        action = act(env, settings)
        outcome = oracle.step(settings, oracle.state_of(env), action, env.observation_space)
        env.step(action)
        actions.append(action)
        outcomes.append(outcome)
        if outcome.reason:
            break
    return start, actions, outcomes


def replay(env_id: str, seed: int, actions: list, start: oracle.StartState, options=None, **kwargs) -> list | None:
    """Replay ``actions`` in ``gym.make(env_id, **kwargs)`` from ``start``: each step's reason, checked.

    Every step is checked against the oracle with the new settings. None if the reset did not give ``start``
    (a threshold that shapes the task sampler, as the hard tasks' thresholds do, can change the episode, or leave
    no task at all: an ill-conditioned band 2 k_hard ≤ k < k_safe that is empty).
    """
    env = make(env_id, **kwargs)
    settings = oracle.settings_of(env)
    try:
        env.reset(seed=seed, options=options)
    except RuntimeError as exc:
        if "no certified" not in str(exc):
            raise
        return None
    again = oracle.state_of(env)
    if not (np.array_equal(again.x, start.x) and np.array_equal(again.target, start.target)):
        return None
    reasons = []
    for action in actions:
        expected = oracle.step(settings, oracle.state_of(env), action, env.observation_space)
        assert assert_step_matches(env, settings, env.step(action), expected)
        reasons.append(expected.reason)
        if expected.reason:
            break
    return reasons


def candidates(entries, pick: Callable, seeds: int = 20):
    """Recorded episodes (each id, keyword arguments and policy of ``entries``, seeds 0–19) where ``pick`` finds a step.

    Yields:
        (id, keyword arguments, seed, start, the actions up to the step, the outcomes, the step).
    """
    for seed in range(seeds):
        for env_id, kwargs, names in entries:
            for name in names:
                start, actions, outcomes = record(env_id, seed, name, **kwargs)
                t = pick(start, outcomes)
                if t is not None:
                    yield env_id, kwargs, seed, start, actions[: t + 1], outcomes, t


def assert_both_sides(entries, pick: Callable, sides: Callable, options: Callable | None = None) -> None:
    """Find a boundary case and assert the reasons its two replays give.

    Args:
        entries: (id, keyword arguments, policies) to explore.
        pick: (start, outcomes) → the step of the boundary case, or None.
        sides: (id kwargs, outcomes, step) → ((kwargs, expected reasons), (kwargs, expected reasons)).
        options: start → reset options of the replays (None: the seed alone).
    """
    for env_id, kwargs, seed, start, actions, outcomes, t in candidates(entries, pick):
        replays = [
            (replay(env_id, seed, actions, start, options and options(start), **{**kwargs, **changed}), expected)
            for changed, expected in sides(kwargs, outcomes, t)
        ]
        if any(reasons is None for reasons, _ in replays):
            continue
        for reasons, expected in replays:
            assert reasons == expected
        return
    raise AssertionError("no recorded episode reaches the boundary case with the same start")


def new_minimum(values: list[float], below: float) -> int | None:
    """The last step whose value is below ``below`` and under every earlier value by more than 1e-5 (relative)."""
    best = None
    for t, value in enumerate(values):
        if value < below and all(value < v * (1 - 1e-5) for v in values[:t]):
            best = t
    return best


@pytest.mark.parametrize("case", list(CASES))
def test_singular_threshold_on_both_sides(case):
    """hard_threshold just above the oracle's k terminates "singular" at that step; just below, it does not."""
    safe = oracle.settings_of(make(CASES[case][0][0])).safe_threshold

    def pick(start, outcomes):
        ok = [o for o in outcomes if not o.reason]
        return new_minimum([o.k for o in ok], below=safe / (1 + MARGIN))

    def sides(kwargs, outcomes, t):
        k = outcomes[t].k
        return (
            ({"hard_threshold": k * (1 + MARGIN)}, [""] * t + ["singular"]),
            ({"hard_threshold": k * (1 - MARGIN)}, [""] * (t + 1)),
        )

    assert_both_sides(CASES[case], pick, sides)


@pytest.mark.parametrize("case", TYPE_ONE)
def test_actuator_singular_threshold_on_both_sides(case):
    """actuator_hard_threshold just above the oracle's k_I terminates "actuator_singular"; just below, not."""
    safe1 = oracle.settings_of(make(CASES[case][0][0])).actuator_safe_threshold

    def pick(start, outcomes):
        ok = [o for o in outcomes if not o.reason]
        return new_minimum([o.k1 for o in ok], below=safe1 / (1 + MARGIN))

    def sides(kwargs, outcomes, t):
        k1 = outcomes[t].k1
        return (
            ({"actuator_hard_threshold": k1 * (1 + MARGIN)}, [""] * t + ["actuator_singular"]),
            ({"actuator_hard_threshold": k1 * (1 - MARGIN)}, [""] * (t + 1)),
        )

    assert_both_sides(CASES[case][:1], pick, sides)


@pytest.mark.parametrize("case", list(CASES))
def test_pose_bounds_on_both_sides(case):
    """A pose bound just inside the oracle's pose ends the episode "out_of_bounds" at that step; just outside, not."""
    entry = CASES[case][0]
    params = make(entry[0]).params
    grid = params.task_region == "grid"  # a grid is certified within the pose bounds: the task is given
    chosen: list[tuple[str, int]] = []

    def pick(start, outcomes):
        # The new bound must keep the task box inside it (for a grid, the start and the target with a margin).
        if grid:
            ends = np.array([start.x, start.target])
            inner_low, inner_high = ends.min(axis=0) - 0.15, ends.max(axis=0) + 0.15
        else:
            inner_low, inner_high = np.asarray(params.sample_low), np.asarray(params.sample_high)
        ok = [o for o in outcomes if not o.reason]
        for t in range(len(ok) - 1, 0, -1):
            x, earlier = ok[t].x, np.array([start.x] + [o.x for o in ok[:t]])
            for j in range(len(x)):
                if x[j] > inner_high[j] and x[j] > earlier[:, j].max() + 1e-6:
                    chosen.append(("pose_high", j))
                    return t
                if x[j] < inner_low[j] and x[j] < earlier[:, j].min() - 1e-6:
                    chosen.append(("pose_low", j))
                    return t
        return None

    def sides(kwargs, outcomes, t):
        name, j = chosen[-1]
        sign = 1.0 if name == "pose_high" else -1.0
        inside, outside = list(getattr(params, name)), list(getattr(params, name))
        inside[j] = float(outcomes[t].x[j] + sign * 1e-7)
        outside[j] = float(outcomes[t].x[j] - sign * 1e-7)
        box = {}
        if grid:  # the sampling box must stay inside the bounds; the task itself is given
            low, high = list(params.sample_low), list(params.sample_high)
            if name == "pose_high":
                high[j] = min(high[j], outside[j])
            else:
                low[j] = max(low[j], outside[j])
            box = {"sample_low": tuple(low), "sample_high": tuple(high)}
        return (
            ({name: tuple(inside), **box}, [""] * (t + 1)),
            ({name: tuple(outside), **box}, [""] * t + ["out_of_bounds"]),
        )

    def options(start):
        return {"start": start.x, "target": start.target} if grid else None

    assert_both_sides([(entry[0], entry[1], ("drift", "random"))], pick, sides, options)


@pytest.mark.parametrize("case", list(CASES))
def test_jump_tolerance_on_both_sides(case):
    """jump_tolerance just below the oracle's largest correction ends the episode "assembly_mode_change"; above, not."""

    def pick(start, outcomes):
        ok = [o for o in outcomes if not o.reason]
        best = None
        for t, o in enumerate(ok):
            if o.jump > 1e-6 and all(o.jump > p.jump * (1 + 1e-5) for p in ok[:t]):
                best = t
        return best

    def sides(kwargs, outcomes, t):
        jump = outcomes[t].jump
        return (
            ({"jump_tolerance": jump * (1 + MARGIN)}, [""] * (t + 1)),
            ({"jump_tolerance": jump * (1 - MARGIN)}, [""] * t + ["assembly_mode_change"]),
        )

    assert_both_sides(CASES[case][:1], pick, sides)
